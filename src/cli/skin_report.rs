//! `export --skin-report FILE.json`: the model markers' signed distances to the subject's posed
//! skin over every frame of a converted trial ([`crate::body::skin_distance`]).

use crate::body::skin_distance::{marker_skin_distances, pooled, quantiles, MARKER_RADIUS};
use anyhow::Context as _;
use std::path::Path;

/// Writes the report of `rec` (read from `file`) to `out` and a summary line to stderr.
pub fn write(
    rec: &crate::archive::export::TrialRecord,
    file: &Path,
    out: &Path,
    sub: crate::body::SubjectBody,
) -> anyhow::Result<()> {
    let take = crate::render::Take::from_record(rec, file)?;
    let asset = crate::body::BodyAsset::shipped()?;
    let (body, _) = take
        .dress(&asset, &sub, &crate::body::FitSettings::default())
        .context("binding the body mesh to the trial's model")?;
    let nq = take.model.nq();
    let states: Vec<Vec<f64>> = take
        .q
        .iter()
        .map(|q| {
            let mut y = q[..nq].to_vec();
            y.extend_from_slice(&take.scales);
            y
        })
        .collect();
    let markers = marker_skin_distances(&take.model, &body, states.iter().map(|y| y.as_slice()));
    let mm = |x: f64| (x * 1e4).round() / 10.0;
    let per: Vec<serde_json::Value> = markers
        .iter()
        .map(|m| {
            let (med, p90) = m.off_skin();
            let (signed, _) = quantiles(m.distances.clone());
            serde_json::json!({
                "marker": m.name, "body": m.body, "landmark": m.landmark, "computed": m.computed, "frames": m.distances.len(),
                "median_off_skin_mm": mm(med), "p90_off_skin_mm": mm(p90), "median_signed_mm": mm(signed),
            })
        })
        .collect();
    let group = |pick: &dyn Fn(&crate::body::skin_distance::MarkerSkin) -> bool| {
        let (med, p90, n) = pooled(&markers, pick);
        serde_json::json!({ "markers": n, "median_off_skin_mm": mm(med), "p90_off_skin_mm": mm(p90) })
    };
    let report = serde_json::json!({
        "trial": take.name,
        "frames": states.len(),
        "marker_radius_mm": MARKER_RADIUS * 1e3,
        "distance": "signed, marker centre to the nearest point of the posed skin (positive outside); off_skin = |distance - radius|",
        "landmarks": group(&|m| m.landmark && !m.computed),
        "others": group(&|m| !m.landmark && !m.computed),
        "computed_points": group(&|m| m.computed),
        "markers": per,
    });
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    std::fs::write(out, serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!(
        "wrote {}: off the skin (|d − 7 mm|) median / p90: landmarks {} / {} mm, others {} / {} mm (computed points apart)",
        out.display(),
        report["landmarks"]["median_off_skin_mm"],
        report["landmarks"]["p90_off_skin_mm"],
        report["others"]["median_off_skin_mm"],
        report["others"]["p90_off_skin_mm"]
    );
    Ok(())
}
