//! OpenSim `<MarkerSet>` files and marker elements.

use super::xml::{child, elements, last_segment, Ctx};
use super::{parse_xml, OsimError};
use crate::model::{Marker, Model};
use nalgebra::Vector3;
use roxmltree::Node;
use std::path::Path;

/// Reads an OpenSim `<MarkerSet>` file (as used by the Scale tool) into markers on `model`'s
/// bodies. A marker names its body by `socket_parent_frame` (format 4) or `body` (older).
pub fn read_marker_set(path: &Path, model: &Model) -> Result<Vec<Marker>, OsimError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| OsimError::Io { file: file.clone(), source })?;
    parse_marker_set(&text, &file, model)
}

/// Parses marker-set text; see [`read_marker_set`].
pub fn parse_marker_set(text: &str, file_name: &str, model: &Model) -> Result<Vec<Marker>, OsimError> {
    let doc = parse_xml(text, file_name)?;
    let ctx = Ctx::new(&doc, file_name);
    let root = doc.root_element();
    let set = if root.has_tag_name("MarkerSet") { Some(root) } else { child(root, "MarkerSet") };
    let Some(set) = set else {
        return Err(ctx.err(root, "missing <MarkerSet>"));
    };
    let mut markers = Vec::new();
    for mk in child(set, "objects").into_iter().flat_map(elements).filter(|n| n.has_tag_name("Marker")) {
        let (name, body_name, offset, fixed) = marker_fields(&ctx, mk)?;
        let Some(body) = model.body_index(body_name) else {
            let valid: Vec<&str> = model.bodies.iter().map(|b| b.name.as_str()).collect();
            let msg = format!("marker '{name}' is on unknown body '{body_name}' (valid bodies: {})", valid.join(", "));
            return Err(ctx.err(mk, msg));
        };
        if markers.iter().any(|m: &Marker| m.name == name) {
            return Err(ctx.err(mk, format!("duplicate marker name '{name}'")));
        }
        markers.push(Marker {
            name: name.to_string(),
            body,
            offset,
            weight: 1.0,
            fixed: fixed.unwrap_or(false),
            class: class_of(fixed),
        });
    }
    Ok(markers)
}

/// Name, body name and location of a `<Marker>`.
pub(super) fn marker_fields<'a>(
    ctx: &Ctx<'a>,
    mk: Node<'a, 'a>,
) -> Result<(&'a str, &'a str, Vector3<f64>, Option<bool>), OsimError> {
    let Some(name) = mk.attribute("name") else {
        return Err(ctx.err(mk, "marker without a name"));
    };
    let frame = ctx.text(mk, "socket_parent_frame").or_else(|| ctx.text(mk, "body")).map(|(_, t)| last_segment(t));
    let Some(body) = frame.filter(|b| !b.is_empty()) else {
        return Err(ctx.err(mk, format!("marker '{name}' names no body (socket_parent_frame or body)")));
    };
    let offset = ctx.vec3(mk, "location")?.unwrap_or_default();
    let fixed = ctx.boolean(mk, "fixed")?;
    Ok((name, body, offset, fixed))
}

/// The registration class an OpenSim `<fixed>` flag gives (none when absent).
pub(super) fn class_of(fixed: Option<bool>) -> Option<crate::model::MarkerClass> {
    fixed.map(|f| if f { crate::model::MarkerClass::Anatomical } else { crate::model::MarkerClass::Tracking })
}
