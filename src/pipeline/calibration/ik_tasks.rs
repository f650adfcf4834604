//! Applying an OpenSim IK setup's task set to a subject (OpenSim semantics, see
//! [`crate::io::osim::ik_setup`]): the marker tasks replace every marker weight (a marker without
//! an applied task gets weight 0, as OpenSim ignores it), and applied coordinate tasks become soft
//! coordinate targets `½·w·(q − target)²` in each frame's objective, on the same footing as the
//! marker terms `½·w_m·‖x̂ − x‖²` (OpenSim's objective without the common factor ½).

use crate::pipeline::context::Context;

use crate::io::osim::ik_setup::{CoordinateValue, IkSetup};
use crate::pipeline::context::ContextError;

/// What applying an IK setup did, for the user.
#[derive(Clone, Debug, Default)]
pub struct IkApplied {
    /// Markers with weight > 0.
    pub markers_weighted: usize,
    /// Model markers without any task (weight 0, as in OpenSim).
    pub markers_without_task: Vec<String>,
    /// Coordinate targets set.
    pub coordinate_targets: usize,
    /// Tasks naming markers or coordinates the model lacks, and inert tasks.
    pub warnings: Vec<String>,
}

impl Context {
    /// Applies `setup`'s tasks to this context (replacing the profile's marker weights).
    /// Errors on an applied coordinate task with `value_type` `from_file` (not supported).
    pub fn apply_ik_setup(&mut self, setup: &IkSetup) -> Result<IkApplied, ContextError> {
        let mut out = IkApplied::default();
        let err =
            |line: u32, message: String| ContextError::Settings { path: format!("{}:{line}", setup.file), message };
        let mut weights = vec![0.0; self.model.markers.len()];
        let mut tasked = vec![false; self.model.markers.len()];
        for t in &setup.marker_tasks {
            match self.model.marker_index(&t.name) {
                Some(m) => {
                    tasked[m] = true;
                    weights[m] = if t.apply { t.weight } else { 0.0 };
                }
                None => out.warnings.push(format!(
                    "{}:{}: IK marker task '{}' names a marker the model lacks; ignored",
                    setup.file, t.line, t.name
                )),
            }
        }
        let nq = self.model.nq();
        let (mut cw, mut ct) = (vec![0.0; nq], vec![0.0; nq]);
        for t in setup.coordinate_tasks.iter().filter(|t| t.apply) {
            let Some(j) = self.model.coordinate_index(&t.name) else {
                out.warnings.push(format!(
                    "{}:{}: IK coordinate task '{}' names a coordinate the model lacks; ignored",
                    setup.file, t.line, t.name
                ));
                continue;
            };
            let target = match t.value {
                CoordinateValue::Default => self.model.coordinates[j].default,
                CoordinateValue::Manual(v) => v,
                CoordinateValue::FromFile => {
                    return Err(err(
                        t.line,
                        format!(
                            "coordinate task '{}': value_type from_file is not supported; use manual_value or \
                             default_value, or set apply to false",
                            t.name
                        ),
                    ))
                }
            };
            if t.weight == 0.0 {
                continue;
            }
            if self.proxy.y_terms[j].is_empty() {
                out.warnings.push(format!(
                    "{}:{}: IK coordinate task '{}' has no effect: the coordinate is locked or fixed",
                    setup.file, t.line, t.name
                ));
                continue;
            }
            cw[j] = t.weight;
            ct[j] = target;
            out.coordinate_targets += 1;
        }
        out.markers_weighted = weights.iter().filter(|&&w| w > 0.0).count();
        out.markers_without_task =
            self.model.markers.iter().zip(&tasked).filter(|(_, t)| !**t).map(|(m, _)| m.name.clone()).collect();
        self.marker_weights = weights;
        self.coordinate_weights = cw;
        self.coordinate_targets = ct;
        Ok(out)
    }
}
