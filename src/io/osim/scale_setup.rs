//! OpenSim Scale tool setups (`<ScaleTool>`), read so that a lab's scaling choices carry over to
//! smocap's joint calibration:
//! - which bodies share scale factors, and along which axes: from the `MeasurementSet` (each
//!   measurement's `BodyScale`s and their `axes`) and the manual `ScaleSet` (bodies given the same
//!   factors form one group), in the `ModelScaler`'s order; bodies named nowhere keep scale 1;
//! - whether markers are placed on the static trial afterwards (`MarkerPlacer` `apply`) and with
//!   which per-marker weights the static pose is fitted (its `IKTaskSet`);
//! - the marker set file (`GenericModelMaker`), the static trial (`MarkerPlacer` `marker_file`)
//!   and the subject mass, for information.
//!
//! smocap estimates the factors of those groups from the markers (jointly with the pose), rather
//! than from marker-pair distances or manual values; the groups are what is kept. The measurements
//! themselves (marker pairs and the body axes they scale) and the manual factors are kept too, for
//! the stage-wise baseline of the leakage audit (`smocap audit`), which scales as OpenSim does.

use super::ik_setup::{read_task, IkSetup};
use super::xml::{child, elements, set_objects, Ctx};
use super::{parse_xml, OsimError};
use crate::model::profile::{ScaleAxes, ScaleGroup};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What smocap takes from a Scale tool setup.
#[derive(Clone, Debug, Default)]
pub struct ScaleSetup {
    /// Scale groups implied by the measurement and manual scale sets.
    pub scale_groups: Vec<ScaleGroup>,
    /// `MarkerPlacer` `apply`.
    pub place_markers: bool,
    /// Static-pose marker weights of the `MarkerPlacer` tasks (`apply` false → 0).
    pub static_weights: BTreeMap<String, f64>,
    /// The `MarkerPlacer`'s applied coordinate tasks: the static pose's known coordinate values
    /// (OpenSim solves the static pose toward them before placing markers).
    pub static_coordinate_tasks: Vec<super::ik_setup::IkCoordinateTask>,
    /// `GenericModelMaker` `marker_set_file`, resolved against the setup's folder.
    pub marker_set_file: Option<PathBuf>,
    /// `MarkerPlacer` `marker_file` (the static trial), resolved against the setup's folder.
    pub static_file: Option<PathBuf>,
    /// Subject mass (kg), when given (OpenSim's `-1` means not given).
    pub mass_kg: Option<f64>,
    /// Subject height (m), when given: OpenSim writes it in millimetres (`1803.4`); a value
    /// under 10 is taken as metres, `-1` as not given.
    pub height_m: Option<f64>,
    /// The applied measurements, in the `ModelScaler`'s order (empty when it does not apply).
    pub measurements: Vec<Measurement>,
    /// The applied manual scale factors `(body, [sx, sy, sz])`, in the `ModelScaler`'s order.
    pub manual_scales: Vec<(String, [f64; 3])>,
}

/// One `<Measurement>`: its factor is the mean over its marker pairs of (distance in the static
/// trial / distance on the unscaled model), applied to the listed body axes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Measurement {
    pub name: String,
    /// Marker name pairs.
    pub pairs: Vec<(String, String)>,
    /// Bodies scaled, with the axes (x, y, z) the factor applies to.
    pub bodies: Vec<(String, [bool; 3])>,
}

/// Reads a Scale tool setup file.
pub fn read_scale_setup(path: &Path) -> Result<ScaleSetup, OsimError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| OsimError::Io { file: file.clone(), source })?;
    parse_scale_setup(&text, &file, path.parent().unwrap_or(Path::new("")))
}

/// Parses Scale tool setup text; relative file names resolve against `base`.
pub fn parse_scale_setup(text: &str, file_name: &str, base: &Path) -> Result<ScaleSetup, OsimError> {
    let doc = parse_xml(text, file_name)?;
    let mut ctx = Ctx::new(&doc, file_name);
    let root = doc.root_element();
    let tool = if root.has_tag_name("ScaleTool") { Some(root) } else { child(root, "ScaleTool") };
    let Some(tool) = tool else {
        return Err(ctx.err(root, "missing <ScaleTool>: not an OpenSim Scale tool setup"));
    };
    let resolve = |t: &str| (!t.is_empty() && t != "Unassigned").then(|| base.join(t));
    let height = ctx.scalar(tool, "height")?.filter(|h| *h > 0.0).map(|h| if h > 10.0 { h / 1000.0 } else { h });
    let mass = ctx.scalar(tool, "mass")?.filter(|m| *m > 0.0);
    let mut out = ScaleSetup { mass_kg: mass, height_m: height, ..Default::default() };
    if let Some(maker) = child(tool, "GenericModelMaker") {
        out.marker_set_file = ctx.text(maker, "marker_set_file").and_then(|(_, t)| resolve(t));
    }
    if let Some(scaler) = child(tool, "ModelScaler").filter(|s| ctx.boolean(*s, "apply").ok().flatten() != Some(false))
    {
        (out.scale_groups, out.measurements, out.manual_scales) = scale_groups(&ctx, scaler)?;
    }
    if let Some(placer) = child(tool, "MarkerPlacer") {
        out.place_markers = ctx.boolean(placer, "apply")?.unwrap_or(true);
        out.static_file = ctx.text(placer, "marker_file").and_then(|(_, t)| resolve(t));
        let mut tasks = IkSetup::default();
        for task in set_objects(placer, "IKTaskSet") {
            read_task(&mut ctx, &doc, task, &mut tasks)?;
        }
        for t in tasks.marker_tasks {
            out.static_weights.insert(t.name, if t.apply { t.weight } else { 0.0 });
        }
        out.static_coordinate_tasks =
            tasks.coordinate_tasks.into_iter().filter(|t| t.apply && t.weight > 0.0).collect();
    }
    Ok(out)
}

/// Per body and axis, the source of its factor: a measurement name or a manual factor.
type AxisSources = BTreeMap<String, [Option<String>; 3]>;

/// The scaler's groups, measurements and manual factors.
type Scaler = (Vec<ScaleGroup>, Vec<Measurement>, Vec<(String, [f64; 3])>);

fn scale_groups(ctx: &Ctx<'_>, scaler: roxmltree::Node<'_, '_>) -> Result<Scaler, OsimError> {
    let mut measurements = Vec::new();
    let mut manual = Vec::new();
    let order = ctx.text(scaler, "scaling_order").map(|(_, t)| t.to_string()).unwrap_or_default();
    let mut sources: AxisSources = BTreeMap::new();
    let mut first_seen: Vec<String> = Vec::new();
    let mut set = |body: &str, axis: usize, source: String| {
        if !first_seen.iter().any(|b| b == body) {
            first_seen.push(body.to_string());
        }
        sources.entry(body.to_string()).or_default()[axis] = Some(source);
    };
    for step in order.split_whitespace() {
        match step {
            "measurements" => {
                let Some(ms) = child(scaler, "MeasurementSet") else { continue };
                for m in child(ms, "objects").into_iter().flat_map(elements).filter(|n| n.has_tag_name("Measurement")) {
                    if ctx.boolean(m, "apply")? == Some(false) {
                        continue;
                    }
                    let name = m.attribute("name").unwrap_or("measurement");
                    let mut meas = Measurement { name: name.into(), ..Default::default() };
                    for pair in set_objects(m, "MarkerPairSet").into_iter().filter(|n| n.has_tag_name("MarkerPair")) {
                        let names: Vec<&str> =
                            ctx.text(pair, "markers").map(|(_, t)| t.split_whitespace().collect()).unwrap_or_default();
                        match names[..] {
                            [a, b] => meas.pairs.push((a.into(), b.into())),
                            _ => return Err(ctx.err(pair, "MarkerPair needs exactly two marker names")),
                        }
                    }
                    for bs in set_objects(m, "BodyScaleSet").into_iter().filter(|n| n.has_tag_name("BodyScale")) {
                        let Some(body) = bs.attribute("name") else {
                            return Err(ctx.err(bs, "BodyScale without a body name"));
                        };
                        let axes = ctx.text(bs, "axes").map(|(_, t)| t).unwrap_or("X Y Z");
                        let mut on = [false; 3];
                        for a in axes.split_whitespace() {
                            let axis = match a {
                                "X" | "x" => 0,
                                "Y" | "y" => 1,
                                "Z" | "z" => 2,
                                other => return Err(ctx.err(bs, format!("axis '{other}': expected X, Y or Z"))),
                            };
                            set(body, axis, format!("measurement {name}"));
                            on[axis] = true;
                        }
                        meas.bodies.push((body.to_string(), on));
                    }
                    measurements.push(meas);
                }
            }
            "manualScale" => {
                for s in set_objects(scaler, "ScaleSet").into_iter().filter(|n| n.has_tag_name("Scale")) {
                    if ctx.boolean(s, "apply")? == Some(false) {
                        continue;
                    }
                    let Some((_, body)) = ctx.text(s, "segment") else {
                        return Err(ctx.err(s, "Scale without a <segment>"));
                    };
                    let f = ctx.fixed(s, "scales", 3, false)?.unwrap_or_else(|| vec![1.0; 3]);
                    for (axis, v) in f.iter().enumerate() {
                        set(body, axis, format!("manual {v}"));
                    }
                    manual.push((body.to_string(), [f[0], f[1], f[2]]));
                }
            }
            _ => {}
        }
    }
    // Bodies with identical sources on every axis share one group.
    let mut groups: Vec<(Vec<String>, [Option<String>; 3])> = Vec::new();
    for body in first_seen {
        let src = sources[&body].clone();
        match groups.iter_mut().find(|(_, s)| *s == src) {
            Some((bodies, _)) => bodies.push(body),
            None => groups.push((vec![body], src)),
        }
    }
    let groups = groups
        .into_iter()
        .map(|(bodies, src)| {
            let uniform = src[0].is_some() && src.iter().all(|s| *s == src[0]);
            ScaleGroup {
                name: bodies.join("+"),
                bodies,
                axes: if uniform { ScaleAxes::Uniform } else { ScaleAxes::Xyz },
                range: [0.5, 2.0],
            }
        })
        .collect();
    Ok((groups, measurements, manual))
}
