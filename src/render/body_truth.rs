//! The body's ground truth for `project`: the subject's body dressed on a take, and per frame its
//! surface keypoints (COCO-17 + feet, [`crate::body::keypoints`]) and virtual markers
//! ([`crate::body::virtual_markers`]), in the take's Z-up `world` (m).

use super::take::Take;
use crate::body::keypoints::SurfaceKeypoints;
use crate::body::virtual_markers::VirtualMarkers;
use crate::body::{BodyAsset, Dressed, FitSettings, PoseWorkspace, SubjectBody};
use nalgebra::Vector3;

/// A take's body and what `project` reads off it per frame.
pub struct BodyTruth {
    pub body: Dressed,
    pub keypoints: SurfaceKeypoints,
    pub virtual_markers: VirtualMarkers,
    ws: PoseWorkspace,
    y: Vec<f64>,
    /// Per frame, refilled by [`BodyTruth::at`].
    pub surface: Vec<[f64; 3]>,
    pub virtual_points: Vec<Vector3<f64>>,
}

impl BodyTruth {
    /// The body of `take`'s subject; `None`, with a note on stderr, where the mesh does not bind
    /// to the take's model (a dog, a model without a human's bodies).
    pub fn new(take: &Take, sub: &SubjectBody) -> Result<Option<BodyTruth>, crate::body::BodyError> {
        let asset = BodyAsset::shipped()?;
        let (body, line) = match take.dress(&asset, sub, &FitSettings::default()) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("note: {}: no body ground truth: the body mesh does not bind to this model ({e})", take.name);
                return Ok(None);
            }
        };
        eprintln!("{}: {line}", take.name);
        let virtual_markers = VirtualMarkers::new(&take.model, &body, &take.scales);
        Ok(Some(BodyTruth {
            keypoints: SurfaceKeypoints::new(&asset),
            virtual_markers,
            ws: PoseWorkspace::new(&take.model, &body),
            y: vec![0.0; take.model.ny()],
            body,
            surface: Vec::new(),
            virtual_points: Vec::new(),
        }))
    }

    /// Poses the body at frame `i` of `take`: [`Self::surface`] and [`Self::virtual_points`].
    pub fn at(&mut self, take: &Take, i: usize) {
        let nq = take.model.nq();
        self.y[..nq].copy_from_slice(&take.q[i][..nq]);
        self.y[nq..].copy_from_slice(&take.scales);
        self.body.pose(&take.model, &self.y, &mut self.ws);
        self.keypoints.evaluate(&self.ws.vertices, &mut self.surface);
        self.virtual_markers.evaluate(&self.ws.vertices, &mut self.virtual_points);
    }
}
