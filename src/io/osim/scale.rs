//! Rewriting an OpenSim model file with a subject's scale factors, as OpenSim's ScaleTool applies
//! them (`Model::scale`: every component's `extendScale`, then `Body::scaleInertialProperties`,
//! then the subject mass). Everything else in the file (muscles, geometry files, comments) is
//! kept: only the scaled values are spliced into the original text.
//!
//! What is rescaled, with the factors `s` of the frame's base body (OpenSim 4.x sources):
//! - `PhysicalOffsetFrame` `translation` (`OffsetFrame::extendScale`), everywhere in the model;
//! - `Marker` `location` (`Station::extendScale`); the `MarkerSet` is rebuilt from the model's
//!   markers (so markers attached from a separate marker-set file are written), keeping the
//!   file's own element for a marker of the same name on the same body, and markers on ground;
//! - path points: `PathPoint`, `ConditionalPathPoint` and `Station` `location`; the
//!   `x/y/z_location` functions of a `MovingPathPoint` are multiplied by `s_x`, `s_y`, `s_z`;
//! - `CustomJoint` translation functions other than `LinearFunction 1 0`, multiplied by the
//!   parent frame's factors (`SpatialTransform::scale`: wrapped in a `MultiplierFunction`, or its
//!   `scale` multiplied). The factor is `w · s` with `w = axis / (axis · 1)` as the importer's
//!   `parent_scale_weights` (identical to OpenSim's `axis · s` for axes along +x, +y, +z);
//! - `scale_factors` of the `attached_geometry` of bodies and offset frames (`Frame::extendScale`;
//!   not the `FrameGeometry` axes);
//! - wrap objects: `translation`; `WrapCylinder` radius and length, `WrapSphere` radius,
//!   `WrapEllipsoid` dimensions as their `extendScale`; other wrap objects' dimensions are kept
//!   (warning);
//! - bodies: `mass_center`, `inertia` (`Body::scaleInertialProperties`, including its cylinder
//!   approximation for unequal factors) and `mass` as [`MassScaling`] says.
//!
//! Not rescaled (warning): muscle and ligament lengths (`optimal_fiber_length`,
//! `tendon_slack_length`, `resting_length`), which OpenSim rescales by the change of each path's
//! length at the default pose (`postScale`), through its wrapping surfaces.

use super::export::{esc, marker, num, nums, vec3, Writer};
use super::xml::{child, elements, last_segment, set_objects, Ctx};
use super::{body_fixed_xyz, parse_xml, scale_weights, OsimError};
use crate::model::Model;
use nalgebra::{Matrix3, Vector3};
use roxmltree::Node;
use std::collections::HashMap;
use std::ops::Range;

/// How body masses change with scaling (OpenSim ScaleTool `preserve_mass_distribution` and the
/// subject mass). The default keeps every mass.
#[derive(Clone, Copy, Debug, Default)]
pub struct MassScaling {
    /// Multiply each body's mass by the product of its scale factors (OpenSim
    /// `preserve_mass_distribution = false`); `false` keeps the masses.
    pub scale_with_volume: bool,
    /// Then multiply every mass and inertia by one factor so that the model weighs this (kg).
    pub subject_mass: Option<f64>,
}

/// Rewrites `.osim` text (format 4) with body `b` of `model` scaled by `scales[b]` (x, y, z).
/// `model` is the model read from this text (its body names index `scales`), possibly with
/// another marker set attached: its markers make the written `MarkerSet`. Returns the text and
/// warnings about what was left unscaled.
pub fn scale_osim(
    text: &str,
    file_name: &str,
    model: &Model,
    scales: &[Vector3<f64>],
    mass: MassScaling,
) -> Result<(String, Vec<String>), OsimError> {
    let doc = parse_xml(text, file_name)?;
    let ctx = Ctx::new(&doc, file_name);
    let root = doc.root_element();
    let version = root.attribute("Version").and_then(|v| v.trim().parse::<u32>().ok());
    if !root.has_tag_name("OpenSimDocument") || version.is_none_or(|v| v < 40000) {
        return Err(ctx.err(root, "expected <OpenSimDocument Version=\"40000\"> or later"));
    }
    let Some(m) = child(root, "Model") else {
        return Err(ctx.err(root, "missing <Model>"));
    };
    if scales.len() != model.nb() {
        return Err(ctx.err(m, format!("{} scale factor triples for a model of {} bodies", scales.len(), model.nb())));
    }
    let mut s = Scaler {
        text,
        model,
        scales,
        frames: HashMap::new(),
        edits: Vec::new(),
        warnings: Vec::new(),
        bodies: Vec::new(),
    };
    for f in m.descendants().filter(|n| n.has_tag_name("PhysicalOffsetFrame")) {
        if let (Some(name), Some((_, p))) = (f.attribute("name"), ctx.text(f, "socket_parent")) {
            s.frames.entry(name).or_insert(p);
        }
    }
    let mut lengths_kept = 0;
    for n in m.descendants().filter(Node::is_element) {
        let tag = n.tag_name().name();
        match tag {
            "PhysicalOffsetFrame" => {
                let scope = n.parent_element().filter(|p| p.has_tag_name("frames")).and_then(|p| p.parent_element());
                let base = ctx.text(n, "socket_parent").and_then(|(_, p)| s.base(scope, p, 0));
                if let Some(f) = base {
                    match s.joint_location(&ctx, scope, n) {
                        Some(t) => s.vec_set(&ctx, n, "translation", t.component_mul(&f))?,
                        None => s.vec_edit(&ctx, n, "translation", &f, Vector3::zeros())?,
                    }
                    s.geometry(&ctx, n, &f)?;
                    s.wrap_objects(&ctx, n, &f)?;
                }
            }
            "PathPoint" | "ConditionalPathPoint" | "Station" => {
                if let Some(f) = s.parent_frame_scale(&ctx, n) {
                    s.vec_edit(&ctx, n, "location", &f, Vector3::zeros())?;
                }
            }
            "MovingPathPoint" => {
                if let Some(f) = s.parent_frame_scale(&ctx, n) {
                    for (k, t) in ["x_location", "y_location", "z_location"].into_iter().enumerate() {
                        if let Some(func) = child(n, t).and_then(|c| elements(c).next()) {
                            s.multiply_function(&ctx, func, f[k])?;
                        }
                    }
                }
            }
            "Body" => s.body(&ctx, n)?,
            "CustomJoint" => s.custom_joint(&ctx, n)?,
            _ if ["optimal_fiber_length", "tendon_slack_length", "resting_length"]
                .iter()
                .any(|t| child(n, t).is_some()) =>
            {
                lengths_kept += 1
            }
            _ => {}
        }
    }
    s.masses(&ctx, m, mass)?;
    s.marker_set(&ctx, m)?;
    if lengths_kept > 0 {
        s.warnings.push(format!(
            "{file_name}: {lengths_kept} muscles/ligaments keep their optimal_fiber_length, tendon_slack_length or \
             resting_length (OpenSim's ScaleTool rescales them by the change of path length at the default pose)"
        ));
    }
    let out = apply(text, s.edits).map_err(|at| {
        let node = doc.descendants().find(|n| n.range().start == at).unwrap_or(m);
        ctx.err(node, "overlapping rewrites (unexpected nesting of scaled elements)")
    })?;
    Ok((out, s.warnings))
}

/// Inertial properties of one body, before the mass pass.
struct BodyMass<'a> {
    node: Node<'a, 'a>,
    mass: f64,
    inertia: [f64; 6],
}

struct Scaler<'a, 'm> {
    text: &'a str,
    model: &'m Model,
    scales: &'m [Vector3<f64>],
    /// Offset frames by name → their `socket_parent` path (first of each name).
    frames: HashMap<&'a str, &'a str>,
    edits: Vec<(Range<usize>, String)>,
    warnings: Vec<String>,
    bodies: Vec<BodyMass<'a>>,
}

impl<'a> Scaler<'a, '_> {
    fn body_scale(&self, name: &str) -> Option<Vector3<f64>> {
        self.model.body_index(name).map(|b| self.scales[b])
    }

    /// Scale factors of the base body of the frame at `path` (`None`: ground or unknown). Offset
    /// frames are looked up in `scope`'s `<frames>` first, then anywhere in the model.
    fn base(&self, scope: Option<Node<'a, 'a>>, path: &str, depth: usize) -> Option<Vector3<f64>> {
        let name = last_segment(path);
        if depth > 8 || name == "ground" {
            return None;
        }
        let local = scope
            .and_then(|j| child(j, "frames"))
            .into_iter()
            .flat_map(elements)
            .find(|f| f.has_tag_name("PhysicalOffsetFrame") && f.attribute("name") == Some(name));
        if let Some(p) = local.and_then(|f| child(f, "socket_parent")).and_then(|p| p.text()) {
            return self.base(scope, p, depth + 1);
        }
        if let Some(s) = self.body_scale(name) {
            return Some(s);
        }
        self.frames.get(name).and_then(|p| self.base(None, p, depth + 1))
    }

    fn parent_frame_scale(&self, ctx: &Ctx<'a>, n: Node<'a, 'a>) -> Option<Vector3<f64>> {
        let (_, p) = ctx.text(n, "socket_parent_frame").or_else(|| ctx.text(n, "body"))?;
        self.base(None, p, 0)
    }

    fn replace(&mut self, n: Node, text: String) {
        self.edits.push((n.range(), text));
    }

    /// `<tag>` of `n` (absent: `default`) multiplied component-wise by `f`.
    fn vec_edit(
        &mut self,
        ctx: &Ctx<'a>,
        n: Node<'a, 'a>,
        tag: &str,
        f: &Vector3<f64>,
        default: Vector3<f64>,
    ) -> Result<(), OsimError> {
        let v = ctx.vec3(n, tag)?;
        if let Some(c) = child(n, tag) {
            self.replace(c, format!("<{tag}>{}</{tag}>", vec3(&v.unwrap_or(default).component_mul(f))));
        } else if default != Vector3::zeros() {
            self.insert_before_end(ctx, n, format!("<{tag}>{}</{tag}>", vec3(&default.component_mul(f))))?;
        }
        Ok(())
    }

    /// `<tag>` of `n` set to `v` (added when absent and `v` is not zero).
    fn vec_set(&mut self, ctx: &Ctx<'a>, n: Node<'a, 'a>, tag: &str, v: Vector3<f64>) -> Result<(), OsimError> {
        if let Some(c) = child(n, tag) {
            self.replace(c, format!("<{tag}>{}</{tag}>", vec3(&v)));
        } else if v != Vector3::zeros() {
            self.insert_before_end(ctx, n, format!("<{tag}>{}</{tag}>", vec3(&v)))?;
        }
        Ok(())
    }

    /// Where the model puts the joint whose parent frame `frame` is (unit scale, in the parent
    /// body's frame), when `frame` is that joint's `socket_parent_frame` and hangs directly on a
    /// body: the model's location is written rather than the file's, so that a joint calibration
    /// moved (the functional hips) is where the subject's model has it. For every other joint
    /// the two are the same value.
    fn joint_location(&self, ctx: &Ctx<'a>, scope: Option<Node<'a, 'a>>, frame: Node<'a, 'a>) -> Option<Vector3<f64>> {
        let j = scope?;
        let name = frame.attribute("name")?;
        if last_segment(ctx.text(j, "socket_parent_frame")?.1) != name {
            return None;
        }
        self.body_scale(last_segment(ctx.text(frame, "socket_parent")?.1))?;
        let jname = j.attribute("name")?;
        self.model.bodies.iter().find(|b| b.joint.name == jname).map(|b| b.joint.parent_offset.translation.vector)
    }

    fn insert_before_end(&mut self, ctx: &Ctx<'a>, n: Node<'a, 'a>, text: String) -> Result<(), OsimError> {
        let r = n.range();
        match self.text[r.clone()].rfind("</") {
            Some(i) if !self.text[r.clone()].ends_with("/>") => {
                self.edits.push((r.start + i..r.start + i, text));
                Ok(())
            }
            _ => Err(ctx.err(n, "cannot add a scaled value to an empty element")),
        }
    }

    /// Scales a function element by `factor` (OpenSim: wrap in a `MultiplierFunction`).
    fn multiply_function(&mut self, ctx: &Ctx<'a>, f: Node<'a, 'a>, factor: f64) -> Result<(), OsimError> {
        if factor == 1.0 {
            return Ok(());
        }
        if f.has_tag_name("MultiplierFunction") {
            let old = ctx.scalar(f, "scale")?;
            return match child(f, "scale") {
                Some(c) => {
                    self.replace(c, format!("<scale>{}</scale>", num(old.unwrap_or(1.0) * factor)));
                    Ok(())
                }
                None => self.insert_before_end(ctx, f, format!("<scale>{}</scale>", num(factor))),
            };
        }
        let name = f.attribute("name").map_or(String::new(), |n| format!(r#" name="{}""#, esc(n)));
        let orig = &self.text[f.range()];
        self.replace(
            f,
            format!(
                "<MultiplierFunction{name}><function>{orig}</function><scale>{}</scale></MultiplierFunction>",
                num(factor)
            ),
        );
        Ok(())
    }

    /// `scale_factors` of the geometry attached to frame `n`.
    fn geometry(&mut self, ctx: &Ctx<'a>, n: Node<'a, 'a>, f: &Vector3<f64>) -> Result<(), OsimError> {
        for g in child(n, "attached_geometry").into_iter().flat_map(elements) {
            self.vec_edit(ctx, g, "scale_factors", f, Vector3::new(1.0, 1.0, 1.0))?;
        }
        Ok(())
    }

    fn body(&mut self, ctx: &Ctx<'a>, n: Node<'a, 'a>) -> Result<(), OsimError> {
        let name = n.attribute("name").unwrap_or("");
        let Some(f) = self.body_scale(name) else {
            self.warnings.push(format!("{}: body '{name}' is not in the model: not scaled", ctx.file));
            return Ok(());
        };
        self.vec_edit(ctx, n, "mass_center", &f, Vector3::zeros())?;
        self.geometry(ctx, n, &f)?;
        self.wrap_objects(ctx, n, &f)?;
        let m = ctx.scalar(n, "mass")?.unwrap_or(0.0);
        let i = ctx.fixed(n, "inertia", 6, false)?.unwrap_or_else(|| vec![0.0; 6]);
        self.bodies.push(BodyMass { node: n, mass: m, inertia: [i[0], i[1], i[2], i[3], i[4], i[5]] });
        Ok(())
    }

    /// The wrap objects of frame `n` (a body or an offset frame) on a body scaled by `f`.
    fn wrap_objects(&mut self, ctx: &Ctx<'a>, n: Node<'a, 'a>, f: &Vector3<f64>) -> Result<(), OsimError> {
        let f = *f;
        for w in set_objects(n, "WrapObjectSet") {
            self.vec_edit(ctx, w, "translation", &f, Vector3::zeros())?;
            let r = body_fixed_xyz(ctx.vec3(w, "xyz_body_rotation")?.unwrap_or_default()).to_rotation_matrix();
            let local = |k: usize| r.matrix().column(k).component_mul(&f).norm();
            let scalar = |s: &mut Self, tag: &str, factor: f64| -> Result<(), OsimError> {
                if let (Some(c), Some(v)) = (child(w, tag), ctx.scalar(w, tag)?) {
                    s.replace(c, format!("<{tag}>{}</{tag}>", num(v * factor)));
                }
                Ok(())
            };
            match w.tag_name().name() {
                "WrapCylinder" => {
                    scalar(self, "radius", 0.5 * (local(0) + local(1)))?;
                    scalar(self, "length", local(2))?;
                }
                "WrapSphere" => scalar(self, "radius", f.sum() / 3.0)?,
                "WrapEllipsoid" => {
                    let d = Vector3::new(local(0), local(1), local(2));
                    self.vec_edit(ctx, w, "dimensions", &d, Vector3::zeros())?;
                }
                other => self.warnings.push(format!(
                    "{}: {other} '{}' on '{}': dimensions not scaled (position scaled)",
                    ctx.file,
                    w.attribute("name").unwrap_or(""),
                    n.attribute("name").unwrap_or("")
                )),
            }
        }
        Ok(())
    }

    /// Scaled masses and inertias of all bodies, then the subject mass.
    fn masses(&mut self, ctx: &Ctx<'a>, model: Node<'a, 'a>, opt: MassScaling) -> Result<(), OsimError> {
        let mut new: Vec<(f64, [f64; 6])> = Vec::with_capacity(self.bodies.len());
        for b in &self.bodies {
            let f = self.body_scale(b.node.attribute("name").unwrap_or("")).unwrap_or(Vector3::new(1.0, 1.0, 1.0));
            let m = if opt.scale_with_volume { b.mass * (f.x * f.y * f.z).abs() } else { b.mass };
            new.push((m, scale_inertia(&b.inertia, b.mass, m, &f, opt.scale_with_volume)));
        }
        if let Some(target) = opt.subject_mass {
            let total: f64 = new.iter().map(|(m, _)| m).sum();
            if !(target > 0.0 && total > 0.0 && target.is_finite()) {
                let msg = format!("subject mass {target} kg for a model of total mass {total} kg: need both > 0");
                return Err(ctx.err(model, msg));
            }
            for (m, i) in &mut new {
                *m *= target / total;
                i.iter_mut().for_each(|v| *v *= target / total);
            }
        }
        let bodies = std::mem::take(&mut self.bodies);
        for (b, (m, i)) in bodies.iter().zip(new) {
            if let Some(c) = child(b.node, "mass") {
                self.replace(c, format!("<mass>{}</mass>", num(m)));
            }
            match child(b.node, "inertia") {
                Some(c) => self.replace(c, format!("<inertia>{}</inertia>", nums(&i))),
                None if i.iter().any(|v| *v != 0.0) => {
                    self.insert_before_end(ctx, b.node, format!("<inertia>{}</inertia>", nums(&i)))?
                }
                None => {}
            }
        }
        Ok(())
    }

    fn custom_joint(&mut self, ctx: &Ctx<'a>, j: Node<'a, 'a>) -> Result<(), OsimError> {
        let Some(s_p) = ctx.text(j, "socket_parent_frame").and_then(|(_, p)| self.base(Some(j), p, 0)) else {
            return Ok(());
        };
        let axes = child(j, "SpatialTransform").into_iter().flat_map(elements);
        for ax in axes.filter(|a| a.attribute("name").is_some_and(|n| n.starts_with("translation"))) {
            let f = match child(ax, "function") {
                Some(w) => elements(w).next(),
                None => elements(ax).find(|n| !n.has_tag_name("coordinates") && !n.has_tag_name("axis")),
            };
            let Some(f) = f else { continue };
            if f.has_tag_name("LinearFunction") {
                let c = ctx.fixed(f, "coefficients", 2, false)?.unwrap_or_else(|| vec![1.0, 0.0]);
                if c[0] == 1.0 && c[1] == 0.0 {
                    continue;
                }
            }
            let axis = ctx.vec3(ax, "axis")?.unwrap_or(Vector3::x());
            self.multiply_function(ctx, f, scale_weights(axis).dot(&s_p))?;
        }
        Ok(())
    }

    /// Rebuilds the `MarkerSet` objects from the model's markers (see the module docs).
    fn marker_set(&mut self, ctx: &Ctx<'a>, m: Node<'a, 'a>) -> Result<(), OsimError> {
        let file: Vec<Node> = set_objects(m, "MarkerSet").into_iter().filter(|n| n.has_tag_name("Marker")).collect();
        let body_of = |n: Node<'a, 'a>| {
            ctx.text(n, "socket_parent_frame").or_else(|| ctx.text(n, "body")).map_or("", |(_, t)| last_segment(t))
        };
        let mut w = Writer::default();
        w.out.push('\n');
        for mk in &self.model.markers {
            let body = &self.model.bodies[mk.body].name;
            let loc = self.scales[mk.body].component_mul(&mk.offset);
            let own = file.iter().find(|n| n.attribute("name") == Some(mk.name.as_str()) && body_of(**n) == body);
            match own.and_then(|n| child(*n, "location").map(|l| (n, l))) {
                Some((n, l)) => {
                    let (r, lr) = (n.range(), l.range());
                    let t = self.text;
                    let loc = format!("<location>{}</location>", vec3(&loc));
                    w.line(4, &format!("{}{loc}{}", &t[r.start..lr.start], &t[lr.end..r.end]));
                }
                None => marker(&mut w, 4, &mk.name, body, &loc, mk.fixed),
            }
        }
        let mut dropped = 0;
        for n in &file {
            if body_of(*n) == "ground" {
                w.line(4, &self.text[n.range()]);
            } else if self.model.marker_index(n.attribute("name").unwrap_or("")).is_none() {
                dropped += 1;
            }
        }
        if dropped > 0 {
            self.warnings.push(format!(
                "{}: {dropped} markers of the file are not in the model's marker set: left out",
                ctx.file
            ));
        }
        w.line(3, "</objects>");
        let objects = format!("<objects>{}", w.out);
        let set = child(m, "MarkerSet");
        match (set, set.and_then(|s| child(s, "objects"))) {
            (_, Some(o)) => self.replace(o, objects.trim_end().to_string()),
            (Some(s), None) => {
                let name = s.attribute("name").unwrap_or("markerset");
                self.replace(s, format!("<MarkerSet name=\"{}\">\n\t\t\t{}\t\t</MarkerSet>", esc(name), objects));
            }
            (None, None) => self.insert_before_end(
                ctx,
                m,
                format!("\t<MarkerSet name=\"markerset\">\n\t\t\t{objects}\t\t</MarkerSet>\n\t"),
            )?,
        }
        Ok(())
    }
}

/// OpenSim `Body::scaleInertialProperties`: the inertia `[xx yy zz xy xz yz]` (kg·m², about the
/// mass centre) of a body of mass `unscaled` → `mass` whose geometry scales by `f`. Equal factors
/// scale it by `f²` (and the mass ratio); unequal ones treat the body as a cylinder along its
/// axis of least inertia.
pub fn scale_inertia(i: &[f64; 6], unscaled: f64, mass: f64, f: &Vector3<f64>, scale_mass: bool) -> [f64; 6] {
    let mut t = Matrix3::new(i[0], i[3], i[4], i[3], i[1], i[5], i[4], i[5], i[2]);
    let msf = (f.x * f.y * f.z).abs();
    let equal = |a: f64, b: f64| (a - b).abs() <= 1e-14 * a.abs().max(b.abs()).max(1.0);
    if mass <= f64::EPSILON {
        t = Matrix3::zeros();
    } else if equal(f.x, f.y) && equal(f.y, f.z) {
        if scale_mass {
            t *= msf;
        }
        t *= f.x * f.x;
    } else {
        let axis = if t[(0, 0)] <= t[(1, 1)] {
            if t[(0, 0)] <= t[(2, 2)] {
                0
            } else {
                2
            }
        } else if t[(1, 1)] <= t[(2, 2)] {
            1
        } else {
            2
        };
        let radius = (2.0 * t[(axis, axis)] / unscaled).max(0.0).sqrt();
        let oa = if axis == 0 { 1 } else { 0 };
        let length = (12.0 * (t[(oa, oa)] - 0.25 * unscaled * radius * radius) / unscaled).max(0.0).sqrt() * f[axis];
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let rad_sqr = radius * f[u.min(v)] * radius * f[u.max(v)];
        for k in 0..3 {
            t[(k, k)] = if k == axis { 0.5 * mass * rad_sqr } else { mass * (length * length / 12.0 + 0.25 * rad_sqr) };
        }
        for (r, c) in [(0, 1), (0, 2), (1, 2)] {
            let k = f[r] * f[c] * if scale_mass { msf } else { 1.0 };
            t[(r, c)] *= k;
            t[(c, r)] *= k;
        }
    }
    [t[(0, 0)], t[(1, 1)], t[(2, 2)], t[(0, 1)], t[(0, 2)], t[(1, 2)]]
}

/// Applies non-overlapping edits; `Err(start)` of the first edit overlapping its predecessor.
fn apply(text: &str, mut edits: Vec<(Range<usize>, String)>) -> Result<String, usize> {
    edits.sort_by_key(|(r, _)| (r.start, r.end));
    let mut out = String::with_capacity(text.len() + text.len() / 8);
    let mut at = 0;
    for (r, t) in edits {
        if r.start < at {
            return Err(r.start);
        }
        out.push_str(&text[at..r.start]);
        out.push_str(&t);
        at = r.end;
    }
    out.push_str(&text[at..]);
    Ok(out)
}
