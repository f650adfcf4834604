//! Which way is up in a model file: the opposite of its gravity. OpenSim `.osim`:
//! `<Model><gravity>` (OpenSim's default is −Y); MJCF: `<option gravity>` (MuJoCo's default is
//! `0 0 −9.81`, so Z up).

use nalgebra::Vector3;

/// The model's up direction (unit vector in the model's world frame) from the model file's
/// text, or `None` when the file cannot be parsed or its gravity is zero or malformed.
pub fn model_up(text: &str, is_osim: bool) -> Option<Vector3<f64>> {
    let doc = roxmltree::Document::parse(text).ok()?;
    let root = doc.root_element();
    let g = if is_osim {
        let model = root.children().find(|n| n.has_tag_name("Model"))?;
        match model.children().find(|n| n.has_tag_name("gravity")) {
            Some(g) => parse3(g.text().unwrap_or(""))?,
            None => Vector3::new(0.0, -9.80665, 0.0),
        }
    } else {
        let option = root.children().filter(|n| n.has_tag_name("option")).find_map(|o| o.attribute("gravity"));
        match option {
            Some(g) => parse3(g)?,
            None => Vector3::new(0.0, 0.0, -9.81),
        }
    };
    let n = g.norm();
    (n > 0.0 && n.is_finite()).then(|| -g / n)
}

fn parse3(text: &str) -> Option<Vector3<f64>> {
    let v: Vec<f64> = text.split_whitespace().map(|t| t.parse::<f64>().ok()).collect::<Option<_>>()?;
    (v.len() == 3).then(|| Vector3::new(v[0], v[1], v[2]))
}
