//! The body mesh measured on a converted trial: the model markers' signed distances to the
//! subject's posed skin over every frame ([`crate::body::skin_distance`]), the body's height
//! against the subject's stature and the virtual markers' spatial error
//! ([`crate::body::virtual_markers`]). `export --skin-report FILE.json` writes it for one trial,
//! `convert --body` for every converted trial ([`convert_pass`]).

use crate::archive::convert::{BodyOutcome, ConvertSummary};
use crate::body::skin_distance::{marker_skin_distances, pooled, quantiles, MARKER_RADIUS};
use anyhow::Context as _;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Writes the report of `rec` (read from `file`) to `out` and a summary line to stderr.
pub fn write(
    rec: &crate::archive::export::TrialRecord,
    file: &Path,
    out: &Path,
    sub: crate::body::SubjectBody,
) -> anyhow::Result<()> {
    let report = body_report(rec, file, sub)?;
    write_json(out, &report)?;
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

/// Writes `report` to `out` (pretty JSON) through a temporary file renamed over it.
fn write_json(out: &Path, report: &serde_json::Value) -> anyhow::Result<()> {
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let tmp = out.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(report)? + "\n")
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, out).with_context(|| format!("writing {}", out.display()))
}

/// The body report of `rec` (read from `file`) as JSON.
pub fn body_report(
    rec: &crate::archive::export::TrialRecord,
    file: &Path,
    sub: crate::body::SubjectBody,
) -> anyhow::Result<serde_json::Value> {
    let take = crate::render::Take::from_record(rec, file)?;
    let asset = crate::body::BodyAsset::shipped()?;
    let (body, line) = take
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
    let height = body.bind_pose_height(&take.model, &take.scales);
    let motion = in_motion(&take, &body);
    Ok(serde_json::json!({
        "trial": take.name,
        "frames": states.len(),
        "body": {
            "summary": line,
            "height_m": height,
            "stature_m": body.target_stature,
            "height_minus_stature_mm": mm(height - body.target_stature),
            "shape_fit": body.fit,
        },
        "marker_radius_mm": MARKER_RADIUS * 1e3,
        "distance": "signed, marker centre to the nearest point of the posed skin (positive outside); off_skin = |distance - radius|",
        "landmarks": group(&|m| m.landmark && !m.computed),
        "others": group(&|m| !m.landmark && !m.computed),
        "computed_points": group(&|m| m.computed),
        "virtual_marker_error_mm": motion.virtual_all.map(mm),
        "virtual_landmark_error_mm": motion.virtual_landmarks.map(mm),
        "mesh_in_motion": {
            "edges_within_half_to_twice_rest": (motion.edges_in_range * 1e6).round() / 1e6,
            "volume_over_rest_min": (motion.volume.0 * 1e4).round() / 1e4,
            "volume_over_rest_max": (motion.volume.1 * 1e4).round() / 1e4,
        },
        "markers": per,
    }))
}

/// The body over the trial's frames: the thesis' "marker spatial error" (the mean distance, m,
/// over frames and skin markers from each virtual marker, fixed on the posed skin, to the
/// model's marker; all of them and the landmarks; `None` where there are none), the share of
/// edge-frames within 0.5–2× their rest length and the enclosed volume over the rest volume.
struct InMotion {
    virtual_all: Option<f64>,
    virtual_landmarks: Option<f64>,
    edges_in_range: f64,
    volume: (f64, f64),
}

fn in_motion(take: &crate::render::Take, body: &crate::body::Dressed) -> InMotion {
    use crate::body::metrics::{edge_ratios, edges, volume};
    let vm = crate::body::virtual_markers::VirtualMarkers::new(&take.model, body, &take.scales);
    let mut ws = crate::body::PoseWorkspace::new(&take.model, body);
    let mut kin = crate::kinematics::cpu::Workspace::new(&take.model);
    body.pose(&take.model, &body.bind_state(&take.model, &take.scales), &mut ws);
    let rest = ws.vertices.clone();
    let rest_volume = volume(&rest, &body.triangles);
    let e = edges(&body.triangles);
    let (mut points, mut ratios, mut y) = (Vec::new(), Vec::new(), vec![0.0; take.model.ny()]);
    let nq = take.model.nq();
    let (mut all, mut landmarks) = ((0.0, 0usize), (0.0, 0usize));
    let (mut in_range, mut n_edges, mut vol) = (0usize, 0usize, (f64::INFINITY, f64::NEG_INFINITY));
    for i in 0..take.len() {
        y[..nq].copy_from_slice(&take.q[i]);
        y[nq..].copy_from_slice(&take.scales);
        body.pose(&take.model, &y, &mut ws);
        vm.evaluate(&ws.vertices, &mut points);
        let pose = take.pose(i, &mut kin);
        for (v, p) in vm.markers.iter().zip(&points) {
            let e = (p - pose.markers[v.marker]).norm();
            all = (all.0 + e, all.1 + 1);
            if v.landmark {
                landmarks = (landmarks.0 + e, landmarks.1 + 1);
            }
        }
        edge_ratios(&rest, &ws.vertices, &e, &mut ratios);
        in_range += ratios.iter().filter(|r| (0.5..=2.0).contains(*r)).count();
        n_edges += ratios.len();
        let v = volume(&ws.vertices, &body.triangles) / rest_volume;
        vol = (vol.0.min(v), vol.1.max(v));
    }
    let mean = |(s, n): (f64, usize)| (n > 0).then(|| s / n as f64);
    InMotion {
        virtual_all: mean(all),
        virtual_landmarks: mean(landmarks),
        edges_in_range: in_range as f64 / n_edges.max(1) as f64,
        volume: vol,
    }
}

/// Bounds past which `convert --body` calls a trial's body `suspect` (issue 33's acceptance):
/// height against stature (mm), the landmarks' median and 90th percentile |d − radius| (mm),
/// the virtual markers' mean error (mm), the share of edge-frames within 0.5–2× rest, the
/// enclosed volume's change from rest.
const SUSPECT_HEIGHT_MM: f64 = 10.0;
const SUSPECT_LANDMARK_MEDIAN_MM: f64 = 8.0;
const SUSPECT_LANDMARK_P90_MM: f64 = 20.0;
const SUSPECT_VIRTUAL_MM: f64 = 10.0;
const SUSPECT_EDGES_IN_RANGE: f64 = 0.999;
const SUSPECT_VOLUME_CHANGE: f64 = 0.05;

/// `convert --body`: the body report of every converted trial of `summary` written beside its
/// file (`<trial>.body.json`), its figures and verdict in the trial's `body`, on `jobs` threads.
/// Resuming, a trial whose report exists is read back (`skipped`).
pub fn convert_pass(summary: &mut ConvertSummary, jobs: usize, resume: bool) -> anyhow::Result<()> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build()?;
    pool.install(|| {
        summary.trials.par_iter_mut().filter(|t| t.status != "failed").for_each(|t| {
            let mcap = PathBuf::from(&t.output);
            let out = mcap.with_extension("body.json");
            let existing = (resume && t.status == "skipped")
                .then(|| std::fs::read(&out).ok())
                .flatten()
                .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
            t.body = Some(match existing {
                Some(report) => outcome(&report, "skipped"),
                None => match measure(&mcap, &out) {
                    Ok(report) => outcome(&report, "ok"),
                    Err(e) => BodyOutcome::failed(format!("{e:#}")),
                },
            });
        })
    });
    Ok(())
}

/// Reads `mcap`, writes its body report to `out` and returns it.
fn measure(mcap: &Path, out: &Path) -> anyhow::Result<serde_json::Value> {
    let rec = crate::archive::export::read_trial_record(mcap)?;
    let sub = crate::body::SubjectBody { stature_m: rec.subject_stature_m, info: rec.subject_info };
    let report = body_report(&rec, mcap, sub)?;
    write_json(out, &report)?;
    Ok(report)
}

/// The summary's figures of a body report, `status` unless a figure is past its bound.
fn outcome(report: &serde_json::Value, status: &str) -> BodyOutcome {
    let height = report["body"]["height_minus_stature_mm"].as_f64();
    let (median, p90) =
        (report["landmarks"]["median_off_skin_mm"].as_f64(), report["landmarks"]["p90_off_skin_mm"].as_f64());
    let virtual_mm = report["virtual_marker_error_mm"].as_f64();
    let mut past = Vec::new();
    let mut check = |what: &str, v: Option<f64>, bound: f64| {
        if let Some(v) = v.filter(|v| v.abs() > bound) {
            past.push(format!("{what} {v} mm (bound {bound} mm)"));
        }
    };
    check("height − stature", height, SUSPECT_HEIGHT_MM);
    check("landmarks' median |d − radius|", median, SUSPECT_LANDMARK_MEDIAN_MM);
    check("landmarks' p90 |d − radius|", p90, SUSPECT_LANDMARK_P90_MM);
    check("virtual markers' error", virtual_mm, SUSPECT_VIRTUAL_MM);
    let mesh = &report["mesh_in_motion"];
    if let Some(e) = mesh["edges_within_half_to_twice_rest"].as_f64().filter(|&e| e < SUSPECT_EDGES_IN_RANGE) {
        past.push(format!(
            "edge-frames within 0.5–2× rest {:.2} % (bound {} %)",
            100.0 * e,
            100.0 * SUSPECT_EDGES_IN_RANGE
        ));
    }
    let (lo, hi) = (mesh["volume_over_rest_min"].as_f64(), mesh["volume_over_rest_max"].as_f64());
    if let (Some(lo), Some(hi)) = (lo, hi) {
        if (1.0 - lo).max(hi - 1.0) > SUSPECT_VOLUME_CHANGE {
            past.push(format!("volume {lo}–{hi} × rest (bound ±{} %)", 100.0 * SUSPECT_VOLUME_CHANGE));
        }
    }
    let note = if past.is_empty() {
        report["body"]["summary"].as_str().unwrap_or("").to_string()
    } else {
        format!("past the bounds: {}", past.join("; "))
    };
    BodyOutcome {
        status: if past.is_empty() { status.into() } else { "suspect".into() },
        note,
        height_minus_stature_mm: height,
        landmark_median_off_skin_mm: median,
        landmark_p90_off_skin_mm: p90,
        virtual_marker_error_mm: virtual_mm,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(height_mm: f64, p90_mm: f64, edges: f64, volume_min: f64) -> serde_json::Value {
        serde_json::json!({
            "body": { "summary": "body: shaped", "height_minus_stature_mm": height_mm },
            "landmarks": { "median_off_skin_mm": 1.0, "p90_off_skin_mm": p90_mm },
            "virtual_marker_error_mm": 3.0,
            "mesh_in_motion": {
                "edges_within_half_to_twice_rest": edges,
                "volume_over_rest_min": volume_min,
                "volume_over_rest_max": 1.0,
            },
        })
    }

    #[test]
    fn a_body_within_every_bound_keeps_its_status_and_summary() {
        let o = outcome(&report(2.0, 6.0, 0.9995, 0.97), "ok");
        assert_eq!((o.status.as_str(), o.note.as_str()), ("ok", "body: shaped"));
        assert_eq!(o.height_minus_stature_mm, Some(2.0));
    }

    #[test]
    fn a_body_past_a_bound_is_suspect_and_says_which() {
        let o = outcome(&report(-12.0, 25.0, 0.998, 0.90), "skipped");
        assert_eq!(o.status, "suspect");
        for what in ["height − stature -12 mm", "p90", "edge-frames within 0.5–2× rest 99.80 %", "volume 0.9–1"]
        {
            assert!(o.note.contains(what), "{what}: {}", o.note);
        }
    }
}
