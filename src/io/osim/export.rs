//! Writing a [`Model`] as an OpenSim 4 `.osim` model, with per-body scale factors baked in.
//!
//! Each body becomes a `Body` (placeholder inertial properties: the model carries none) and its
//! joint a `CustomJoint` (a `WeldJoint` when nothing moves it) whose `PhysicalOffsetFrame`s are
//! the joint's parent and child offsets. OpenSim's `SpatialTransform` is `X_FM = (R₁R₂R₃, Σ fᵢ tᵢ)`:
//! translations along the parent-frame axes `translation1-3`, then rotations about the successive
//! (body-fixed) axes `rotation1-3` (see the module docs of [`super`]). A joint's motions must
//! therefore be at most three translations followed by at most three rotations, each group with
//! pairwise non-collinear axes; anything else is an [`OsimWriteError::Joint`]. Unused axes get
//! `Constant 0` on axes completing the used ones to independent triads.
//!
//! Scaling (as OpenSim's ScaleTool, [`crate::model`]): parent offsets scale with the parent body,
//! child offsets and markers with the body, translations with `parent_scale_weights` by
//! `w · s_parent` (written as a `MultiplierFunction`). The written model at unit scale has the
//! kinematics of `model` at the given scales.
//!
//! Functions map to `Constant`, `LinearFunction`, `PolynomialFunction`, `PiecewiseLinearFunction`,
//! `MultiplierFunction`, and a cubic spline to the `SimmSpline` or `NaturalCubicSpline` through its
//! knots that reproduces it (else an error). Couplings become `CoordinateCouplerConstraint`s.
//! Infinite coordinate range ends are written as ±99999.9 (OpenSim's convention).

use super::func::simm_spline;
use crate::io::sto::push_number;
use crate::model::{CubicSpline, Function, Model, MotionKind};
use nalgebra::{Isometry3, Matrix3, Translation3, Unit, UnitQuaternion, Vector3};

/// Errors writing a model as `.osim`.
#[derive(Debug, thiserror::Error)]
pub enum OsimWriteError {
    #[error("joint '{joint}': {message}")]
    Joint { joint: String, message: String },
    #[error("coordinate '{coordinate}' drives motions of joints '{first}' and '{second}'; an OpenSim coordinate belongs to one joint")]
    SharedCoordinate { coordinate: String, first: String, second: String },
    #[error("{what}: {message}")]
    Function { what: String, message: String },
    #[error("{count} scale factor triples for a model of {bodies} bodies")]
    Scales { count: usize, bodies: usize },
}

/// Placeholder inertial properties of generated bodies (kg, kg·m²): the model carries none, so the
/// written model is for kinematics (inverse kinematics, visualisation) until real ones are set.
pub const PLACEHOLDER_MASS: f64 = 1.0;
pub const PLACEHOLDER_INERTIA: f64 = 0.01;

/// Gravity written into generated models (m/s², ground frame): −z, the MJCF convention.
pub const GENERATED_GRAVITY: [f64; 3] = [0.0, 0.0, -9.80665];

/// Writes `model` with body `b` scaled by `scales[b]` (x, y, z) as OpenSim 4 `.osim` text.
/// Returns the text and warnings (coordinates that drive no motion are left out).
pub fn format_osim(model: &Model, scales: &[Vector3<f64>]) -> Result<(String, Vec<String>), OsimWriteError> {
    if scales.len() != model.nb() {
        return Err(OsimWriteError::Scales { count: scales.len(), bodies: model.nb() });
    }
    let mut warnings = Vec::new();
    let owner = coordinate_owners(model)?;
    let mut w = Writer::default();
    w.line(0, r#"<?xml version="1.0" encoding="UTF-8" ?>"#);
    w.line(0, r#"<OpenSimDocument Version="40000">"#);
    w.line(1, &format!(r#"<Model name="{}">"#, esc(&model.name)));
    w.line(2, "<!--Written by smocap: scale factors applied, placeholder inertial properties.-->");
    w.line(2, "<length_units>meters</length_units>");
    w.line(2, "<force_units>N</force_units>");
    w.line(2, &format!("<gravity>{}</gravity>", nums(&GENERATED_GRAVITY)));
    w.line(2, r#"<Ground name="ground" />"#);
    w.line(2, r#"<BodySet name="bodyset">"#);
    w.line(3, "<objects>");
    let i = PLACEHOLDER_INERTIA;
    for b in &model.bodies {
        w.line(4, &format!(r#"<Body name="{}">"#, esc(&b.name)));
        w.line(5, &format!("<mass>{}</mass>", num(PLACEHOLDER_MASS)));
        w.line(5, "<mass_center>0 0 0</mass_center>");
        w.line(5, &format!("<inertia>{}</inertia>", nums(&[i, i, i, 0.0, 0.0, 0.0])));
        w.line(4, "</Body>");
    }
    w.line(3, "</objects>");
    w.line(3, "<groups />");
    w.line(2, "</BodySet>");
    w.line(2, r#"<JointSet name="jointset">"#);
    w.line(3, "<objects>");
    for b in 0..model.nb() {
        joint(&mut w, model, b, scales, &owner)?;
    }
    w.line(3, "</objects>");
    w.line(3, "<groups />");
    w.line(2, "</JointSet>");
    if !model.couplings.is_empty() {
        w.line(2, r#"<ConstraintSet name="constraintset">"#);
        w.line(3, "<objects>");
        for c in &model.couplings {
            let (dep, ind) = (&model.coordinates[c.dependent].name, &model.coordinates[c.independent].name);
            w.line(4, &format!(r#"<CoordinateCouplerConstraint name="{}_coupler">"#, esc(dep)));
            w.line(5, "<isEnforced>true</isEnforced>");
            w.line(5, "<coupled_coordinates_function>");
            function(&mut w, 6, &c.func, &format!("coupling of '{dep}'"))?;
            w.line(5, "</coupled_coordinates_function>");
            w.line(5, &format!("<independent_coordinate_names>{}</independent_coordinate_names>", esc(ind)));
            w.line(5, &format!("<dependent_coordinate_name>{}</dependent_coordinate_name>", esc(dep)));
            w.line(5, "<scale_factor>1</scale_factor>");
            w.line(4, "</CoordinateCouplerConstraint>");
        }
        w.line(3, "</objects>");
        w.line(3, "<groups />");
        w.line(2, "</ConstraintSet>");
    }
    w.line(2, r#"<MarkerSet name="markerset">"#);
    w.line(3, "<objects>");
    for m in &model.markers {
        marker(&mut w, 4, &m.name, &model.bodies[m.body].name, &scales[m.body].component_mul(&m.offset), m.fixed);
    }
    w.line(3, "</objects>");
    w.line(3, "<groups />");
    w.line(2, "</MarkerSet>");
    w.line(1, "</Model>");
    w.line(0, "</OpenSimDocument>");
    for (c, o) in owner.iter().enumerate() {
        if o.is_none() {
            warnings
                .push(format!("coordinate '{}' drives no motion: left out of the .osim", model.coordinates[c].name));
        }
    }
    Ok((w.out, warnings))
}

/// An OpenSim `ScaleSet` document with the factors of every body (`scales[b]` for body `b`),
/// which OpenSim's ScaleTool applies as manual scales.
pub fn format_scale_set(model: &Model, scales: &[Vector3<f64>]) -> String {
    let mut w = Writer::default();
    w.line(0, r#"<?xml version="1.0" encoding="UTF-8" ?>"#);
    w.line(0, r#"<OpenSimDocument Version="40000">"#);
    w.line(1, r#"<ScaleSet name="smocap_scale_set">"#);
    w.line(2, "<objects>");
    for (b, s) in model.bodies.iter().zip(scales) {
        w.line(3, "<Scale>");
        w.line(4, &format!("<scales>{}</scales>", vec3(s)));
        w.line(4, &format!("<segment>{}</segment>", esc(&b.name)));
        w.line(4, "<apply>true</apply>");
        w.line(3, "</Scale>");
    }
    w.line(2, "</objects>");
    w.line(2, "<groups />");
    w.line(1, "</ScaleSet>");
    w.line(0, "</OpenSimDocument>");
    w.out
}

/// Writes one `<Marker>` element (location in the body frame, m).
pub(super) fn marker(w: &mut Writer, depth: usize, name: &str, body: &str, location: &Vector3<f64>, fixed: bool) {
    w.line(depth, &format!(r#"<Marker name="{}">"#, esc(name)));
    w.line(depth + 1, &format!("<socket_parent_frame>/bodyset/{}</socket_parent_frame>", esc(body)));
    w.line(depth + 1, &format!("<location>{}</location>", vec3(location)));
    w.line(depth + 1, &format!("<fixed>{fixed}</fixed>"));
    w.line(depth, "</Marker>");
}

/// For each coordinate, the body whose joint it drives (`None`: it drives nothing).
fn coordinate_owners(model: &Model) -> Result<Vec<Option<usize>>, OsimWriteError> {
    let mut owner: Vec<Option<usize>> = vec![None; model.nq()];
    for (b, body) in model.bodies.iter().enumerate() {
        for m in &model.motions[body.joint.motions.clone()] {
            let Some(c) = m.coordinate else { continue };
            match owner[c] {
                Some(o) if o != b => {
                    return Err(OsimWriteError::SharedCoordinate {
                        coordinate: model.coordinates[c].name.clone(),
                        first: model.bodies[o].joint.name.clone(),
                        second: body.joint.name.clone(),
                    })
                }
                _ => owner[c] = Some(b),
            }
        }
    }
    Ok(owner)
}

/// One elementary motion as a TransformAxis: axis, coordinate, function (scale baked in).
struct Axis {
    axis: Vector3<f64>,
    coordinate: Option<usize>,
    func: Function,
}

fn joint(
    w: &mut Writer,
    model: &Model,
    b: usize,
    scales: &[Vector3<f64>],
    owner: &[Option<usize>],
) -> Result<(), OsimWriteError> {
    let body = &model.bodies[b];
    let j = &body.joint;
    let s_p = body.parent.map_or(Vector3::new(1.0, 1.0, 1.0), |p| scales[p]);
    let err = |message: String| OsimWriteError::Joint { joint: j.name.clone(), message };
    let mut parent_offset = scaled(&j.parent_offset, &s_p);
    let child_offset = scaled(&j.child_offset, &scales[b]);
    let (mut trans, mut rots): (Vec<Axis>, Vec<Axis>) = (Vec::new(), Vec::new());
    let moving = model.motions[j.motions.clone()].iter().any(|m| m.coordinate.is_some());
    for (k, m) in model.motions[j.motions.clone()].iter().enumerate() {
        let sigma = m.parent_scale_weights.map_or(1.0, |wt| wt.dot(&s_p));
        if !moving {
            // A welded joint: fold the constant motions into the parent offset.
            let v = m.func.eval(0.0).0;
            let step = match m.kind {
                MotionKind::Rotation => Isometry3::from_parts(
                    Translation3::identity(),
                    crate::model::math::quaternion(&Unit::new_normalize(m.axis), v),
                ),
                MotionKind::Translation => {
                    Isometry3::from_parts((m.axis * (v * sigma)).into(), UnitQuaternion::identity())
                }
            };
            parent_offset *= step;
            continue;
        }
        let func = match m.coordinate {
            None => Function::Constant { value: m.func.eval(0.0).0 },
            Some(_) => m.func.clone(),
        };
        let func = match (m.kind, sigma) {
            (MotionKind::Translation, s) if s != 1.0 => match func {
                Function::Constant { value } => Function::Constant { value: value * s },
                f => Function::Multiplier { scale: s, inner: Box::new(f) },
            },
            (_, _) => func,
        };
        let axis = Axis { axis: m.axis, coordinate: m.coordinate, func };
        match m.kind {
            MotionKind::Translation if !rots.is_empty() => {
                return Err(err(format!(
                "motion {k} is a translation after a rotation; an OpenSim CustomJoint translates first, then rotates"
            )))
            }
            MotionKind::Translation => trans.push(axis),
            MotionKind::Rotation => rots.push(axis),
        }
    }
    if trans.len() > 3 || rots.len() > 3 {
        return Err(err(format!(
            "{} translations and {} rotations; an OpenSim CustomJoint has at most 3 of each",
            trans.len(),
            rots.len()
        )));
    }
    let tag = if moving { "CustomJoint" } else { "WeldJoint" };
    let parent_name = body.parent.map_or("ground", |p| model.bodies[p].name.as_str());
    let parent_frame = format!("{parent_name}_offset");
    let child_frame = format!("{}_offset", body.name);
    w.line(4, &format!(r#"<{tag} name="{}">"#, esc(&j.name)));
    w.line(5, &format!("<socket_parent_frame>{}</socket_parent_frame>", esc(&parent_frame)));
    w.line(5, &format!("<socket_child_frame>{}</socket_child_frame>", esc(&child_frame)));
    if moving {
        let order: Vec<usize> = rots.iter().chain(&trans).filter_map(|a| a.coordinate).fold(Vec::new(), |mut v, c| {
            if !v.contains(&c) {
                v.push(c);
            }
            v
        });
        w.line(5, "<coordinates>");
        for c in order.into_iter().filter(|&c| owner[c] == Some(b)) {
            coordinate(w, model, c);
        }
        w.line(5, "</coordinates>");
    }
    w.line(5, "<frames>");
    let parent_path = if body.parent.is_some() { format!("/bodyset/{parent_name}") } else { "/ground".into() };
    offset_frame(w, &parent_frame, &parent_path, &parent_offset);
    offset_frame(w, &child_frame, &format!("/bodyset/{}", body.name), &child_offset);
    w.line(5, "</frames>");
    if moving {
        w.line(5, "<SpatialTransform>");
        for (prefix, axes) in [("rotation", &mut rots), ("translation", &mut trans)] {
            complete_triad(axes).map_err(|m| err(format!("{prefix} axes: {m}")))?;
            for (i, a) in axes.iter().enumerate() {
                transform_axis(w, model, &format!("{prefix}{}", i + 1), a, &j.name)?;
            }
        }
        w.line(5, "</SpatialTransform>");
    }
    w.line(4, &format!("</{tag}>"));
    Ok(())
}

fn scaled(iso: &Isometry3<f64>, s: &Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(s.component_mul(&iso.translation.vector).into(), iso.rotation)
}

fn coordinate(w: &mut Writer, model: &Model, c: usize) {
    let co = &model.coordinates[c];
    let end = |v: f64| if v.is_finite() { v } else { v.signum() * 99999.9 };
    w.line(6, &format!(r#"<Coordinate name="{}">"#, esc(&co.name)));
    w.line(7, &format!("<default_value>{}</default_value>", num(co.default)));
    w.line(7, "<default_speed_value>0</default_speed_value>");
    w.line(7, &format!("<range>{}</range>", nums(&[end(co.range.0), end(co.range.1)])));
    w.line(7, &format!("<clamped>{}</clamped>", co.clamped));
    w.line(7, &format!("<locked>{}</locked>", co.locked));
    w.line(6, "</Coordinate>");
}

fn offset_frame(w: &mut Writer, name: &str, parent: &str, pose: &Isometry3<f64>) {
    let o = body_fixed_xyz_angles(pose.rotation.to_rotation_matrix().matrix());
    w.line(6, &format!(r#"<PhysicalOffsetFrame name="{}">"#, esc(name)));
    w.line(7, &format!("<socket_parent>{}</socket_parent>", esc(parent)));
    w.line(7, &format!("<translation>{}</translation>", vec3(&pose.translation.vector)));
    w.line(7, &format!("<orientation>{}</orientation>", vec3(&o)));
    w.line(6, "</PhysicalOffsetFrame>");
}

/// Body-fixed X-Y-Z Euler angles `(a, b, c)` with `R = Rx(a) Ry(b) Rz(c)` (inverse of
/// [`super::body_fixed_xyz`]); `c = 0` at gimbal lock.
pub(super) fn body_fixed_xyz_angles(r: &Matrix3<f64>) -> Vector3<f64> {
    use crate::model::math::atan2;
    let b = atan2(r[(0, 2)], (r[(0, 0)].powi(2) + r[(0, 1)].powi(2)).sqrt());
    if r[(0, 0)].hypot(r[(0, 1)]) < 1e-12 {
        return Vector3::new(atan2(r[(2, 1)], r[(1, 1)]), b, 0.0);
    }
    Vector3::new(atan2(-r[(1, 2)], r[(2, 2)]), b, atan2(-r[(0, 1)], r[(0, 0)]))
}

/// Checks that `axes` are pairwise non-collinear and appends constant-zero axes up to three.
fn complete_triad(axes: &mut Vec<Axis>) -> Result<(), String> {
    const TOL: f64 = 1e-5; // OpenSim's CustomJoint check
    for i in 0..axes.len() {
        for k in i + 1..axes.len() {
            if axes[i].axis.normalize().cross(&axes[k].axis.normalize()).norm() < TOL {
                return Err(format!("axes {} and {} are collinear; OpenSim needs independent axes", i + 1, k + 1));
            }
        }
    }
    let zero = |axis: Vector3<f64>| Axis { axis, coordinate: None, func: Function::Constant { value: 0.0 } };
    if axes.is_empty() {
        axes.push(zero(Vector3::x()));
    }
    if axes.len() == 1 {
        let a = axes[0].axis.normalize();
        let e = [Vector3::x(), Vector3::y(), Vector3::z()]
            .into_iter()
            .min_by(|u, v| a.dot(u).abs().total_cmp(&a.dot(v).abs()))
            .unwrap_or(Vector3::y());
        axes.push(zero(a.cross(&e).normalize()));
    }
    if axes.len() == 2 {
        let n = axes[0].axis.cross(&axes[1].axis).normalize();
        axes.push(zero(n));
    }
    Ok(())
}

fn transform_axis(w: &mut Writer, model: &Model, name: &str, a: &Axis, joint: &str) -> Result<(), OsimWriteError> {
    let coords = a.coordinate.map_or(String::new(), |c| esc(&model.coordinates[c].name));
    w.line(6, &format!(r#"<TransformAxis name="{name}">"#));
    w.line(7, &format!("<coordinates>{coords}</coordinates>"));
    w.line(7, &format!("<axis>{}</axis>", vec3(&a.axis)));
    function(w, 7, &a.func, &format!("joint '{joint}' {name}"))?;
    w.line(6, "</TransformAxis>");
    Ok(())
}

/// Writes `f` as an OpenSim function element named `function`.
fn function(w: &mut Writer, depth: usize, f: &Function, what: &str) -> Result<(), OsimWriteError> {
    let open = |tag: &str| format!(r#"<{tag} name="function">"#);
    match f {
        Function::Constant { value } => {
            w.line(depth, &format!("{}<value>{}</value></Constant>", open("Constant"), num(*value)));
        }
        Function::Linear { slope, intercept } => w.line(
            depth,
            &format!(
                "{}<coefficients>{}</coefficients></LinearFunction>",
                open("LinearFunction"),
                nums(&[*slope, *intercept])
            ),
        ),
        Function::Polynomial { coefficients } => {
            let c: Vec<f64> = coefficients.iter().rev().copied().collect();
            w.line(
                depth,
                &format!(
                    "{}<coefficients>{}</coefficients></PolynomialFunction>",
                    open("PolynomialFunction"),
                    nums(&c)
                ),
            );
        }
        Function::PiecewiseLinear { x, y } => {
            w.line(depth, &open("PiecewiseLinearFunction"));
            w.line(depth + 1, &format!("<x>{}</x>", nums(x)));
            w.line(depth + 1, &format!("<y>{}</y>", nums(y)));
            w.line(depth, "</PiecewiseLinearFunction>");
        }
        Function::Spline(s) => {
            let tag = spline_kind(s).ok_or_else(|| OsimWriteError::Function {
                what: what.to_string(),
                message: "a cubic spline that is neither the SimmSpline nor the NaturalCubicSpline through its knots"
                    .into(),
            })?;
            w.line(depth, &open(tag));
            w.line(depth + 1, &format!("<x>{}</x>", nums(&s.x)));
            w.line(depth + 1, &format!("<y>{}</y>", nums(&s.a)));
            w.line(depth, &format!("</{tag}>"));
        }
        Function::Multiplier { scale, inner } => {
            w.line(depth, &open("MultiplierFunction"));
            w.line(depth + 1, "<function>");
            function(w, depth + 2, inner, what)?;
            w.line(depth + 1, "</function>");
            w.line(depth + 1, &format!("<scale>{}</scale>", num(*scale)));
            w.line(depth, "</MultiplierFunction>");
        }
    }
    Ok(())
}

/// Which OpenSim spline through the knots of `s` reproduces it.
fn spline_kind(s: &CubicSpline) -> Option<&'static str> {
    let close = |t: &CubicSpline| {
        let same = |u: &[f64], v: &[f64]| {
            u.len() == v.len() && u.iter().zip(v).all(|(a, b)| (a - b).abs() <= 1e-9 * (1.0 + a.abs()))
        };
        same(&t.b, &s.b) && same(&t.c, &s.c) && same(&t.d, &s.d)
    };
    if let Function::Spline(t) = simm_spline(&s.x, &s.a) {
        if close(&t) {
            return Some("SimmSpline");
        }
    }
    CubicSpline::natural(&s.x, &s.a).filter(close).map(|_| "NaturalCubicSpline")
}

/// Indented line output.
#[derive(Default)]
pub(super) struct Writer {
    pub out: String,
}

impl Writer {
    pub fn line(&mut self, depth: usize, text: &str) {
        for _ in 0..depth {
            self.out.push('\t');
        }
        self.out.push_str(text);
        self.out.push('\n');
    }
}

/// XML-escapes text and attribute values.
pub(super) fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&apos;"),
            c => o.push(c),
        }
    }
    o
}

pub(super) fn num(v: f64) -> String {
    let mut s = String::new();
    push_number(&mut s, v);
    s
}

pub(super) fn nums(v: &[f64]) -> String {
    let mut s = String::new();
    for (i, x) in v.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        push_number(&mut s, *x);
    }
    s
}

pub(super) fn vec3(v: &Vector3<f64>) -> String {
    nums(v.as_slice())
}
