//! The MCAP channels of a converted trial: topic, schema name (Foxglove's well-known names for
//! Foxglove's messages) and the protobuf descriptor set written as the schema's data, so that any
//! MCAP reader decodes every channel (`proto/` holds the `.proto` sources, `proto/descriptors/` the
//! descriptor sets generated from them by `scripts/gen_descriptors.sh`).

/// Serialized `google.protobuf.FileDescriptorSet` of `proto/foxglove/schemas.proto` (with the
/// `google/protobuf` files it imports).
pub const FOXGLOVE_DESCRIPTORS: &[u8] = include_bytes!("../../proto/descriptors/schemas.fds");
/// Serialized `google.protobuf.FileDescriptorSet` of `proto/smocap/smocap.proto`.
pub const SMOCAP_DESCRIPTORS: &[u8] = include_bytes!("../../proto/descriptors/smocap.fds");
/// Serialized `google.protobuf.FileDescriptorSet` of `proto/smocap/unfittable.proto` (a file of
/// its own: the other channels' schema data is unchanged by it).
pub const UNFITTABLE_DESCRIPTORS: &[u8] = include_bytes!("../../proto/descriptors/unfittable.fds");

/// One channel of a converted trial.
#[derive(Clone, Copy, Debug)]
pub struct ChannelSpec {
    pub topic: &'static str,
    /// Fully qualified protobuf message name (the MCAP schema name).
    pub schema: &'static str,
    /// The schema data (a descriptor set holding `schema`).
    pub descriptors: &'static [u8],
    /// Frame of reference of its geometry, where it has any.
    pub frame: &'static str,
    /// One message per frame (else one per trial, at the trial's first log time).
    pub per_frame: bool,
}

/// `/smocap/state`: each frame's coordinates (and scale proxies).
pub const STATE: ChannelSpec = ChannelSpec {
    topic: "/smocap/state",
    schema: "smocap.State",
    descriptors: SMOCAP_DESCRIPTORS,
    frame: "",
    per_frame: true,
};
/// `/smocap/stats`: each frame's solver statistics and marker RMSE.
pub const STATS: ChannelSpec = ChannelSpec {
    topic: "/smocap/stats",
    schema: "smocap.SolverStats",
    descriptors: SMOCAP_DESCRIPTORS,
    frame: "",
    per_frame: true,
};
/// `/tf`: the transform tree, each body in its parent body, rooted at Z-up `world`.
pub const TF: ChannelSpec = ChannelSpec {
    topic: "/tf",
    schema: "foxglove.FrameTransforms",
    descriptors: FOXGLOVE_DESCRIPTORS,
    frame: "world",
    per_frame: true,
};
/// `/markers`: each frame's observed markers, packed float32 x, y, z in the `model` frame.
pub const MARKERS: ChannelSpec = ChannelSpec {
    topic: "/markers",
    schema: "foxglove.PointCloud",
    descriptors: FOXGLOVE_DESCRIPTORS,
    frame: "model",
    per_frame: true,
};
/// `/scene`: the skeleton (bones, model marker spheres), one frame-locked entity per body, once.
pub const SCENE: ChannelSpec = ChannelSpec {
    topic: "/scene",
    schema: "foxglove.SceneUpdate",
    descriptors: FOXGLOVE_DESCRIPTORS,
    frame: "body frames",
    per_frame: false,
};
/// `/smocap/subject`: the names the other channels' arrays follow and the calibrated scales, once.
pub const SUBJECT: ChannelSpec = ChannelSpec {
    topic: "/smocap/subject",
    schema: "smocap.Subject",
    descriptors: SMOCAP_DESCRIPTORS,
    frame: "",
    per_frame: false,
};

/// `/smocap/label_qc`: the trial's label quality control (swaps repaired, jumps masked), once.
pub const LABEL_QC: ChannelSpec = ChannelSpec {
    topic: "/smocap/label_qc",
    schema: "smocap.LabelQc",
    descriptors: SMOCAP_DESCRIPTORS,
    frame: "",
    per_frame: false,
};

/// `/smocap/unfittable`: the trial's runs of unfittable frames (issue 32), once, at the last
/// frame's log time; added after the last frame, and only when the trial has such a run (a clean
/// trial's file is as before). Not in [`CHANNELS`].
pub const UNFITTABLE: ChannelSpec = ChannelSpec {
    topic: "/smocap/unfittable",
    schema: "smocap.Unfittable",
    descriptors: UNFITTABLE_DESCRIPTORS,
    frame: "",
    per_frame: false,
};

/// Every channel a file always has, in channel-id order.
pub const CHANNELS: [ChannelSpec; 7] = [STATE, STATS, TF, MARKERS, SCENE, SUBJECT, LABEL_QC];
