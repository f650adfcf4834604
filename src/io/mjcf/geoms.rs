//! Collision geoms of an MJCF body: spheres and capsules (what robot self-collision and ground
//! contact use), resolved against their `<default>` classes.
//!
//! A geom collides when `contype` or `conaffinity` is non-zero (MuJoCo's defaults are 1).
//! Capsules come from `fromto` or from `pos`/orientation with half-length `size[1]` along the
//! geom's z; a sphere from `pos` and `size[0]`. Colliding geoms of other types are kept as
//! [`GeomShape::Other`] so that callers can say what they ignore.

use super::{attrs::Attrs, Builder, MjcfError};
use nalgebra::Vector3;

/// A geom's shape in its body's frame (m).
#[derive(Clone, Debug, PartialEq)]
pub enum GeomShape {
    Sphere {
        centre: Vector3<f64>,
        radius: f64,
    },
    /// The points within `radius` of the segment `a`–`b`.
    Capsule {
        a: Vector3<f64>,
        b: Vector3<f64>,
        radius: f64,
    },
    /// A colliding geom of a type not modelled here (`mesh`, `box`, …): its type.
    Other(String),
}

/// One colliding geom.
#[derive(Clone, Debug, PartialEq)]
pub struct Geom {
    /// The geom's name, or `<body>_geom<i>` (`i` counts the body's geoms from 0).
    pub name: String,
    /// Model body index.
    pub body: usize,
    pub shape: GeomShape,
    pub contype: u32,
    pub conaffinity: u32,
}

impl<'a> Builder<'a> {
    /// Appends `node` (the `i`-th geom of `body`) to the geoms when it collides.
    pub(super) fn geom(
        &mut self,
        node: roxmltree::Node<'a, 'a>,
        class: &'a str,
        body: usize,
        i: usize,
    ) -> Result<(), MjcfError> {
        let a = self.ctx.resolve(node, class, |c| &c.geom)?;
        let int = |key: &str| -> Result<u32, MjcfError> {
            match a.get(key) {
                None => Ok(1),
                Some((pos, v)) => v
                    .trim()
                    .parse()
                    .map_err(|_| self.ctx.err_at(pos, "geom", format!("{key} '{v}': expected an integer"))),
            }
        };
        let (contype, conaffinity) = (int("contype")?, int("conaffinity")?);
        if contype == 0 && conaffinity == 0 {
            return Ok(());
        }
        let name = node.attribute("name").map_or_else(|| format!("{}_geom{i}", self.bodies[body].name), str::to_string);
        let shape = self.geom_shape(node, &a)?;
        self.geoms.push(Geom { name, body, shape, contype, conaffinity });
        Ok(())
    }

    /// The geom's shape; one this reader cannot interpret (no radius, a malformed `fromto`) is
    /// [`GeomShape::Other`] with a warning, never an error: geoms do not change the kinematics.
    fn geom_shape(&mut self, node: roxmltree::Node<'a, 'a>, a: &Attrs<'a>) -> Result<GeomShape, MjcfError> {
        let kind = a.get("type").map_or("sphere", |v| v.1);
        let size = a.get("size").and_then(|(_, v)| super::attrs::parse_numbers(v)).unwrap_or_default();
        let radius = size.first().copied().unwrap_or(0.0);
        let pos = self.ctx.vec3(node, a, "pos").ok().flatten().unwrap_or_default();
        let shape = match kind {
            _ if matches!(kind, "sphere" | "capsule") && (radius.is_nan() || radius <= 0.0) => None,
            "sphere" => Some(GeomShape::Sphere { centre: pos, radius }),
            "capsule" => match (self.ctx.nums::<6>(node, a, "fromto"), size.get(1)) {
                (Ok(Some(f)), _) => Some(GeomShape::Capsule {
                    a: Vector3::new(f[0], f[1], f[2]),
                    b: Vector3::new(f[3], f[4], f[5]),
                    radius,
                }),
                (Ok(None), Some(&half)) => self.ctx.orientation(node, a).ok().map(|r| {
                    let axis = r * Vector3::z();
                    GeomShape::Capsule { a: pos - axis * half, b: pos + axis * half, radius }
                }),
                _ => None,
            },
            other => Some(GeomShape::Other(other.to_string())),
        };
        Ok(shape.unwrap_or_else(|| {
            self.ctx.warn(node, &format!("{kind} geom without a usable size or fromto: not a collider here"));
            GeomShape::Other(format!("{kind} without a usable size"))
        }))
    }
}
