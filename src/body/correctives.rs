//! Volume-preserving pose correctives: the skin in front of a bending trunk, hip or knee
//! bulges out by as much as the bend closes in, as soft tissue (incompressible) does.
//!
//! Skinning turns a joint's two sides about one centre. Where that centre lies toward the back
//! of the body (the lumbar joint sits at the spine), bending closes a wedge of the body in front
//! of it: the skin there folds inward and the enclosed volume falls linearly with the angle
//! (OpenCap's drop jumps: 4.5 % for a trunk flexed 38°, 2 % for hips flexed 95°). A real belly
//! or groin keeps its volume and bulges. Here each bend of a driving pair (a body and its
//! descendant that share skin: pelvis–trunk and along the spine, pelvis–thigh) has a corrective shape
//! per direction: vertices of the pair's blend zone on the side the bend closes are displaced
//! along their rest normal, the most where the skin is half on each side
//! (`φ = 4 t (1 − t)`, `t` the descendant's share, [`super::helpers::split`]), fading to zero
//! where the normal turns away from the closing side. Its weight is a function of `σ θ`, with
//! `θ` the bend (rad) about the body's left–right axis since the bind pose and `σ` the
//! direction, measured on the subject's own mesh when it is dressed ([`build`]): the bend posed
//! alone at every [`CALIBRATION_STEP`], the weight there is the one that brings the enclosed
//! volume back to the rest volume (none where bending adds volume), linear in between.
//!
//! The displacements are in the output frame at the rest pose (the subject's scales) and turn
//! with the vertex's joints (`Σ w_j G_j δ`, `G_j` joint `j`'s rotation since the bind pose), as
//! glTF applies morph targets before skinning: the `.glb` carries them as morph targets whose
//! weights are animated ([`crate::render::scene`]).

pub use super::corrective::Corrective;
use super::helpers::Helper;
use super::pose::{Dressed, PoseWorkspace};
use crate::model::Model;
use nalgebra::{Rotation3, Unit, Vector3};

pub use super::corrective::{CALIBRATION_KEYS, CALIBRATION_STEP};

/// Displacement (m) of a vertex at `φ = 1` facing the closing side, at weight 1.
const UNIT_DISPLACEMENT: f64 = 0.01;

/// The largest weight: a bulge of at most 10 cm (past it the bend's loss stays).
const MAX_WEIGHT: f64 = 10.0;

/// The asset segments whose pair with their ancestor drives correctives: trunk and thighs (the
/// knees' loss is small: OpenCap's DJ5 0.947 → 0.951 × rest with them, and they cost edges).
const DRIVEN: &[&str] = &["torso", "femur_r", "femur_l"];

/// Rounds of neighbour averaging that widen a pair's blend zone into its corrective's field and
/// smooth the normals it moves along: about 6.5 cm on the body's ~12 mm edges (a round spreads
/// by half an edge's squared length), the width the trunk's weights are averaged over.
const SPREAD: usize = 60;

/// `rounds` of `f ← (f + mean of the neighbours' f) / 2` over the mesh's edges.
fn spread(f: &mut Vec<f64>, neighbours: &[Vec<u32>], rounds: usize) {
    let mut next = f.clone();
    for _ in 0..rounds {
        for (v, nv) in neighbours.iter().enumerate() {
            if !nv.is_empty() {
                let m: f64 = nv.iter().map(|&u| f[u as usize]).sum::<f64>() / nv.len() as f64;
                next[v] = 0.5 * (f[v] + m);
            }
        }
        std::mem::swap(f, &mut next);
    }
}

/// Per vertex, its share in the chain of pair `(a, d)` and where along it (`t`: 0 at `a`, 1 at
/// `d`), from its joint influences.
fn chain_share(body: &Dressed, nb: usize, a: usize, d: usize) -> Vec<(f64, f64)> {
    let helpers: &[Helper] = &body.binding.helpers.helpers;
    let along = |j: usize| -> Option<f64> {
        match j {
            j if j == a => Some(0.0),
            j if j == d => Some(1.0),
            j if j >= nb => {
                let h = &helpers[j - nb];
                (h.parent == a && h.child == d).then_some(h.fraction)
            }
            _ => None,
        }
    };
    body.binding
        .helpers
        .joints
        .iter()
        .map(|inf| {
            let (mut s, mut t) = (0.0, 0.0);
            for x in inf.iter().filter(|x| x.weight > 0.0) {
                if let Some(f) = along(x.joint as usize) {
                    s += x.weight as f64;
                    t += x.weight as f64 * f;
                }
            }
            (s, if s > 0.0 { t / s } else { 0.0 })
        })
        .collect()
}

/// The pairs that drive correctives: `(a, d, centre)` of the binding's helpers where `d` carries
/// a [`DRIVEN`] segment or is a spine body below the torso's, in helper order.
fn driving_pairs(model: &Model, body: &Dressed, asset: &super::BodyAsset) -> Vec<(usize, usize, usize)> {
    let map = &body.binding.map;
    let mut driven: Vec<usize> = DRIVEN.iter().filter_map(|s| asset.segment_index(s)).map(|i| map.host[i]).collect();
    let pelvis = asset.segment_index("pelvis").map(|i| map.host[i]);
    if let Some(torso) = asset.segment_index("torso").map(|i| map.host[i]) {
        let mut b = model.bodies[torso].parent;
        while let Some(x) = b.filter(|&x| Some(x) != pelvis) {
            driven.push(x);
            b = model.bodies[x].parent;
        }
    }
    let mut out: Vec<(usize, usize, usize)> = Vec::new();
    for h in &body.binding.helpers.helpers {
        if driven.contains(&h.child) && !out.iter().any(|p| p.0 == h.parent && p.1 == h.child) {
            out.push((h.parent, h.child, h.centre));
        }
    }
    out
}

/// The bodies below `c` (itself included).
fn subtree(model: &Model, c: usize) -> Vec<usize> {
    (0..model.nb())
        .filter(|&b| {
            let mut x = Some(b);
            while let Some(y) = x {
                if y == c {
                    return true;
                }
                x = model.bodies[y].parent;
            }
            false
        })
        .collect()
}

/// The correctives of `body` at `scales` (its calibrated subject's), weights measured on its own
/// mesh. None where the binding has no driving pairs or no hips to take the left–right axis from.
pub fn build(model: &Model, body: &Dressed, asset: &super::BodyAsset, scales: &[f64]) -> Vec<Corrective> {
    use super::metrics::volume;
    let map = &body.binding.map;
    let host = |s: &str| asset.segment_index(s).map(|i| map.host[i]);
    let mut ws = PoseWorkspace::new(model, body);
    let y = body.bind_state(model, scales);
    body.pose_joints(model, &y, &mut ws);
    let (Some(r), Some(l)) = (host("femur_r"), host("femur_l")) else { return Vec::new() };
    let Some(axis) = (ws.joint(l).1 - ws.joint(r).1).try_normalize(1e-9) else { return Vec::new() };
    body.pose(model, &y, &mut ws);
    let rest = ws.vertices.clone();
    let rest_volume = volume(&rest, &body.triangles);
    let nb = model.nb();
    let neighbours = super::metrics::neighbours(&body.triangles, rest.len());
    // normals averaged as widely as the fields, so a dimple (the navel) moves as a whole
    let mut n = super::metrics::vertex_normals(&rest, &body.triangles);
    for a in 0..3 {
        let mut f: Vec<f64> = n.iter().map(|x| x[a]).collect();
        spread(&mut f, &neighbours, SPREAD);
        n.iter_mut().zip(&f).for_each(|(x, v)| x[a] = *v);
    }
    n.iter_mut().for_each(|x| *x /= x.norm().max(1e-30));
    let mut out = Vec::new();
    for (a, d, c) in driving_pairs(model, body, asset) {
        let share = chain_share(body, nb, a, d);
        let Some(reach) = reach(&share, &rest, ws.joint(c).1) else { continue };
        for sign in [1.0, -1.0] {
            let Some(closing) = (axis.cross(&reach) * sign).try_normalize(1e-9) else { continue };
            let (vertices, deltas) = shape(&share, &n, &neighbours, &closing);
            let mut k = Corrective { parent: a, child: d, axis, sign, weights: Vec::new(), vertices, deltas };
            let weights = calibrate(model, body, &y, c, &k, rest_volume, &mut ws);
            if weights.iter().any(|&w| w > 0.0) {
                k.weights = weights;
                out.push(k);
            }
        }
    }
    out
}

/// From the joint centre (output frame) to the mean of the rest vertices mostly on the far half
/// of the pair's chain (`share` of [`chain_share`]): the descendant's side.
fn reach(share: &[(f64, f64)], rest: &[[f32; 3]], centre: Vector3<f64>) -> Option<Vector3<f64>> {
    let (mut far, mut count) = (Vector3::zeros(), 0.0);
    for (v, &(s, t)) in share.iter().enumerate() {
        if s > 0.5 && t > 0.5 {
            far += Vector3::new(rest[v][0] as f64, rest[v][1] as f64, rest[v][2] as f64);
            count += 1.0;
        }
    }
    (count > 0.0).then(|| far / count - centre)
}

/// The corrective shape of a pair (`share` of [`chain_share`]) closing toward `closing`: its
/// vertices and their displacements at weight 1 along the smoothed normals `n`.
fn shape(
    share: &[(f64, f64)],
    n: &[Vector3<f64>],
    neighbours: &[Vec<u32>],
    closing: &Vector3<f64>,
) -> (Vec<u32>, Vec<[f32; 3]>) {
    let mut field: Vec<f64> = share.iter().map(|&(s, t)| s * 4.0 * t * (1.0 - t)).collect();
    spread(&mut field, neighbours, SPREAD);
    let (mut vertices, mut deltas) = (Vec::new(), Vec::new());
    for (v, &f) in field.iter().enumerate() {
        let facing = (n[v].dot(closing) / 0.5).clamp(0.0, 1.0);
        let phi = f * facing * facing * (3.0 - 2.0 * facing);
        if phi > 1e-3 {
            vertices.push(v as u32);
            deltas.push((n[v] * (phi * UNIT_DISPLACEMENT)).map(|x| x as f32).into());
        }
    }
    (vertices, deltas)
}

/// `k`'s weight at each calibration bend: the pair bent alone at the centre body `c` from state
/// `y`, the weight that brings the enclosed volume back to `rest_volume` (≥ 0, ≤ [`MAX_WEIGHT`]).
fn calibrate(
    model: &Model,
    body: &Dressed,
    y: &[f64],
    c: usize,
    k: &Corrective,
    rest_volume: f64,
    ws: &mut PoseWorkspace,
) -> Vec<f64> {
    let mut volume_at = |bend_angle: f64, w: f64| {
        bend(model, body, y, c, &Unit::new_unchecked(k.axis), k.sign * bend_angle, ws);
        ws.add_corrective(k, w, &body.binding.helpers.joints);
        super::metrics::volume(&ws.vertices, &body.triangles)
    };
    (1..=CALIBRATION_KEYS)
        .map(|i| {
            let angle = i as f64 * CALIBRATION_STEP;
            let (v0, v1) = (volume_at(angle, 0.0), volume_at(angle, 1.0));
            if v1 > v0 + 1e-12 {
                ((rest_volume - v0) / (v1 - v0)).clamp(0.0, MAX_WEIGHT)
            } else {
                0.0
            }
        })
        .collect()
}

/// Poses `body` at state `y` with the bodies below `c` turned by `angle` about `axis` through
/// `c`'s origin (the output frame), skinned into `ws.vertices` without correctives.
fn bend(
    model: &Model,
    body: &Dressed,
    y: &[f64],
    c: usize,
    axis: &Unit<Vector3<f64>>,
    angle: f64,
    ws: &mut PoseWorkspace,
) {
    body.pose_joints(model, y, ws);
    let g = Rotation3::from_axis_angle(axis, angle).into_inner();
    let centre = ws.joint(c).1;
    for b in subtree(model, c) {
        ws.turn_body(b, &g, &centre);
    }
    ws.refresh_helpers(body);
    body.skin_only(ws);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::metrics::volume;
    use crate::body::{dress_subject, BodyAsset, SubjectBody};
    use crate::pipeline::context::Context;

    fn shipped() -> (Model, Dressed, BodyAsset, Vec<f64>) {
        let asset = BodyAsset::shipped().unwrap();
        let model = Context::shipped().unwrap().model;
        let ones = vec![1.0; 3 * model.nb()];
        let sub = SubjectBody { stature_m: Some(1.75), info: Default::default() };
        let (body, _) = dress_subject(&model, &nalgebra::UnitQuaternion::identity(), &asset, &ones, &sub).unwrap();
        (model, body, asset, ones)
    }

    /// Volume over rest of `body` at the bind state with `coords` (degrees) set, with and
    /// without its correctives.
    fn volumes(model: &Model, body: &Dressed, ones: &[f64], coords: &[(&str, f64)]) -> (f64, f64) {
        let mut y = body.bind_state(model, ones);
        let mut ws = PoseWorkspace::new(model, body);
        body.pose(model, &y, &mut ws);
        let rest = volume(&ws.vertices, &body.triangles);
        assert!(ws.morph.iter().all(|&w| w < 1e-9), "no corrective at the bind pose: {:?}", ws.morph);
        for (name, deg) in coords {
            let c = model.coordinates.iter().position(|c| c.name == *name).unwrap();
            y[c] = deg.to_radians();
        }
        body.pose(model, &y, &mut ws);
        let with = volume(&ws.vertices, &body.triangles) / rest;
        let mut bare = body.clone();
        bare.correctives.clear();
        let mut ws = PoseWorkspace::new(model, &bare);
        bare.pose(model, &y, &mut ws);
        (with, volume(&ws.vertices, &bare.triangles) / rest)
    }

    #[test]
    fn a_flexed_trunk_and_flexed_hips_keep_their_volume_with_the_correctives() {
        let (model, body, _, ones) = shipped();
        let levels = ["L5_S1", "L4_L5", "L3_L4", "L2_L3", "L1_L2", "T12_L1"];
        let trunk: Vec<(String, f64)> = levels.iter().map(|l| (format!("{l}_flexion"), 6.0)).collect();
        let trunk: Vec<(&str, f64)> = trunk.iter().map(|(n, d)| (n.as_str(), *d)).collect();
        let (with, without) = volumes(&model, &body, &ones, &trunk);
        eprintln!("trunk flexed 36°: volume {with:.4} with the correctives, {without:.4} without");
        let hips = [("hip_flexion_r", 90.0), ("hip_flexion_l", 90.0)];
        let (hwith, hwithout) = volumes(&model, &body, &ones, &hips);
        eprintln!("hips flexed 90°: volume {hwith:.4} with the correctives, {hwithout:.4} without");
        assert!(without < 0.99 && (with - 1.0).abs() < 0.01, "{with} {without}");
        assert!(hwithout < 0.99 && (hwith - 1.0).abs() < 0.01, "{hwith} {hwithout}");
    }
}
