//! OpenSim Inverse Kinematics setup files (`<InverseKinematicsTool>`, any format version): the
//! task set that weights markers and holds coordinates, plus the tool's informational settings.
//!
//! OpenSim semantics (`InverseKinematicsTool::populateReferences`): only markers with an applied
//! `IKMarkerTask` are tracked, with its weight; markers without a task are ignored. An applied
//! `IKCoordinateTask` adds `weight·(q − value)²` to the objective, where `value` is the
//! coordinate's default (`default_value`), the task's `value` (`manual_value`), or a curve read
//! from `coordinate_file` (`from_file`). Task defaults (`IKTask`): `apply` true, `weight` 0;
//! `value_type` `default_value`, `value` 0.

use super::xml::{child, elements, Ctx};
use super::{parse_xml, OsimError};
use roxmltree::Node;
use std::path::Path;

/// A marker task: weight of the squared distance between a model marker and its observation.
#[derive(Clone, Debug, PartialEq)]
pub struct IkMarkerTask {
    pub name: String,
    pub apply: bool,
    pub weight: f64,
    /// Line of the task in the setup file (1-based).
    pub line: u32,
}

/// Where a coordinate task takes its target value from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CoordinateValue {
    /// The coordinate's default value in the model.
    Default,
    /// This value (rad or m, as the model's coordinate).
    Manual(f64),
    /// A curve from the tool's `coordinate_file`.
    FromFile,
}

/// A coordinate task: `weight·(q − target)²` added to each frame's objective.
#[derive(Clone, Debug, PartialEq)]
pub struct IkCoordinateTask {
    pub name: String,
    pub apply: bool,
    pub weight: f64,
    pub value: CoordinateValue,
    /// Line of the task in the setup file (1-based).
    pub line: u32,
}

/// An `<InverseKinematicsTool>` setup. File names are as written (relative to the setup file).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IkSetup {
    /// Where the setup came from (for messages).
    pub file: String,
    /// The tool's `name` attribute.
    pub name: Option<String>,
    pub marker_tasks: Vec<IkMarkerTask>,
    pub coordinate_tasks: Vec<IkCoordinateTask>,
    /// Informational: the tool's accuracy, time range (s) and files; smocap does not act on them.
    pub accuracy: Option<f64>,
    pub time_range: Option<(f64, f64)>,
    pub marker_file: Option<String>,
    pub model_file: Option<String>,
    pub coordinate_file: Option<String>,
    /// Task types and set features that were skipped.
    pub warnings: Vec<String>,
}

/// Reads an IK setup file.
pub fn read_ik_setup(path: &Path) -> Result<IkSetup, OsimError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| OsimError::Io { file: file.clone(), source })?;
    parse_ik_setup(&text, &file)
}

/// Parses IK setup text; `file_name` is used in messages.
pub fn parse_ik_setup(text: &str, file_name: &str) -> Result<IkSetup, OsimError> {
    let doc = parse_xml(text, file_name)?;
    let mut ctx = Ctx::new(&doc, file_name);
    let root = doc.root_element();
    let tool =
        if root.has_tag_name("InverseKinematicsTool") { Some(root) } else { child(root, "InverseKinematicsTool") };
    let Some(tool) = tool else {
        return Err(ctx.err(root, "missing <InverseKinematicsTool>"));
    };
    let file_text =
        |tag: &str| ctx.text(tool, tag).map(|(_, t)| t.to_string()).filter(|t| !t.is_empty() && t != "Unassigned");
    let mut setup = IkSetup {
        file: file_name.to_string(),
        name: tool.attribute("name").map(str::to_string),
        marker_file: file_text("marker_file"),
        model_file: file_text("model_file"),
        coordinate_file: file_text("coordinate_file"),
        accuracy: ctx.scalar(tool, "accuracy")?,
        time_range: ctx.fixed(tool, "time_range", 2, true)?.map(|v| (v[0], v[1])),
        ..IkSetup::default()
    };
    if let Some(set) = child(tool, "IKTaskSet") {
        if set.attribute("file").is_some_and(|f| !f.trim().is_empty()) {
            return Err(ctx.err(set, "a task set in a separate file (file=\"…\") is not supported; inline its tasks"));
        }
        for task in child(set, "objects").into_iter().flat_map(elements) {
            read_task(&mut ctx, &doc, task, &mut setup)?;
        }
    }
    setup.warnings = std::mem::take(&mut ctx.warnings);
    Ok(setup)
}

/// Reads one `IKMarkerTask` / `IKCoordinateTask` into `setup` (also used for the tasks of a Scale
/// setup's `MarkerPlacer`).
pub(super) fn read_task<'a>(
    ctx: &mut Ctx<'a>,
    doc: &roxmltree::Document,
    task: Node<'a, 'a>,
    setup: &mut IkSetup,
) -> Result<(), OsimError> {
    let kind = task.tag_name().name();
    if kind != "IKMarkerTask" && kind != "IKCoordinateTask" {
        ctx.warn(task, "unknown task type skipped (expected IKMarkerTask or IKCoordinateTask)");
        return Ok(());
    }
    let Some(name) = task.attribute("name").map(str::trim).filter(|n| !n.is_empty()) else {
        return Err(ctx.err(task, "task without a name"));
    };
    let duplicate = if kind == "IKMarkerTask" {
        setup.marker_tasks.iter().any(|t| t.name == name)
    } else {
        setup.coordinate_tasks.iter().any(|t| t.name == name)
    };
    if duplicate {
        return Err(ctx.err(task, format!("duplicate {kind} '{name}'")));
    }
    let apply = ctx.boolean(task, "apply")?.unwrap_or(true);
    let weight = ctx.scalar(task, "weight")?.unwrap_or(0.0);
    if weight < 0.0 {
        let node = child(task, "weight").unwrap_or(task);
        return Err(ctx.err(node, format!("weight {weight} is negative")));
    }
    let line = doc.text_pos_at(task.range().start).row;
    if kind == "IKMarkerTask" {
        setup.marker_tasks.push(IkMarkerTask { name: name.to_string(), apply, weight, line });
        return Ok(());
    }
    let value = match ctx.text(task, "value_type") {
        None => CoordinateValue::Default,
        Some((_, "default_value")) => CoordinateValue::Default,
        Some((_, "manual_value")) => CoordinateValue::Manual(ctx.scalar(task, "value")?.unwrap_or(0.0)),
        Some((_, "from_file")) => CoordinateValue::FromFile,
        Some((node, other)) => {
            return Err(ctx.err(node, format!("'{other}': expected one of default_value, manual_value, from_file")))
        }
    };
    setup.coordinate_tasks.push(IkCoordinateTask { name: name.to_string(), apply, weight, value, line });
    Ok(())
}
