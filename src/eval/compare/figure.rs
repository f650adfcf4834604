//! The figure of a comparison (SVG, no fonts needed): the worst coordinates by RMSE, one panel
//! each, ours (solid) and the reference (dashed) over time, with the reference shifted by the mean
//! offset (dotted) so that a definition offset and a waveform error can be told apart.

use super::{Comparison, Motion};
use plotters::prelude::*;
use std::path::Path;

/// Errors drawing the figure.
#[derive(Debug, thiserror::Error)]
#[error("writing the figure {path}: {message}")]
pub struct FigureError {
    pub path: String,
    pub message: String,
}

/// Writes panels of the `worst` coordinates of `c` (by RMSE) to `path` (SVG).
pub fn write_figure(
    c: &Comparison,
    ours: &Motion,
    reference: &Motion,
    worst: usize,
    path: &Path,
) -> Result<(), FigureError> {
    let err = |e: &dyn std::fmt::Display| FigureError { path: path.display().to_string(), message: e.to_string() };
    let mut order: Vec<&super::CoordinateStats> = c.coordinates.iter().collect();
    order.sort_by(|a, b| b.rmse.total_cmp(&a.rmse).then_with(|| a.name.cmp(&b.name)));
    order.truncate(worst.max(1));
    let cols = if order.len() > 1 { 2 } else { 1 };
    let rows = order.len().div_ceil(cols);
    let root = SVGBackend::new(path, (560 * cols as u32, 300 * rows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let panels = root.split_evenly((rows, cols));
    for (stat, area) in order.iter().zip(&panels) {
        let (Some(a), Some(r)) = (ours.get(&stat.name), reference.get(&stat.name)) else { continue };
        let shift = c.reference_shift_s;
        let pa: Vec<(f64, f64)> =
            ours.times.iter().zip(&a.values).filter(|(_, v)| v.is_finite()).map(|(t, v)| (*t, *v)).collect();
        let pr: Vec<(f64, f64)> = reference
            .times
            .iter()
            .zip(&r.values)
            .filter(|(_, v)| v.is_finite())
            .map(|(t, v)| (t + shift, *v))
            .collect();
        let t0 = pa.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let t1 = pa.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let pr: Vec<(f64, f64)> = pr.into_iter().filter(|p| p.0 >= t0 && p.0 <= t1).collect();
        let shifted: Vec<(f64, f64)> = pr.iter().map(|(t, v)| (*t, v + stat.offset)).collect();
        let all = pa.iter().chain(&pr).chain(&shifted).map(|p| p.1);
        let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
        if !(lo.is_finite() && hi.is_finite() && t0 < t1) {
            continue;
        }
        let pad = 0.08 * (hi - lo).max(1.0);
        let title = format!(
            "{} ({}): RMSE {:.1}, offset {:+.1}, centred {:.1}",
            stat.name,
            stat.quantity.unit(),
            stat.rmse,
            stat.offset,
            stat.rmse_centred
        );
        let mut chart = ChartBuilder::on(area)
            .caption(title, ("sans-serif", 15))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(46)
            .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
            .map_err(|e| err(&e))?;
        chart.configure_mesh().x_desc("time (s)").draw().map_err(|e| err(&e))?;
        let blue = RGBColor(40, 90, 170);
        let red = RGBColor(200, 60, 40);
        chart
            .draw_series(LineSeries::new(pa, blue.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label("ours")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], blue.stroke_width(2)));
        chart
            .draw_series(DashedLineSeries::new(pr, 6, 4, red.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label("reference")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], red.stroke_width(2)));
        chart
            .draw_series(DashedLineSeries::new(shifted, 2, 3, red.mix(0.6).stroke_width(1)))
            .map_err(|e| err(&e))?
            .label("reference + offset")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], red.mix(0.6).stroke_width(1)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK.mix(0.3))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
