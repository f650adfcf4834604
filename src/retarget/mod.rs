//! Humanoid robots from the solved human motion (planned; `docs/ARCHITECTURE.md`, layer 6).
//!
//! This module is where retargeting lands: a robot's MJCF read with [`crate::io::mjcf`], a
//! mapping of the model's bodies to the robot's, and a per-frame QP over the robot's joints with
//! hard joint and velocity limits, foot contact and self-collision, warm-started frame to frame.
//! It may import `pipeline`, `archive` and everything below them, and is imported by `cli` only.
//! Nothing is implemented here yet: `smocap` has no `retarget` command.
