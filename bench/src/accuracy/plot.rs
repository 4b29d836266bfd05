//! The log–log error-against-time plot of one kind, with the Pareto front marked, as SVG
//! (plotters with its SVG backend only: no font or bitmap stack to build).

use crate::accuracy::stats::Row;
use plotters::prelude::*;

/// One setting over all scenes: summed time per frame, worst plotted error, and whether it
/// kept every silhouette pixel on every scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub family: String,
    pub setting: String,
    pub ms: f64,
    pub error: f64,
    pub keeps: bool,
}

/// The rows' settings as points, in first-seen order.
pub fn points(rows: &[Row]) -> Vec<Point> {
    let mut out: Vec<Point> = Vec::new();
    for r in rows {
        match out
            .iter_mut()
            .find(|p| p.family == r.family && p.setting == r.setting)
        {
            Some(p) => {
                p.ms += r.ms;
                p.error = p.error.max(r.plotted_error());
                p.keeps &= r.keeps_silhouette();
            }
            None => out.push(Point {
                family: r.family.clone(),
                setting: r.setting.clone(),
                ms: r.ms,
                error: r.plotted_error(),
                keeps: r.keeps_silhouette(),
            }),
        }
    }
    out
}

/// The Pareto front of the points that keep the silhouette: no other such point is both
/// faster and more accurate (ties kept). Sorted by time.
pub fn pareto(points: &[Point]) -> Vec<Point> {
    let eligible: Vec<&Point> = points.iter().filter(|p| p.keeps).collect();
    let mut front: Vec<Point> = eligible
        .iter()
        .filter(|p| {
            !eligible
                .iter()
                .any(|q| q.ms <= p.ms && q.error <= p.error && (q.ms < p.ms || q.error < p.error))
        })
        .map(|p| (*p).clone())
        .collect();
    front.sort_by(|a, b| a.ms.total_cmp(&b.ms));
    front
}

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// The SVG text of the plot.
pub fn svg(title: &str, x_label: &str, y_label: &str, points: &[Point]) -> Result<String, String> {
    let mut text = String::new();
    draw(&mut text, title, x_label, y_label, points).map_err(|e| format!("plot {title}: {e}"))?;
    Ok(text)
}

fn draw(
    text: &mut String,
    title: &str,
    x_label: &str,
    y_label: &str,
    points: &[Point],
) -> Result<(), Box<dyn std::error::Error>> {
    let range = |f: &dyn Fn(&Point) -> f64| {
        let lo = points.iter().map(f).fold(f64::INFINITY, f64::min);
        let hi = points.iter().map(f).fold(0.0, f64::max);
        if lo.is_finite() && hi > 0.0 {
            (lo / 1.5, hi * 1.5)
        } else {
            (1e-3, 1.0)
        }
    };
    let (x0, x1) = range(&|p| p.ms);
    let (y0, y1) = range(&|p| p.error);
    let root = SVGBackend::with_string(text, (900, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(72)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .x_label_formatter(&|v| format!("{v:.3}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    let mut families: Vec<&str> = Vec::new();
    for p in points {
        if !families.contains(&p.family.as_str()) {
            families.push(&p.family);
        }
    }
    for (k, family) in families.iter().enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        let of: Vec<&Point> = points.iter().filter(|p| p.family == *family).collect();
        chart
            .draw_series(LineSeries::new(
                of.iter().map(|p| (p.ms, p.error)),
                colour.stroke_width(1),
            ))?
            .label(*family)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        chart.draw_series(of.iter().map(|p| {
            let style = if p.keeps {
                colour.filled()
            } else {
                colour.stroke_width(1)
            };
            Circle::new((p.ms, p.error), 4, style)
        }))?;
    }
    let front = pareto(points);
    chart
        .draw_series(LineSeries::new(
            front.iter().map(|p| (p.ms, p.error)),
            BLACK.stroke_width(2),
        ))?
        .label("Pareto front (settings that keep every silhouette pixel)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(2)));
    chart.draw_series(
        front
            .iter()
            .map(|p| Circle::new((p.ms, p.error), 7, BLACK.stroke_width(2))),
    )?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(ms: f64, error: f64, keeps: bool) -> Point {
        Point {
            family: "f".into(),
            setting: format!("{ms}"),
            ms,
            error,
            keeps,
        }
    }

    #[test]
    fn the_front_keeps_only_undominated_settings_that_keep_the_silhouette() {
        let pts = vec![
            p(1.0, 1e-2, true),
            p(2.0, 1e-3, true),
            p(3.0, 1e-3, true),  // dominated by (2, 1e-3)
            p(0.5, 1e-6, false), // loses pixels: not eligible
            p(4.0, 1e-5, true),
        ];
        let front: Vec<f64> = pareto(&pts).iter().map(|p| p.ms).collect();
        assert_eq!(front, vec![1.0, 2.0, 4.0]);
    }

    #[test]
    fn the_plot_is_an_svg_with_every_family() {
        let mut pts = vec![p(1.0, 1e-2, true), p(2.0, 1e-4, false)];
        pts[1].family = "g".into();
        let text = svg("t", "ms", "error", &pts).expect("draws");
        assert!(text.starts_with("<svg"), "{}", &text[..40.min(text.len())]);
        // plotters writes each label on its own line inside its <text> element.
        assert!(
            text.contains("\nf\n") && text.contains("\ng\n"),
            "legend names the families"
        );
    }
}
