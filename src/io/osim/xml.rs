//! XML helpers for the OpenSim reader: child lookup, numbers, booleans, and located errors.

use super::OsimError;
use nalgebra::Vector3;
use roxmltree::{Document, Node};

/// Parsing context: the document (for line numbers), the file name and the warnings.
pub(super) struct Ctx<'a> {
    doc: &'a Document<'a>,
    pub file: &'a str,
    pub warnings: Vec<String>,
}

impl<'a> Ctx<'a> {
    pub fn new(doc: &'a Document<'a>, file: &'a str) -> Ctx<'a> {
        Ctx { doc, file, warnings: Vec::new() }
    }

    /// Error located at `node`'s start tag.
    pub fn err(&self, node: Node, message: impl Into<String>) -> OsimError {
        let p = self.doc.text_pos_at(node.range().start);
        let element = match node.attribute("name") {
            Some(n) => format!("{} name=\"{n}\"", node.tag_name().name()),
            None => node.tag_name().name().to_string(),
        };
        OsimError::Element { file: self.file.to_string(), line: p.row, column: p.col, element, message: message.into() }
    }

    pub fn warn(&mut self, node: Node, message: &str) {
        let p = self.doc.text_pos_at(node.range().start);
        self.warnings.push(format!("{}:{}: <{}>: {message}", self.file, p.row, node.tag_name().name()));
    }

    /// Text of the first child element `tag`, trimmed.
    pub fn text(&self, node: Node<'a, 'a>, tag: &str) -> Option<(Node<'a, 'a>, &'a str)> {
        child(node, tag).map(|c| (c, c.text().unwrap_or("").trim()))
    }

    /// Numbers of child `tag` (any count); non-finite numbers are rejected unless `allow_inf`.
    pub fn nums(&self, node: Node<'a, 'a>, tag: &str, allow_inf: bool) -> Result<Option<Vec<f64>>, OsimError> {
        let Some((c, t)) = self.text(node, tag) else {
            return Ok(None);
        };
        parse_numbers(t, allow_inf).map(Some).ok_or_else(|| self.err(c, format!("'{}': expected numbers", truncate(t))))
    }

    /// Exactly `n` numbers of child `tag`.
    pub fn fixed(
        &self,
        node: Node<'a, 'a>,
        tag: &str,
        n: usize,
        allow_inf: bool,
    ) -> Result<Option<Vec<f64>>, OsimError> {
        match self.nums(node, tag, allow_inf)? {
            Some(v) if v.len() != n => {
                let c = child(node, tag).unwrap_or(node);
                Err(self.err(c, format!("expected {n} numbers, found {}", v.len())))
            }
            v => Ok(v),
        }
    }

    pub fn vec3(&self, node: Node<'a, 'a>, tag: &str) -> Result<Option<Vector3<f64>>, OsimError> {
        Ok(self.fixed(node, tag, 3, false)?.map(|v| Vector3::new(v[0], v[1], v[2])))
    }

    pub fn scalar(&self, node: Node<'a, 'a>, tag: &str) -> Result<Option<f64>, OsimError> {
        Ok(self.fixed(node, tag, 1, false)?.map(|v| v[0]))
    }

    pub fn boolean(&self, node: Node<'a, 'a>, tag: &str) -> Result<Option<bool>, OsimError> {
        match self.text(node, tag) {
            None => Ok(None),
            Some((_, t)) if t.eq_ignore_ascii_case("true") => Ok(Some(true)),
            Some((_, t)) if t.eq_ignore_ascii_case("false") => Ok(Some(false)),
            Some((c, t)) => Err(self.err(c, format!("'{}': expected one of true, false", truncate(t)))),
        }
    }
}

/// First child element named `tag`.
pub(super) fn child<'a>(node: Node<'a, 'a>, tag: &str) -> Option<Node<'a, 'a>> {
    node.children().find(|c| c.is_element() && c.has_tag_name(tag))
}

/// Child elements of `<tag><objects>…</objects></tag>` (an OpenSim `Set`), empty when absent.
pub(super) fn set_objects<'a>(node: Node<'a, 'a>, tag: &str) -> Vec<Node<'a, 'a>> {
    child(node, tag).and_then(|s| child(s, "objects")).map_or_else(Vec::new, |o| elements(o).collect())
}

pub(super) fn elements<'a>(node: Node<'a, 'a>) -> impl Iterator<Item = Node<'a, 'a>> {
    node.children().filter(Node::is_element)
}

/// Whitespace-separated numbers; `None` if any is unparsable, NaN, or infinite (unless `allow_inf`).
pub(super) fn parse_numbers(text: &str, allow_inf: bool) -> Option<Vec<f64>> {
    text.split_whitespace()
        .map(|t| t.parse::<f64>().ok().filter(|v| v.is_finite() || (allow_inf && !v.is_nan())))
        .collect()
}

/// The last segment of an OpenSim component path (`/bodyset/pelvis` → `pelvis`).
pub(super) fn last_segment(path: &str) -> &str {
    path.trim().rsplit('/').next().unwrap_or("")
}

fn truncate(t: &str) -> String {
    if t.chars().count() > 40 {
        format!("{}…", t.chars().take(40).collect::<String>())
    } else {
        t.to_string()
    }
}
