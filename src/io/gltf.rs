//! Writing glTF 2.0 binary files (`.glb`) of an animated node tree: nodes with names, rest
//! transforms, meshes (triangles with normals, one material each) and cameras, and one
//! animation of per-node translation / rotation / scale samplers at shared key times.
//!
//! The document model is gltf-rs' (`gltf::json`), the GLB container its `::gltf::binary::Glb`.
//! What this module adds is the binary buffer layout: every accessor in its own 4-byte aligned
//! buffer view, vertex and index views with their targets, `min`/`max` where the specification
//! requires them (positions, animation inputs). Units are the caller's (smocap: metres, seconds);
//! frames are glTF's (a node's transform maps its children into its parent's frame).
//! The output depends on the input alone: JSON fields in a fixed order, no timestamps.

use ::gltf::json::{self, validation::Checked::Valid, validation::USize64};
use std::collections::BTreeMap;

/// Errors writing a glTF file.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    #[error("glTF node '{node}': parent index {parent} does not come before it")]
    ParentOrder { node: String, parent: usize },
    #[error("glTF {what} '{name}': {problem}")]
    Invalid { what: &'static str, name: String, problem: String },
    #[error(
        "glTF animation key times must increase strictly (as float32): key {index} is {time} s after {previous} s"
    )]
    Times { index: usize, time: f64, previous: f64 },
    #[error("glTF serialisation: {0}")]
    Json(String),
}

/// A node: its name, parent (an earlier node, or `None` for a scene root), rest transform in
/// its parent's frame, and what it shows.
#[derive(Clone, Debug)]
pub struct Node {
    pub name: String,
    pub parent: Option<usize>,
    pub translation: [f64; 3],
    /// Unit quaternion `[x, y, z, w]`.
    pub rotation: [f64; 4],
    pub scale: [f64; 3],
    pub mesh: Option<usize>,
    pub camera: Option<usize>,
    /// The skin (index into [`Document::skins`]) deforming this node's mesh.
    pub skin: Option<usize>,
}

impl Node {
    /// A node at its parent's origin, unrotated, showing nothing.
    pub fn new(name: impl Into<String>, parent: Option<usize>) -> Node {
        Node {
            name: name.into(),
            parent,
            translation: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
            scale: [1.0; 3],
            mesh: None,
            camera: None,
            skin: None,
        }
    }
}

/// Triangles in the frame of the node that shows them.
#[derive(Clone, Debug, Default)]
pub struct Primitive {
    pub positions: Vec<[f32; 3]>,
    /// Unit normals, one per position.
    pub normals: Vec<[f32; 3]>,
    /// Three per triangle, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
    pub material: usize,
    /// Skinning, one per position where the mesh is skinned (else empty): joint indices into
    /// the skin's joints and their weights (summing to 1).
    pub joints: Vec<[u16; 4]>,
    pub weights: Vec<[f32; 4]>,
    /// Morph targets: per target, a position displacement per position (the primitive's
    /// frame, before skinning), blended by the mesh's weights; written as sparse accessors.
    pub targets: Vec<Vec<[f32; 3]>>,
}

/// A skin: its joints (node indices) and each joint's inverse bind matrix (column-major 4×4).
#[derive(Clone, Debug)]
pub struct Skin {
    pub name: String,
    pub joints: Vec<usize>,
    pub inverse_bind: Vec<[f32; 16]>,
}

/// A mesh of one or more primitives.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub name: String,
    pub primitives: Vec<Primitive>,
    /// Default morph target weights (one per target of its primitives; empty without targets).
    pub weights: Vec<f32>,
}

/// A plain coloured material (linear RGBA, metallic 0).
#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub rgba: [f32; 4],
}

/// A perspective camera (looking along its node's −Z, +Y up, as glTF defines).
#[derive(Clone, Debug)]
pub struct Camera {
    pub name: String,
    /// Vertical field of view (rad).
    pub yfov: f64,
    /// Width / height.
    pub aspect_ratio: f64,
    /// Near and far clipping distances (m).
    pub znear: f64,
    pub zfar: f64,
}

/// What a sampler animates, with one value per key time.
#[derive(Clone, Debug)]
pub enum Values {
    Translation(Vec<[f32; 3]>),
    /// Unit quaternions `[x, y, z, w]`.
    Rotation(Vec<[f32; 4]>),
    Scale(Vec<[f32; 3]>),
    /// Morph target weights: `per_key` (the mesh's target count) per key time, key by key.
    Weights {
        per_key: usize,
        values: Vec<f32>,
    },
}

/// One animated property of one node.
#[derive(Clone, Debug)]
pub struct Track {
    pub node: usize,
    pub values: Values,
    /// Step interpolation (values held until the next key) instead of linear (slerp for rotations).
    pub step: bool,
}

/// One animation: key times (s) shared by all its tracks.
#[derive(Clone, Debug)]
pub struct Animation {
    pub name: String,
    pub times: Vec<f64>,
    pub tracks: Vec<Track>,
}

/// A whole document: one scene of all root nodes.
#[derive(Clone, Debug, Default)]
pub struct Document {
    pub nodes: Vec<Node>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub cameras: Vec<Camera>,
    pub animation: Option<Animation>,
    pub skins: Vec<Skin>,
}

/// The binary buffer being laid out and the JSON root referring to it.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends `bytes` as a new buffer view (4-byte aligned) and returns it.
    fn view(&mut self, bytes: &[u8], target: Option<json::buffer::Target>) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// An accessor over a new view of `data` (float32, `n` per element), with `min`/`max` when asked.
    fn floats(
        &mut self,
        data: &[f32],
        type_: json::accessor::Type,
        n: usize,
        bounds: bool,
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let (min, max) = if bounds {
            let mut lo = vec![f32::INFINITY; n];
            let mut hi = vec![f32::NEG_INFINITY; n];
            for e in data.chunks_exact(n) {
                for a in 0..n {
                    lo[a] = lo[a].min(e[a]);
                    hi[a] = hi[a].max(e[a]);
                }
            }
            (Some(json::Value::from(lo)), Some(json::Value::from(hi)))
        } else {
            (None, None)
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(data.len() / n),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::F32)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// A sparse VEC3 float accessor of `n` elements, zero but at `idx` (ascending) where they
    /// are `values`; `min`/`max` over all `n` (as the specification asks of morph positions).
    fn sparse_vec3(&mut self, n: usize, idx: &[u32], values: &[[f32; 3]]) -> json::Index<json::Accessor> {
        let (mut lo, mut hi) = (vec![0f32; 3], vec![0f32; 3]);
        for v in values {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        let idx_bytes: Vec<u8> = idx.iter().flat_map(|v| v.to_le_bytes()).collect();
        let val_bytes: Vec<u8> = values.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let indices = self.view(&idx_bytes, None);
        let vals = self.view(&val_bytes, None);
        use json::accessor::sparse;
        self.root.push(json::Accessor {
            buffer_view: None,
            byte_offset: None,
            count: USize64::from(n),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::F32)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(json::accessor::Type::Vec3),
            min: Some(json::Value::from(lo)),
            max: Some(json::Value::from(hi)),
            name: None,
            normalized: false,
            sparse: Some(sparse::Sparse {
                count: USize64::from(idx.len()),
                indices: sparse::Indices {
                    buffer_view: indices,
                    byte_offset: USize64(0),
                    component_type: Valid(json::accessor::IndexComponentType(json::accessor::ComponentType::U32)),
                    extensions: None,
                    extras: Default::default(),
                },
                values: sparse::Values {
                    buffer_view: vals,
                    byte_offset: USize64(0),
                    extensions: None,
                    extras: Default::default(),
                },
                extensions: None,
                extras: Default::default(),
            }),
        })
    }

    fn joints(&mut self, j: &[[u16; 4]]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = j.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(json::buffer::Target::ArrayBuffer));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(j.len()),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::U16)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(json::accessor::Type::Vec4),
            min: None,
            max: None,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn indices(&mut self, idx: &[u32]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = idx.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(json::buffer::Target::ElementArrayBuffer));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(idx.len()),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::U32)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(json::accessor::Type::Scalar),
            min: None,
            max: None,
            name: None,
            normalized: false,
            sparse: None,
        })
    }
}

fn f32s<const N: usize>(v: &[f64; N]) -> [f32; N] {
    v.map(|x| x as f32)
}

/// The document as GLB bytes.
pub fn to_glb(doc: &Document) -> Result<Vec<u8>, GltfError> {
    use json::accessor::Type;
    let mut b = Builder {
        root: json::Root {
            asset: json::Asset {
                generator: Some(format!("smocap {}", env!("CARGO_PKG_VERSION"))),
                version: "2.0".into(),
                ..Default::default()
            },
            ..Default::default()
        },
        bin: Vec::new(),
    };
    for m in &doc.materials {
        let mut mat = json::Material { name: Some(m.name.clone()), ..Default::default() };
        mat.pbr_metallic_roughness.base_color_factor = json::material::PbrBaseColorFactor(m.rgba);
        mat.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
        mat.pbr_metallic_roughness.roughness_factor = json::material::StrengthFactor(0.6);
        b.root.push(mat);
    }
    for m in &doc.meshes {
        let mut primitives = Vec::new();
        for p in &m.primitives {
            let bad = |problem: String| GltfError::Invalid { what: "mesh", name: m.name.clone(), problem };
            if p.material >= doc.materials.len() {
                return Err(bad(format!("material {} of {}", p.material, doc.materials.len())));
            }
            if p.normals.len() != p.positions.len() || !p.indices.len().is_multiple_of(3) || p.positions.is_empty() {
                return Err(bad("positions, normals and triangles do not match".into()));
            }
            if let Some(i) = p.indices.iter().find(|&&i| i as usize >= p.positions.len()) {
                return Err(bad(format!("index {i} of {} positions", p.positions.len())));
            }
            let pos: Vec<f32> = p.positions.iter().flatten().copied().collect();
            let nor: Vec<f32> = p.normals.iter().flatten().copied().collect();
            let target = Some(json::buffer::Target::ArrayBuffer);
            let mut attributes = BTreeMap::new();
            attributes.insert(Valid(json::mesh::Semantic::Positions), b.floats(&pos, Type::Vec3, 3, true, target));
            attributes.insert(Valid(json::mesh::Semantic::Normals), b.floats(&nor, Type::Vec3, 3, false, target));
            if !p.joints.is_empty() {
                if p.joints.len() != p.positions.len() || p.weights.len() != p.positions.len() {
                    return Err(bad("joints and weights do not match the positions".into()));
                }
                attributes.insert(Valid(json::mesh::Semantic::Joints(0)), b.joints(&p.joints));
                let w: Vec<f32> = p.weights.iter().flatten().copied().collect();
                attributes.insert(Valid(json::mesh::Semantic::Weights(0)), b.floats(&w, Type::Vec4, 4, false, target));
            }
            if p.targets.len() != m.weights.len() || p.targets.iter().any(|t| t.len() != p.positions.len()) {
                return Err(bad("morph targets do not match the positions or the mesh's weights".into()));
            }
            let targets: Vec<json::mesh::MorphTarget> = p
                .targets
                .iter()
                .map(|t| {
                    // sparse: a corrective moves a few hundred of the body's vertices
                    let idx: Vec<u32> = (0..t.len() as u32).filter(|&i| t[i as usize] != [0.0; 3]).collect();
                    let values: Vec<[f32; 3]> = idx.iter().map(|&i| t[i as usize]).collect();
                    let positions = Some(b.sparse_vec3(t.len(), &idx, &values));
                    json::mesh::MorphTarget { positions, normals: None, tangents: None }
                })
                .collect();
            primitives.push(json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: Default::default(),
                indices: Some(b.indices(&p.indices)),
                material: Some(json::Index::new(p.material as u32)),
                mode: Valid(json::mesh::Mode::Triangles),
                targets: (!targets.is_empty()).then_some(targets),
            });
        }
        b.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(m.name.clone()),
            primitives,
            weights: (!m.weights.is_empty()).then(|| m.weights.clone()),
        });
    }
    for c in &doc.cameras {
        if !(c.yfov > 0.0 && c.aspect_ratio > 0.0 && c.znear > 0.0 && c.zfar > c.znear) {
            return Err(GltfError::Invalid {
                what: "camera",
                name: c.name.clone(),
                problem: "yfov, aspect ratio and znear must be positive and zfar beyond znear".into(),
            });
        }
        b.root.push(json::Camera {
            name: Some(c.name.clone()),
            orthographic: None,
            perspective: Some(json::camera::Perspective {
                aspect_ratio: Some(c.aspect_ratio as f32),
                yfov: c.yfov as f32,
                zfar: Some(c.zfar as f32),
                znear: c.znear as f32,
                extensions: None,
                extras: Default::default(),
            }),
            type_: Valid(json::camera::Type::Perspective),
            extensions: None,
            extras: Default::default(),
        });
    }
    let mut children: Vec<Vec<json::Index<json::Node>>> = vec![Vec::new(); doc.nodes.len()];
    let mut roots = Vec::new();
    for (i, n) in doc.nodes.iter().enumerate() {
        match n.parent {
            Some(p) if p < i => children[p].push(json::Index::new(i as u32)),
            Some(p) => return Err(GltfError::ParentOrder { node: n.name.clone(), parent: p }),
            None => roots.push(json::Index::new(i as u32)),
        }
        let bad = |problem: String| GltfError::Invalid { what: "node", name: n.name.clone(), problem };
        if n.mesh.is_some_and(|m| m >= doc.meshes.len()) || n.camera.is_some_and(|c| c >= doc.cameras.len()) {
            return Err(bad("mesh or camera index out of range".into()));
        }
    }
    for (n, kids) in doc.nodes.iter().zip(children) {
        let r = unit_f32(n.rotation);
        b.root.push(json::Node {
            camera: n.camera.map(|c| json::Index::new(c as u32)),
            children: (!kids.is_empty()).then_some(kids),
            extensions: None,
            extras: Default::default(),
            matrix: None,
            mesh: n.mesh.map(|m| json::Index::new(m as u32)),
            name: Some(n.name.clone()),
            rotation: (r != [0.0, 0.0, 0.0, 1.0]).then_some(json::scene::UnitQuaternion(r)),
            scale: (n.scale != [1.0; 3]).then(|| f32s(&n.scale)),
            translation: (n.translation != [0.0; 3]).then(|| f32s(&n.translation)),
            skin: n.skin.map(|k| json::Index::new(k as u32)),
            weights: None,
        });
    }
    for sk in &doc.skins {
        if sk.joints.len() != sk.inverse_bind.len() || sk.joints.iter().any(|&j| j >= doc.nodes.len()) {
            return Err(GltfError::Invalid {
                what: "skin",
                name: sk.name.clone(),
                problem: "joints and matrices".into(),
            });
        }
        let m: Vec<f32> = sk.inverse_bind.iter().flatten().copied().collect();
        let ibm = b.floats(&m, Type::Mat4, 16, false, None);
        b.root.push(json::Skin {
            extensions: None,
            extras: Default::default(),
            inverse_bind_matrices: Some(ibm),
            joints: sk.joints.iter().map(|&j| json::Index::new(j as u32)).collect(),
            name: Some(sk.name.clone()),
            skeleton: None,
        });
    }
    let scene = b.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("scene".into()),
        nodes: roots,
    });
    b.root.scene = Some(scene);
    if let Some(a) = &doc.animation {
        animation(&mut b, a, doc.nodes.len())?;
    }
    while !b.bin.len().is_multiple_of(4) {
        b.bin.push(0);
    }
    if !b.bin.is_empty() {
        b.root.push(json::Buffer {
            byte_length: USize64::from(b.bin.len()),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
    }
    let mut text = json::serialize::to_vec(&b.root).map_err(|e| GltfError::Json(e.to_string()))?;
    // The JSON chunk is padded with spaces (the container pads with zeros otherwise).
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let glb = ::gltf::binary::Glb {
        header: ::gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
        json: std::borrow::Cow::Owned(text),
        bin: (!b.bin.is_empty()).then_some(std::borrow::Cow::Owned(b.bin)),
    };
    glb.to_vec().map_err(|e| GltfError::Json(e.to_string()))
}

/// A quaternion as float32, renormalised after rounding (glTF requires unit rotations).
pub fn unit_f32(q: [f64; 4]) -> [f32; 4] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let r = q.map(|v| (v / n) as f32);
    let m = r.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    r.map(|v| (v as f64 / m) as f32)
}

fn animation(b: &mut Builder, a: &Animation, nodes: usize) -> Result<(), GltfError> {
    use json::accessor::Type;
    let times: Vec<f32> = a.times.iter().map(|&t| t as f32).collect();
    for i in 1..times.len() {
        if times[i] <= times[i - 1] {
            return Err(GltfError::Times { index: i, time: a.times[i], previous: a.times[i - 1] });
        }
    }
    let input = b.floats(&times, Type::Scalar, 1, true, None);
    let (mut samplers, mut channels) = (Vec::new(), Vec::new());
    for t in &a.tracks {
        let bad = |problem: String| GltfError::Invalid { what: "animation", name: a.name.clone(), problem };
        if t.node >= nodes {
            return Err(bad(format!("track of node {} of {nodes}", t.node)));
        }
        let (data, type_, n, path): (Vec<f32>, _, _, _) = match &t.values {
            Values::Translation(v) => {
                (v.iter().flatten().copied().collect(), Type::Vec3, 3, json::animation::Property::Translation)
            }
            Values::Rotation(v) => {
                (v.iter().flatten().copied().collect(), Type::Vec4, 4, json::animation::Property::Rotation)
            }
            Values::Scale(v) => {
                (v.iter().flatten().copied().collect(), Type::Vec3, 3, json::animation::Property::Scale)
            }
            Values::Weights { per_key, values } => {
                (values.clone(), Type::Scalar, *per_key, json::animation::Property::MorphTargetWeights)
            }
        };
        if data.len() != n * times.len() {
            return Err(bad(format!("{} values for {} key times", data.len() / n, times.len())));
        }
        let output = match type_ {
            // one scalar per target and key: the accessor counts them all
            Type::Scalar => b.floats(&data, type_, 1, false, None),
            _ => b.floats(&data, type_, n, false, None),
        };
        let sampler = json::Index::push(
            &mut samplers,
            json::animation::Sampler {
                extensions: None,
                extras: Default::default(),
                input,
                interpolation: Valid(if t.step {
                    json::animation::Interpolation::Step
                } else {
                    json::animation::Interpolation::Linear
                }),
                output,
            },
        );
        channels.push(json::animation::Channel {
            sampler,
            target: json::animation::Target {
                extensions: None,
                extras: Default::default(),
                node: json::Index::new(t.node as u32),
                path: Valid(path),
            },
            extensions: None,
            extras: Default::default(),
        });
    }
    if !channels.is_empty() {
        b.root.push(json::Animation {
            extensions: None,
            extras: Default::default(),
            channels,
            name: Some(a.name.clone()),
            samplers,
        });
    }
    Ok(())
}
