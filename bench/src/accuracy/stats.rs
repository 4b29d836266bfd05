//! One row of the accuracy study, how a setting's answers are compared with the reference's,
//! and the CSV and markdown the rows become.

use glam::DVec3;
use serde::Serialize;

/// A hit as the study compares it: distance along the ray and unit normal.
pub type Answer = Option<(f64, DVec3)>;

/// One setting on one scene.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Row {
    pub kind: &'static str,
    pub scene: String,
    /// The series the plot draws (one setting varied).
    pub family: String,
    /// This setting's value in the family.
    pub setting: String,
    /// Time per frame, ms (median of the runs).
    pub ms: f64,
    /// Rays compared with the reference.
    pub rays: usize,
    /// Rays both hit.
    pub both: usize,
    /// Silhouette pixels lost (the reference hits, the setting misses) and gained.
    pub lost: usize,
    pub gained: usize,
    /// Hit-distance error over rays both hit, world units.
    pub mean: f64,
    pub p99: f64,
    pub max: f64,
    /// The scene's extent (largest side of its bounds), world units.
    pub extent: f64,
    /// Angle between the setting's normal and the reference's, degrees.
    pub normal_mean_deg: f64,
    pub normal_max_deg: f64,
    /// Searches that stopped at their iteration cap during the timed frame.
    pub capped: u64,
    pub iterations_per_hit: f64,
    /// Codecs only: mean PSNR (dB) and bytes per frame.
    pub psnr_db: f64,
    pub bytes: f64,
}

impl Row {
    /// The error the plot draws: the 99th-percentile hit-distance error relative to the
    /// scene's extent, or for codecs the RMS error relative to full scale (`10^(−PSNR/20)`).
    pub fn plotted_error(&self) -> f64 {
        if self.kind == "codecs" {
            10f64.powf(-self.psnr_db / 20.0)
        } else {
            (self.p99 / self.extent.max(1e-30)).max(1e-12)
        }
    }

    /// Whether the setting lost no silhouette pixel (codecs: always).
    pub fn keeps_silhouette(&self) -> bool {
        self.lost == 0
    }
}

/// Fills `row`'s comparison columns from the setting's `answers` and the `reference`'s.
pub fn compare(row: &mut Row, answers: &[Answer], reference: &[Answer]) {
    let (mut errors, mut angles) = (Vec::new(), Vec::new());
    let (mut lost, mut gained) = (0, 0);
    for (a, r) in answers.iter().zip(reference) {
        match (a, r) {
            (Some((ta, na)), Some((tr, nr))) => {
                errors.push((ta - tr).abs());
                if na.length_squared() > 0.0 && nr.length_squared() > 0.0 {
                    let cos = na.normalize().dot(nr.normalize()).clamp(-1.0, 1.0);
                    angles.push(cos.acos().to_degrees());
                }
            }
            (None, None) => {}
            (None, Some(_)) => lost += 1,
            (Some(_), None) => gained += 1,
        }
    }
    errors.sort_by(f64::total_cmp);
    angles.sort_by(f64::total_cmp);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    row.rays = answers.len();
    row.both = errors.len();
    row.lost = lost;
    row.gained = gained;
    row.mean = mean(&errors);
    row.p99 = percentile(&errors, 0.99);
    row.max = errors.last().copied().unwrap_or(0.0);
    row.normal_mean_deg = mean(&angles);
    row.normal_max_deg = angles.last().copied().unwrap_or(0.0);
}

/// The `q`-quantile of sorted `v` (nearest rank), 0 when empty.
fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

pub const CSV_HEADER: &str = "kind,scene,family,setting,ms_per_frame,rays,both_hit,lost,gained,\
mean_error,p99_error,max_error,extent,p99_relative,max_relative,normal_mean_deg,normal_max_deg,\
capped,iterations_per_hit,psnr_db,bytes_per_frame\n";

/// The rows as CSV (one header line).
pub fn csv(rows: &[Row]) -> String {
    let mut text = String::from(CSV_HEADER);
    for r in rows {
        let extent = r.extent.max(1e-30);
        text.push_str(&format!(
            "{},{},{},{},{:.3},{},{},{},{},{:e},{:e},{:e},{:.4},{:e},{:e},{:.4},{:.4},{},{:.3},{:.3},{:.0}\n",
            r.kind,
            r.scene,
            r.family,
            r.setting,
            r.ms,
            r.rays,
            r.both,
            r.lost,
            r.gained,
            r.mean,
            r.p99,
            r.max,
            r.extent,
            r.p99 / extent,
            r.max / extent,
            r.normal_mean_deg,
            r.normal_max_deg,
            r.capped,
            r.iterations_per_hit,
            r.psnr_db,
            r.bytes
        ));
    }
    text
}

/// A markdown table with one line per setting: over the scenes, the summed time per frame,
/// the summed silhouette pixels lost and gained, and the worst relative errors and angles.
pub fn summary_table(rows: &[Row]) -> String {
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in rows {
        let k = (r.family.clone(), r.setting.clone());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    let scenes = {
        let mut s: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
        s.dedup();
        s.len()
    };
    let mut out = format!(
        "| setting | | ms/frame (sum of {scenes} scene(s)) | rays lost / gained | mean \\|Δt\\|/extent | p99 \\|Δt\\|/extent | max \\|Δt\\|/extent | normal ° mean / max | capped |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    for (family, setting) in keys {
        let of: Vec<&Row> = rows
            .iter()
            .filter(|r| r.family == family && r.setting == setting)
            .collect();
        let worst = |f: &dyn Fn(&Row) -> f64| of.iter().map(|r| f(r)).fold(0.0, f64::max);
        let ms: f64 = of.iter().map(|r| r.ms).sum();
        let lost: usize = of.iter().map(|r| r.lost).sum();
        let gained: usize = of.iter().map(|r| r.gained).sum();
        let capped: u64 = of.iter().map(|r| r.capped).sum();
        out.push_str(&format!(
            "| {family} | {setting} | {ms:.1} | {lost} / {gained} | {:.1e} | {:.1e} | {:.1e} | {:.2} / {:.1} | {capped} |\n",
            worst(&|r| r.mean / r.extent.max(1e-30)),
            worst(&|r| r.p99 / r.extent.max(1e-30)),
            worst(&|r| r.max / r.extent.max(1e-30)),
            worst(&|r| r.normal_mean_deg),
            worst(&|r| r.normal_max_deg),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compare_counts_lost_gained_and_errors() {
        let n = Some((1.0, DVec3::Z));
        let reference = vec![n, n, None, Some((2.0, DVec3::Z)), None];
        let answers = vec![
            Some((1.5, DVec3::Z)),
            None,
            Some((3.0, DVec3::X)),
            Some((2.25, DVec3::X)),
            None,
        ];
        let mut row = Row::default();
        compare(&mut row, &answers, &reference);
        assert_eq!((row.rays, row.both, row.lost, row.gained), (5, 2, 1, 1));
        assert_eq!(row.max, 0.5);
        assert_eq!(row.mean, 0.375);
        assert_eq!(row.p99, 0.5);
        assert!((row.normal_max_deg - 90.0).abs() < 1e-9);
    }

    #[test]
    fn percentile_is_the_nearest_rank() {
        let v: Vec<f64> = (1..=200).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.99), 198.0);
        assert_eq!(percentile(&[3.0], 0.99), 3.0);
        assert_eq!(percentile(&[], 0.5), 0.0);
    }
}
