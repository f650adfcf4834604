//! Joint emission: motions and coordinates of each OpenSim joint type.

use super::xml::{child, elements};
use super::{func, scale_weights, Axis, Builder, OsimError};
use crate::model::{Body, Coordinate, CoordinateKind, Function, Joint, Motion, MotionKind};
use nalgebra::{Isometry3, Vector3};
use roxmltree::Node;

impl<'c, 'a> Builder<'c, 'a> {
    /// Appends body `b` with the joint `j`, its motions and coordinates.
    pub(super) fn emit(
        &mut self,
        j: Node<'a, 'a>,
        b: usize,
        parent: Option<usize>,
        parent_offset: Isometry3<f64>,
        child_offset: Isometry3<f64>,
    ) -> Result<(), OsimError> {
        let kind = j.tag_name().name();
        let declared: Vec<Node> =
            child(j, "coordinates").into_iter().flat_map(elements).filter(|c| c.has_tag_name("Coordinate")).collect();
        let jname = j.attribute("name").unwrap_or(self.names[b]).to_string();
        let (names, axes): (Vec<String>, Vec<Axis>) = if kind == "CustomJoint" {
            self.custom_axes(j)?
        } else {
            use MotionKind::{Rotation as R, Translation as T};
            let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
            let seq: Vec<(MotionKind, Vector3<f64>, usize)> = match kind {
                "PinJoint" => vec![(R, z, 0)],
                "SliderJoint" => vec![(T, x, 0)],
                "UniversalJoint" => vec![(R, x, 0), (R, y, 1)],
                "BallJoint" | "GimbalJoint" => vec![(R, x, 0), (R, y, 1), (R, z, 2)],
                "FreeJoint" => vec![(T, x, 3), (T, y, 4), (T, z, 5), (R, x, 0), (R, y, 1), (R, z, 2)],
                _ => vec![],
            };
            let n = seq.len();
            let names = (0..n)
                .map(|i| {
                    declared
                        .get(i)
                        .and_then(|c| c.attribute("name"))
                        .map_or_else(|| format!("{jname}_coord_{i}"), str::to_string)
                })
                .collect();
            let axes = seq
                .into_iter()
                .enumerate()
                .map(|(order, (kind, axis, c))| Axis {
                    kind,
                    axis,
                    coordinate: Some(c),
                    func: Function::IDENTITY,
                    weights: None,
                    order,
                })
                .collect();
            (names, axes)
        };
        if declared.len() > names.len() {
            return Err(self
                .ctx
                .err(j, format!("{} coordinates declared but the joint has {}", declared.len(), names.len())));
        }
        // Coordinates, with OpenSim's motion type.
        let first = self.coordinates.len();
        for (i, name) in names.iter().enumerate() {
            if self.coordinates.iter().any(|c| &c.name == name) {
                return Err(self.ctx.err(j, format!("duplicate coordinate name '{name}'")));
            }
            let node = declared.iter().find(|c| c.attribute("name") == Some(name.as_str())).copied();
            // As `CustomJoint::constructCoordinates`: over the axes in OpenSim's order, the last
            // pure one (LinearFunction of slope ±1) decides; without one the coordinate is
            // "Coupled", which we call rotational when it drives a rotation.
            let mut pure = None;
            let mut rotates = false;
            let mut driven: Vec<&Axis> = axes.iter().filter(|a| a.coordinate == Some(i)).collect();
            driven.sort_by_key(|a| a.order);
            for a in driven {
                rotates |= a.kind == MotionKind::Rotation;
                if matches!(a.func, Function::Linear { slope, .. } if slope.abs() == 1.0) {
                    pure = Some(a.kind);
                }
            }
            let kind = match pure.unwrap_or(if rotates { MotionKind::Rotation } else { MotionKind::Translation }) {
                MotionKind::Rotation => CoordinateKind::Rotational,
                MotionKind::Translation => CoordinateKind::Translational,
            };
            self.coordinates.push(self.coordinate(node, name, kind)?);
        }
        let start = self.motions.len();
        for a in axes {
            if a.coordinate.is_none() && a.func == (Function::Constant { value: 0.0 }) {
                continue;
            }
            let coordinate = a.coordinate.map(|c| first + c);
            let m = Motion { kind: a.kind, axis: a.axis, coordinate, func: a.func, parent_scale_weights: a.weights };
            self.motions.push(m);
        }
        let joint = Joint { name: jname, parent_offset, child_offset, motions: start..self.motions.len() };
        self.placed[b] = Some(self.bodies.len());
        self.bodies.push(Body { name: self.names[b].to_string(), parent, joint });
        Ok(())
    }

    fn coordinate(
        &self,
        node: Option<Node<'a, 'a>>,
        name: &str,
        kind: CoordinateKind,
    ) -> Result<Coordinate, OsimError> {
        let mut c = Coordinate {
            name: name.to_string(),
            kind,
            default: 0.0,
            range: (f64::NEG_INFINITY, f64::INFINITY),
            locked: false,
            clamped: false,
        };
        if let Some(n) = node {
            c.default = self.ctx.scalar(n, "default_value")?.unwrap_or(0.0);
            if let Some(r) = self.ctx.fixed(n, "range", 2, true)? {
                if r[0] > r[1] {
                    return Err(self.ctx.err(n, format!("empty range [{}, {}]", r[0], r[1])));
                }
                c.range = (r[0], r[1]);
            }
            c.clamped = self.ctx.boolean(n, "clamped")?.unwrap_or(false);
            c.locked = self.ctx.boolean(n, "locked")?.unwrap_or(false);
        }
        Ok(c)
    }

    /// Coordinate names (in order of first use) and motions of a `CustomJoint`'s SpatialTransform.
    fn custom_axes(&mut self, j: Node<'a, 'a>) -> Result<(Vec<String>, Vec<Axis>), OsimError> {
        const NAMES: [&str; 6] =
            ["rotation1", "rotation2", "rotation3", "translation1", "translation2", "translation3"];
        let st = child(j, "SpatialTransform");
        let mut names: Vec<String> = Vec::new();
        let mut parsed = Vec::with_capacity(6);
        for (i, an) in NAMES.iter().enumerate() {
            let node = st
                .and_then(|s| elements(s).find(|n| n.has_tag_name("TransformAxis") && n.attribute("name") == Some(an)));
            let default_axis = [Vector3::x(), Vector3::y(), Vector3::z()][i % 3];
            let Some(n) = node else {
                parsed.push((default_axis, None, Function::Constant { value: 0.0 }));
                continue;
            };
            let coords: Vec<&str> =
                self.ctx.text(n, "coordinates").map_or(vec![], |(_, t)| t.split_whitespace().collect());
            if coords.len() > 1 {
                return Err(self.ctx.err(n, "TransformAxis functions of several coordinates are not supported"));
            }
            let axis = self.ctx.vec3(n, "axis")?.unwrap_or(Vector3::x());
            let func = func::child_function(self.ctx, n, &["coordinates", "axis"])?;
            let func =
                func.unwrap_or(if coords.is_empty() { Function::Constant { value: 0.0 } } else { Function::IDENTITY });
            let coordinate = coords.first().map(|c| match names.iter().position(|x| x == c) {
                Some(k) => k,
                None => {
                    names.push(c.to_string());
                    names.len() - 1
                }
            });
            parsed.push((axis, coordinate, func));
        }
        for start in [0, 3] {
            let a = |k: usize| parsed[start + k].0;
            if a(0).cross(&a(1)).norm() < 1e-5 || a(0).cross(&a(2)).norm() < 1e-5 || a(1).cross(&a(2)).norm() < 1e-5 {
                let what = if start == 0 { "rotation" } else { "translation" };
                return Err(self.ctx.err(st.unwrap_or(j), format!("collinear or zero {what} axes")));
            }
        }
        let mut axes = Vec::with_capacity(6);
        for i in [3, 4, 5, 0, 1, 2] {
            let (axis, coordinate, func) = parsed[i].clone();
            let translation = i >= 3;
            let weights = (translation && func != Function::IDENTITY).then(|| scale_weights(axis));
            let kind = if translation { MotionKind::Translation } else { MotionKind::Rotation };
            axes.push(Axis { kind, axis, coordinate, func, weights, order: i });
        }
        Ok((names, axes))
    }
}
