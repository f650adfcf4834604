//! Choosing the evaluation backend (`--backend cpu|wgpu|wgpu-f64|auto`).
//!
//! `auto` takes wgpu only on a real GPU (discrete or integrated): a CPU adapter such as
//! lavapipe runs the shaders slower than the CPU backend, so `auto` falls back to the CPU and
//! says why. `wgpu` takes whatever adapter exists and fails clearly when there is none.

use crate::kinematics::assembly::Evaluator;
use crate::kinematics::backend::{BackendError, BatchBackend};
use crate::kinematics::gpu::{self, WgpuBackend};

/// The backend asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BackendChoice {
    /// The f64 CPU reference on rayon's pool.
    Cpu,
    /// wgpu compute shaders (f32) on the best adapter found, CPU adapters included.
    Wgpu,
    /// wgpu compute shaders in f64, on the best adapter offering `SHADER_F64` (agrees with the
    /// CPU reference to ~1e-12; slow on consumer GPUs, whose f64 rate is 1/32–1/64 of f32).
    WgpuF64,
    /// wgpu on a real GPU, else the CPU backend.
    #[default]
    Auto,
}

/// The backend chosen, with why.
pub enum Chosen {
    Cpu {
        /// Why `auto` did not take wgpu (None when the CPU was asked for).
        note: Option<String>,
    },
    Wgpu(Box<WgpuBackend>),
}

impl Chosen {
    /// "cpu" or "wgpu".
    pub fn name(&self) -> &'static str {
        match self {
            Chosen::Cpu { .. } => "cpu",
            Chosen::Wgpu(_) => "wgpu",
        }
    }

    /// Device description for run metadata.
    pub fn device(&self) -> String {
        match self {
            Chosen::Cpu { .. } => "cpu, f64".into(),
            Chosen::Wgpu(b) => b.device(),
        }
    }

    /// The note explaining a fallback, if any.
    pub fn note(&self) -> Option<&str> {
        match self {
            Chosen::Cpu { note } => note.as_deref(),
            Chosen::Wgpu(_) => None,
        }
    }

    /// Lanes of the scheduler when none are asked for: one per thread on the CPU, 4096 on wgpu
    /// (enough segments in flight to fill a device batch).
    pub fn default_lanes(&self, threads: usize) -> usize {
        match self {
            Chosen::Cpu { .. } => threads,
            Chosen::Wgpu(_) => 4096,
        }
    }

    /// The batch backend to pass to the trial driver (None: the driver's own CPU backend).
    pub fn backend(&mut self) -> Option<&mut (dyn BatchBackend + 'static)> {
        match self {
            Chosen::Cpu { .. } => None,
            Chosen::Wgpu(b) => Some(b.as_mut()),
        }
    }
}

/// Picks the backend for `eval`'s model, with at most `cap` frames per wgpu dispatch. Errors only
/// for `wgpu` without a usable adapter.
pub fn choose(choice: BackendChoice, eval: &Evaluator<'_>, cap: usize) -> Result<Chosen, BackendError> {
    choose_with(choice, eval, cap, gpu::Kernel::default())
}

/// As [`choose`], with the given shader [`gpu::Kernel`] where wgpu is chosen.
pub fn choose_with(
    choice: BackendChoice,
    eval: &Evaluator<'_>,
    cap: usize,
    kernel: gpu::Kernel,
) -> Result<Chosen, BackendError> {
    use gpu::Precision::{F32, F64};
    match choice {
        BackendChoice::Cpu => Ok(Chosen::Cpu { note: None }),
        BackendChoice::Wgpu => Ok(Chosen::Wgpu(Box::new(WgpuBackend::with_options(eval, cap, F32, kernel)?))),
        BackendChoice::WgpuF64 => Ok(Chosen::Wgpu(Box::new(WgpuBackend::with_options(eval, cap, F64, kernel)?))),
        BackendChoice::Auto => {
            let adapters = gpu::list_adapters();
            if let Some(note) = auto_stays_on_cpu(&adapters) {
                return Ok(Chosen::Cpu { note: Some(note) });
            }
            let best = &adapters[0];
            match WgpuBackend::with_options(eval, cap, F32, kernel) {
                Ok(b) => Ok(Chosen::Wgpu(Box::new(b))),
                Err(e) => Ok(Chosen::Cpu {
                    note: Some(format!("backend auto: {best} could not be used ({e}); using the CPU backend")),
                }),
            }
        }
    }
}

/// Why `auto` takes the CPU backend with these adapters (best first): none, or the best is not
/// a real GPU. `None` when `auto` tries wgpu.
fn auto_stays_on_cpu(adapters: &[gpu::AdapterSummary]) -> Option<String> {
    let Some(best) = adapters.first() else {
        return Some(format!(
            "backend auto: no wgpu adapter found on {}; using the CPU backend",
            gpu::searched_backends()
        ));
    };
    (!best.real_gpu).then(|| {
        format!(
            "backend auto: the best wgpu adapter, {best}, is not a real GPU (a CPU adapter such as lavapipe is \
             slower than the CPU backend); using the CPU backend"
        )
    })
}

/// The choice settled before any work, for a command that builds one backend per subject
/// (`smocap convert`): `auto` becomes `cpu` (with the note saying why) where it would not take
/// wgpu, and `wgpu`/`wgpu-f64` without any adapter is an error, so that a run does not find out
/// subject by subject. (Whether an adapter offers `SHADER_F64`, or a device can be created, is
/// found when the backend is built.)
pub fn settle(choice: BackendChoice) -> Result<(BackendChoice, Option<String>), BackendError> {
    match choice {
        BackendChoice::Cpu => Ok((choice, None)),
        BackendChoice::Wgpu | BackendChoice::WgpuF64 => {
            if gpu::list_adapters().is_empty() {
                Err(BackendError::NoAdapter(format!("none found on {}", gpu::searched_backends())))
            } else {
                Ok((choice, None))
            }
        }
        BackendChoice::Auto => match auto_stays_on_cpu(&gpu::list_adapters()) {
            Some(note) => Ok((BackendChoice::Cpu, Some(note))),
            None => Ok((choice, None)),
        },
    }
}
