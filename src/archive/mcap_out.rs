//! One solved trial as an MCAP file (zstd chunks, log time = frame time in ns from the trial's
//! first sample time): our channels with JSON Schemas (`/smocap/state`, `/smocap/residuals`,
//! `/smocap/stats`), Foxglove's `foxglove.FrameTransforms` on `/tf` (each body's pose in `world`)
//! and `foxglove.SceneUpdate` on `/scene` (observed and model markers as spheres, bones as lines),
//! JSON-encoded; a `smocap.run` metadata record; the settings and the scaled model attached.
//!
//! Frames are written as they are solved ([`TrialWriter`]), so memory does not grow with the
//! trial's length (the writer holds one zstd chunk, ≤ 1 MiB, and one index entry per chunk). The
//! file is written as `<name>.partial` and renamed only once its summary is written, so a file
//! with the final name is always complete; a writer dropped unfinished removes its temporary file.

use super::schemas;
use crate::io::MarkerTrial;
use crate::kinematics::cpu::{self, Workspace};
use crate::pipeline::{Context, SolvedFrame};
use mcap::records::{MessageHeader, Metadata};
use nalgebra::{Rotation3, UnitQuaternion};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Errors writing an MCAP file.
#[derive(Debug, thiserror::Error)]
pub enum McapOutError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {source}{}", cause(source))]
    Mcap { file: String, source: mcap::McapError },
}

/// The underlying error of an MCAP error (e.g. "no space left on device"), as ": <cause>".
fn cause(e: &mcap::McapError) -> String {
    std::error::Error::source(e).map(|c| format!(": {c}")).unwrap_or_default()
}

/// What the `smocap.run` metadata record holds (all strings).
pub type RunInfo = BTreeMap<String, String>;

/// The temporary name a trial's output is written under.
pub fn partial_path(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

fn stamp(t: f64) -> Value {
    let ns = (t.max(0.0) * 1e9).round() as u64;
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn v3(p: &[f64]) -> Value {
    json!({"x": p[0], "y": p[1], "z": p[2]})
}

/// A trial's MCAP file being written, frame by frame as frames are solved. Created as
/// `<out>.partial`; [`TrialWriter::finish`] writes the summary and renames it to `out`. Dropped
/// unfinished (an error, a panic), it removes the temporary file.
pub struct TrialWriter<'a> {
    ctx: &'a Context,
    trial: &'a MarkerTrial,
    /// Trial column of each model marker.
    cols: Vec<Option<usize>>,
    w: Option<mcap::Writer<BufWriter<std::fs::File>>>,
    tmp: PathBuf,
    out: PathBuf,
    /// Channels: state, residuals, stats, /tf, /scene.
    ch: [u16; 5],
    ws: Workspace,
    y: Vec<f64>,
    dphi: Vec<f64>,
    t0: f64,
}

impl<'a> TrialWriter<'a> {
    /// Starts `out` (as its temporary file) for `trial` (named `name`), solved with `ctx`.
    pub fn create(out: &Path, ctx: &'a Context, name: &str, trial: &'a MarkerTrial) -> Result<Self, McapOutError> {
        let tmp = partial_path(out);
        let file = tmp.display().to_string();
        let io = |source| McapOutError::Io { file: file.clone(), source };
        let mc = |source| McapOutError::Mcap { file: file.clone(), source };
        let f = std::fs::File::create(&tmp).map_err(io)?;
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(format!("smocap {}", env!("CARGO_PKG_VERSION")));
        let w = opts.create(BufWriter::new(f)).map_err(mc);
        let model = &ctx.model;
        let mut tw = TrialWriter {
            ctx,
            trial,
            cols: crate::pipeline::trial::match_markers(ctx, name, trial).map(|m| m.columns).unwrap_or_default(),
            w: None,
            tmp: tmp.clone(),
            out: out.to_path_buf(),
            ch: [0; 5],
            ws: Workspace::new(model),
            y: vec![0.0; model.ny()],
            dphi: vec![0.0; ctx.proxy.terms.len()],
            t0: trial.times.first().copied().unwrap_or(0.0),
        };
        // From here on, dropping `tw` removes the temporary file.
        tw.w = Some(w?);
        let w = tw.w.as_mut().expect("just set");
        let meta: BTreeMap<String, String> = [
            ("length_unit", "m"),
            ("angle_unit", "rad"),
            ("frame", "world: the model's frame (the marker data rotated into it)"),
            ("up", &ctx.up.map_or("none".into(), |u| format!("[{}, {}, {}]", u.x + 0.0, u.y + 0.0, u.z + 0.0))),
            ("log_time", "ns since the trial's first sample time"),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        let mut channel = |name: &str, topic: &str, schema: &Value| -> Result<u16, McapOutError> {
            let id = w.add_schema(name, "jsonschema", schema.to_string().as_bytes()).map_err(mc)?;
            w.add_channel(id, topic, "json", &meta).map_err(mc)
        };
        tw.ch = [
            channel("smocap.State", "/smocap/state", &schemas::state())?,
            channel("smocap.Residuals", "/smocap/residuals", &schemas::residuals())?,
            channel("smocap.SolverStats", "/smocap/stats", &schemas::stats())?,
            channel("foxglove.FrameTransforms", "/tf", &schemas::frame_transforms())?,
            channel("foxglove.SceneUpdate", "/scene", &schemas::scene_update())?,
        ];
        Ok(tw)
    }

    fn mcap_err(&self, source: mcap::McapError) -> McapOutError {
        McapOutError::Mcap { file: self.tmp.display().to_string(), source }
    }

    /// Writes one solved frame: a message on each channel, log time = the frame's time.
    pub fn frame(&mut self, fr: &SolvedFrame) -> Result<(), McapOutError> {
        let (ctx, trial) = (self.ctx, self.trial);
        let model = &ctx.model;
        let f = fr.index;
        let p = &fr.proxies;
        let t = trial.times.get(f).copied().unwrap_or(f as f64 / trial.rate_hz.max(1e-9)) - self.t0;
        ctx.proxy.apply(p, &mut self.y, &mut self.dphi);
        cpu::forward(model, &self.y, &mut self.ws);
        let (y, ws) = (&self.y, &self.ws);
        let s = &fr.stats;
        let ts = stamp(t);
        let q: serde_json::Map<String, Value> =
            model.coordinates.iter().enumerate().map(|(j, c)| (c.name.clone(), json!(y[j]))).collect();
        let scales: serde_json::Map<String, Value> = model
            .bodies
            .iter()
            .enumerate()
            .map(|(b, body)| (body.name.clone(), json!([0, 1, 2].map(|a| y[model.scale_index(b, a)]))))
            .collect();
        let pm: serde_json::Map<String, Value> =
            ctx.proxy.proxies.iter().zip(p).map(|(px, v)| (px.name.clone(), json!(v))).collect();
        let state = json!({"time": t, "frame": f, "q": q, "s": scales, "p": pm});
        let mut markers = Vec::new();
        let (mut spheres, mut sq, mut n) = (Vec::new(), 0.0, 0usize);
        for (m, mk) in model.markers.iter().enumerate() {
            let mp = &ws.markers[3 * m..3 * m + 3];
            let obs = self.cols.get(m).copied().flatten().and_then(|c| trial.position(f, c));
            let err = obs.map(|o| [o[0] - mp[0], o[1] - mp[1], o[2] - mp[2]]);
            if let Some(e) = err {
                sq += e.iter().map(|v| v * v).sum::<f64>();
                n += 1;
            }
            markers.push(json!({"name": mk.name, "observed": obs, "model": mp, "error": err}));
            spheres.push(sphere(mp, [1.0, 0.5, 0.0]));
            if let Some(o) = obs {
                spheres.push(sphere(&o, [0.2, 0.4, 1.0]));
            }
        }
        let rmse = if n > 0 { (sq / n as f64).sqrt() } else { f64::NAN };
        let residuals = json!({"time": t, "frame": f, "rmse": finite(rmse), "markers": markers});
        let stats = json!({
            "time": t, "frame": f, "iterations": s.iterations, "accepted_steps": s.accepted,
            "energy": finite(s.energy), "rmse": finite(s.rmse_m), "markers_used": s.markers_used,
            "solve_s": fr.seconds, "status": format!("{:?}", s.status), "bridged": fr.bridged,
        });
        let transforms: Vec<Value> = model
            .bodies
            .iter()
            .enumerate()
            .map(|(b, body)| {
                let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(ws.body_rot[b]));
                json!({"timestamp": ts, "parent_frame_id": "world", "child_frame_id": body.name,
                    "translation": v3(ws.body_pos[b].as_slice()),
                    "rotation": {"x": r.i, "y": r.j, "z": r.k, "w": r.w}})
            })
            .collect();
        let bones: Vec<Value> = model
            .bodies
            .iter()
            .enumerate()
            .filter_map(|(b, body)| {
                body.parent.map(|pa| [v3(ws.body_pos[pa].as_slice()), v3(ws.body_pos[b].as_slice())])
            })
            .flatten()
            .collect();
        let scene = json!({"deletions": [], "entities": [{
            "timestamp": ts, "frame_id": "world", "id": "subject", "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": false, "metadata": [], "arrows": [], "cubes": [], "spheres": spheres,
            "cylinders": [], "lines": [{"type": 2, "pose": identity(), "thickness": 0.01, "scale_invariant": false,
                "points": bones, "color": {"r": 0.8, "g": 0.8, "b": 0.8, "a": 1.0}, "colors": [], "indices": []}],
            "triangles": [], "texts": [], "models": []}]});
        let ns = (t.max(0.0) * 1e9).round() as u64;
        let [ch_state, ch_res, ch_stats, ch_tf, ch_scene] = self.ch;
        for (ch, msg) in [
            (ch_state, state),
            (ch_res, residuals),
            (ch_stats, stats),
            (ch_tf, json!({"transforms": transforms})),
            (ch_scene, scene),
        ] {
            let header = MessageHeader { channel_id: ch, sequence: f as u32, log_time: ns, publish_time: ns };
            let w = self.w.as_mut().expect("present until finished");
            w.write_to_known_channel(&header, msg.to_string().as_bytes()).map_err(|e| self.mcap_err(e))?;
        }
        Ok(())
    }

    /// Writes the `smocap.run` metadata (`run`), attaches `settings_json` and `scaled_model`
    /// (OpenSim `.osim` text), writes the summary, syncs, and renames the file to its final name.
    pub fn finish(
        mut self,
        run: &RunInfo,
        settings_json: &str,
        scaled_model: Option<&str>,
    ) -> Result<(), McapOutError> {
        let file = self.tmp.display().to_string();
        let io = |source| McapOutError::Io { file: file.clone(), source };
        let mc = |source| McapOutError::Mcap { file: file.clone(), source };
        let mut w = self.w.take().expect("present until finished");
        // On an error below, `w` and then `self` drop, which removes the temporary file.
        w.write_metadata(&Metadata { name: "smocap.run".into(), metadata: run.clone() }).map_err(mc)?;
        let attach = |w: &mut mcap::Writer<_>, name: &str, media: &str, data: &[u8]| {
            w.attach(&mcap::Attachment {
                log_time: 0,
                create_time: 0,
                name: name.into(),
                media_type: media.into(),
                data: std::borrow::Cow::Borrowed(data),
            })
        };
        attach(&mut w, "settings.json", "application/json", settings_json.as_bytes()).map_err(mc)?;
        if let Some(m) = scaled_model {
            attach(&mut w, "scaled_model.osim", "application/xml", m.as_bytes()).map_err(mc)?;
        }
        w.finish().map_err(mc)?;
        let f = w.into_inner().into_inner().map_err(|e| io(e.into_error()))?;
        f.sync_all().map_err(io)?;
        drop(f);
        std::fs::rename(&self.tmp, &self.out)
            .map_err(|source| McapOutError::Io { file: self.out.display().to_string(), source })?;
        self.tmp = PathBuf::new();
        Ok(())
    }
}

impl Drop for TrialWriter<'_> {
    fn drop(&mut self) {
        drop(self.w.take());
        if !self.tmp.as_os_str().is_empty() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

fn finite(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

fn identity() -> Value {
    json!({"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}})
}

fn sphere(p: &[f64], rgb: [f64; 3]) -> Value {
    json!({"pose": {"position": v3(p), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
        "size": {"x": 0.02, "y": 0.02, "z": 0.02}, "color": {"r": rgb[0], "g": rgb[1], "b": rgb[2], "a": 1.0}})
}
