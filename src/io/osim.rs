//! OpenSim model import (`.osim`, format version 4: `<OpenSimDocument Version="4xxxx">`) into a
//! [`Model`], and OpenSim marker-set files; export of a scaled subject: [`scale_osim`] rewrites
//! the model's own file with scale factors as OpenSim's ScaleTool does, [`format_osim`] writes any
//! [`Model`] (e.g. one read from MJCF) as a new `.osim` file.
//!
//! How OpenSim maps onto our conventions (SI: metres, radians; sources in OpenSim 4 / Simbody):
//! - Bodies: `BodySet` bodies, attached in topological order (parents first, then file order);
//!   `ground` is the world. Each body must be the child of exactly one joint.
//! - Joint frames: `socket_parent_frame` / `socket_child_frame` name a `PhysicalOffsetFrame` of
//!   the joint (`translation`, `orientation` = body-fixed X-Y-Z Euler angles, `OffsetFrame.h`),
//!   or a body / ground directly. Offset frames on offset frames are composed
//!   (`findTransformInBaseFrame`); their scaling is then approximate (warning).
//! - `CustomJoint` (Simbody `MobilizedBody::FunctionBased`): `X_FM = (R₁R₂R₃, Σ fᵢ tᵢ)`, rotations
//!   about successive (body-fixed) unit axes, translations along the parent-frame axes. We emit
//!   translation1-3 first, then rotation1-3. Constant-zero axes are dropped. Collinear axes are
//!   an error (as `CustomJoint::extendFinalizeFromProperties`). An axis without function gets
//!   `f(q) = q` with one coordinate, constant 0 with none (`SpatialTransform::connectToJoint`).
//! - Scaling (`SpatialTransform::scale`, OpenSim ≥ 4.5): every translation function except
//!   `LinearFunction` `1 0` (constants and slope −1 included) is multiplied by
//!   `|axis| · s_parent` (sign ignored, OpenSim issue #3991). We set `parent_scale_weights =
//!   |axis| / Σ|axisᵢ|`, so the unscaled model is unchanged: identical to OpenSim for axes along
//!   ±x/±y/±z; for an oblique axis OpenSim's factor is `Σ|axisᵢ|` (e.g. 1.4) even at unit scale,
//!   and ours is that much smaller at every scale (`tests/io_osim_joints.rs` shows both).
//! - Other joints (Simbody mobilizers, Euler angles as OpenSim uses them): `PinJoint` rotation
//!   about z; `SliderJoint` translation along x; `UniversalJoint` rotations x, y; `GimbalJoint`
//!   and `BallJoint` rotations x, y, z (body-fixed); `FreeJoint` coordinates rx ry rz tx ty tz,
//!   motions: translations x, y, z then rotations x, y, z; `WeldJoint` none.
//! - Every joint type, offset frames (translated and rotated), spline/linear/constant
//!   translations, a coordinate coupler and non-uniform `Model::scale` are checked against
//!   OpenSim 4.6's own FK to 1e-14 m (`tests/io_osim_joints.rs`, fixture made by
//!   `scripts/gen_osim_joint_fixture.py`).
//! - Coordinates: `default_value`, `range` (±∞ when absent), `clamped`, `locked`. The kind
//!   follows OpenSim's `MotionType` (`CustomJoint::constructCoordinates`): over the axes in
//!   OpenSim's order (rotation1 … translation3), the last one driven by a `LinearFunction` of
//!   slope ±1 makes it rotational / translational; without one ("coupled") it is rotational if
//!   it drives any rotation axis, else translational.
//! - Functions: `Constant`, `LinearFunction`, `PolynomialFunction` (highest power first),
//!   `NaturalCubicSpline`, `PiecewiseLinearFunction`, `MultiplierFunction`, and `SimmSpline` with
//!   SIMM's own end conditions ([`simm_spline`]).
//! - `CoordinateCouplerConstraint` (enforced, one independent coordinate) →
//!   [`CoordinateCoupling`] `dependent = scale_factor · f(independent)`; the dependent default is
//!   set to match.
//! - Markers: `MarkerSet` markers with `socket_parent_frame` naming a body, `location` in its
//!   frame; markers on ground are skipped with a warning.
//! - Everything else (forces, contact geometry, controllers, probes, other constraints) is
//!   ignored with one warning per component type.

mod export;
mod func;
pub mod ik_setup;
mod joints;
mod markers;
mod scale;
mod scale_setup;
mod xml;

pub use export::{
    format_osim, format_scale_set, OsimWriteError, GENERATED_GRAVITY, PLACEHOLDER_INERTIA, PLACEHOLDER_MASS,
};
pub use func::simm_spline;
pub use ik_setup::{parse_ik_setup, read_ik_setup, CoordinateValue, IkCoordinateTask, IkSetup};
pub use markers::{parse_marker_set, read_marker_set};
pub use scale::{scale_inertia, scale_osim, MassScaling};
pub use scale_setup::{parse_scale_setup, read_scale_setup, Measurement, ScaleSetup};

use crate::model::{Body, Coordinate, CoordinateCoupling, Function, Marker, Model, ModelError, Motion, MotionKind};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use roxmltree::{Document, Node};
use std::path::Path;
use xml::{child, elements, last_segment, set_objects, Ctx};

/// Errors from reading an OpenSim file. Lines and columns are 1-based.
#[derive(Debug, thiserror::Error)]
pub enum OsimError {
    #[error("{file}: cannot read: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}:{line}:{column}: malformed XML: {message}")]
    Xml { file: String, line: u32, column: u32, message: String },
    #[error("{file}:{line}:{column}: <{element}>: {message}")]
    Element { file: String, line: u32, column: u32, element: String, message: String },
    #[error("{file}: invalid model: {source}")]
    Model { file: String, source: ModelError },
}

impl OsimError {
    /// Line of the offending text, when known.
    pub fn line(&self) -> Option<u32> {
        match self {
            OsimError::Xml { line, .. } | OsimError::Element { line, .. } => Some(*line),
            _ => None,
        }
    }
}

/// The joint types this reader understands.
pub const SUPPORTED_JOINTS: [&str; 8] =
    ["CustomJoint", "PinJoint", "SliderJoint", "UniversalJoint", "BallJoint", "GimbalJoint", "FreeJoint", "WeldJoint"];

/// Reads an `.osim` file; returns the model and the warnings about ignored content.
pub fn read_osim(path: &Path) -> Result<(Model, Vec<String>), OsimError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| OsimError::Io { file: file.clone(), source })?;
    parse_osim(&text, &file)
}

/// Parses `.osim` text; `file_name` is used in messages and for the default model name.
pub fn parse_osim(text: &str, file_name: &str) -> Result<(Model, Vec<String>), OsimError> {
    let doc = parse_xml(text, file_name)?;
    let mut ctx = Ctx::new(&doc, file_name);
    let root = doc.root_element();
    if root.tag_name().name() != "OpenSimDocument" {
        return Err(ctx.err(root, "expected the root element <OpenSimDocument>"));
    }
    match root.attribute("Version").map(|v| v.trim().parse::<u32>()) {
        Some(Ok(v)) if v >= 40000 => {}
        _ => return Err(ctx.err(root, "only OpenSim format version 4 (Version=\"40000\" or later) is supported")),
    }
    let Some(m) = child(root, "Model") else {
        return Err(ctx.err(root, "missing <Model>"));
    };
    let mut b = Builder::new(&mut ctx, m)?;
    b.joints(m)?;
    b.markers(m)?;
    b.constraints(m)?;
    b.ignored(m);
    let stem = Path::new(file_name).file_stem().and_then(|s| s.to_str()).unwrap_or("opensim");
    let name = m.attribute("name").unwrap_or(stem).to_string();
    let Builder { bodies, motions, coordinates, markers, couplings, .. } = b;
    let model = Model::new(name, bodies, motions, coordinates, markers, couplings)
        .map_err(|source| OsimError::Model { file: file_name.to_string(), source })?;
    Ok((model, std::mem::take(&mut ctx.warnings)))
}

fn parse_xml<'t>(text: &'t str, file: &str) -> Result<Document<'t>, OsimError> {
    Document::parse(text).map_err(|e| {
        let p = e.pos();
        OsimError::Xml { file: file.to_string(), line: p.row, column: p.col, message: e.to_string() }
    })
}

/// A resolved joint frame: base body (`None` = ground) and the frame in that body.
#[derive(Clone, Copy)]
struct Frame {
    body: Option<usize>,
    pose: Isometry3<f64>,
}

/// One joint of the file, before ordering.
struct JointSpec<'a> {
    node: Node<'a, 'a>,
    parent: Frame,
    child: Frame,
}

struct Builder<'c, 'a> {
    ctx: &'c mut Ctx<'a>,
    /// Body names in file order, and their index in `bodies` once attached.
    names: Vec<&'a str>,
    placed: Vec<Option<usize>>,
    bodies: Vec<Body>,
    motions: Vec<Motion>,
    coordinates: Vec<Coordinate>,
    markers: Vec<Marker>,
    couplings: Vec<CoordinateCoupling>,
}

/// One elementary motion of a joint before emission.
struct Axis {
    kind: MotionKind,
    axis: Vector3<f64>,
    /// Index into the joint's coordinate list.
    coordinate: Option<usize>,
    func: Function,
    weights: Option<Vector3<f64>>,
    /// Position in OpenSim's own axis order (`rotation1` … `translation3` for a `CustomJoint`),
    /// which decides a coordinate's motion type.
    order: usize,
}

impl<'c, 'a> Builder<'c, 'a> {
    fn new(ctx: &'c mut Ctx<'a>, m: Node<'a, 'a>) -> Result<Builder<'c, 'a>, OsimError> {
        let mut names = Vec::new();
        for b in set_objects(m, "BodySet") {
            let Some(name) = b.attribute("name") else {
                return Err(ctx.err(b, "body without a name"));
            };
            if name == "ground" || names.contains(&name) {
                return Err(ctx.err(b, format!("duplicate body name '{name}'")));
            }
            names.push(name);
        }
        let placed = vec![None; names.len()];
        let (bodies, motions, coordinates, markers, couplings) = Default::default();
        Ok(Builder { ctx, names, placed, bodies, motions, coordinates, markers, couplings })
    }

    fn body_by_name(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| *n == name)
    }

    /// Resolves a socket path against the joint's own offset frames, then bodies and ground.
    fn resolve(&mut self, joint: Node<'a, 'a>, path: &str, depth: usize) -> Result<Frame, OsimError> {
        let name = last_segment(path);
        let frames = child(joint, "frames").into_iter().flat_map(elements);
        if let Some(f) = frames.filter(|f| f.attribute("name") == Some(name)).last() {
            if depth > 8 {
                return Err(self.ctx.err(f, "offset frames nested too deeply (or cyclic)"));
            }
            let Some((_, parent)) = self.ctx.text(f, "socket_parent") else {
                return Err(self.ctx.err(f, "offset frame without <socket_parent>"));
            };
            let base = self.resolve(joint, parent, depth + 1)?;
            let t = self.ctx.vec3(f, "translation")?.unwrap_or_default();
            let o = self.ctx.vec3(f, "orientation")?.unwrap_or_default();
            if last_segment(parent) != "ground" && self.body_by_name(last_segment(parent)).is_none() {
                self.ctx.warn(f, "offset frame on an offset frame: its scaling is approximated");
            }
            let offset = Isometry3::from_parts(Translation3::from(t), body_fixed_xyz(o));
            return Ok(Frame { body: base.body, pose: base.pose * offset });
        }
        if name == "ground" {
            return Ok(Frame { body: None, pose: Isometry3::identity() });
        }
        match self.body_by_name(name) {
            Some(b) => Ok(Frame { body: Some(b), pose: Isometry3::identity() }),
            None => {
                let msg = format!(
                    "unknown frame '{path}': expected one of this joint's offset frames, ground, or a body ({})",
                    self.names.join(", ")
                );
                Err(self.ctx.err(joint, msg))
            }
        }
    }

    fn joints(&mut self, m: Node<'a, 'a>) -> Result<(), OsimError> {
        let mut specs: Vec<JointSpec> = Vec::new();
        let mut child_joint: Vec<Option<usize>> = vec![None; self.names.len()];
        for j in set_objects(m, "JointSet") {
            let kind = j.tag_name().name();
            if !SUPPORTED_JOINTS.contains(&kind) {
                let msg = format!("unsupported joint type '{kind}': expected one of {}", SUPPORTED_JOINTS.join(", "));
                return Err(self.ctx.err(j, msg));
            }
            if self.ctx.boolean(j, "reverse")? == Some(true) {
                return Err(self.ctx.err(j, "reversed joints are not supported"));
            }
            let socket = |tag: &str| self.ctx.text(j, tag).map(|(_, t)| t);
            let (Some(p), Some(c)) = (socket("socket_parent_frame"), socket("socket_child_frame")) else {
                return Err(self.ctx.err(j, "joint needs <socket_parent_frame> and <socket_child_frame>"));
            };
            let parent = self.resolve(j, p, 0)?;
            let child = self.resolve(j, c, 0)?;
            let Some(cb) = child.body else {
                return Err(self.ctx.err(j, "the child frame of a joint cannot be ground"));
            };
            if parent.body == Some(cb) {
                return Err(self.ctx.err(j, "a joint cannot connect a body to itself"));
            }
            if child_joint[cb].is_some() {
                let msg =
                    format!("body '{}' is the child of two joints (closed loops are not supported)", self.names[cb]);
                return Err(self.ctx.err(j, msg));
            }
            child_joint[cb] = Some(specs.len());
            specs.push(JointSpec { node: j, parent, child });
        }
        // Attach in topological order: sweep the bodies in file order until none can be added.
        loop {
            let mut progress = false;
            for b in 0..self.names.len() {
                let Some(k) = child_joint[b] else { continue };
                let spec = &specs[k];
                let parent = match spec.parent.body {
                    None => None,
                    Some(p) => match self.placed[p] {
                        Some(i) => Some(i),
                        None => continue,
                    },
                };
                if self.placed[b].is_some() {
                    continue;
                }
                let (node, po, co) = (spec.node, spec.parent.pose, spec.child.pose);
                self.emit(node, b, parent, po, co)?;
                progress = true;
            }
            if !progress {
                break;
            }
        }
        if let Some(b) = (0..self.names.len()).find(|&b| self.placed[b].is_none()) {
            let body = set_objects(m, "BodySet").into_iter().find(|n| n.attribute("name") == Some(self.names[b]));
            let msg = format!("body '{}' is not connected to ground by joints", self.names[b]);
            return Err(self.ctx.err(body.unwrap_or(m), msg));
        }
        Ok(())
    }

    fn markers(&mut self, m: Node<'a, 'a>) -> Result<(), OsimError> {
        for mk in set_objects(m, "MarkerSet").into_iter().filter(|n| n.has_tag_name("Marker")) {
            let (name, body, offset, fixed) = markers::marker_fields(self.ctx, mk)?;
            if body == "ground" {
                self.ctx.warn(mk, &format!("marker '{name}' on ground skipped"));
                continue;
            }
            let Some(b) = self.body_by_name(body).and_then(|b| self.placed[b]) else {
                let msg =
                    format!("marker '{name}' is on unknown body '{body}' (valid bodies: {})", self.names.join(", "));
                return Err(self.ctx.err(mk, msg));
            };
            if self.markers.iter().any(|x| x.name == name) {
                return Err(self.ctx.err(mk, format!("duplicate marker name '{name}'")));
            }
            self.markers.push(Marker {
                name: name.to_string(),
                body: b,
                offset,
                weight: 1.0,
                fixed: fixed.unwrap_or(false),
                class: markers::class_of(fixed),
            });
        }
        Ok(())
    }

    fn coordinate_index(&self, node: Node<'a, 'a>, name: &str) -> Result<usize, OsimError> {
        self.coordinates.iter().position(|c| c.name == name).ok_or_else(|| {
            let valid: Vec<&str> = self.coordinates.iter().map(|c| c.name.as_str()).collect();
            self.ctx.err(node, format!("unknown coordinate '{name}' (valid: {})", valid.join(", ")))
        })
    }

    fn constraints(&mut self, m: Node<'a, 'a>) -> Result<(), OsimError> {
        for c in set_objects(m, "ConstraintSet").into_iter().filter(|n| n.has_tag_name("CoordinateCouplerConstraint")) {
            let enforced = match self.ctx.boolean(c, "isEnforced")? {
                Some(e) => e,
                None => !self.ctx.boolean(c, "isDisabled")?.unwrap_or(false),
            };
            if !enforced {
                self.ctx.warn(c, "CoordinateCouplerConstraint not enforced: ignored");
                continue;
            }
            let indep: Vec<&str> = self
                .ctx
                .text(c, "independent_coordinate_names")
                .map_or(vec![], |(_, t)| t.split_whitespace().collect());
            let [indep] = indep.as_slice() else {
                return Err(self.ctx.err(c, "exactly one independent coordinate is supported"));
            };
            let Some((_, dep)) = self.ctx.text(c, "dependent_coordinate_name") else {
                return Err(self.ctx.err(c, "missing <dependent_coordinate_name>"));
            };
            let (independent, dependent) = (self.coordinate_index(c, indep)?, self.coordinate_index(c, dep)?);
            if independent == dependent || self.couplings.iter().any(|k| k.dependent == dependent) {
                return Err(self.ctx.err(c, format!("coordinate '{dep}' is coupled twice or to itself")));
            }
            let wrapper = child(c, "coupled_coordinates_function");
            let Some(func) = wrapper.map(|w| func::child_function(self.ctx, w, &[])).transpose()?.flatten() else {
                return Err(self.ctx.err(c, "missing <coupled_coordinates_function>"));
            };
            let scale = self.ctx.scalar(c, "scale_factor")?.unwrap_or(1.0);
            let func = if scale == 1.0 { func } else { Function::Multiplier { scale, inner: Box::new(func) } };
            self.coordinates[dependent].default = func.eval(self.coordinates[independent].default).0;
            self.couplings.push(CoordinateCoupling { dependent, independent, func });
        }
        Ok(())
    }

    /// One warning per ignored component type, in order of first appearance.
    fn ignored(&mut self, m: Node<'a, 'a>) {
        const SETS: [&str; 6] =
            ["ForceSet", "ContactGeometrySet", "ControllerSet", "ProbeSet", "ComponentSet", "ConstraintSet"];
        let mut counts: Vec<(&str, usize)> = Vec::new();
        for set in SETS {
            for n in set_objects(m, set) {
                let kind = n.tag_name().name();
                if kind == "CoordinateCouplerConstraint" {
                    continue;
                }
                match counts.iter_mut().find(|(k, _)| *k == kind) {
                    Some((_, c)) => *c += 1,
                    None => counts.push((kind, 1)),
                }
            }
        }
        for (kind, n) in counts {
            self.ctx.warnings.push(format!("{}: ignored {n} {kind}", self.ctx.file));
        }
    }
}

/// `parent_scale_weights` for a scaled translation axis: `|axis| / Σ|axisᵢ|` (see module docs).
fn scale_weights(axis: Vector3<f64>) -> Vector3<f64> {
    let a = axis.abs();
    a / a.sum().max(1e-300)
}

/// Rotation from body-fixed X-Y-Z Euler angles (Simbody `setRotationToBodyFixedXYZ`).
fn body_fixed_xyz(o: Vector3<f64>) -> UnitQuaternion<f64> {
    use crate::model::math::quaternion;
    quaternion(&Vector3::x_axis(), o.x) * quaternion(&Vector3::y_axis(), o.y) * quaternion(&Vector3::z_axis(), o.z)
}
