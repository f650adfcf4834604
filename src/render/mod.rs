//! Canonical motion into rendering pipelines: the solved subject and its motion as an animated
//! glTF scene ([`scene`]), camera rigs and pinhole projection in the OpenCV convention
//! ([`rig`]), 2D/3D ground truth per camera and frame with the thesis' marker metrics
//! ([`project`]), and a contact sheet of the projected skeleton ([`preview`]).
//!
//! Input is a [`take::Take`]: a converted MCAP file read back, or a trial `solve` just solved;
//! everything is placed in the Z-up `world` of the MCAP `/tf` tree (metres, seconds).

pub mod backdrop;
pub mod body_truth;
pub mod coco;
pub mod look;
pub mod png_out;
pub mod preview;
pub mod project;
pub mod raster;
pub mod rig;
pub mod scene;
pub mod take;
pub mod video;
pub mod video_out;
pub mod visibility;

pub use rig::{Camera, SubjectFrame};
pub use take::{Pose, Take};

/// Errors rendering, projecting or reading a rig.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("{file}: {source}")]
    Io { file: String, source: std::io::Error },
    #[error("{file}: {what}")]
    Content { file: String, what: String },
    #[error("camera rig {file}: {what}")]
    Rig { file: String, what: String },
    #[error(transparent)]
    Record(#[from] crate::archive::export::ExportError),
    #[error(transparent)]
    Gltf(#[from] crate::io::gltf::GltfError),
    #[error("{file}: {what}")]
    Image { file: String, what: String },
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    #[error("binding the body mesh to the trial's model: {0}")]
    Bind(#[from] crate::body::BindError),
    #[error(transparent)]
    Body(#[from] crate::body::BodyError),
}

/// The subject frame of a take (for default rigs and rigs in subject coordinates): from its
/// root body's `world` positions and headings over all frames.
pub fn subject_frame(take: &Take) -> SubjectFrame {
    let Some(root) = take.model.bodies.iter().position(|b| b.parent.is_none()) else {
        return SubjectFrame::world();
    };
    let mut ws = crate::kinematics::Workspace::new(&take.model);
    let (mut pos, mut x) = (Vec::new(), Vec::new());
    for i in 0..take.len() {
        let p = take.pose(i, &mut ws);
        pos.push(p.body_pos[root]);
        x.push(p.body_rot[root].column(0).into_owned());
    }
    SubjectFrame::from_root(&pos, &x)
}

/// The cameras of `rig` (a rig file) or, without one, the default rig ([`rig::default_rig`])
/// placed around `take` with `seed`.
pub fn cameras(take: &Take, rig: Option<&std::path::Path>, seed: u64) -> Result<Vec<Camera>, RenderError> {
    let frame = subject_frame(take);
    match rig {
        Some(path) => rig::read_rig(path, &frame),
        None => Ok(rig::default_rig(&frame, seed)),
    }
}

/// Writes `bytes` to `path`, creating its folder.
pub(crate) fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<(), RenderError> {
    let io = |source| RenderError::Io { file: path.display().to_string(), source };
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(io)?;
    }
    std::fs::write(path, bytes).map_err(io)
}
