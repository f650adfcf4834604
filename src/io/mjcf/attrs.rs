//! Attribute access for the MJCF reader: `<compiler>` settings, `<default>` classes, numbers,
//! orientations, and located errors/warnings.

use super::MjcfError;
use nalgebra::{Quaternion, Rotation3, Unit, UnitQuaternion, Vector3};
use roxmltree::{Document, Node, NodeId};
use std::collections::HashMap;

/// Attribute name → (byte offset of the attribute in the text, value).
#[derive(Clone, Default)]
pub(super) struct Attrs<'a>(HashMap<&'a str, (usize, &'a str)>);

impl<'a> Attrs<'a> {
    /// The element's own attributes.
    pub fn own(node: Node<'a, 'a>) -> Attrs<'a> {
        let mut a = Attrs::default();
        a.overlay(node);
        a
    }
    fn overlay(&mut self, node: Node<'a, 'a>) {
        for attr in node.attributes() {
            self.0.insert(attr.name(), (attr.range().start, attr.value()));
        }
    }
    pub fn get(&self, key: &str) -> Option<(usize, &'a str)> {
        self.0.get(key).copied()
    }
    /// Offset of attribute `key`, else of `node`.
    pub fn pos(&self, key: &str, node: Node) -> usize {
        self.get(key).map_or(node.range().start, |v| v.0)
    }
}

/// Attribute defaults of one `<default>` class.
#[derive(Clone, Default)]
pub(super) struct Class<'a> {
    pub joint: Attrs<'a>,
    pub site: Attrs<'a>,
    pub geom: Attrs<'a>,
}

/// Parsing context: document, compiler settings, default classes, warnings.
pub(super) struct Ctx<'a> {
    doc: &'a Document<'a>,
    pub file: &'a str,
    pub warnings: Vec<String>,
    /// Factor from the file's angle unit to radians.
    pub angle: f64,
    eulerseq: [u8; 3],
    pub autolimits: bool,
    classes: HashMap<&'a str, Class<'a>>,
}

const ORIENTATIONS: [&str; 5] = ["quat", "axisangle", "euler", "xyaxes", "zaxis"];

impl<'a> Ctx<'a> {
    pub fn new(doc: &'a Document<'a>, file: &'a str) -> Ctx<'a> {
        let classes = HashMap::from([("main", Class::default())]);
        let angle = std::f64::consts::PI / 180.0;
        Ctx { doc, file, warnings: Vec::new(), angle, eulerseq: *b"xyz", autolimits: true, classes }
    }

    /// Error at byte offset `pos` about `element`.
    pub fn err_at(&self, pos: usize, element: &str, message: impl Into<String>) -> MjcfError {
        let p = self.doc.text_pos_at(pos);
        let (file, element, message) = (self.file.to_string(), element.to_string(), message.into());
        MjcfError::Element { file, line: p.row, column: p.col, element, message }
    }
    /// Error located at `node`'s start tag.
    pub fn err(&self, node: Node, message: impl Into<String>) -> MjcfError {
        self.err_at(node.range().start, node.tag_name().name(), message)
    }
    pub fn warn(&mut self, node: Node, message: &str) {
        let p = self.doc.text_pos_at(node.range().start);
        self.warnings.push(format!("{}:{}: <{}>: {message}", self.file, p.row, node.tag_name().name()));
    }

    pub fn read_compiler(&mut self, c: Node<'a, 'a>) -> Result<(), MjcfError> {
        let a = Attrs::own(c);
        let bad = |key: &str, v: &str, expected: &str| {
            self.err_at(a.pos(key, c), "compiler", format!("invalid {key} '{v}': expected {expected}"))
        };
        let angle = match a.get("angle").map(|v| v.1) {
            None => self.angle,
            Some("degree") => std::f64::consts::PI / 180.0,
            Some("radian") => 1.0,
            Some(v) => return Err(bad("angle", v, "one of degree, radian")),
        };
        let eulerseq = match a.get("eulerseq").map(|v| v.1) {
            None => self.eulerseq,
            Some(v) => match <[u8; 3]>::try_from(v.as_bytes()) {
                Ok(seq) if seq.iter().all(|ch| b"xyzXYZ".contains(ch)) => seq,
                _ => return Err(bad("eulerseq", v, "three letters from x, y, z, X, Y, Z")),
            },
        };
        let autolimits = match a.get("autolimits").map(|v| v.1) {
            None => self.autolimits,
            Some("true") => true,
            Some("false") => false,
            Some(v) => return Err(bad("autolimits", v, "one of true, false")),
        };
        match a.get("coordinate").map(|v| v.1) {
            None | Some("local") => {}
            Some(v) => return Err(bad("coordinate", v, "local (global coordinates are not supported)")),
        }
        (self.angle, self.eulerseq, self.autolimits) = (angle, eulerseq, autolimits);
        Ok(())
    }

    /// Reads every `<default>` tree; a nested class starts from its parent's attributes.
    pub fn read_defaults(&mut self, root: Node<'a, 'a>) -> Result<(), MjcfError> {
        let mut node_class: HashMap<NodeId, &'a str> = HashMap::new();
        for top in root.children().filter(|n| n.has_tag_name("default")) {
            for d in top.descendants().filter(|n| n.has_tag_name("default")) {
                let (name, parent) = if d == top {
                    let name = d.attribute("class").unwrap_or("main");
                    (name, (name != "main").then_some("main"))
                } else {
                    let parent = d.parent_element().and_then(|p| node_class.get(&p.id()).copied());
                    let Some(parent) = parent else {
                        return Err(self.err(d, "<default> must be nested directly in <default>"));
                    };
                    let Some(name) = d.attribute("class") else {
                        return Err(self.err(d, "nested <default> needs a 'class' attribute"));
                    };
                    (name, Some(parent))
                };
                let mut class = match parent {
                    Some(p) if self.classes.contains_key(name) => {
                        return Err(self.err(d, format!("duplicate default class '{name}' (parent '{p}')")));
                    }
                    Some(p) => self.classes.get(p).cloned().unwrap_or_default(),
                    None => self.classes.get(name).cloned().unwrap_or_default(),
                };
                for c in d.children() {
                    match c.tag_name().name() {
                        "joint" => class.joint.overlay(c),
                        "site" => class.site.overlay(c),
                        "geom" => class.geom.overlay(c),
                        _ => {}
                    }
                }
                self.classes.insert(name, class);
                node_class.insert(d.id(), name);
            }
        }
        Ok(())
    }

    /// Checks that default class `name` exists.
    pub fn class_name(&self, node: Node, name: &'a str) -> Result<&'a str, MjcfError> {
        if self.classes.contains_key(name) {
            Ok(name)
        } else {
            Err(self.err(node, format!("unknown default class '{name}'")))
        }
    }

    /// Attributes of `node` over its class defaults (`class`, else `inherited`).
    pub fn resolve(
        &self,
        node: Node<'a, 'a>,
        inherited: &'a str,
        pick: impl for<'c> Fn(&'c Class<'a>) -> &'c Attrs<'a>,
    ) -> Result<Attrs<'a>, MjcfError> {
        let name = node.attribute("class").unwrap_or(inherited);
        let class = self.classes.get(name).ok_or_else(|| self.err(node, format!("unknown default class '{name}'")))?;
        let mut a = pick(class).clone();
        a.overlay(node);
        Ok(a)
    }

    /// Exactly `N` finite numbers from attribute `key`, if present.
    pub fn nums<const N: usize>(&self, node: Node, a: &Attrs, key: &str) -> Result<Option<[f64; N]>, MjcfError> {
        let Some((pos, text)) = a.get(key) else {
            return Ok(None);
        };
        match parse_numbers(text).and_then(|v| <[f64; N]>::try_from(v).ok()) {
            Some(v) => Ok(Some(v)),
            None => {
                Err(self.err_at(pos, node.tag_name().name(), format!("{key} '{text}': expected {N} finite numbers")))
            }
        }
    }
    pub fn vec3(&self, node: Node, a: &Attrs, key: &str) -> Result<Option<Vector3<f64>>, MjcfError> {
        Ok(self.nums::<3>(node, a, key)?.map(Vector3::from))
    }

    /// Frame orientation from at most one of `quat`, `axisangle`, `euler`, `xyaxes`, `zaxis`.
    pub fn orientation(&self, node: Node, a: &Attrs) -> Result<UnitQuaternion<f64>, MjcfError> {
        let present: Vec<&str> = ORIENTATIONS.into_iter().filter(|k| a.get(k).is_some()).collect();
        let el = node.tag_name().name();
        let bad = |key: &str, what: &str| self.err_at(a.pos(key, node), el, format!("{key}: {what}"));
        if let [first, second, ..] = present[..] {
            let msg = format!(
                "conflicting orientation attributes '{first}' and '{second}': use at most one of {}",
                ORIENTATIONS.join(", ")
            );
            return Err(self.err_at(a.pos(second, node), el, msg));
        }
        let unit = |v: Vector3<f64>, key: &str| {
            let n = v.norm();
            if n > 1e-12 && n.is_finite() {
                Ok(v / n)
            } else {
                Err(bad(key, "needs a non-zero finite vector"))
            }
        };
        match present.first().copied() {
            Some("quat") => {
                let [w, x, y, z] = self.nums::<4>(node, a, "quat")?.unwrap_or_default();
                let q = Quaternion::new(w, x, y, z);
                if !(q.norm() > 1e-12 && q.norm().is_finite()) {
                    return Err(bad("quat", "needs a non-zero finite quaternion"));
                }
                Ok(UnitQuaternion::from_quaternion(q))
            }
            Some("axisangle") => {
                let [x, y, z, angle] = self.nums::<4>(node, a, "axisangle")?.unwrap_or_default();
                let axis = unit(Vector3::new(x, y, z), "axisangle")?;
                Ok(crate::model::math::quaternion(&Unit::new_unchecked(axis), angle * self.angle))
            }
            Some("euler") => {
                let e = self.nums::<3>(node, a, "euler")?.unwrap_or_default();
                let mut q = UnitQuaternion::identity();
                for (&axis, angle) in self.eulerseq.iter().zip(e) {
                    let v = match axis.to_ascii_lowercase() {
                        b'x' => Vector3::x_axis(),
                        b'y' => Vector3::y_axis(),
                        _ => Vector3::z_axis(),
                    };
                    let r = crate::model::math::quaternion(&v, angle * self.angle);
                    // Rotating (lowercase) axes post-multiply, fixed (uppercase) axes pre-multiply.
                    q = if axis.is_ascii_lowercase() { q * r } else { r * q };
                }
                Ok(q)
            }
            Some("xyaxes") => {
                let v = self.nums::<6>(node, a, "xyaxes")?.unwrap_or_default();
                let x = unit(Vector3::new(v[0], v[1], v[2]), "xyaxes")?;
                let y = Vector3::new(v[3], v[4], v[5]);
                let y = unit(y - x * x.dot(&y), "xyaxes")?;
                let r = Rotation3::from_basis_unchecked(&[x, y, x.cross(&y)]);
                Ok(UnitQuaternion::from_rotation_matrix(&r))
            }
            Some(_) => {
                // MuJoCo's minimal rotation taking +z onto the given axis (π about x when opposite).
                let v = self.vec3(node, a, "zaxis")?.unwrap_or_default();
                let v = unit(v, "zaxis")?;
                let c = Vector3::z().cross(&v);
                let s = c.norm();
                let axis = if s < 1e-10 { Vector3::x_axis() } else { Unit::new_unchecked(c / s) };
                Ok(crate::model::math::quaternion(&axis, crate::model::math::atan2(s, v.z)))
            }
            None => Ok(UnitQuaternion::identity()),
        }
    }
}

/// Whitespace-separated finite numbers; `None` when any is malformed or non-finite.
pub(super) fn parse_numbers(text: &str) -> Option<Vec<f64>> {
    text.split_ascii_whitespace().map(|t| t.parse::<f64>().ok().filter(|v| v.is_finite())).collect()
}
