//! A humanoid robot's motion in the files robot-learning tools read:
//!
//! - GMR's pickle (github.com/YanjieZe/GMR, `scripts/smplx_to_robot.py`): a dict of NumPy arrays,
//!   root quaternion x y z w;
//! - the headerless CSV of mjlab / BeyondMimic (`scripts/csv_to_npz.py`, `np.loadtxt(…,
//!   delimiter=",")`): 30 fps, root position, quaternion x y z w, joints;
//! - an NPZ of MuJoCo's `qpos` with the bodies' world positions, readable with `np.load`'s
//!   default `allow_pickle=False`.
//!
//! Every file is written to a temporary name beside it and renamed into place, and the same
//! motion gives the same bytes. `scripts/check_robot_files.py` reads them back with NumPy.
//!
//! Over 600 lines: three small encoders (pickle, NPY in a zip, CSV), the resampling the CSV
//! needs and their tests, whose zip and NPY readers check the encoders' byte layouts.

use crate::model::math;
use nalgebra::{Matrix3, Vector3};
use std::path::Path;

/// A robot's motion in MuJoCo's `qpos` order, sampled at `fps`.
#[derive(Clone, Debug)]
pub struct RobotMotion {
    /// Frames per second of `qpos` (Hz).
    pub fps: f64,
    /// Names of the robot's hinge joints, in `qpos` order after the free joint's 7 values.
    pub joint_names: Vec<String>,
    /// Per frame: root position (m, world, Z up), root orientation quaternion **w x y z** (MuJoCo
    /// order), then one value per joint (rad).
    pub qpos: Vec<Vec<f64>>,
    /// Robot body names (MuJoCo body order, without `world`).
    pub body_names: Vec<String>,
    /// Per frame, per body: the world position of the body origin (m).
    pub body_pos_w: Vec<Vec<[f64; 3]>>,
}

/// A robot motion file that could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FilesError {
    /// Creating the folder, writing or renaming the file failed.
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    /// The motion does not fit the file: no frames, rows of the wrong length, non-finite values.
    #[error("{file}: {what}")]
    Motion { file: String, what: String },
}

/// Frame rate of mjlab's CSV (Hz): its `csv_to_npz.py` reads `--input_fps 30` by default.
pub const MJLAB_FPS: f64 = 30.0;

/// Bytes of array data a file may hold: the pickle's BINBYTES and the zip's offsets are 32-bit.
const MAX_ARRAY_BYTES: usize = 1 << 31;

impl RobotMotion {
    /// What keeps the motion from being written, if anything; `bodies`: whether `body_pos_w` is
    /// written too.
    fn check(&self, bodies: bool) -> Result<(), String> {
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(format!("frame rate {} Hz is not a positive number", self.fps));
        }
        if self.qpos.is_empty() {
            return Err("the motion has no frames".into());
        }
        let width = 7 + self.joint_names.len();
        for (i, q) in self.qpos.iter().enumerate() {
            if q.len() != width {
                return Err(format!("frame {i} has {} qpos values, not {width} (7 + one per joint)", q.len()));
            }
            if !q.iter().all(|v| v.is_finite()) {
                return Err(format!("frame {i} has a non-finite qpos value"));
            }
        }
        let mut values = self.qpos.len() * width;
        if bodies {
            if self.body_pos_w.len() != self.qpos.len() {
                return Err(format!("{} frames of body positions, {} of qpos", self.body_pos_w.len(), self.qpos.len()));
            }
            for (i, b) in self.body_pos_w.iter().enumerate() {
                if b.len() != self.body_names.len() {
                    return Err(format!("frame {i} has {} body positions, not {}", b.len(), self.body_names.len()));
                }
                if !b.iter().flatten().all(|v| v.is_finite()) {
                    return Err(format!("frame {i} has a non-finite body position"));
                }
            }
            values += self.qpos.len() * self.body_names.len() * 3;
        }
        if values * 8 > MAX_ARRAY_BYTES {
            return Err(format!("{values} values are over the files' 2 GiB"));
        }
        Ok(())
    }
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> FilesError + '_ {
    move |source| FilesError::Io { file: path.display().to_string(), source }
}

/// Checks `m` for a file at `path`.
fn check(path: &Path, m: &RobotMotion, bodies: bool) -> Result<(), FilesError> {
    m.check(bodies).map_err(|what| FilesError::Motion { file: path.display().to_string(), what })
}

/// [`crate::io::write_atomic`] with the file named in the error.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FilesError> {
    crate::io::write_atomic(path, bytes).map_err(io_error(path))
}

// ---------------------------------------------------------------------------------------------
// GMR pickle

/// Writes GMR's robot motion pickle: `{"fps": float, "root_pos": (F, 3), "root_rot": (F, 4)
/// x y z w, "dof_pos": (F, joints), "local_body_pos": None, "link_body_list": None}`, arrays
/// float64, at the motion's own frame rate (as `scripts/smplx_to_robot.py` saves it and
/// `load_robot_motion` of its viewers reads it).
pub fn write_gmr_pickle(path: &Path, m: &RobotMotion) -> Result<(), FilesError> {
    check(path, m, false)?;
    write_atomic(path, &gmr_pickle(m))
}

/// The pickle bytes (protocol 3: `PROTO 3`, `EMPTY_DICT`, `MARK`, key–value pairs, `SETITEMS`,
/// `STOP`; see [`Pickle::array`] for an array).
fn gmr_pickle(m: &RobotMotion) -> Vec<u8> {
    let f = m.qpos.len();
    let nj = m.joint_names.len();
    let mut p = Pickle(b"\x80\x03}(".to_vec());
    p.str("fps").float(m.fps);
    p.str("root_pos").array(&[f, 3], m.qpos.iter().flat_map(|q| &q[..3]).copied());
    p.str("root_rot").array(&[f, 4], m.qpos.iter().flat_map(|q| [q[4], q[5], q[6], q[3]]));
    p.str("dof_pos").array(&[f, nj], m.qpos.iter().flat_map(|q| &q[7..]).copied());
    p.str("local_body_pos").op(b"N");
    p.str("link_body_list").op(b"N");
    p.op(b"u.");
    p.0
}

/// A pickle under construction; each method appends one value's opcodes.
struct Pickle(Vec<u8>);

impl Pickle {
    fn op(&mut self, bytes: &[u8]) -> &mut Self {
        self.0.extend_from_slice(bytes);
        self
    }

    /// `GLOBAL`: `c module\nname\n`.
    fn global(&mut self, module: &str, name: &str) -> &mut Self {
        self.op(format!("c{module}\n{name}\n").as_bytes())
    }

    /// `BINUNICODE`: `X`, length (u32 LE), UTF-8.
    fn str(&mut self, s: &str) -> &mut Self {
        self.op(b"X").op(&(s.len() as u32).to_le_bytes()).op(s.as_bytes())
    }

    /// `BININT1` (`K`, u8) or `BININT` (`J`, i32 LE).
    fn int(&mut self, v: i32) -> &mut Self {
        match u8::try_from(v) {
            Ok(b) => self.op(&[b'K', b]),
            Err(_) => self.op(b"J").op(&v.to_le_bytes()),
        }
    }

    /// `BINFLOAT`: `G`, f64 big-endian.
    fn float(&mut self, v: f64) -> &mut Self {
        self.op(b"G").op(&v.to_be_bytes())
    }

    /// `SHORT_BINBYTES` (`C`, u8 length) or `BINBYTES` (`B`, u32 LE length), then the bytes.
    fn bytes(&mut self, b: &[u8]) -> &mut Self {
        match u8::try_from(b.len()) {
            Ok(n) => self.op(&[b'C', n]),
            Err(_) => self.op(b"B").op(&(b.len() as u32).to_le_bytes()),
        };
        self.op(b)
    }

    /// A float64 C-order array as NumPy's `ndarray.__reduce__` gives it below protocol 5:
    /// `_reconstruct(ndarray, (0,), b"b")` (`numpy.core.multiarray`, which NumPy 2 keeps loadable
    /// without a warning for old pickles), then `BUILD` with the state `(1, shape,
    /// dtype("f8", False, True) BUILD (3, "<", None, None, None, -1, -1, 0), False, data)`,
    /// data the values as little-endian f64. Loaded, it is a writable `ndarray`.
    fn array(&mut self, shape: &[usize], values: impl Iterator<Item = f64>) -> &mut Self {
        let data = le_f64(shape, values);
        self.global("numpy.core.multiarray", "_reconstruct").global("numpy", "ndarray");
        self.int(0).op(b"\x85").bytes(b"b").op(b"\x87R(").int(1).op(b"(");
        for &d in shape {
            self.int(d as i32);
        }
        self.op(b"t").global("numpy", "dtype").str("f8").op(b"\x89\x88\x87R(").int(3).str("<");
        self.op(b"NNN").int(-1).int(-1).int(0).op(b"tb\x89").bytes(&data).op(b"tb")
    }
}

// ---------------------------------------------------------------------------------------------
// mjlab / BeyondMimic CSV

/// Writes mjlab's motion CSV: no header, [`MJLAB_FPS`] (the motion [`resample`]d), one row a
/// frame: root x y z (m), root quaternion x y z w, the joints in `joint_names` order (rad);
/// numbers in their shortest round-trip form (ryu: `0.5`, `1e-7`).
pub fn write_mjlab_csv(path: &Path, m: &RobotMotion) -> Result<(), FilesError> {
    check(path, m, false)?;
    let r = resample(m, MJLAB_FPS);
    let mut text = String::with_capacity(r.qpos.len() * (7 + m.joint_names.len()) * 24);
    let mut fmt = ryu::Buffer::new();
    for q in &r.qpos {
        let row = [q[0], q[1], q[2], q[4], q[5], q[6], q[3]].into_iter().chain(q[7..].iter().copied());
        for (i, v) in row.enumerate() {
            if i > 0 {
                text.push(',');
            }
            // Non-finite values never reach here ([`check`]); ryu writes the shortest round-trip form.
            text.push_str(fmt.format_finite(v));
        }
        text.push('\n');
    }
    write_atomic(path, text.as_bytes())
}

// ---------------------------------------------------------------------------------------------
// NPZ

/// Writes an NPZ (a zip of `.npy` files, stored): `qpos` (F, 7 + joints) float64, `fps` () float64
/// (Hz), `body_names` (bodies,) `<U…`, `body_pos_w` (F, bodies, 3) float64 (m, world),
/// `joint_names` (joints,) `<U…`. No object arrays: `np.load` needs no `allow_pickle`.
pub fn write_npz(path: &Path, m: &RobotMotion) -> Result<(), FilesError> {
    check(path, m, true)?;
    let (f, nb) = (m.qpos.len(), m.body_names.len());
    let entries = [
        ("qpos.npy", npy_f64(&[f, 7 + m.joint_names.len()], m.qpos.iter().flatten().copied())),
        ("fps.npy", npy_f64(&[], [m.fps].into_iter())),
        ("body_names.npy", npy_str(&m.body_names)),
        ("body_pos_w.npy", npy_f64(&[f, nb, 3], m.body_pos_w.iter().flatten().flatten().copied())),
        ("joint_names.npy", npy_str(&m.joint_names)),
    ];
    write_atomic(path, &zip_stored(&entries))
}

/// What the robot was asked to do, per frame (for inspection and for driving other IK
/// libraries with the same targets, `scripts/compare_mink.py`).
#[derive(Clone, Debug)]
pub struct TargetRecord {
    pub fps: f64,
    /// Per task: the robot body, the human body, and the position / orientation weights.
    pub robot_bodies: Vec<String>,
    pub human_bodies: Vec<String>,
    pub weights: Vec<[f64; 2]>,
    /// Per frame, per task: target position (m, world) and orientation (world).
    pub pos: Vec<Vec<Vector3<f64>>>,
    pub rot: Vec<Vec<Matrix3<f64>>>,
    /// Per frame, per task: the human joint centre it comes from (m, world, unscaled).
    pub human: Vec<Vec<Vector3<f64>>>,
    /// The feet's robot bodies and, per frame, whether each is planted.
    pub feet: Vec<String>,
    pub contact: Vec<Vec<bool>>,
}

/// Writes `t` as an NPZ: `fps` (), `robot_bodies`/`human_bodies` (tasks,) `<U…`, `weights`
/// (tasks, 2), `pos` (F, tasks, 3), `rot` (F, tasks, 3, 3), `human` (F, tasks, 3), `feet`
/// (feet,) `<U…`, `contact` (F, feet) float64.
pub fn write_targets_npz(path: &Path, t: &TargetRecord) -> Result<(), FilesError> {
    let (f, n, nf) = (t.pos.len(), t.robot_bodies.len(), t.feet.len());
    let bad = |what: &str| Err(FilesError::Motion { file: path.display().to_string(), what: what.into() });
    let rows_ok =
        [&t.pos, &t.human].iter().all(|v| v.iter().all(|r| r.len() == n)) && t.rot.iter().all(|r| r.len() == n);
    if t.rot.len() != f
        || t.human.len() != f
        || t.contact.len() != f
        || !rows_ok
        || t.contact.iter().any(|c| c.len() != nf)
    {
        return bad("targets: frames or tasks disagree");
    }
    let entries = [
        ("fps.npy", npy_f64(&[], [t.fps].into_iter())),
        ("robot_bodies.npy", npy_str(&t.robot_bodies)),
        ("human_bodies.npy", npy_str(&t.human_bodies)),
        ("weights.npy", npy_f64(&[n, 2], t.weights.iter().flatten().copied())),
        ("pos.npy", npy_f64(&[f, n, 3], t.pos.iter().flatten().flat_map(|p| [p.x, p.y, p.z]))),
        // Row-major: the transpose's columns.
        ("rot.npy", npy_f64(&[f, n, 3, 3], t.rot.iter().flatten().flat_map(|r| r.transpose().data.0).flatten())),
        ("human.npy", npy_f64(&[f, n, 3], t.human.iter().flatten().flat_map(|p| [p.x, p.y, p.z]))),
        ("feet.npy", npy_str(&t.feet)),
        ("contact.npy", npy_f64(&[f, nf], t.contact.iter().flatten().map(|&c| f64::from(u8::from(c))))),
    ];
    write_atomic(path, &zip_stored(&entries))
}

/// An NPY 1.0 file: `\x93NUMPY`, version 1 0, header length (u16 LE), the header (a Python dict
/// literal `{'descr': …, 'fortran_order': False, 'shape': (…), }` padded with spaces and ended by
/// `\n` so that the data start at a multiple of 64 bytes), then `data` in C order.
fn npy(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    let unpadded = 10 + header.len() + 1;
    header.extend(std::iter::repeat_n(' ', (64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// A little-endian float64 array (`<f8`).
fn npy_f64(shape: &[usize], values: impl Iterator<Item = f64>) -> Vec<u8> {
    npy("<f8", shape, &le_f64(shape, values))
}

/// The bytes of `values`, an array of `shape` in C order, as little-endian float64.
fn le_f64(shape: &[usize], values: impl Iterator<Item = f64>) -> Vec<u8> {
    let mut data = Vec::with_capacity(shape.iter().product::<usize>() * 8);
    for v in values {
        data.extend_from_slice(&v.to_le_bytes());
    }
    debug_assert_eq!(data.len(), shape.iter().product::<usize>() * 8);
    data
}

/// A 1-D unicode array (`<U{n}`, n the longest name in characters, at least 1): each name as
/// n UTF-32LE code points, zero-padded, as NumPy stores `str_`.
fn npy_str(names: &[String]) -> Vec<u8> {
    let n = names.iter().map(|s| s.chars().count()).max().unwrap_or(0).max(1);
    let mut data = Vec::with_capacity(names.len() * n * 4);
    for s in names {
        let chars = s.chars().map(u32::from).chain(std::iter::repeat(0)).take(n);
        data.extend(chars.flat_map(u32::to_le_bytes));
    }
    npy(&format!("<U{n}"), &[names.len()], &data)
}

/// DOS time and date of every zip entry: 1980-01-01 00:00:00, the format's earliest (fixed, so
/// the bytes depend on the motion only).
const DOS_TIME: u16 = 0;
const DOS_DATE: u16 = (1 << 5) | 1;

/// A zip of `entries`, stored (method 0), no extra fields: per entry a local header (`PK\3\4`,
/// version 2.0, flags 0, method 0, time, date, CRC-32, sizes, name length, 0) with the name and
/// data; then the central directory (`PK\1\2`, the same fields, offset of the local header) and
/// the end record (`PK\5\6`). Sizes under 4 GiB ([`RobotMotion::check`]).
fn zip_stored(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let (mut out, mut central) = (Vec::new(), Vec::new());
    for (name, data) in entries {
        let mut fields = Vec::new();
        for v in [20u16, 0, 0, DOS_TIME, DOS_DATE] {
            fields.extend_from_slice(&v.to_le_bytes());
        }
        for v in [crc32fast::hash(data), data.len() as u32, data.len() as u32] {
            fields.extend_from_slice(&v.to_le_bytes());
        }
        fields.extend_from_slice(&(name.len() as u16).to_le_bytes());
        fields.extend_from_slice(&0u16.to_le_bytes());
        let offset = out.len() as u32;
        out.extend_from_slice(b"PK\x03\x04");
        out.extend_from_slice(&fields);
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(data);
        central.extend_from_slice(b"PK\x01\x02\x14\x00"); // made by: version 2.0, MS-DOS
        central.extend_from_slice(&fields);
        central.extend_from_slice(&[0; 10]); // comment length, disk, internal and external attributes
        central.extend_from_slice(&offset.to_le_bytes());
        central.extend_from_slice(name.as_bytes());
    }
    let (cd_offset, cd_size, count) = (out.len() as u32, central.len() as u32, entries.len() as u16);
    out.extend_from_slice(&central);
    out.extend_from_slice(b"PK\x05\x06\0\0\0\0");
    for v in [count, count] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [cd_size, cd_offset] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&0u16.to_le_bytes());
    out
}

// ---------------------------------------------------------------------------------------------
// Resampling

/// The motion resampled at `fps` (linear in positions and joints, slerp in the root quaternion,
/// keeping quaternion sign continuity); frames cover [0, last time].
///
/// Output frame k is at k / `fps` s, for k up to ⌈T · `fps`⌉ with T the last input frame's
/// time: the first frame is the first input frame, the last one the last input frame (held for
/// the under one frame past T). Root quaternions are made sign-continuous first (a frame's
/// quaternion negated where its dot product with the previous one is negative), so the last
/// frame's may be the input's negated. `body_pos_w` is interpolated linearly where it has one
/// entry a frame, else left empty.
pub fn resample(m: &RobotMotion, fps: f64) -> RobotMotion {
    let mut out = RobotMotion {
        fps,
        joint_names: m.joint_names.clone(),
        qpos: Vec::new(),
        body_names: m.body_names.clone(),
        body_pos_w: Vec::new(),
    };
    let n = m.qpos.len();
    if n == 0 {
        return out;
    }
    let qpos = sign_continuous(&m.qpos);
    let span = (n - 1) as f64 * fps / m.fps; // the last input time, in output frames
    let frames = (span - 1e-9).ceil().max(0.0) as usize + 1;
    let bodies = m.body_pos_w.len() == n;
    for k in 0..frames {
        let (i, a) = locate(k as f64 * m.fps / fps, n);
        let j = (i + 1).min(n - 1);
        out.qpos.push(lerp_qpos(&qpos[i], &qpos[j], a));
        if bodies {
            let (b0, b1) = (&m.body_pos_w[i], &m.body_pos_w[j]);
            out.body_pos_w.push(b0.iter().zip(b1).map(|(p, q)| std::array::from_fn(|c| lerp(p[c], q[c], a))).collect());
        }
    }
    out
}

/// The input frame at or before `u` (in input frames; within 1e-9 of a whole frame counts as on
/// it) and the blend toward the next one; past the last frame, the last with blend 0.
fn locate(u: f64, n: usize) -> (usize, f64) {
    let u = if (u - u.round()).abs() < 1e-9 { u.round() } else { u };
    if u >= (n - 1) as f64 {
        return (n - 1, 0.0);
    }
    let i = u.floor();
    (i as usize, u - i)
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    if t == 0.0 {
        a
    } else {
        a + (b - a) * t
    }
}

/// `qpos` with each root quaternion negated where it points away from the previous one.
fn sign_continuous(qpos: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut out = qpos.to_vec();
    for i in 1..out.len() {
        let dot: f64 = (3..7).map(|c| out[i][c] * out[i - 1][c]).sum();
        if dot < 0.0 {
            out[i][3..7].iter_mut().for_each(|v| *v = -*v);
        }
    }
    out
}

/// `a` toward `b` by `t`: linear but for the root quaternion (slerp, unit length).
fn lerp_qpos(a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
    if t == 0.0 {
        return a.to_vec();
    }
    let mut q: Vec<f64> = a.iter().zip(b).map(|(&x, &y)| lerp(x, y, t)).collect();
    let dot: f64 = (3..7).map(|c| a[c] * b[c]).sum::<f64>().clamp(-1.0, 1.0);
    let (wa, wb) = if dot > 1.0 - 1e-12 {
        (1.0 - t, t)
    } else {
        let theta = math::acos(dot);
        let s = math::sin(theta);
        (math::sin((1.0 - t) * theta) / s, math::sin(t * theta) / s)
    };
    (3..7).for_each(|c| q[c] = wa * a[c] + wb * b[c]);
    let norm = q[3..7].iter().map(|v| v * v).sum::<f64>().sqrt();
    q[3..7].iter_mut().for_each(|v| *v /= norm);
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use std::path::PathBuf;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("smocap-robotfiles-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A motion of `joints` joints and 3 bodies at `fps`: the root walks along x, turns about z
    /// (its quaternion negated on odd frames), joint j swings as sin(t + j).
    fn walk(frames: usize, joints: usize, fps: f64) -> RobotMotion {
        let mut m = RobotMotion {
            fps,
            joint_names: (0..joints).map(|j| format!("joint_{j}")).collect(),
            qpos: Vec::new(),
            body_names: vec!["pelvis".into(), "left_ankle_roll_link".into(), "torso_link".into()],
            body_pos_w: Vec::new(),
        };
        for k in 0..frames {
            let t = k as f64 / fps;
            let (s, c) = (0.5 * t).sin_cos();
            let sign = if k % 2 == 1 { -1.0 } else { 1.0 };
            let mut q = vec![0.8 * t, 0.1 * t * t, 0.75, sign * c, 0.0, 0.0, sign * s];
            q.extend((0..joints).map(|j| (t + j as f64).sin()));
            m.body_pos_w.push((0..3).map(|b| [q[0], q[1] + b as f64 * 0.1, q[2] - b as f64 * 0.3]).collect());
            m.qpos.push(q);
        }
        m
    }

    /// The header dict of an NPY 1.0 file and its data, checking the magic and the alignment.
    fn parse_npy(b: &[u8]) -> (String, &[u8]) {
        assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
        let len = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + len) % 64, 0, "data start at a multiple of 64");
        let header = std::str::from_utf8(&b[10..10 + len]).unwrap();
        assert!(header.ends_with('\n') && header.starts_with('{'));
        (header.trim_end().to_string(), &b[10 + len..])
    }

    fn u16_at(b: &[u8], i: usize) -> usize {
        u16::from_le_bytes([b[i], b[i + 1]]) as usize
    }

    fn u32_at(b: &[u8], i: usize) -> usize {
        u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize
    }

    /// The entries of a stored zip, through its end record and central directory, each checked
    /// against its local header and its CRC-32.
    fn read_zip(z: &[u8]) -> BTreeMap<String, Vec<u8>> {
        let end = z.len() - 22;
        assert_eq!(&z[end..end + 4], b"PK\x05\x06");
        let (count, cd_size, cd) = (u16_at(z, end + 10), u32_at(z, end + 12), u32_at(z, end + 16));
        assert_eq!(cd + cd_size, end, "the central directory ends where the end record starts");
        let (mut out, mut at) = (BTreeMap::new(), cd);
        for _ in 0..count {
            assert_eq!(&z[at..at + 4], b"PK\x01\x02");
            let (crc, size, name_len) = (u32_at(z, at + 16), u32_at(z, at + 24), u16_at(z, at + 28));
            assert_eq!(u16_at(z, at + 10), 0, "stored");
            assert_eq!(u32_at(z, at + 20), size, "stored: compressed size is the size");
            let local = u32_at(z, at + 42);
            let name = &z[at + 46..at + 46 + name_len];
            assert_eq!(&z[local..local + 4], b"PK\x03\x04");
            assert_eq!(&z[local + 4..local + 30], &z[at + 6..at + 32], "local header fields as in the directory");
            assert_eq!(&z[local + 30..local + 30 + name_len], name);
            let data = &z[local + 30 + name_len..local + 30 + name_len + size];
            assert_eq!(crc32fast::hash(data) as usize, crc, "CRC-32");
            out.insert(String::from_utf8(name.to_vec()).unwrap(), data.to_vec());
            at += 46 + name_len;
        }
        assert_eq!(at, end);
        out
    }

    fn f64s(b: &[u8]) -> Vec<f64> {
        b.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
    }

    #[test]
    fn npy_header_is_64_byte_aligned_and_parses() {
        for shape in [&[][..], &[0], &[3], &[2, 3], &[5, 4, 3], &[123456, 36]] {
            let count: usize = shape.iter().product();
            let b = npy_f64(shape, (0..count).map(|i| i as f64));
            let (header, data) = parse_npy(&b);
            let dims = match shape {
                [d] => format!("({d},)"),
                _ => format!("({})", shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
            };
            assert_eq!(header, format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {dims}, }}"));
            assert_eq!(f64s(data), (0..count).map(|i| i as f64).collect::<Vec<_>>());
        }
        let names = ["pelvis".to_string(), "ü".into(), String::new()];
        let b = npy_str(&names);
        let (header, data) = parse_npy(&b);
        assert_eq!(header, "{'descr': '<U6', 'fortran_order': False, 'shape': (3,), }");
        assert_eq!(data.len(), 3 * 6 * 4);
        assert_eq!(&data[24..32], &[0xfc, 0, 0, 0, 0, 0, 0, 0], "UTF-32LE, zero-padded");
        assert!(parse_npy(&npy_str(&[])).0.contains("'<U1'"));
    }

    #[test]
    fn npz_is_a_valid_stored_zip_of_the_arrays() {
        let m = walk(5, 2, 50.0);
        let path = scratch("npz").join("walk.npz");
        write_npz(&path, &m).unwrap();
        let entries = read_zip(&std::fs::read(&path).unwrap());
        let names: Vec<&str> = entries.keys().map(String::as_str).collect();
        assert_eq!(names, ["body_names.npy", "body_pos_w.npy", "fps.npy", "joint_names.npy", "qpos.npy"]);
        let (h, data) = parse_npy(&entries["qpos.npy"]);
        assert!(h.contains("'shape': (5, 9)"));
        assert_eq!(f64s(data), m.qpos.concat());
        let (h, data) = parse_npy(&entries["body_pos_w.npy"]);
        assert!(h.contains("'shape': (5, 3, 3)"));
        assert_eq!(f64s(data)[3..6], m.body_pos_w[0][1]);
        let (h, data) = parse_npy(&entries["fps.npy"]);
        assert!(h.contains("'shape': ()"));
        assert_eq!(f64s(data), [50.0]);
        assert!(parse_npy(&entries["body_names.npy"]).0.contains("'<U20', 'fortran_order': False, 'shape': (3,)"));
        assert!(parse_npy(&entries["joint_names.npy"]).0.contains("'<U7'"));
        std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    }

    #[test]
    fn gmr_pickle_holds_root_rot_as_xyzw_and_the_keys_in_gmr_order() {
        let m = walk(3, 2, 30.0);
        let p = gmr_pickle(&m);
        assert!(p.starts_with(b"\x80\x03}(X\x03\x00\x00\x00fpsG\x40\x3e\x00\x00\x00\x00\x00\x00"));
        assert!(p.ends_with(b"tbX\x0e\x00\x00\x00local_body_posNX\x0e\x00\x00\x00link_body_listNu."));
        let at = |needle: &[u8]| p.windows(needle.len()).position(|w| w == needle);
        let keys = ["root_pos", "root_rot", "dof_pos"].map(|k| at(k.as_bytes()).unwrap());
        assert!(keys[0] < keys[1] && keys[1] < keys[2]);
        let bytes = |v: &[f64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let xyzw: Vec<f64> = m.qpos.iter().flat_map(|q| [q[4], q[5], q[6], q[3]]).collect();
        let shape = b"(K\x03K\x04tcnumpy\ndtype\n";
        assert!(at(shape).is_some_and(|i| i > keys[1] && i < keys[2]), "shape (3, 4)");
        assert!(at(&bytes(&xyzw)).is_some_and(|i| i > keys[1] && i < keys[2]));
        let dof: Vec<f64> = m.qpos.iter().flat_map(|q| q[7..].to_vec()).collect();
        assert!(at(&bytes(&dof)).is_some_and(|i| i > keys[2]));
    }

    #[test]
    fn csv_is_thirty_fps_rows_of_position_xyzw_and_joints() {
        let m = walk(9, 2, 120.0); // 8/120 s: 3 rows at 30 fps, on input frames 0, 4 and 8
        let path = scratch("csv").join("walk.csv");
        write_mjlab_csv(&path, &m).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let rows: Vec<Vec<f64>> = text.lines().map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
        assert_eq!(rows.len(), 3);
        for (row, k) in rows.iter().zip([0, 4, 8]) {
            let q = &sign_continuous(&m.qpos)[k];
            assert_eq!(row[..], [q[0], q[1], q[2], q[4], q[5], q[6], q[3], q[7], q[8]]);
        }
        std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    }

    #[test]
    fn resample_keeps_endpoints_and_interpolates_linearly() {
        let m = walk(11, 3, 100.0); // 0.1 s
        let r = resample(&m, 30.0); // frames at 0, 1/30, 2/30, 3/30 s: 4 frames, the last one held
        assert_eq!((r.qpos.len(), r.body_pos_w.len(), r.fps), (4, 4, 30.0));
        assert_eq!(r.qpos[0], m.qpos[0]);
        assert_eq!(r.qpos[3][..3], m.qpos[10][..3]);
        assert_eq!(r.qpos[3][7..], m.qpos[10][7..]);
        assert_eq!(r.body_pos_w[3], m.body_pos_w[10]);
        let u: f64 = 100.0 / 30.0; // frame 1 is a third of the way from input frame 3 to 4
        let (a, b, t) = (&m.qpos[3], &m.qpos[4], u - 3.0);
        for c in (0..3).chain(7..10) {
            assert!((r.qpos[1][c] - (a[c] + (b[c] - a[c]) * t)).abs() < 1e-15, "column {c}");
        }
        assert!(
            (r.body_pos_w[1][2][2] - (m.body_pos_w[3][2][2] * (1.0 - t) + m.body_pos_w[4][2][2] * t)).abs() < 1e-12
        );
        let same = resample(&m, 100.0);
        assert_eq!(same.qpos.len(), 11);
        assert_eq!(same.qpos[7][..3], m.qpos[7][..3]);
        assert_eq!(resample(&walk(1, 3, 100.0), 30.0).qpos.len(), 1);
    }

    #[test]
    fn resample_keeps_quaternions_unit_and_sign_continuous() {
        let m = walk(41, 1, 120.0); // turning at 0.5 rad/s, sign flipped every other frame
        let r = resample(&m, 50.0);
        for (k, q) in r.qpos.iter().enumerate() {
            let norm = q[3..7].iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!((norm - 1.0).abs() < 1e-14, "frame {k}: |q| = {norm}");
            let half_angle = 0.5 * (k as f64 / 50.0).min(40.0 / 120.0);
            assert!((q[3] - half_angle.cos()).abs() < 1e-12 && (q[6] - half_angle.sin()).abs() < 1e-12, "frame {k}");
            if k > 0 {
                let dot: f64 = (3..7).map(|c| q[c] * r.qpos[k - 1][c]).sum();
                assert!(dot > 0.99, "frame {k}");
            }
        }
    }

    #[test]
    fn the_same_motion_gives_the_same_bytes() {
        let m = walk(37, 29, 120.0);
        let dir = scratch("same");
        type Write = fn(&Path, &RobotMotion) -> Result<(), FilesError>;
        for (name, write) in [("a.pkl", write_gmr_pickle as Write), ("a.csv", write_mjlab_csv), ("a.npz", write_npz)] {
            let (a, b) = (dir.join(name), dir.join(format!("b-{name}")));
            write(&a, &m).unwrap();
            write(&b, &m.clone()).unwrap();
            assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "{name}");
        }
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 6, "no temporary file left: {names:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_motion_that_does_not_fit_is_refused_with_its_file() {
        let dir = scratch("refused");
        let mut m = walk(4, 2, 30.0);
        m.qpos[2].pop();
        let e = write_gmr_pickle(&dir.join("short.pkl"), &m).unwrap_err().to_string();
        assert!(e.contains("short.pkl") && e.contains("frame 2 has 8 qpos values, not 9"), "{e}");
        let mut m = walk(4, 2, 30.0);
        m.body_pos_w.pop();
        assert!(write_mjlab_csv(&dir.join("ok.csv"), &m).is_ok(), "the CSV has no body positions");
        let e = write_npz(&dir.join("bodies.npz"), &m).unwrap_err().to_string();
        assert!(e.contains("3 frames of body positions, 4 of qpos"), "{e}");
        m.fps = 0.0;
        assert!(write_mjlab_csv(&dir.join("zero.csv"), &m).is_err());
        assert!(!dir.join("short.pkl").exists() && !dir.join("zero.csv").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Sample files for `scripts/check_robot_files.py`: `SMOCAP_ROBOT_FILES_DIR=DIR cargo test
    /// --lib retarget::files -- --ignored` writes `walk.{pkl,csv,npz}` (29 joints, 120 fps,
    /// 301/120 s) and `short.{pkl,csv,npz}` (3 frames at 100 fps).
    #[test]
    #[ignore]
    fn write_sample_robot_files() {
        let dir = PathBuf::from(std::env::var("SMOCAP_ROBOT_FILES_DIR").expect("SMOCAP_ROBOT_FILES_DIR"));
        for (stem, m) in [("walk", walk(302, 29, 120.0)), ("short", walk(3, 29, 100.0))] {
            write_gmr_pickle(&dir.join(format!("{stem}.pkl")), &m).unwrap();
            write_mjlab_csv(&dir.join(format!("{stem}.csv")), &m).unwrap();
            write_npz(&dir.join(format!("{stem}.npz")), &m).unwrap();
        }
    }
}
