//! The bench figure (SVG, no fonts needed): per dataset, the distribution of per-frame solve
//! time (left, log scale) and of per-frame marker RMSE (right) as boxes (p25–p75, median line,
//! whiskers p10–p90), with OpenSim's figures on the same datasets (crosses) and the range of the
//! published SmoCap medians (grey band).

use super::{BenchReport, DatasetBench, Row};
use crate::pipeline::stats::percentile;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Errors drawing the figure.
#[derive(Debug, thiserror::Error)]
#[error("writing the figure {path}: {message}")]
pub struct FigureError {
    pub path: String,
    pub message: String,
}

/// One panel's data: per dataset, its values and OpenSim's value; the published median range.
struct Panel<'a> {
    title: &'a str,
    datasets: Vec<(&'a str, &'a [f64], Option<f64>)>,
    published: Option<(f64, f64)>,
    /// Plot `log10(value)` (labels show the value).
    log: bool,
}

/// Writes the figure of `report` to `path` (SVG).
pub fn write_figure(report: &BenchReport, path: &Path) -> Result<(), FigureError> {
    let err = |e: &dyn std::fmt::Display| FigureError { path: path.display().to_string(), message: e.to_string() };
    let runs: Vec<&DatasetBench> = report.datasets.iter().filter(|d| !d.frame_ms.is_empty()).collect();
    let opensim =
        |name: &str, f: fn(&Row) -> Option<f64>| report.opensim.iter().find(|r| r.dataset == name).and_then(f);
    let range = |f: fn(&Row) -> Option<f64>| {
        let v: Vec<f64> = report.published.iter().filter_map(f).collect();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo <= hi).then_some((lo, hi))
    };
    let time = Panel {
        title: "per-frame solve time (ms, log scale)",
        datasets: runs.iter().map(|d| (d.name.as_str(), &d.frame_ms[..], opensim(&d.name, |r| r.ms_p50))).collect(),
        published: range(|r| r.ms_p50),
        log: true,
    };
    let rmse = Panel {
        title: "per-frame marker RMSE (mm)",
        datasets: runs
            .iter()
            .map(|d| (d.name.as_str(), &d.frame_rmse_mm[..], opensim(&d.name, |r| r.rmse_mm_p50)))
            .collect(),
        published: range(|r| r.rmse_mm_p50),
        log: false,
    };
    let root = SVGBackend::new(path, (1200, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (left, right) = root.split_horizontally(600);
    draw_panel(&left, &time).map_err(|e| err(&e))?;
    draw_panel(&right, &rmse).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

type DrawResult = Result<(), DrawingAreaErrorKind<std::io::Error>>;

fn draw_panel(area: &DrawingArea<SVGBackend<'_>, Shift>, p: &Panel<'_>) -> DrawResult {
    let tf = |v: f64| if p.log { v.max(1e-6).log10() } else { v };
    let mut all: Vec<f64> = p
        .datasets
        .iter()
        .flat_map(|(_, v, o)| [percentile(v, 0.02), percentile(v, 0.98)].into_iter().chain(*o))
        .collect();
    if let Some((lo, hi)) = p.published {
        all.extend([lo, hi]);
    }
    let all: Vec<f64> = all.into_iter().filter(|v| v.is_finite() && (!p.log || *v > 0.0)).map(tf).collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo < hi { (lo, hi) } else { (lo.min(0.0) - 1.0, hi.max(0.0) + 1.0) };
    let pad = 0.08 * (hi - lo);
    let (y0, y1) = if p.log { (lo - pad, hi + pad) } else { ((lo - pad).max(0.0), hi + pad) };
    let n = p.datasets.len().max(1);
    let names: Vec<&str> = p.datasets.iter().map(|d| d.0).collect();
    let mut chart = ChartBuilder::on(area)
        .caption(p.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), y0..y1)?;
    let x_label = |v: &f64| {
        let i = v.round();
        if (v - i).abs() < 1e-6 && i >= 0.0 {
            names.get(i as usize).map_or(String::new(), |s| s.to_string())
        } else {
            String::new()
        }
    };
    let y_label = |v: &f64| if p.log { format!("{:.3}", 10f64.powf(*v)) } else { format!("{v:.0}") };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n)
        .x_label_formatter(&x_label)
        .y_label_formatter(&y_label)
        .draw()?;
    if let Some((a, b)) = p.published {
        let band = [(-0.5, tf(a)), (n as f64 - 0.5, tf(b))];
        chart
            .draw_series(std::iter::once(Rectangle::new(band, RGBColor(200, 200, 200).mix(0.5).filled())))?
            .label("SmoCap published p50 range")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], RGBColor(200, 200, 200).filled()));
    }
    let blue = RGBColor(40, 90, 170);
    let mut boxes = Vec::new();
    for (i, (_, v, _)) in p.datasets.iter().enumerate() {
        let q = [0.1, 0.25, 0.5, 0.75, 0.9].map(|f| tf(percentile(v, f)));
        let x = i as f64;
        boxes.push(Rectangle::new([(x - 0.25, q[1]), (x + 0.25, q[3])], blue.mix(0.3).filled()));
        boxes.push(Rectangle::new([(x - 0.25, q[1]), (x + 0.25, q[3])], blue.stroke_width(1)));
        for (a, b) in [((x - 0.25, q[2]), (x + 0.25, q[2])), ((x, q[0]), (x, q[1])), ((x, q[3]), (x, q[4]))] {
            chart.draw_series(std::iter::once(PathElement::new(vec![a, b], blue.stroke_width(2))))?;
        }
        for y in [q[0], q[4]] {
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(x - 0.1, y), (x + 0.1, y)],
                blue.stroke_width(1),
            )))?;
        }
    }
    chart
        .draw_series(boxes)?
        .label("smocap (box p25–p75, median, whiskers p10–p90)")
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], blue.mix(0.3).filled()));
    let crosses: Vec<(f64, f64)> =
        p.datasets.iter().enumerate().filter_map(|(i, d)| d.2.map(|o| (i as f64, tf(o)))).collect();
    if !crosses.is_empty() {
        chart
            .draw_series(crosses.into_iter().map(|c| Cross::new(c, 7, RED.stroke_width(2))))?
            .label("OpenSim 4.6 IK (time: mean; RMSE: p50)")
            .legend(|(x, y)| Cross::new((x + 7, y), 5, RED.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 12))
        .draw()?;
    Ok(())
}
