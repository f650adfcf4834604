//! MuJoCo MJCF (XML) import into a [`Model`].
//!
//! Supported subset and how it maps (SI units: metres, radians):
//! - `<compiler angle="degree|radian" eulerseq="xyz" autolimits="true|false"/>`, MuJoCo defaults
//!   (degree, `xyz`, true). `angle` converts `euler`, `axisangle`, hinge `range`/`ref` and ball `range`.
//!   Euler letters: lowercase = rotating (intrinsic) axes, uppercase = fixed (extrinsic) axes.
//! - `worldbody/body` (any depth, several `worldbody` sections allowed) → bodies in document
//!   order; a body directly under `worldbody` hangs from ground. Body frame in its parent's frame:
//!   `pos` plus at most one of `quat` (w x y z, normalised), `euler`, `axisangle`, `xyaxes`,
//!   `zaxis`. Unnamed bodies are called `body<i>` (`i` = MuJoCo body id, world = 0).
//! - Joints of a body, in order, become the elementary motions of its [`Joint`] (named after the
//!   first MJCF joint, or after the body when welded): `hinge` → a rotation about `axis`
//!   (default z, body frame), `slide` → a translation, `ball` → rotations about x, y, z
//!   (coordinates `<name>_x/_y/_z`), `free` (or `<freejoint>`) → translations x, y, z then
//!   rotations z, y, x (coordinates `<name>_tx/_ty/_tz/_rz/_ry/_rx`). Unnamed joints are called
//!   `<body>_joint<i>` (`i` counts from 0 within the body).
//! - Hinge/slide coordinates: default = `ref`; motion `q − ref` (`Linear{1, −ref}`), as MuJoCo's
//!   `qpos − qpos0`. `range` gives the bounds, `clamped` when limited (`limited="true"`, or
//!   `limited="auto"` (default) with `autolimits` and a non-zero range; a range with neither is
//!   an error, as in MuJoCo). Unlimited → (−∞, ∞).
//! - Ball: `ref` and `axis` ignored (as MuJoCo); a limited `range="0 a"` bounds each of the three
//!   angles to [−a, a] (a box approximation of MuJoCo's cone).
//! - Free: the joint frame is the parent frame itself (`parent_offset` identity) and the
//!   coordinates are the body pose in it (the world for a top-level body, like MuJoCo's free-joint
//!   `qpos`): defaults = body `pos` and the z-y-x (intrinsic) angles of its orientation; `ref`,
//!   `axis`, `pos` and `range` are ignored. A free joint must be the only joint of its body.
//! - Joint `pos` (body frame): hinge and ball joints of a body must share one anchor `p`
//!   (else an error). With `p ≠ 0`: `parent_offset = (body orientation, pos + R·p)` and
//!   `child_offset = p`, so the motions turn about the anchor. Slide and free anchors do not
//!   change the kinematics and are ignored.
//! - `site` in a body → [`Marker`] (name, body, `pos` or `fromto` midpoint, weight 1). Unnamed
//!   sites and sites on `worldbody` are skipped (the latter with a warning).
//! - `<default>` classes (nested classes inherit) for `joint` and `site`: an element uses its
//!   `class`, else the nearest enclosing body `childclass`, else `main`; explicit attributes win.
//! - `<equality><joint joint1="a" joint2="b" polycoef="c0 … c4"/>` → [`CoordinateCoupling`]
//!   `a = a_ref + Σ cₖ (b − b_ref)ᵏ`, expanded into a polynomial in `b`; the dependent default is
//!   set to match. Without `joint2`, `a` is locked at `a_ref + c0`. Fewer than five coefficients
//!   keep the MuJoCo defaults (`0 1 0 0 0`) for the rest. Other equality kinds and inactive ones
//!   are ignored with a warning.
//! - `geom`: not part of the [`Model`]; [`parse_mjcf_document`] collects the colliding spheres and
//!   capsules (`geoms.rs`) and the `<contact><exclude>` pairs, for robots.
//! - Ignored silently: `inertial`, `camera`, `light`, `plugin`, and all top-level sections
//!   other than `compiler`, `default`, `worldbody`, `equality`. Unknown elements inside bodies are
//!   ignored with a warning. Kinematics-changing elements we do not support (`include`, `frame`,
//!   `composite`, `flexcomp`, `replicate`, `attach`) are errors.
//! - Model name: `<mujoco model>`, else the file stem.
//!
//! Warnings are plain strings `file:line: <element>: message`.

mod attrs;
mod geoms;

pub use geoms::{Geom, GeomShape};

use crate::model::{
    Body, Coordinate, CoordinateCoupling, CoordinateKind, Function, Joint, Marker, Model, ModelError, Motion,
    MotionKind,
};
use attrs::{Attrs, Ctx};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use roxmltree::{Document, Node, NodeId};
use std::collections::{HashMap, HashSet};
use std::path::Path;

/// Errors from reading an MJCF file. Lines and columns are 1-based.
#[derive(Debug, thiserror::Error)]
pub enum MjcfError {
    #[error("{file}: cannot read: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}:{line}:{column}: malformed XML: {message}")]
    Xml { file: String, line: u32, column: u32, message: String },
    #[error("{file}:{line}:{column}: <{element}>: {message}")]
    Element { file: String, line: u32, column: u32, element: String, message: String },
    #[error("{file}: invalid model: {source}")]
    Model { file: String, source: ModelError },
}

impl MjcfError {
    /// Line of the offending text, when known.
    pub fn line(&self) -> Option<u32> {
        match self {
            MjcfError::Xml { line, .. } | MjcfError::Element { line, .. } => Some(*line),
            _ => None,
        }
    }
}

/// Reads an MJCF file; returns the model and the warnings about ignored content.
pub fn read_mjcf(path: &Path) -> Result<(Model, Vec<String>), MjcfError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| MjcfError::Io { file: file.clone(), source })?;
    parse_mjcf_with_warnings(&text, &file)
}

/// Parses MJCF text; `file_name` is used in messages and for the default model name.
pub fn parse_mjcf(text: &str, file_name: &str) -> Result<Model, MjcfError> {
    parse_mjcf_with_warnings(text, file_name).map(|(model, _)| model)
}

/// Like [`parse_mjcf`], also returning the warnings about ignored content.
pub fn parse_mjcf_with_warnings(text: &str, file_name: &str) -> Result<(Model, Vec<String>), MjcfError> {
    parse_mjcf_document(text, file_name).map(|d| (d.model, d.warnings))
}

/// What an MJCF file says beyond the kinematic [`Model`]: its colliding geoms and the body
/// pairs its `<contact><exclude>` elements take out of collision.
#[derive(Clone, Debug)]
pub struct MjcfDocument {
    pub model: Model,
    /// Colliding geoms (`contype` or `conaffinity` non-zero), in document order.
    pub geoms: Vec<Geom>,
    /// `<contact><exclude body1 body2>` pairs, by body name.
    pub excludes: Vec<(String, String)>,
    pub warnings: Vec<String>,
}

/// Reads an MJCF file into an [`MjcfDocument`].
pub fn read_mjcf_document(path: &Path) -> Result<MjcfDocument, MjcfError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| MjcfError::Io { file: file.clone(), source })?;
    parse_mjcf_document(&text, &file)
}

/// Parses MJCF text into the model, its colliding geoms and contact exclusions.
pub fn parse_mjcf_document(text: &str, file_name: &str) -> Result<MjcfDocument, MjcfError> {
    let doc = Document::parse(text).map_err(|e| {
        let p = e.pos();
        MjcfError::Xml { file: file_name.to_string(), line: p.row, column: p.col, message: e.to_string() }
    })?;
    let mut ctx = Ctx::new(&doc, file_name);
    let root = doc.root_element();
    if root.tag_name().name() != "mujoco" {
        return Err(ctx.err(root, "expected the root element <mujoco>"));
    }
    const UNSUPPORTED: [&str; 6] = ["include", "frame", "composite", "flexcomp", "replicate", "attach"];
    if let Some(n) = root.descendants().find(|n| UNSUPPORTED.contains(&n.tag_name().name()) && n.is_element()) {
        return Err(ctx.err(n, "element not supported by this importer (it changes the kinematics)"));
    }
    for c in root.children().filter(|n| n.has_tag_name("compiler")) {
        ctx.read_compiler(c)?;
    }
    ctx.read_defaults(root)?;
    let mut b = Builder::new(ctx);
    for wb in root.children().filter(|n| n.has_tag_name("worldbody")) {
        b.walk(wb)?;
    }
    for eq in root.children().filter(|n| n.has_tag_name("equality")) {
        for c in eq.children().filter(Node::is_element) {
            b.equality(c)?;
        }
    }
    let stem = Path::new(file_name).file_stem().and_then(|s| s.to_str()).unwrap_or("mujoco");
    let name = root.attribute("model").unwrap_or(stem);
    let file = b.ctx.file.to_string();
    let warnings = std::mem::take(&mut b.ctx.warnings);
    let excludes = root
        .children()
        .filter(|n| n.has_tag_name("contact"))
        .flat_map(|c| c.children().filter(|n| n.has_tag_name("exclude")))
        .filter_map(|e| Some((e.attribute("body1")?.to_string(), e.attribute("body2")?.to_string())))
        .collect();
    let geoms = std::mem::take(&mut b.geoms);
    let model = Model::new(name, b.bodies, b.motions, b.coordinates, b.markers, b.couplings)
        .map_err(|source| MjcfError::Model { file, source })?;
    Ok(MjcfDocument { model, geoms, excludes, warnings })
}

/// One MJCF joint, resolved against its defaults.
struct JointSpec {
    name: String,
    kind: JointType,
    axis: Vector3<f64>,
    pos: Vector3<f64>,
    /// Converted range when limited.
    limits: Option<(f64, f64)>,
    reference: f64,
}

#[derive(Clone, Copy, PartialEq)]
enum JointType {
    Hinge,
    Slide,
    Ball,
    Free,
}

/// A named hinge/slide joint, for equality constraints.
struct ScalarJoint {
    coordinate: usize,
    reference: f64,
}

struct Builder<'a> {
    ctx: Ctx<'a>,
    bodies: Vec<Body>,
    motions: Vec<Motion>,
    coordinates: Vec<Coordinate>,
    markers: Vec<Marker>,
    couplings: Vec<CoordinateCoupling>,
    /// Body element → (body index, effective childclass).
    body_nodes: HashMap<NodeId, (usize, &'a str)>,
    /// Named joints: `Some` for hinge/slide, `None` for ball/free.
    joints: HashMap<String, Option<ScalarJoint>>,
    names: HashSet<(&'static str, String)>,
    geoms: Vec<Geom>,
}

impl<'a> Builder<'a> {
    fn new(ctx: Ctx<'a>) -> Builder<'a> {
        let (bodies, motions, coordinates, markers, couplings) = Default::default();
        let (body_nodes, joints, names, geoms) = Default::default();
        Builder { ctx, bodies, motions, coordinates, markers, couplings, body_nodes, joints, names, geoms }
    }

    /// Visits every element under one `worldbody` in document order.
    fn walk(&mut self, wb: Node<'a, 'a>) -> Result<(), MjcfError> {
        for node in wb.descendants().filter(|n| n.is_element() && *n != wb) {
            let tag = node.tag_name().name();
            let parent = node.parent_element().map(|p| p.tag_name().name()).unwrap_or("");
            let in_body = parent == "body" || parent == "worldbody";
            match tag {
                "body" | "joint" | "freejoint" | "site" if !in_body => {
                    return Err(self
                        .ctx
                        .err(node, format!("must be a child of <body> or <worldbody>, not <{parent}>")));
                }
                "body" => self.body(node)?,
                "joint" | "freejoint" if parent == "worldbody" => {
                    return Err(self.ctx.err(node, "joints cannot be attached to <worldbody>"));
                }
                "site" if parent == "worldbody" => {
                    self.ctx.warn(node, "site on <worldbody> skipped (markers must be on a body)");
                }
                "joint" | "freejoint" | "site" | "geom" | "inertial" | "camera" | "light" | "plugin" => {}
                _ if in_body => self.ctx.warn(node, "unknown element ignored"),
                _ => {}
            }
        }
        Ok(())
    }

    fn unique(&mut self, what: &'static str, name: &str, node: Node) -> Result<(), MjcfError> {
        if !self.names.insert((what, name.to_string())) {
            return Err(self.ctx.err(node, format!("duplicate {what} name '{name}'")));
        }
        Ok(())
    }

    fn body(&mut self, node: Node<'a, 'a>) -> Result<(), MjcfError> {
        let index = self.bodies.len();
        let (parent, inherited) = match node.parent_element().and_then(|p| self.body_nodes.get(&p.id())) {
            Some(&(p, class)) => (Some(p), class),
            None => (None, "main"),
        };
        let name = node.attribute("name").map_or_else(|| format!("body{}", index + 1), str::to_string);
        self.unique("body", &name, node)?;
        let class = match node.attribute("childclass") {
            Some(c) => self.ctx.class_name(node, c)?,
            None => inherited,
        };
        self.body_nodes.insert(node.id(), (index, class));
        let own = Attrs::own(node);
        let pos = self.ctx.vec3(node, &own, "pos")?.unwrap_or_default();
        let rot = self.ctx.orientation(node, &own)?;

        let mut specs = Vec::new();
        for (i, j) in node.children().filter(|n| n.has_tag_name("joint") || n.has_tag_name("freejoint")).enumerate() {
            specs.push((j, self.joint_spec(j, class, &name, i)?));
        }
        if specs.len() > 1 && specs.iter().any(|(_, s)| s.kind == JointType::Free) {
            return Err(self.ctx.err(node, "a free joint must be the only joint of its body"));
        }
        let mut anchor: Option<Vector3<f64>> = None;
        for (j, s) in specs.iter().filter(|(_, s)| matches!(s.kind, JointType::Hinge | JointType::Ball)) {
            match anchor {
                Some(a) if a != s.pos => {
                    return Err(self.ctx.err(*j, "joints of one body with different 'pos' anchors are not supported"));
                }
                _ => anchor = Some(s.pos),
            }
        }
        let anchor = anchor.unwrap_or_default();
        let mut parent_offset = Isometry3::from_parts(Translation3::from(pos + rot * anchor), rot);
        let child_offset = Isometry3::translation(anchor.x, anchor.y, anchor.z);
        let start = self.motions.len();
        for (j, s) in &specs {
            if s.kind == JointType::Free {
                parent_offset = Isometry3::identity();
            }
            self.emit_joint(*j, s, pos, rot)?;
        }
        let joint_name = specs.first().map_or_else(|| name.clone(), |(_, s)| s.name.clone());
        let joint = Joint { name: joint_name, parent_offset, child_offset, motions: start..self.motions.len() };
        self.bodies.push(Body { name, parent, joint });

        for site in node.children().filter(|n| n.has_tag_name("site")) {
            self.site(site, class, index)?;
        }
        for (i, g) in node.children().filter(|n| n.has_tag_name("geom")).enumerate() {
            self.geom(g, class, index, i)?;
        }
        Ok(())
    }

    fn joint_spec(&mut self, j: Node<'a, 'a>, class: &'a str, body: &str, i: usize) -> Result<JointSpec, MjcfError> {
        let name = j.attribute("name").map_or_else(|| format!("{body}_joint{i}"), str::to_string);
        if j.has_tag_name("freejoint") {
            let (axis, pos) = (Vector3::z(), Vector3::zeros());
            return Ok(JointSpec { name, kind: JointType::Free, axis, pos, limits: None, reference: 0.0 });
        }
        let a = self.ctx.resolve(j, class, |c| &c.joint)?;
        let kind = match a.get("type").map_or("hinge", |v| v.1) {
            "hinge" => JointType::Hinge,
            "slide" => JointType::Slide,
            "ball" => JointType::Ball,
            "free" => JointType::Free,
            other => {
                return Err(self.ctx.err_at(
                    a.pos("type", j),
                    "joint",
                    format!("unknown joint type '{other}': expected one of hinge, slide, ball, free"),
                ))
            }
        };
        let angular = matches!(kind, JointType::Hinge | JointType::Ball);
        let unit = if angular { self.ctx.angle } else { 1.0 };
        let axis = self.ctx.vec3(j, &a, "axis")?.unwrap_or_else(Vector3::z);
        if kind != JointType::Ball && kind != JointType::Free && !(axis.norm() > 1e-12 && axis.norm().is_finite()) {
            return Err(self.ctx.err_at(a.pos("axis", j), "joint", "axis must be a non-zero finite vector"));
        }
        let pos = self.ctx.vec3(j, &a, "pos")?.unwrap_or_default();
        let reference = self.ctx.nums::<1>(j, &a, "ref")?.map_or(0.0, |[r]| r * unit);
        let range = self.ctx.nums::<2>(j, &a, "range")?;
        let has_range = range.is_some_and(|r| r != [0.0, 0.0]);
        let limited = match a.get("limited").map_or("auto", |v| v.1) {
            "true" => true,
            "false" => false,
            "auto" if has_range && !self.ctx.autolimits => {
                return Err(self.ctx.err_at(
                    a.pos("range", j),
                    "joint",
                    "joint has 'range' but not 'limited': \
                    set compiler autolimits=\"true\", give limited=\"true\" or \"false\", or remove the range",
                ));
            }
            "auto" => has_range,
            other => {
                return Err(self.ctx.err_at(
                    a.pos("limited", j),
                    "joint",
                    format!("invalid limited '{other}': expected one of true, false, auto"),
                ))
            }
        };
        let limits = match (limited && kind != JointType::Free, range) {
            (false, _) => None,
            (true, Some([_, hi])) if kind == JointType::Ball && hi > 0.0 => Some((-hi * unit, hi * unit)),
            (true, Some([lo, hi])) if kind != JointType::Ball && lo < hi => Some((lo * unit, hi * unit)),
            _ => {
                let need = if kind == JointType::Ball { "'0 max' with max > 0" } else { "lo < hi" };
                return Err(self.ctx.err_at(a.pos("range", j), "joint", format!("limited joint needs a range {need}")));
            }
        };
        Ok(JointSpec { name, kind, axis, pos, limits, reference })
    }

    /// Appends the motions and coordinates of one MJCF joint; `pos`/`rot` is the body frame.
    fn emit_joint(
        &mut self,
        j: Node,
        s: &JointSpec,
        pos: Vector3<f64>,
        rot: UnitQuaternion<f64>,
    ) -> Result<(), MjcfError> {
        use {CoordinateKind::*, MotionKind::*};
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        let parts: Vec<(String, MotionKind, Vector3<f64>, f64)> = match s.kind {
            JointType::Hinge => vec![(s.name.clone(), Rotation, s.axis, s.reference)],
            JointType::Slide => vec![(s.name.clone(), Translation, s.axis, s.reference)],
            JointType::Ball => [("x", x), ("y", y), ("z", z)]
                .iter()
                .map(|&(n, a)| (format!("{}_{n}", s.name), Rotation, a, 0.0))
                .collect(),
            JointType::Free => {
                let (roll, pitch, yaw) = crate::model::math::euler_angles(rot.to_rotation_matrix().matrix());
                let t = [("tx", x, pos.x), ("ty", y, pos.y), ("tz", z, pos.z)].map(|(n, a, v)| (n, Translation, a, v));
                let r = [("rz", z, yaw), ("ry", y, pitch), ("rx", x, roll)].map(|(n, a, v)| (n, Rotation, a, v));
                t.into_iter().chain(r).map(|(n, k, a, v)| (format!("{}_{n}", s.name), k, a, v)).collect()
            }
        };
        let free = s.kind == JointType::Free;
        for (name, kind, axis, default) in parts {
            self.unique("coordinate", &name, j)?;
            let coordinate = self.coordinates.len();
            let func = if free { Function::IDENTITY } else { Function::Linear { slope: 1.0, intercept: -default } };
            self.motions.push(Motion { kind, axis, coordinate: Some(coordinate), func, parent_scale_weights: None });
            let kind = if kind == Rotation { Rotational } else { Translational };
            let range = s.limits.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
            let clamped = s.limits.is_some();
            self.coordinates.push(Coordinate { name, kind, default, range, locked: false, clamped });
        }
        if let Some(explicit) = j.attribute("name") {
            self.unique("joint", explicit, j)?;
            let scalar = matches!(s.kind, JointType::Hinge | JointType::Slide);
            let entry = scalar.then(|| ScalarJoint { coordinate: self.coordinates.len() - 1, reference: s.reference });
            self.joints.insert(explicit.to_string(), entry);
        }
        Ok(())
    }

    fn site(&mut self, site: Node<'a, 'a>, class: &'a str, body: usize) -> Result<(), MjcfError> {
        let a = self.ctx.resolve(site, class, |c| &c.site)?;
        let Some(name) = site.attribute("name") else {
            return Ok(());
        };
        self.unique("marker", name, site)?;
        let offset = match self.ctx.nums::<6>(site, &a, "fromto")? {
            Some(f) => (Vector3::new(f[0], f[1], f[2]) + Vector3::new(f[3], f[4], f[5])) / 2.0,
            None => self.ctx.vec3(site, &a, "pos")?.unwrap_or_default(),
        };
        self.markers.push(Marker { name: name.to_string(), body, offset, weight: 1.0, fixed: false, class: None });
        Ok(())
    }

    fn equality(&mut self, e: Node<'a, 'a>) -> Result<(), MjcfError> {
        if !e.has_tag_name("joint") {
            self.ctx.warn(e, "equality constraint ignored (only <joint> equalities are imported)");
            return Ok(());
        }
        let own = Attrs::own(e);
        match e.attribute("active").unwrap_or("true") {
            "true" => {}
            "false" => {
                self.ctx.warn(e, "inactive joint equality ignored");
                return Ok(());
            }
            other => {
                let msg = format!("invalid active '{other}': expected one of true, false");
                return Err(self.ctx.err_at(own.pos("active", e), "joint", msg));
            }
        }
        let mut c = [0.0, 1.0, 0.0, 0.0, 0.0];
        if let Some((p, text)) = own.get("polycoef") {
            match attrs::parse_numbers(text) {
                Some(v) if (1..=5).contains(&v.len()) => c[..v.len()].copy_from_slice(&v),
                _ => {
                    return Err(self.ctx.err_at(
                        p,
                        "joint",
                        format!("polycoef '{text}': expected 1 to 5 finite numbers"),
                    ))
                }
            }
        }
        let (a, a_ref) = self.scalar_joint(e, &own, "joint1")?;
        if e.attribute("joint2").is_none() {
            let coord = &mut self.coordinates[a];
            coord.locked = true;
            coord.default = a_ref + c[0];
            return Ok(());
        }
        let (b, b_ref) = self.scalar_joint(e, &own, "joint2")?;
        // Σ cₖ (x − r)ᵏ = Σⱼ xʲ Σ_{k≥j} cₖ C(k, j) (−r)^(k−j).
        let mut coefficients = vec![0.0; 5];
        for (k, &ck) in c.iter().enumerate() {
            let mut binom = 1.0;
            for (jj, out) in coefficients.iter_mut().enumerate().take(k + 1) {
                *out += ck * binom * (-b_ref).powi((k - jj) as i32);
                binom = binom * (k - jj) as f64 / (jj + 1) as f64;
            }
        }
        coefficients[0] += a_ref;
        while coefficients.len() > 1 && coefficients.last() == Some(&0.0) {
            coefficients.pop();
        }
        let func = Function::Polynomial { coefficients };
        self.coordinates[a].default = func.eval(self.coordinates[b].default).0;
        self.couplings.push(CoordinateCoupling { dependent: a, independent: b, func });
        Ok(())
    }

    /// Coordinate index and reference of the hinge/slide joint named by attribute `key`.
    fn scalar_joint(&self, e: Node, own: &Attrs, key: &str) -> Result<(usize, f64), MjcfError> {
        let Some(name) = e.attribute(key) else {
            return Err(self.ctx.err(e, format!("missing attribute '{key}'")));
        };
        match self.joints.get(name) {
            Some(Some(j)) => Ok((j.coordinate, j.reference)),
            Some(None) => Err(self.ctx.err_at(
                own.pos(key, e),
                "joint",
                format!("joint '{name}' is not a hinge or slide joint; joint equalities need scalar joints"),
            )),
            None => Err(self.ctx.err_at(own.pos(key, e), "joint", format!("unknown joint '{name}'"))),
        }
    }
}
