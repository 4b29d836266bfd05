//! `isoray-bench accuracy`: what accuracy costs in time, for every kind, against references
//! that share no code with the tracers (issue 13).
//!
//! Per kind, every setting that trades accuracy for speed (`metaballs`: root finder and
//! tolerance, marching's and the secant method's step, `f64` hit refinement; `tets`: single
//! rays against packets, normals; `surfels`: MLS iterations and threshold; `codecs`: JPEG
//! quality and H.264 bit rate against PSNR): time per frame, silhouette pixels lost and
//! gained, hit-distance error (mean, p99, max, relative to the scene's extent), normal angle,
//! and searches that hit their iteration cap. `--out` writes a CSV and a log–log SVG (Pareto
//! front marked) per kind; `--doc` rewrites the generated block of docs/accuracy.md (with
//! `--kinds`, only those kinds' sections, marked as re-run alone). The one
//! command that regenerates it all is in docs/accuracy.md.

use crate::common::{write_json, Machine};
use clap::Args;
use isoray_render::{Backend, CpuBackend};
use serde::Serialize;
use std::path::{Path, PathBuf};

mod codecs;
mod metaballs;
mod plot;
mod stats;
mod surfels;
mod tets;

use stats::Row;

/// The block of docs/accuracy.md this command rewrites.
const BEGIN: &str = "<!-- isoray-bench accuracy: begin (generated, do not edit) -->";
const END: &str = "<!-- isoray-bench accuracy: end -->";

#[derive(Args)]
pub struct AccuracyArgs {
    /// Kinds to study: metaballs, tets, surfels, codecs (default: all).
    #[arg(long, value_delimiter = ',')]
    kinds: Vec<String>,
    /// Metaball scene ids (default: the six paper scenes).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Hit-distance tolerances of every root finder, world units.
    #[arg(long, value_delimiter = ',', default_values_t = [1e-1, 1e-2, 1e-3, 1e-4, 1e-5])]
    tolerances: Vec<f32>,
    /// Steps of marching and the secant method, fractions of the smallest radius.
    #[arg(long, value_delimiter = ',', default_values_t = [1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625, 0.0078125])]
    steps: Vec<f32>,
    /// Timed frames per setting; the median is reported.
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Compare every n-th pixel in x and y with the reference.
    #[arg(long, default_value_t = 4)]
    sample: u32,
    /// Surfel demos at this fraction of their full size.
    #[arg(long, default_value_t = 0.1)]
    surfel_detail: f32,
    /// Frames encoded per codec setting.
    #[arg(long, default_value_t = 8)]
    frames: usize,
    /// Folder for `<kind>.csv` and `<kind>.svg` (created).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Markdown file whose generated block (between its markers) is rewritten with the tables.
    #[arg(long)]
    doc: Option<PathBuf>,
    /// Also write every row as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Also write every row as CSV to this file.
    #[arg(long)]
    csv: Option<PathBuf>,
}

#[derive(Serialize)]
struct Report<'a> {
    machine: Machine,
    rows: &'a [Row],
}

const KINDS: [&str; 4] = ["metaballs", "tets", "surfels", "codecs"];

pub fn run(args: AccuracyArgs) -> Result<(), String> {
    if args.runs == 0 || args.sample == 0 {
        return Err("--runs and --sample must be at least 1".into());
    }
    if let Some(t) = args
        .tolerances
        .iter()
        .chain(&args.steps)
        .find(|t| !(t.is_finite() && **t > 0.0))
    {
        return Err(format!("tolerance or step {t} must be a positive number"));
    }
    if !(args.surfel_detail > 0.0 && args.surfel_detail <= 1.0) {
        return Err(format!(
            "--surfel-detail {} must be in (0, 1]",
            args.surfel_detail
        ));
    }
    let kinds: Vec<&str> = if args.kinds.is_empty() {
        KINDS.to_vec()
    } else {
        let mut v = Vec::new();
        for k in &args.kinds {
            v.push(
                *KINDS
                    .iter()
                    .find(|n| **n == k.as_str())
                    .ok_or_else(|| format!("unknown kind {k:?}: use {}", KINDS.join(", ")))?,
            );
        }
        v
    };
    let demos = crate::metaballs::pick(&args.scenes)?;
    let backend = Backend::Cpu(CpuBackend::new(0).map_err(|e| e.to_string())?);
    let machine = Machine::here();
    let started = std::time::Instant::now();
    let mut all: Vec<(&str, Vec<Row>)> = Vec::new();
    let mut notes: Vec<String> = Vec::new();
    for kind in kinds {
        let rows = match kind {
            "metaballs" => {
                let settings = metaballs::Settings {
                    tolerances: args.tolerances.clone(),
                    steps: {
                        let mut s = args.steps.clone();
                        s.push(f32::INFINITY); // the secant method's centre projections only
                        s
                    },
                };
                let rows = metaballs::rows(&demos, &settings, args.runs, args.sample);
                notes.extend(metaballs::step_bounds(&rows));
                rows
            }
            // The tet reference tests every tet per ray (100k): a coarser grid.
            "tets" => tets::rows(&backend, args.runs, args.sample.max(12))?,
            "surfels" => surfels::rows(&backend, args.surfel_detail, args.runs, args.sample)?,
            _ => codecs::rows(&backend, args.frames)?,
        };
        all.push((kind, rows));
    }
    let (header, sections) = document(
        &machine,
        &args,
        &all,
        &notes,
        started.elapsed().as_secs_f64(),
    )?;
    let mut doc = header.clone();
    doc.extend(sections.iter().map(|(_, text)| text.as_str()));
    println!("{doc}");
    if let Some(path) = &args.doc {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let (Some(b), Some(e)) = (text.find(BEGIN), text.find(END)) else {
            return Err(format!(
                "{} has no generated block ({BEGIN} … {END})",
                path.display()
            ));
        };
        // A run of some kinds replaces only their sections, each marked as re-run alone.
        let block = if args.kinds.is_empty() {
            doc
        } else {
            let note = format!(
                "Re-run alone (`--kinds {}`). {header}",
                args.kinds.join(",")
            );
            merge(&text[b + BEGIN.len()..e], &sections, &note)
        };
        let updated = format!("{}{BEGIN}\n{block}\n{}", &text[..b], &text[e..]);
        std::fs::write(path, updated).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    let rows: Vec<Row> = all.iter().flat_map(|(_, r)| r.iter().cloned()).collect();
    if let Some(path) = &args.csv {
        std::fs::write(path, stats::csv(&rows)).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    if let Some(path) = &args.json {
        write_json(
            path,
            &Report {
                machine,
                rows: &rows,
            },
        )?;
    }
    Ok(())
}

/// The generated block `old` (without its markers) with the sections of `fresh` in place of
/// those of the same kinds (appended where it has none), `note` under each fresh heading;
/// the other sections and the block's first lines stay as they were.
fn merge(old: &str, fresh: &[(String, String)], note: &str) -> String {
    let old = old.trim_start_matches('\n').trim_end();
    let mut starts: Vec<usize> = old.match_indices("\n### ").map(|(i, _)| i).collect();
    let lead = &old[..starts.first().copied().unwrap_or(old.len())];
    starts.push(old.len());
    let mut sections: Vec<(String, String)> = starts
        .windows(2)
        .map(|w| {
            let text = &old[w[0]..w[1]];
            let kind = text["\n### ".len()..].lines().next().unwrap_or("").trim();
            (kind.to_string(), format!("{}\n", text.trim_end()))
        })
        .collect();
    for (kind, text) in fresh {
        let heading = format!("\n### {kind}\n\n");
        let body = text.strip_prefix(heading.as_str()).unwrap_or(text);
        let marked = format!("{heading}{}\n\n{body}", note.trim_end());
        match sections.iter_mut().find(|(k, _)| k == kind) {
            Some(slot) => slot.1 = marked,
            None => sections.push((kind.clone(), marked)),
        }
    }
    let mut out = lead.to_string();
    out.extend(sections.iter().map(|(_, text)| text.as_str()));
    out
}

/// The markdown of the study: its first lines, then a section per kind (tables, plot links,
/// the step bounds), writing each kind's CSV and SVG under `--out`.
fn document(
    machine: &Machine,
    args: &AccuracyArgs,
    all: &[(&str, Vec<Row>)],
    notes: &[String],
    seconds: f64,
) -> Result<(String, Vec<(String, String)>), String> {
    let mut sections = Vec::new();
    let header = format!(
        "Measured on {} by `isoray-bench accuracy` in {seconds:.0} s; times are medians of {} \
         frame(s), errors on every {}th pixel in x and y.\n",
        machine.line(),
        args.runs,
        args.sample
    );
    for (kind, rows) in all {
        if rows.is_empty() {
            continue;
        }
        let mut doc = String::new();
        let points = plot::points(rows);
        let front = plot::pareto(&points);
        let (x_label, y_label) = if *kind == "codecs" {
            (
                "encode ms per frame (one core)",
                "RMS error / full scale = 10^(-PSNR/20)",
            )
        } else {
            (
                "ms per frame (summed over the scenes)",
                "p99 |Δt| / scene extent (worst scene)",
            )
        };
        doc.push_str(&format!("\n### {kind}\n\n"));
        if let Some(out) = &args.out {
            std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
            let csv = out.join(format!("{kind}.csv"));
            std::fs::write(&csv, stats::csv(rows))
                .map_err(|e| format!("{}: {e}", csv.display()))?;
            let svg = out.join(format!("{kind}.svg"));
            let title = format!("{kind}: error against time (filled: no silhouette pixel lost)");
            std::fs::write(&svg, plot::svg(&title, x_label, y_label, &points)?)
                .map_err(|e| format!("{}: {e}", svg.display()))?;
            let link = |p: &Path| relative(p, args.doc.as_deref());
            doc.push_str(&format!(
                "![{kind}: error against time]({}) (rows per scene: [{kind}.csv]({}))\n\n",
                link(&svg),
                link(&csv)
            ));
        }
        if *kind == "codecs" {
            doc.push_str(&codec_table(rows));
        } else {
            doc.push_str(&stats::summary_table(rows));
        }
        doc.push_str("\nPareto front (fastest first): ");
        doc.push_str(
            &front
                .iter()
                .map(|p| {
                    format!(
                        "{} {} ({:.1} ms, {:.1e})",
                        p.family, p.setting, p.ms, p.error
                    )
                })
                .collect::<Vec<_>>()
                .join("; "),
        );
        doc.push('\n');
        if *kind == "metaballs" {
            for n in notes {
                doc.push_str(&format!("\n- Step bound: {n}"));
            }
            doc.push('\n');
        }
        sections.push((kind.to_string(), doc));
    }
    Ok((header, sections))
}

/// `path` relative to the folder of `doc` when it lies below it.
fn relative(path: &Path, doc: Option<&Path>) -> String {
    doc.and_then(|d| d.parent())
        .and_then(|base| path.strip_prefix(base).ok())
        .unwrap_or(path)
        .display()
        .to_string()
}

fn codec_table(rows: &[Row]) -> String {
    let mut out = String::from(
        "| codec | setting | encode ms/frame | KB/frame | Mbit/s at 30 fps | PSNR dB |\n|---|---|---:|---:|---:|---:|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {:.2} | {:.1} | {:.2} | {:.1} |\n",
            r.family,
            r.setting,
            r.ms,
            r.bytes / 1e3,
            r.bytes * 8.0 * 30.0 / 1e6,
            r.psnr_db
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_run_of_some_kinds_replaces_only_their_sections() {
        let old = "\nMeasured on A in 85 s.\n\n### metaballs\n\n| m |\n\n- Step bound: x\n\n### surfels\n\nold note\n\n| s old |\n\n### codecs\n\n| c |\n";
        let fresh = vec![
            (
                "surfels".to_string(),
                "\n### surfels\n\n| s new |\n".to_string(),
            ),
            ("tets".to_string(), "\n### tets\n\n| t |\n".to_string()),
        ];
        let merged = super::merge(
            old,
            &fresh,
            "Re-run alone (`--kinds surfels,tets`). Measured on B.",
        );
        assert_eq!(
            merged,
            "Measured on A in 85 s.\n\n### metaballs\n\n| m |\n\n- Step bound: x\n\n### surfels\n\nRe-run alone (`--kinds surfels,tets`). Measured on B.\n\n| s new |\n\n### codecs\n\n| c |\n\n### tets\n\nRe-run alone (`--kinds surfels,tets`). Measured on B.\n\n| t |\n"
        );
    }

    #[test]
    fn bad_arguments_are_named() {
        let args = |runs, sample, tolerances: Vec<f32>| super::AccuracyArgs {
            kinds: vec![],
            scenes: vec![],
            tolerances,
            steps: vec![0.25],
            runs,
            sample,
            surfel_detail: 0.1,
            frames: 1,
            out: None,
            doc: None,
            json: None,
            csv: None,
        };
        assert!(super::run(args(0, 8, vec![1e-3])).is_err());
        assert!(super::run(args(1, 0, vec![1e-3])).is_err());
        let e = super::run(args(1, 8, vec![-1.0])).expect_err("a negative tolerance is refused");
        assert!(e.contains("-1"), "{e}");
    }
}
