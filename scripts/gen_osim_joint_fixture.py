#!/usr/bin/env python3
"""Joint-type fixture for tests/io_osim_joints.rs, computed by OpenSim itself.

Builds, with OpenSim's own API, a small model whose tree uses every joint type the importer
supports (FreeJoint, CustomJoint, PinJoint, UniversalJoint, SliderJoint, BallJoint,
GimbalJoint, WeldJoint), each with parent and child offset frames that are both translated and
rotated; CustomJoints with SimmSpline / LinearFunction / Constant translations (axes along +x,
-y, +z and one oblique axis), oblique rotation axes, and a coordinate driven by a
CoordinateCouplerConstraint; two markers per body. The random states reach beyond every
SimmSpline's knots (linear extrapolation). Then:

- tests/data/osim_joints.osim: the model as OpenSim prints it;
- tests/data/osim_joints_scaled.osim: the same after `Model.scale` with SCALES below;
- tests/data/osim_joints_expected.json: for 20 seeded random coordinate states (radians and
  metres, set with `Coordinate.setValue`; the coupled coordinate set to its constraint value),
  OpenSim's world positions of every marker (`Marker.getLocationInGround`) and body origin, and
  every body rotation (`Body.getTransformInGround`, row-major), for the unscaled model
  ("unscaled") and for the scaled one ("scaled", the first 10 states), plus the scale factors.
  Numbers are written with 15 significant digits; XML comments are stripped from the models.

Regenerate (OpenSim 4.6 Python package; numpy comes with it), from the repository root:

    python scripts/gen_osim_joint_fixture.py

The output is deterministic for a given OpenSim version (seeded states, printed with repr).
"""

import json
import math
import os
import re

import numpy as np
import opensim as osim

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data")
SEED = 20240611
N_STATES = 20
N_SCALED = 10  # the scaled set uses the first N_SCALED states

# Per-body scale factors for the scaled set (non-uniform on every body).
SCALES = {
    "pelvis": (1.10, 0.90, 1.20),
    "thigh": (0.85, 1.15, 1.05),
    "shank": (1.20, 0.95, 0.80),
    "foot": (0.90, 1.30, 1.10),
    "toes": (1.05, 0.75, 1.25),
    "torso": (0.95, 1.10, 0.85),
    "head": (1.30, 1.20, 0.90),
    "arm": (0.80, 1.25, 1.15),
    "forearm": (1.15, 0.85, 0.95),
    "hand": (0.70, 1.10, 1.30),
}


def v3(x, y, z):
    return osim.Vec3(x, y, z)


def unit(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    return v3(x / n, y / n, z / n)


def simm_spline(xs, ys):
    f = osim.SimmSpline()
    for x, y in zip(xs, ys):
        f.addPoint(x, y)
    return f


def axis(st, i, coords, direction, func):
    """Sets TransformAxis i of SpatialTransform st (0-2 rotations, 3-5 translations)."""
    ta = st.updTransformAxis(i)
    names = osim.ArrayStr()
    for c in coords:
        names.append(c)
    ta.setCoordinateNames(names)
    ta.setAxis(direction)
    ta.setFunction(func)
    func.thisown = False  # the TransformAxis adopts the function


def build():
    model = osim.Model()
    model.setName("osim_joints")
    ground = model.getGround()
    bodies = {}
    for k, name in enumerate(SCALES):
        b = osim.Body(name, 1.0 + 0.1 * k, v3(0.01, -0.02, 0.005), osim.Inertia(0.1, 0.12, 0.09))
        model.addBody(b)
        bodies[name] = b

    # Each joint: parent and child offset frames with translation and orientation (body-fixed XYZ).
    def frames(k):
        s = 0.1 * (k + 1)
        return (
            v3(0.03 * s + 0.02, -0.15 - 0.1 * s, 0.04 - 0.02 * s),
            v3(0.3 * s, -0.2 + 0.1 * s, 0.25 - 0.15 * s),
            v3(-0.02 + 0.01 * s, 0.12 + 0.02 * s, -0.03 * s + 0.01),
            v3(-0.15 + 0.05 * s, 0.35 * s, -0.1 - 0.1 * s),
        )

    joints = []

    p, po, c, co = frames(0)
    j = osim.FreeJoint("ground_pelvis", ground, v3(0.1, 0.9, -0.05), v3(0.1, -0.2, 0.3),
                       bodies["pelvis"], v3(0.02, -0.03, 0.01), v3(-0.2, 0.1, 0.05))
    for i, n in enumerate(["pelvis_rx", "pelvis_ry", "pelvis_rz", "pelvis_tx", "pelvis_ty", "pelvis_tz"]):
        j.upd_coordinates(i).setName(n)
    joints.append(j)

    # Hip: CustomJoint, oblique rotation axes; translations: SimmSpline on +x, LinearFunction on -y,
    # Constant on +z (no coordinate).
    st = osim.SpatialTransform()
    axis(st, 0, ["hip_flex"], v3(0, 0, 1), osim.LinearFunction(1, 0))
    axis(st, 1, ["hip_add"], unit(1, 0.2, 0), osim.LinearFunction(1, 0))
    axis(st, 2, ["hip_rot"], unit(0.1, 1, 0.3), osim.LinearFunction(1, 0))
    axis(st, 3, ["hip_flex"], v3(1, 0, 0), simm_spline([-1.0, -0.4, 0, 0.5, 0.9], [-0.02, 0.004, 0.0, 0.012, -0.01]))
    axis(st, 4, ["hip_flex"], v3(0, -1, 0), osim.LinearFunction(0.02, 0.01))
    axis(st, 5, [], v3(0, 0, 1), osim.Constant(0.015))
    p, po, c, co = frames(1)
    joints.append(osim.CustomJoint("hip", bodies["pelvis"], p, po, bodies["thigh"], c, co, st))

    p, po, c, co = frames(2)
    joints.append(osim.PinJoint("knee", bodies["thigh"], p, po, bodies["shank"], c, co))
    p, po, c, co = frames(3)
    joints.append(osim.UniversalJoint("ankle", bodies["shank"], p, po, bodies["foot"], c, co))
    p, po, c, co = frames(4)
    joints.append(osim.SliderJoint("mtp", bodies["foot"], p, po, bodies["toes"], c, co))
    p, po, c, co = frames(5)
    joints.append(osim.BallJoint("back", bodies["pelvis"], p, po, bodies["torso"], c, co))
    p, po, c, co = frames(6)
    joints.append(osim.GimbalJoint("neck", bodies["torso"], p, po, bodies["head"], c, co))
    p, po, c, co = frames(7)
    joints.append(osim.WeldJoint("shoulder", bodies["torso"], p, po, bodies["arm"], c, co))

    # Elbow: CustomJoint with a coupled coordinate (elbow_beta = spline(elbow_flex) through a
    # CoordinateCouplerConstraint) driving a rotation (slope 0.5) and an oblique translation.
    st = osim.SpatialTransform()
    axis(st, 0, ["elbow_flex"], unit(0.3, 0.2, 0.93), osim.LinearFunction(1, 0))
    axis(st, 1, ["elbow_beta"], v3(1, 0, 0), osim.LinearFunction(0.5, 0))
    axis(st, 2, [], v3(0, 1, 0), osim.Constant(0))
    axis(st, 3, ["elbow_beta"], unit(0.6, -0.8, 0), simm_spline([-0.5, 0, 0.08, 0.15], [-0.03, 0.0, 0.02, 0.05]))
    axis(st, 4, ["elbow_flex"], v3(0, 1, 0), osim.LinearFunction(-1, 0))
    axis(st, 5, [], v3(0, 0, 1), osim.Constant(0))
    p, po, c, co = frames(8)
    joints.append(osim.CustomJoint("elbow", bodies["arm"], p, po, bodies["forearm"], c, co, st))

    # Wrist: CustomJoint with one rotation and a translation driven by the same coordinate.
    st = osim.SpatialTransform()
    axis(st, 0, ["wrist_flex"], unit(-0.2, 0.1, 1), osim.LinearFunction(1, 0))
    axis(st, 1, [], v3(1, 0, 0), osim.Constant(0))
    axis(st, 2, [], v3(0, 1, 0), osim.Constant(0))
    axis(st, 3, [], v3(1, 0, 0), osim.Constant(0))
    axis(st, 4, ["wrist_flex"], v3(0, 1, 0), osim.LinearFunction(0.03, -0.005))
    axis(st, 5, [], v3(0, 0, 1), osim.Constant(0))
    p, po, c, co = frames(9)
    joints.append(osim.CustomJoint("wrist", bodies["forearm"], p, po, bodies["hand"], c, co, st))

    for j in joints:
        model.addJoint(j)

    coupler = osim.CoordinateCouplerConstraint()
    coupler.setName("elbow_coupler")
    indep = osim.ArrayStr()
    indep.append("elbow_flex")
    coupler.setIndependentCoordinateNames(indep)
    coupler.setDependentCoordinateName("elbow_beta")
    f = simm_spline([-0.2, -0.1, 0, 0.1, 0.2], [-0.5, -0.2, 0.1, 0.3, 0.6])
    coupler.setFunction(f)
    f.thisown = False  # the constraint adopts the function
    model.addConstraint(coupler)

    for k, name in enumerate(SCALES):
        for m in range(2):
            loc = v3(0.05 * (m + 1) - 0.07 * k % 0.13, 0.11 * (m - 1) + 0.01 * k, 0.04 * (1 - m) - 0.02 * k % 0.07)
            model.addMarker(osim.Marker(f"{name}_m{m}", bodies[name], loc))
    model.finalizeConnections()
    return model


def random_states(model):
    rng = np.random.RandomState(SEED)
    coords = [c for c in model.getCoordinateSet()]
    states = []
    for _ in range(N_STATES):
        q = {}
        for c in coords:
            rot = c.getMotionType() == osim.Coordinate.Rotational
            q[c.getName()] = float(rng.uniform(-1.3, 1.3) if rot else rng.uniform(-0.25, 0.25))
        states.append(q)
    return states


def coupled(model, q):
    """Sets the dependent coordinate to its CoordinateCouplerConstraint value."""
    q = dict(q)
    c = osim.CoordinateCouplerConstraint.safeDownCast(model.getConstraintSet().get("elbow_coupler"))
    x = osim.Vector(1, q["elbow_flex"])
    q["elbow_beta"] = float(c.getFunction().calcValue(x))
    return q


def evaluate(model, states):
    state = model.initSystem()
    out = []
    for q in states:
        q = coupled(model, q)
        for name, v in q.items():
            model.getCoordinateSet().get(name).setValue(state, v, False)
        model.realizePosition(state)
        for name, v in q.items():
            got = model.getCoordinateSet().get(name).getValue(state)
            assert abs(got - v) < 1e-15, (name, got, v)
        markers = {}
        for m in model.getMarkerSet():
            p = m.getLocationInGround(state)
            markers[m.getName()] = [p.get(0), p.get(1), p.get(2)]
        origins, rotations = {}, {}
        for b in model.getBodySet():
            x = b.getTransformInGround(state)
            p, r = x.p(), x.R()
            origins[b.getName()] = [p.get(0), p.get(1), p.get(2)]
            rotations[b.getName()] = [r.get(i, k) for i in range(3) for k in range(3)]
        out.append({"coordinates": q, "markers": markers, "body_origins": origins, "body_rotations": rotations})
    return out


def print_model(model, path):
    """Prints the model without OpenSim's XML comments (half the size; the content is unchanged)."""
    model.printToXML(path)
    with open(path) as f:
        text = f.read()
    text = re.sub(r"[ \t]*<!--.*?-->\n", "", text, flags=re.S)
    with open(path, "w") as f:
        f.write(text)


def rounded(x):
    """Floats to 15 significant digits, recursively (far below the tests' 1e-9 tolerances)."""
    if isinstance(x, float):
        return float(f"{x:.15g}")
    if isinstance(x, dict):
        return {k: rounded(v) for k, v in x.items()}
    if isinstance(x, list):
        return [rounded(v) for v in x]
    return x


def main():
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    os.makedirs(OUT, exist_ok=True)
    model = build()
    model.initSystem()
    print_model(model, os.path.join(OUT, "osim_joints.osim"))
    # Evaluate the model as read back from the file, so the fixture and the numbers agree.
    model = osim.Model(os.path.join(OUT, "osim_joints.osim"))
    states = random_states(model)
    unscaled = evaluate(model, states)

    scaled_model = osim.Model(os.path.join(OUT, "osim_joints.osim"))
    state = scaled_model.initSystem()
    scale_set = osim.ScaleSet()
    for name, f in SCALES.items():
        s = osim.Scale()
        s.setSegmentName(name)
        s.setScaleFactors(v3(*f))
        s.setApply(True)
        scale_set.cloneAndAppend(s)
    assert scaled_model.scale(state, scale_set, True)
    print_model(scaled_model, os.path.join(OUT, "osim_joints_scaled.osim"))
    scaled = evaluate(scaled_model, states[:N_SCALED])

    doc = {
        "generator": f"scripts/gen_osim_joint_fixture.py, OpenSim {osim.__version__}, seed {SEED}",
        "scales": {k: list(v) for k, v in SCALES.items()},
        "unscaled": unscaled,
        "scaled": scaled,
    }
    with open(os.path.join(OUT, "osim_joints_expected.json"), "w") as f:
        json.dump(rounded(doc), f, separators=(",", ":"))
        f.write("\n")


if __name__ == "__main__":
    main()
