//! `isoray push` of molecules: Protein Data Bank (`.pdb`, `.ent`) and mmCIF (`.cif`) files,
//! read with pdbtbx, as a metaball scene.
//!
//! Each atom becomes a ball like the Molecule scenes of fitted-bvh-metaballs.txt §6: at the
//! atom's position, with support radius `--radius-scale` (default 2) times the element's
//! van der Waals radius (Bondi; with the Wyvill kernel and the isovalue 0.5 this scene is
//! created with, a lone atom's surface is then its van der Waals sphere) and the element's
//! CPK colour; radii and colours are the engine's own table (`kinds::metaballs::pdb`).
//! Each model of the file is a time step. Hydrogens and waters are left out unless
//! `--hydrogens` / `--waters`. Coordinates are moved so that the first model's centre is the
//! origin (the same shift for every model), and a new scene's camera frames the molecule.

use super::push_args::{create_scene, put_step, step_path, PushArgs};
use isoray_render::kinds::metaballs::pdb::Element;
use isoray_server::api::client::{npy_header_f32, Body, Client};
use pdbtbx::{
    ContainsAtomConformer, ContainsAtomConformerResidue, Context, Format, PDBError, ReadOptions,
    StrictnessLevel,
};
use std::path::Path;

/// Whether `path` names a molecule file.
pub fn is_molecule(path: &Path) -> bool {
    matches!(
        path.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .as_deref(),
        Some("pdb" | "ent" | "cif" | "mmcif")
    )
}

/// What to keep of a molecule, and how large its balls are.
#[derive(Clone, Copy, Debug)]
pub struct MoleculeOptions {
    pub hydrogens: bool,
    pub waters: bool,
    pub radius_scale: f32,
}

/// A ball's row of a metaball step: x y z radius strength r g b.
pub type Row = [f32; 8];

fn line_of(context: &Context) -> Option<usize> {
    match context {
        Context::FullLine { linenumber, .. } | Context::Line { linenumber, .. } => {
            Some(*linenumber)
        }
        Context::Range {
            start_linenumber, ..
        }
        | Context::RangeHighlights {
            start_linenumber, ..
        } => Some(*start_linenumber),
        _ => None,
    }
}

/// The first error that refuses the file (not a warning), naming its line (pdbtbx counts
/// lines from 1).
fn describe(errors: &[PDBError]) -> String {
    let refusing = errors.iter().find(|e| e.fails(StrictnessLevel::Loose));
    let Some(e) = refusing.or(errors.first()) else {
        return "unreadable".into();
    };
    let detail = e.long_description().trim();
    match line_of(e.context()) {
        Some(line) => format!("line {line}: {}: {detail}", e.short_description()),
        None => format!("{}: {detail}", e.short_description()),
    }
}

/// The models of a molecule file as rows of balls; errors name the file and line.
pub fn read_models(path: &Path, opts: MoleculeOptions) -> Result<Vec<Vec<Row>>, String> {
    let at = |e: String| format!("{}: {e}", path.display());
    let name = path
        .to_str()
        .ok_or_else(|| at("the path is not UTF-8".into()))?;
    let cif = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("cif") || e.eq_ignore_ascii_case("mmcif"));
    // pdbtbx 0.12 panics on some inputs (a chain id it does not accept, in `add_atom`);
    // a bad file must give an error, so such a panic becomes one.
    let read = std::panic::catch_unwind(|| {
        ReadOptions::default()
            .set_level(StrictnessLevel::Loose)
            .set_only_atomic_coords(true)
            .set_format(if cif { Format::Mmcif } else { Format::Pdb })
            .read(name)
    })
    .map_err(|_| at("pdbtbx could not read the file (it panicked; see above)".into()))?;
    let (pdb, _warnings) = read.map_err(|errors| at(describe(&errors)))?;
    let mut models = Vec::new();
    for model in pdb.models() {
        let mut rows = Vec::new();
        for h in model.atoms_with_hierarchy() {
            let water = h
                .residue()
                .name()
                .is_some_and(|n| matches!(n.trim(), "HOH" | "WAT" | "DOD" | "H2O"));
            if water && !opts.waters {
                continue;
            }
            let atom = h.atom();
            let symbol = atom
                .element()
                .map(|e| e.symbol().to_string())
                .unwrap_or_else(|| atom.name().trim().chars().take(1).collect());
            let element = Element::from_symbol(&symbol);
            if element == Element::H && !opts.hydrogens {
                continue;
            }
            let (x, y, z) = atom.pos();
            let c = element.cpk_color();
            rows.push([
                x as f32,
                y as f32,
                z as f32,
                opts.radius_scale * element.van_der_waals_radius(),
                1.0,
                c.x,
                c.y,
                c.z,
            ]);
        }
        if rows.is_empty() {
            return Err(at(format!(
                "model {} has no atoms to show (hydrogens and waters are left out without \
                 --hydrogens and --waters)",
                models.len() + 1
            )));
        }
        models.push(rows);
    }
    if models.is_empty() {
        return Err(at("no atoms".into()));
    }
    // The first model's centre at the origin, every model moved alike.
    let first = &models[0];
    let n = first.len() as f64;
    let centre = [0, 1, 2].map(|k| (first.iter().map(|r| f64::from(r[k])).sum::<f64>() / n) as f32);
    for row in models.iter_mut().flatten() {
        for k in 0..3 {
            row[k] -= centre[k];
        }
    }
    Ok(models)
}

/// A new scene's description: Wyvill balls at isovalue 0.5, the camera framing the first
/// model.
fn spec(models: &[Vec<Row>], name: &str) -> String {
    let reach = models[0]
        .iter()
        .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt() + r[3])
        .fold(1.0f32, f32::max);
    let distance = 2.6 * reach;
    serde_json::json!({
        "kind": "metaballs",
        "name": name,
        "isovalue": 0.5,
        "camera": {"eye": [0.0, 0.0, distance], "target": [0.0, 0.0, 0.0]},
    })
    .to_string()
}

/// Pushes a molecule file's models as steps of a metaball scene.
pub fn run(args: &PushArgs) -> Result<(), String> {
    let [file] = args.files.as_slice() else {
        return Err("give one molecule file (.pdb or .cif); its models become the steps".into());
    };
    let opts = MoleculeOptions {
        hydrogens: args.hydrogens,
        waters: args.waters,
        radius_scale: args.radius_scale,
    };
    if !(opts.radius_scale.is_finite() && opts.radius_scale > 0.0) {
        return Err(format!(
            "--radius-scale {} must be positive",
            opts.radius_scale
        ));
    }
    let models = read_models(file, opts)?;
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let (scene, token) = match (&args.scene, &args.token) {
        (Some(scene), Some(token)) => (scene.clone(), token.clone()),
        (Some(_), None) => {
            return Err("--scene needs --token (or ISORAY_TOKEN): the scene's write token".into())
        }
        (None, _) => {
            let stem = file
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            create_scene(&client, args, spec(&models, &stem).as_bytes())?
        }
    };
    let auth = format!("Bearer {token}");
    for (i, rows) in models.iter().enumerate() {
        let index = args.start + i as u64;
        let mut body = npy_header_f32(rows.len() as u64, 8);
        body.extend(rows.iter().flatten().flat_map(|v| v.to_le_bytes()));
        let time = args.time_step.map(|dt| index as f64 * dt);
        let answer = put_step(
            &client,
            &step_path(&scene, index, time, args.replace),
            &auth,
            "application/x-npy",
            Body::Bytes(&body),
            &format!("model {} ({})", i + 1, file.display()),
        )?;
        println!(
            "step {index}: {} (model {}, {} atoms, checksum {})",
            answer["outcome"].as_str().unwrap_or("?"),
            i + 1,
            rows.len(),
            answer["step"]["checksum"].as_str().unwrap_or("?")
        );
    }
    println!("pushed {} models to scene {scene}", models.len());
    Ok(())
}
