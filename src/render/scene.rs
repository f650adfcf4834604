//! A take as a glTF scene ([`crate::io::gltf`]): the node tree of the model with its motion, the
//! observed markers and the cameras.
//!
//! Nodes (names are what a rigging script binds to):
//! - `world`: the scene root, turning the Z-up `world` into the consumer's up axis ([`Up`]:
//!   glTF's own +Y by default, or +Z kept);
//! - `model` (in `world`): the model's frame, `world_from_model` from it (as in `/tf`);
//! - one node per body, named as the body, in its parent body's node (a root body in `model`):
//!   its rest transform and animation are the body's pose in its parent's frame (joint offsets
//!   and motions at the subject's calibrated scales); bones are capsules from the body's joint
//!   centre to each child's joint on it, coloured by the child's side (left blue, right red);
//! - one node per model marker, named as the marker, in its body's node at its scaled offset,
//!   a sphere coloured by its side;
//! - `observed` (in `model`) with `observed/<marker>` per model marker: the observed positions
//!   (translation, linear), hidden (scale 0, step) in frames where the marker was not observed;
//! - `cameras` (in `world`) with one node per camera, named as the camera, carrying a glTF
//!   perspective camera (its vertical field of view and aspect ratio; glTF has no principal point
//!   offset: smocap's cameras have none).
//!
//! One animation, `motion`, keyed at the trial's frame times (s since its first sample).

use super::rig::Camera;
use super::take::{side_of, Side, Take};
use super::RenderError;
use crate::body::{Dressed, PoseWorkspace};
use crate::io::gltf::{self, Document, Material, Mesh, Node, Primitive, Track, Values};
use crate::kinematics::Workspace;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The up axis of the exported scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Up {
    /// glTF's convention (+Y up, as Blender's importer and three.js expect): `world` turned by
    /// −90° about x.
    #[default]
    Y,
    /// `world` as it is (+Z up), for consumers that expect Z up without conversion.
    Z,
}

impl Up {
    /// The rotation from the Z-up `world` to the exported scene's frame.
    pub fn scene_from_world(self) -> UnitQuaternion<f64> {
        match self {
            Up::Y => crate::model::math::quaternion(&Vector3::x_axis(), -std::f64::consts::FRAC_PI_2),
            Up::Z => UnitQuaternion::identity(),
        }
    }
}

/// Radius (m) of the bone capsules and of the marker spheres.
pub const BONE_RADIUS_M: f64 = 0.012;
pub const MARKER_RADIUS_M: f64 = 0.01;

const MATERIALS: [(&str, [f32; 4]); 4] = [
    ("left", [0.05, 0.2, 0.8, 1.0]),
    ("right", [0.8, 0.07, 0.05, 1.0]),
    ("centre", [0.6, 0.6, 0.6, 1.0]),
    ("observed", [0.95, 0.8, 0.1, 1.0]),
];

fn material(side: Side) -> usize {
    match side {
        Side::Left => 0,
        Side::Right => 1,
        Side::Centre => 2,
    }
}

/// `[x, y, z, w]` of a rotation.
fn xyzw(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.i, q.j, q.k, q.w]
}

fn quat(m: &Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m))
}

/// The pose of body `b` in its parent's frame (a root body in `model`) after a forward pass.
fn local(take: &Take, ws: &Workspace, b: usize) -> (Matrix3<f64>, Vector3<f64>) {
    match take.model.bodies[b].parent {
        Some(p) => {
            let rt = ws.body_rot[p].transpose();
            (rt * ws.body_rot[b], rt * (ws.body_pos[b] - ws.body_pos[p]))
        }
        None => (ws.body_rot[b], ws.body_pos[b]),
    }
}

/// The glTF document of `take` with `cameras`, for up axis `up` (bones as capsules).
pub fn document(take: &Take, cameras: &[Camera], up: Up) -> Result<Document, RenderError> {
    document_with_body(take, cameras, up, None)
}

/// [`document`] with the subject's body mesh in place of the bone capsules where `body` is
/// given: a root node `body` showing the mesh skinned to the body nodes (glTF skin `body`, one
/// joint per model body in model order, inverse bind matrices of the bind pose at the subject's
/// scales, JOINTS_0 as u16, WEIGHTS_0 as f32). glTF blends one rest position per vertex, where
/// [`Dressed::pose`] scales each influence's own local point: the two agree at the bind pose and
/// differ only where a vertex's bodies are scaled differently.
pub fn document_with_body(
    take: &Take,
    cameras: &[Camera],
    up: Up,
    body: Option<&Dressed>,
) -> Result<Document, RenderError> {
    let model = &take.model;
    let dressed = body;
    let mut doc = Document {
        materials: MATERIALS.iter().map(|(n, c)| Material { name: (*n).into(), rgba: *c }).collect(),
        ..Default::default()
    };
    for (name, side) in [("left", 0), ("right", 1), ("centre", 2), ("observed", 3)] {
        let mut p = sphere(Vector3::zeros(), MARKER_RADIUS_M);
        p.material = side;
        doc.meshes.push(Mesh { name: format!("marker_{name}"), primitives: vec![p], weights: Vec::new() });
    }
    let mut world = Node::new("world", None);
    world.rotation = xyzw(&up.scene_from_world());
    doc.nodes.push(world);
    let mut model_node = Node::new("model", Some(0));
    model_node.rotation = xyzw(&take.world_from_model);
    doc.nodes.push(model_node);
    let mut ws = Workspace::new(model);
    take.forward(0, &mut ws);
    let body_node = |b: usize| 2 + b;
    for (b, body) in model.bodies.iter().enumerate() {
        let mut n = Node::new(body.name.clone(), Some(body.parent.map_or(1, body_node)));
        let (r, t) = local(take, &ws, b);
        n.translation = t.into();
        n.rotation = xyzw(&quat(&r));
        let start = take.joint_centre_local(b);
        let mut prims: Vec<Primitive> = Vec::new();
        let children = model.bodies.iter().enumerate().filter(|(_, c)| c.parent == Some(b) && dressed.is_none());
        for (c, child) in children {
            let s = Vector3::new(take.scales[3 * b], take.scales[3 * b + 1], take.scales[3 * b + 2]);
            let end = s.component_mul(&child.joint.parent_offset.translation.vector);
            if (end - start).norm() < 1e-6 {
                continue;
            }
            let mat = material(side_of(&model.bodies[c].name));
            let mut cap = capsule(start, end, BONE_RADIUS_M);
            cap.material = mat;
            match prims.iter_mut().find(|p| p.material == mat) {
                Some(p) => append(p, cap),
                None => prims.push(cap),
            }
        }
        if !prims.is_empty() {
            n.mesh = Some(doc.meshes.len());
            doc.meshes.push(Mesh { name: format!("bones:{}", body.name), primitives: prims, weights: Vec::new() });
        }
        doc.nodes.push(n);
    }
    for mk in &model.markers {
        let mut n = Node::new(mk.name.clone(), Some(body_node(mk.body)));
        let b = mk.body;
        let s = Vector3::new(take.scales[3 * b], take.scales[3 * b + 1], take.scales[3 * b + 2]);
        n.translation = s.component_mul(&mk.offset).into();
        let side = match side_of(&mk.name) {
            Side::Centre => side_of(&model.bodies[b].name),
            s => s,
        };
        n.mesh = Some(material(side));
        doc.nodes.push(n);
    }
    let observed_root = doc.nodes.len();
    doc.nodes.push(Node::new("observed", Some(1)));
    let first_obs = doc.nodes.len();
    for mk in &model.markers {
        let mut n = Node::new(format!("observed/{}", mk.name), Some(observed_root));
        n.mesh = Some(3);
        doc.nodes.push(n);
    }
    let cams_root = doc.nodes.len();
    let mut cams = Node::new("cameras", None);
    cams.rotation = xyzw(&up.scene_from_world());
    doc.nodes.push(cams);
    // glTF cameras look along −Z with +Y up; OpenCV's along +Z with +Y down.
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    for (i, c) in cameras.iter().enumerate() {
        let mut n = Node::new(c.name.clone(), Some(cams_root));
        n.translation = c.centre().into();
        n.rotation = xyzw(&quat(&(c.r.transpose() * flip)));
        n.camera = Some(i);
        doc.nodes.push(n);
        doc.cameras.push(gltf::Camera {
            name: c.name.clone(),
            yfov: c.yfov(),
            aspect_ratio: c.width_px as f64 / c.height_px as f64,
            znear: 0.05,
            zfar: 1000.0,
        });
    }
    let skinned = dressed.map(|d| skinned_body(&mut doc, take, up, d));
    let mut anim = animation(take, first_obs, &mut ws);
    if let (Some(body), Some((first, node))) = (dressed, skinned) {
        anim.tracks.extend(body_tracks(take, body, first, node));
    }
    doc.animation = Some(anim);
    Ok(doc)
}

/// Adds the root node `body`, its mesh (with the correctives as morph targets,
/// [`crate::body::correctives`]) and its skin over the body nodes (`2 + b`) and the helper
/// joints ([`crate::body::helpers`]: nodes under `model`), animated by [`body_tracks`]; returns
/// the first helper node's index and the `body` node's.
fn skinned_body(doc: &mut Document, take: &Take, up: Up, body: &Dressed) -> (usize, usize) {
    let model = &take.model;
    let mut ws = PoseWorkspace::new(model, body);
    body.pose(model, &body.bind_state(model, &take.scales), &mut ws);
    let first_helper = doc.nodes.len();
    let r0t = body.binding.world_from_model.inverse().to_rotation_matrix().into_inner();
    let nb = model.nb();
    let mut bind_frames = Vec::new();
    for (k, h) in body.binding.helpers.helpers.iter().enumerate() {
        let name = format!("helper:{}-{}:{}", model.bodies[h.parent].name, model.bodies[h.child].name, h.fraction);
        let mut n = Node::new(name, Some(1));
        let (r, t) = ws.joint(nb + k);
        let (r, t) = (r0t * r, r0t * t);
        n.translation = t.into();
        n.rotation = xyzw(&quat(&r));
        doc.nodes.push(n);
        bind_frames.push((r, t));
    }
    let s = up.scene_from_world().to_rotation_matrix().into_inner();
    let sw = s * take.world_from_model.to_rotation_matrix().into_inner();
    let positions: Vec<[f32; 3]> = ws
        .vertices
        .iter()
        .map(|v| {
            let p = s * Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64);
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    let normals = crate::body::metrics::vertex_normals(&positions, &body.triangles)
        .iter()
        .map(|n| n.map(|x| x as f32).into())
        .collect();
    let mut prim = Primitive {
        positions,
        normals,
        indices: body.triangles.iter().flatten().copied().collect(),
        material: doc.materials.len(),
        ..Default::default()
    };
    for k in &body.correctives {
        let mut t = vec![[0f32; 3]; prim.positions.len()];
        for (&v, d) in k.vertices.iter().zip(&k.deltas) {
            let p = s * Vector3::new(d[0] as f64, d[1] as f64, d[2] as f64);
            t[v as usize] = [p.x as f32, p.y as f32, p.z as f32];
        }
        prim.targets.push(t);
    }
    doc.materials.push(Material { name: "skin".into(), rgba: [0.8, 0.62, 0.5, 1.0] });
    for inf in &body.binding.helpers.joints {
        prim.joints.push(inf.map(|x| if x.weight > 0.0 { x.joint } else { 0 }));
        prim.weights.push(inf.map(|x| x.weight));
    }
    let frame = |j: usize| if j < nb { (ws.kin.body_rot[j], ws.kin.body_pos[j]) } else { bind_frames[j - nb] };
    let joints = nb + bind_frames.len();
    let inverse_bind = (0..joints)
        .map(|j| {
            let (r, t) = frame(j);
            let (r, t) = (sw * r, sw * t);
            let inv = nalgebra::Matrix4::new_translation(&t) * r.to_homogeneous();
            let inv = inv.try_inverse().unwrap_or_else(nalgebra::Matrix4::identity);
            let mut m = [0f32; 16];
            for (k, v) in inv.iter().enumerate() {
                m[k] = *v as f32; // column-major, as glTF
            }
            m
        })
        .collect();
    let skin_joints = (0..joints).map(|j| if j < nb { 2 + j } else { first_helper + j - nb }).collect();
    doc.skins.push(gltf::Skin { name: "body".into(), joints: skin_joints, inverse_bind });
    let mut n = Node::new("body", None);
    n.mesh = Some(doc.meshes.len());
    n.skin = Some(0);
    let weights = vec![0.0; body.correctives.len()];
    doc.meshes.push(Mesh { name: "body".into(), primitives: vec![prim], weights });
    doc.nodes.push(n);
    (first_helper, doc.nodes.len() - 1)
}

/// The helper joints' poses per frame (nodes `first..`, in the model's frame) and the
/// correctives' weights (node `node`'s morph targets).
fn body_tracks(take: &Take, body: &Dressed, first: usize, node: usize) -> Vec<Track> {
    let (model, nb, n) = (&take.model, take.model.nb(), take.len());
    let nh = body.binding.helpers.helpers.len();
    let r0t = body.binding.world_from_model.inverse().to_rotation_matrix().into_inner();
    let mut ws = PoseWorkspace::new(model, body);
    let mut trans = vec![Vec::with_capacity(n); nh];
    let mut rots: Vec<Vec<[f32; 4]>> = vec![Vec::with_capacity(n); nh];
    let mut y = vec![0.0; model.ny()];
    let mut morph = Vec::with_capacity(n * body.correctives.len());
    for i in 0..n {
        y[..model.nq()].copy_from_slice(&take.q[i]);
        y[model.nq()..].copy_from_slice(&take.scales);
        body.pose_joints(model, &y, &mut ws);
        morph.extend(ws.morph.iter().map(|&w| w as f32));
        for k in 0..nh {
            let (r, t) = ws.joint(nb + k);
            let t = r0t * t;
            trans[k].push([t.x as f32, t.y as f32, t.z as f32]);
            let mut q = gltf::unit_f32(xyzw(&quat(&(r0t * r))));
            if let Some(prev) = rots[k].last() {
                if prev.iter().zip(&q).map(|(a, b)| a * b).sum::<f32>() < 0.0 {
                    q = q.map(|v| -v);
                }
            }
            rots[k].push(q);
        }
    }
    let mut tracks = Vec::with_capacity(2 * nh);
    for (k, (t, r)) in trans.into_iter().zip(rots).enumerate() {
        tracks.push(Track { node: first + k, values: Values::Translation(t), step: false });
        tracks.push(Track { node: first + k, values: Values::Rotation(r), step: false });
    }
    if !body.correctives.is_empty() {
        let per_key = body.correctives.len();
        tracks.push(Track { node, values: Values::Weights { per_key, values: morph }, step: false });
    }
    tracks
}

/// The `motion` animation: every body's local pose per frame, the observed markers.
fn animation(take: &Take, first_obs: usize, ws: &mut Workspace) -> gltf::Animation {
    let (nb, nm, n) = (take.model.nb(), take.model.markers.len(), take.len());
    let mut trans = vec![Vec::with_capacity(n); nb];
    let mut rots: Vec<Vec<[f32; 4]>> = vec![Vec::with_capacity(n); nb];
    for i in 0..n {
        take.forward(i, ws);
        for b in 0..nb {
            let (r, t) = local(take, ws, b);
            trans[b].push([t.x as f32, t.y as f32, t.z as f32]);
            let mut q = gltf::unit_f32(xyzw(&quat(&r)));
            // Consecutive keys on the same hemisphere: the shortest interpolation path.
            if let Some(prev) = rots[b].last() {
                if prev.iter().zip(&q).map(|(a, b)| a * b).sum::<f32>() < 0.0 {
                    q = q.map(|v| -v);
                }
            }
            rots[b].push(q);
        }
    }
    let mut tracks = Vec::new();
    for b in 0..nb {
        tracks.push(Track { node: 2 + b, values: Values::Translation(std::mem::take(&mut trans[b])), step: false });
        tracks.push(Track { node: 2 + b, values: Values::Rotation(std::mem::take(&mut rots[b])), step: false });
    }
    for m in 0..nm {
        let seen: Vec<Option<Vector3<f64>>> = take.observed.iter().map(|o| o[m]).collect();
        // Where not observed: the last observed position (the first, before it), hidden.
        let mut hold = seen.iter().flatten().next().copied().unwrap_or_else(Vector3::zeros);
        let mut pos = Vec::with_capacity(n);
        let mut scale = Vec::with_capacity(n);
        for s in &seen {
            if let Some(p) = s {
                hold = *p;
            }
            pos.push([hold.x as f32, hold.y as f32, hold.z as f32]);
            scale.push(if s.is_some() { [1.0; 3] } else { [0.0; 3] });
        }
        tracks.push(Track { node: first_obs + m, values: Values::Translation(pos), step: false });
        tracks.push(Track { node: first_obs + m, values: Values::Scale(scale), step: true });
    }
    gltf::Animation { name: "motion".into(), times: take.times.clone(), tracks }
}

/// The `.glb` bytes of `take` with `cameras` for up axis `up`.
pub fn glb(take: &Take, cameras: &[Camera], up: Up) -> Result<Vec<u8>, RenderError> {
    Ok(gltf::to_glb(&document(take, cameras, up)?)?)
}

/// [`glb`] with the body mesh where `body` is given ([`document_with_body`]).
pub fn glb_with_body(take: &Take, cameras: &[Camera], up: Up, body: Option<&Dressed>) -> Result<Vec<u8>, RenderError> {
    Ok(gltf::to_glb(&document_with_body(take, cameras, up, body)?)?)
}

const SEGMENTS: usize = 12;
const RINGS: usize = 4;

/// A capsule of radius `r` around the segment `a`–`b` (positions in the caller's frame).
pub fn capsule(a: Vector3<f64>, b: Vector3<f64>, r: f64) -> Primitive {
    let w = (b - a).normalize();
    let h = std::f64::consts::FRAC_PI_2 / RINGS as f64;
    let mut rings: Vec<(Vector3<f64>, f64)> =
        (1..=RINGS).map(|k| (a, -std::f64::consts::FRAC_PI_2 + k as f64 * h)).collect();
    rings.extend((0..RINGS).map(|k| (b, k as f64 * h)));
    round(a - w * r, b + w * r, w, &rings, r)
}

/// A sphere of radius `r` at `c`.
pub fn sphere(c: Vector3<f64>, r: f64) -> Primitive {
    let h = std::f64::consts::PI / (2 * RINGS) as f64;
    let rings: Vec<(Vector3<f64>, f64)> =
        (1..2 * RINGS).map(|k| (c, -std::f64::consts::FRAC_PI_2 + k as f64 * h)).collect();
    round(c - Vector3::z() * r, c + Vector3::z() * r, Vector3::z(), &rings, r)
}

/// A closed surface of revolution about `w`: two poles and rings `(centre, latitude)`.
fn round(
    south: Vector3<f64>,
    north: Vector3<f64>,
    w: Vector3<f64>,
    rings: &[(Vector3<f64>, f64)],
    r: f64,
) -> Primitive {
    let u = if w.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = (u - w * w.dot(&u)).normalize();
    let v = w.cross(&u);
    let mut p = Primitive::default();
    let put = |pos: Vector3<f64>, nor: Vector3<f64>, p: &mut Primitive| {
        p.positions.push([pos.x as f32, pos.y as f32, pos.z as f32]);
        let n = nor.map(|x| x as f32);
        let n = n / n.norm();
        p.normals.push([n.x, n.y, n.z]);
    };
    put(south, -w, &mut p);
    for &(c, phi) in rings {
        for j in 0..SEGMENTS {
            let th = std::f64::consts::TAU * j as f64 / SEGMENTS as f64;
            let ((st, ct), (sp, cp)) = (crate::model::math::sin_cos(th), crate::model::math::sin_cos(phi));
            let n = (u * ct + v * st) * cp + w * sp;
            put(c + n * r, n, &mut p);
        }
    }
    put(north, w, &mut p);
    let s = SEGMENTS as u32;
    let ring = |i: usize, j: u32| 1 + i as u32 * s + j % s;
    let last = rings.len() - 1;
    for j in 0..s {
        p.indices.extend([0, ring(0, j + 1), ring(0, j)]);
        for i in 0..last {
            p.indices.extend([ring(i, j), ring(i, j + 1), ring(i + 1, j + 1)]);
            p.indices.extend([ring(i, j), ring(i + 1, j + 1), ring(i + 1, j)]);
        }
        p.indices.extend([ring(last, j), ring(last, j + 1), 1 + rings.len() as u32 * s]);
    }
    p
}

/// Appends `b`'s triangles to `a`.
fn append(a: &mut Primitive, b: Primitive) {
    let base = a.positions.len() as u32;
    a.positions.extend(b.positions);
    a.normals.extend(b.normals);
    a.indices.extend(b.indices.into_iter().map(|i| i + base));
}
