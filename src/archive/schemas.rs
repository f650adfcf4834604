//! JSON Schemas of the MCAP channels. Ours describe the messages fully; Foxglove's well-known
//! `foxglove.FrameTransforms` and `foxglove.SceneUpdate` are described for the fields smocap
//! writes (the schema name is what Foxglove recognises; field names follow its message reference).

use serde_json::{json, Value};

fn num(description: &str) -> Value {
    json!({"type": "number", "description": description})
}

fn time() -> Value {
    num("Frame time (s) since the trial's first sample")
}

fn vec3() -> Value {
    json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
        "required": ["x", "y", "z"]})
}

fn quat() -> Value {
    json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"},
        "z": {"type": "number"}, "w": {"type": "number"}}, "required": ["x", "y", "z", "w"]})
}

fn stamp() -> Value {
    json!({"type": "object", "title": "time", "properties": {"sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}})
}

fn color() -> Value {
    json!({"type": "object", "title": "foxglove.Color", "properties": {"r": {"type": "number"}, "g": {"type": "number"},
        "b": {"type": "number"}, "a": {"type": "number"}}})
}

fn point3() -> Value {
    json!({"type": ["array", "null"], "items": {"type": "number"}, "minItems": 3, "maxItems": 3})
}

/// `smocap.State`: coordinates, per-body scales and proxies of one frame.
pub fn state() -> Value {
    json!({"title": "smocap.State", "type": "object", "properties": {
        "time": time(), "frame": {"type": "integer", "description": "Frame index in the trial (0-based)"},
        "q": {"type": "object", "additionalProperties": {"type": "number"}, "description": "Coordinates by name (rad or m)"},
        "s": {"type": "object", "additionalProperties": {"type": "array", "items": {"type": "number"}},
            "description": "Per-body scale factors [sx, sy, sz] by body name"},
        "p": {"type": "object", "additionalProperties": {"type": "number"}, "description": "Solver proxies by name"}},
        "required": ["time", "frame", "q", "s", "p"]})
}

/// `smocap.Residuals`: observed and model marker positions (m, world) and their difference.
pub fn residuals() -> Value {
    json!({"title": "smocap.Residuals", "type": "object", "properties": {
        "time": time(), "frame": {"type": "integer"},
        "rmse": {"type": ["number", "null"], "description": "RMS marker error over observed markers (m)"},
        "markers": {"type": "array", "items": {"type": "object", "properties": {
            "name": {"type": "string"}, "observed": point3(), "model": point3(),
            "error": {"description": "observed − model (m); null when not observed", "type": ["array", "null"]}},
            "required": ["name", "observed", "model", "error"]}}},
        "required": ["time", "frame", "rmse", "markers"]})
}

/// `smocap.SolverStats`: how the frame's solve went.
pub fn stats() -> Value {
    json!({"title": "smocap.SolverStats", "type": "object", "properties": {
        "time": time(), "frame": {"type": "integer"},
        "iterations": {"type": "integer"}, "accepted_steps": {"type": "integer"},
        "energy": {"type": ["number", "null"], "description": "Objective at the solution"},
        "rmse": {"type": ["number", "null"], "description": "Weighted marker RMSE (m)"},
        "markers_used": {"type": "integer"}, "solve_s": num("Solve time (s)"),
        "status": {"type": "string", "enum": ["Converged", "MaxIterations", "TooFewMarkers", "QpFailed", "Stalled"]},
        "bridged": {"type": "boolean", "description": "Interpolated from neighbours (too few markers)"}},
        "required": ["time", "frame", "iterations", "accepted_steps", "energy", "rmse", "status"]})
}

/// `foxglove.FrameTransforms`.
pub fn frame_transforms() -> Value {
    json!({"title": "foxglove.FrameTransforms", "type": "object", "properties": {
        "transforms": {"type": "array", "items": {"title": "foxglove.FrameTransform", "type": "object", "properties": {
            "timestamp": stamp(), "parent_frame_id": {"type": "string"}, "child_frame_id": {"type": "string"},
            "translation": vec3(), "rotation": quat()}}}}})
}

/// `foxglove.SceneUpdate` (spheres and lines; the other primitive lists are written empty).
pub fn scene_update() -> Value {
    let pose =
        json!({"title": "foxglove.Pose", "type": "object", "properties": {"position": vec3(), "orientation": quat()}});
    let empty = json!({"type": "array"});
    json!({"title": "foxglove.SceneUpdate", "type": "object", "properties": {
        "deletions": empty,
        "entities": {"type": "array", "items": {"title": "foxglove.SceneEntity", "type": "object", "properties": {
            "timestamp": stamp(), "frame_id": {"type": "string"}, "id": {"type": "string"},
            "lifetime": stamp(), "frame_locked": {"type": "boolean"}, "metadata": empty,
            "arrows": empty, "cubes": empty, "cylinders": empty, "triangles": empty, "texts": empty, "models": empty,
            "spheres": {"type": "array", "items": {"title": "foxglove.SpherePrimitive", "type": "object",
                "properties": {"pose": pose, "size": vec3(), "color": color()}}},
            "lines": {"type": "array", "items": {"title": "foxglove.LinePrimitive", "type": "object", "properties": {
                "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
                "pose": pose, "thickness": {"type": "number"}, "scale_invariant": {"type": "boolean"},
                "points": {"type": "array", "items": vec3()}, "color": color(), "colors": empty, "indices": empty}}}}}}}})
}
