//! A converted trial back out of its MCAP file: the `/smocap/state` channel (named by
//! `/smocap/subject`, with the frame's marker RMSE and status from `/smocap/stats`) as an OpenSim motion (`.mot`,
//! the columns and degrees of `smocap solve --mot-dir`) or a CSV table.

use super::mcap_out::SCALED_MODEL_ATTACHMENT;
use super::proto;
use crate::io::sto::{self, StoError};
use crate::model::Model;
use crate::pipeline::results::export::coordinate_table;
use prost::Message as _;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Errors reading a converted trial or writing its export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {source}")]
    Mcap { file: String, source: mcap::McapError },
    #[error("{file}: {what}")]
    Content { file: String, what: String },
    #[error("{file}: {source}")]
    Csv { file: String, source: csv::Error },
    #[error(transparent)]
    Sto(#[from] StoError),
    #[error(transparent)]
    Read(#[from] super::inspect::InspectError),
}

/// One frame of the state channel (times in s since the trial's first sample).
#[derive(Clone, Debug, Deserialize)]
pub struct StateMsg {
    pub time: f64,
    pub frame: usize,
    /// Coordinates by name (rad or m).
    pub q: BTreeMap<String, f64>,
    /// Scale factors `[x, y, z]` by body.
    pub s: BTreeMap<String, [f64; 3]>,
}

/// One frame as read back: the state, RMS marker error (m) and solver status.
#[derive(Clone, Debug)]
pub struct Frame {
    pub state: StateMsg,
    pub rmse_m: Option<f64>,
    pub status: Option<String>,
}

/// A converted trial read back.
#[derive(Clone, Debug)]
pub struct TrialRecord {
    /// Frames in frame order.
    pub frames: Vec<Frame>,
    /// The trial's first sample time (s), added to the messages' times (0 when not recorded).
    pub time_offset: f64,
    /// The scaled model attachment (`scaled_model.osim.zst`, decompressed), when the file has one.
    pub scaled_model: Option<String>,
    /// Where the converted model came from (`smocap.run` → `model`).
    pub model_source: Option<String>,
    /// Model marker names in `/smocap/subject` order: the order of the points of `/markers`
    /// (empty for files of the JSON encoding).
    pub marker_names: Vec<String>,
    /// The rotation from the model's frame to the Z-up `world` as `[x, y, z, w]`
    /// (`/smocap/subject`'s `world_from_model`), when recorded.
    pub world_from_model: Option<[f64; 4]>,
    /// Observed markers per frame index (`/markers`): x y z (m, model frame) per marker in
    /// [`Self::marker_names`] order, NaN where not observed.
    pub observed: BTreeMap<usize, Vec<f32>>,
    /// The `/smocap/subject` message (names, calibrated scales), when the file has one.
    pub subject: Option<proto::Subject>,
    /// The `/smocap/stats` messages by frame (protobuf files).
    pub stats: BTreeMap<usize, proto::SolverStats>,
    /// The `/smocap/label_qc` message, when the file has one.
    pub label_qc: Option<proto::LabelQc>,
    /// The `/smocap/unfittable` message (runs of unfittable frames), when the file has one.
    pub unfittable: Option<proto::Unfittable>,
    /// What the body mesh is shaped to: the calibrated stature and the given subject
    /// (`smocap.run` → `subject_stature_m`, `subject_height_m`, `subject_mass_kg`, `subject_sex`).
    pub subject_stature_m: Option<f64>,
    pub subject_info: crate::model::anthropometry::SubjectInfo,
}

/// Reads the frames of `path` (a file written by `smocap convert`: protobuf channels, or the
/// JSON channels of files written before protobuf was the encoding); its MCAP structure is
/// checked first ([`super::inspect::read_checked`]).
pub fn read_trial_record(path: &Path) -> Result<TrialRecord, ExportError> {
    parse_trial_record(&super::inspect::read_checked(path)?, &path.display().to_string())
}

/// The frames of the MCAP file `buf` (named `file` in errors), structure checked first.
pub fn parse_trial_record(buf: &[u8], file: &str) -> Result<TrialRecord, ExportError> {
    let file = file.to_string();
    super::mcap_check::check(buf)
        .map_err(|source| super::inspect::InspectError::Format { file: file.clone(), source })?;
    let mc = |source| ExportError::Mcap { file: file.clone(), source };
    let bad = |what: String| ExportError::Content { file: file.clone(), what };
    let summary = mcap::Summary::read(buf).map_err(mc)?;
    let (mut time_offset, mut scaled_model, mut model_source) = (0.0, None, None);
    let (mut subject_stature_m, mut subject_info) = (None, crate::model::anthropometry::SubjectInfo::default());
    if let Some(summary) = &summary {
        for idx in &summary.metadata_indexes {
            let m = mcap::read::metadata(buf, idx).map_err(mc)?;
            if m.name != "smocap.run" {
                continue;
            }
            if let Some(v) = m.metadata.get("first_sample_time_s") {
                time_offset = v.parse().map_err(|_| bad(format!("first_sample_time_s '{v}' is not a number")))?;
            }
            model_source = m.metadata.get("model").cloned();
            let num = |k: &str| m.metadata.get(k).and_then(|v| v.parse::<f64>().ok()).filter(|v| v.is_finite());
            subject_stature_m = num("subject_stature_m");
            subject_info.height_m = num("subject_height_m");
            subject_info.mass_kg = num("subject_mass_kg");
            subject_info.sex = m.metadata.get("subject_sex").and_then(|v| v.parse().ok());
        }
        for a in &summary.attachment_indexes {
            let compressed = match a.name.as_str() {
                SCALED_MODEL_ATTACHMENT => true,
                "scaled_model.osim" => false,
                _ => continue,
            };
            let data = mcap::read::attachment(buf, a).map_err(mc)?.data;
            let text = if compressed {
                // Bounded: a corrupt size field cannot make it allocate without limit.
                zstd::bulk::decompress(&data, 256 << 20).map_err(|e| bad(format!("{}: {e}", a.name)))?
            } else {
                data.into_owned()
            };
            scaled_model = Some(String::from_utf8_lossy(&text).into_owned());
        }
    }
    let mut states = BTreeMap::new();
    let mut rmse = BTreeMap::new();
    let mut status = BTreeMap::new();
    let mut subject: Option<proto::Subject> = None;
    let mut label_qc: Option<proto::LabelQc> = None;
    let mut unfittable: Option<proto::Unfittable> = None;
    let mut raw_states: Vec<proto::State> = Vec::new();
    let mut observed = BTreeMap::new();
    let mut stats = BTreeMap::new();
    #[derive(Deserialize)]
    struct Tagged {
        frame: usize,
        rmse: Option<f64>,
        status: Option<String>,
    }
    for msg in mcap::MessageStream::new(buf).map_err(mc)? {
        let msg = msg.map_err(mc)?;
        let topic = msg.channel.topic.as_str();
        let what = |e: &dyn std::fmt::Display| bad(format!("{topic} message {}: {e}", msg.sequence));
        if msg.channel.message_encoding == "protobuf" {
            let data = &msg.data[..];
            match topic {
                "/smocap/subject" => subject = Some(proto::Subject::decode(data).map_err(|e| what(&e))?),
                "/smocap/label_qc" => label_qc = Some(proto::LabelQc::decode(data).map_err(|e| what(&e))?),
                "/smocap/unfittable" => unfittable = Some(proto::Unfittable::decode(data).map_err(|e| what(&e))?),
                "/smocap/state" => raw_states.push(proto::State::decode(data).map_err(|e| what(&e))?),
                "/markers" => {
                    let c = proto::PointCloud::decode(data).map_err(|e| what(&e))?;
                    observed.insert(msg.sequence as usize, cloud_xyz(&c).map_err(|e| what(&e))?);
                }
                "/smocap/stats" => {
                    let s = proto::SolverStats::decode(data).map_err(|e| what(&e))?;
                    let f = s.frame as usize;
                    rmse.insert(f, s.marker_rmse.is_finite().then_some(s.marker_rmse));
                    status.insert(f, proto::STATUS_NAMES.get(s.status as usize).map(|n| n.to_string()));
                    stats.insert(f, s);
                }
                _ => {}
            }
            continue;
        }
        match topic {
            "/smocap/state" => {
                let s: StateMsg = serde_json::from_slice(&msg.data).map_err(|e| what(&e))?;
                states.insert(s.frame, s);
            }
            "/smocap/residuals" => {
                let t: Tagged = serde_json::from_slice(&msg.data).map_err(|e| what(&e))?;
                rmse.insert(t.frame, t.rmse);
            }
            "/smocap/stats" => {
                let t: Tagged = serde_json::from_slice(&msg.data).map_err(|e| what(&e))?;
                status.insert(t.frame, t.status);
            }
            _ => {}
        }
    }
    let (mut marker_names, mut world_from_model) = (Vec::new(), None);
    if let Some(sub) = &subject {
        marker_names = sub.markers.clone();
        if let [x, y, z, w] = sub.world_from_model[..] {
            world_from_model = Some([x, y, z, w]);
        }
    }
    if !raw_states.is_empty() {
        let sub = subject.as_ref().ok_or_else(|| bad("/smocap/state without a /smocap/subject message".into()))?;
        for s in raw_states {
            let st = state_by_name(sub, &s).map_err(|e| bad(format!("/smocap/state frame {}: {e}", s.frame)))?;
            states.insert(st.frame, st);
        }
    }
    if states.is_empty() {
        return Err(bad("no /smocap/state messages (not a file written by smocap convert?)".into()));
    }
    let frames = states
        .into_iter()
        .map(|(f, state)| Frame { state, rmse_m: rmse.get(&f).copied().flatten(), status: status.remove(&f).flatten() })
        .collect();
    Ok(TrialRecord {
        frames,
        time_offset,
        scaled_model,
        model_source,
        marker_names,
        world_from_model,
        observed,
        subject,
        stats,
        label_qc,
        unfittable,
        subject_stature_m,
        subject_info,
    })
}

/// The points of a `/markers` cloud as float32 x y z triples (the layout `smocap convert`
/// writes: fields x, y, z as FLOAT32 at offsets 0, 4, 8, stride 12).
fn cloud_xyz(c: &proto::PointCloud) -> Result<Vec<f32>, String> {
    if c.point_stride != 12 || !c.data.len().is_multiple_of(12) {
        return Err(format!(
            "point stride {} and {} bytes: expected packed float32 x y z",
            c.point_stride,
            c.data.len()
        ));
    }
    Ok(c.data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
}

/// A protobuf state with its arrays named after `sub`: coordinates by name, each body's scale
/// factors from its scale proxies (or its fixed value).
fn state_by_name(sub: &proto::Subject, s: &proto::State) -> Result<StateMsg, String> {
    if s.q.len() != sub.coordinates.len() {
        return Err(format!("{} coordinates for {} named", s.q.len(), sub.coordinates.len()));
    }
    let q = sub.coordinates.iter().cloned().zip(s.q.iter().copied()).collect();
    let scales = body_scales(sub, Some(&s.scale_drift_ppm))?;
    Ok(StateMsg { time: s.time, frame: s.frame as usize, q, s: scales })
}

/// Each body's scale factors `[x, y, z]` by name: its scale proxies' calibrated values (times
/// `1 + drift` for a frame's `drift_ppm`, `State.scale_drift_ppm`), or its fixed value.
pub fn body_scales(sub: &proto::Subject, drift_ppm: Option<&[i32]>) -> Result<BTreeMap<String, [f64; 3]>, String> {
    let nb = sub.bodies.len();
    if sub.body_scale.len() != 3 * nb || sub.body_scale_proxy.len() != 3 * nb {
        return Err(format!("the subject's scales do not have 3 values for each of its {nb} bodies"));
    }
    let mut scales = BTreeMap::new();
    for (b, body) in sub.bodies.iter().enumerate() {
        let mut v = [0.0; 3];
        for (a, x) in v.iter_mut().enumerate() {
            let i = 3 * b + a;
            *x = match usize::try_from(sub.body_scale_proxy[i]) {
                Ok(k) => {
                    let missing = || format!("scale proxy {k} of body '{body}' is missing");
                    let drift = match drift_ppm {
                        Some(d) => *d.get(k).ok_or_else(missing)?,
                        None => 0,
                    };
                    sub.calibrated_scale.get(k).ok_or_else(missing)? * (1.0 + drift as f64 * 1e-6)
                }
                Err(_) => sub.body_scale[i],
            };
        }
        scales.insert(body.clone(), v);
    }
    Ok(scales)
}

/// The model a record was converted with (its coordinate order and motion types): the shipped
/// model; for an OpenSim model, the attached scaled model (the source rewritten with scales);
/// an MJCF model is read from its recorded path (an `.osim` generated from it may order a
/// joint's coordinates differently).
pub fn conversion_model(rec: &TrialRecord, file: &Path) -> Result<Model, ExportError> {
    let bad = |what: String| ExportError::Content { file: file.display().to_string(), what };
    let source = rec.model_source.as_deref().unwrap_or("");
    if source.starts_with("shipped:") {
        return Ok(crate::pipeline::Context::shipped().map_err(|e| bad(format!("the shipped model: {e}")))?.model);
    }
    if !source.to_ascii_lowercase().ends_with(".osim") {
        let path = Path::new(source);
        if source.is_empty() || !path.is_file() {
            return Err(bad(format!("its model '{source}' (MJCF) is not readable here")));
        }
        let (model, _) = crate::io::mjcf::read_mjcf(path).map_err(|e| bad(e.to_string()))?;
        return Ok(model);
    }
    let text = rec.scaled_model.as_deref().ok_or_else(|| bad("no scaled model attachment".into()))?;
    let (model, _) = crate::io::osim::parse_osim(text, "scaled_model.osim")
        .map_err(|e| bad(format!("its scaled_model.osim: {e}")))?;
    Ok(model)
}

/// Writes the record as an OpenSim motion (`Coordinates`, `inDegrees=yes`, every coordinate of
/// `model` in model order, rotations in degrees: as `smocap solve --mot-dir`).
pub fn write_mot(rec: &TrialRecord, model: &Model, out: &Path) -> Result<(), ExportError> {
    let mut rows = Vec::with_capacity(rec.frames.len());
    for f in &rec.frames {
        let q = model
            .coordinates
            .iter()
            .map(|c| {
                f.state.q.get(&c.name).copied().ok_or_else(|| ExportError::Content {
                    file: out.display().to_string(),
                    what: format!("frame {} has no coordinate '{}' of the model", f.state.frame, c.name),
                })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push((f.state.time + rec.time_offset, q));
    }
    Ok(sto::write_sto(out, "Coordinates", &coordinate_table(model, rows))?)
}

/// Writes the record as CSV: `time` (s), `frame`, every coordinate (rad or m; in `model` order
/// when given, else by name), `scale_<body>_x|y|z` per body, `rmse_m` (RMS marker error, m;
/// empty when no marker was observed) and `status`; one row per frame.
pub fn write_csv(rec: &TrialRecord, model: Option<&Model>, out: &Path) -> Result<(), ExportError> {
    let first = &rec.frames[0].state;
    let coords: Vec<String> = match model {
        Some(m) => m.coordinates.iter().map(|c| c.name.clone()).filter(|n| first.q.contains_key(n)).collect(),
        None => first.q.keys().cloned().collect(),
    };
    let bodies: Vec<String> = match model {
        Some(m) => m.bodies.iter().map(|b| b.name.clone()).filter(|n| first.s.contains_key(n)).collect(),
        None => first.s.keys().cloned().collect(),
    };
    let file = out.display().to_string();
    let cv = |source| ExportError::Csv { file: file.clone(), source };
    let mut w = csv::Writer::from_path(out).map_err(cv)?;
    let mut header = vec!["time".to_string(), "frame".to_string()];
    header.extend(coords.iter().cloned());
    header.extend(bodies.iter().flat_map(|b| ["x", "y", "z"].map(|a| format!("scale_{b}_{a}"))));
    header.extend(["rmse_m".to_string(), "status".to_string()]);
    w.write_record(&header).map_err(cv)?;
    let num = |v: Option<f64>| {
        let mut s = String::new();
        if let Some(v) = v {
            sto::push_number(&mut s, v);
        }
        s
    };
    for f in &rec.frames {
        let s = &f.state;
        let mut row = vec![num(Some(s.time + rec.time_offset)), s.frame.to_string()];
        row.extend(coords.iter().map(|c| num(s.q.get(c).copied())));
        for b in &bodies {
            row.extend((0..3).map(|a| num(s.s.get(b).map(|v| v[a]))));
        }
        row.push(num(f.rmse_m));
        row.push(f.status.clone().unwrap_or_default());
        w.write_record(&row).map_err(cv)?;
    }
    w.flush().map_err(|source| ExportError::Io { file: file.clone(), source })
}
