#!/usr/bin/env python3
"""Checks `smocap retarget` outputs with MuJoCo itself (an independent implementation):

    python scripts/check_robot_mujoco.py models/robots/g1/g1.xml OUT_DIR [--max-fk-error 1e-6]

For every `<trial>.npz` in OUT_DIR (qpos, body_names, body_pos_w, fps):
  - MuJoCo's forward kinematics (mj_fwdPosition) of each frame's qpos puts every named body where
    smocap says (body_pos_w), within --max-fk-error metres;
  - no hinge joint is outside its MJCF range (jnt_range, limited joints);
  - MuJoCo's collision detection (mj_fwdPosition's, the model's own contype/conaffinity, parent
    filter and <exclude> pairs; the model has no floor) finds no robot geom pair penetrating
    deeper than --max-penetration metres (1 µm default: any overlap);
  - the lowest point of the foot geoms (MuJoCo's geom_xpos of the foot capsules) is not below
    the ground by more than 1 cm;
  - the `<trial>.csv` beside it (mjlab's 30 fps rows: root xyz, quaternion xyzw, joints) loads
    into MuJoCo's qpos with every joint within its range and a unit root quaternion.
Exit status 1 on any failure. Needs `mujoco` and `numpy`; g1.xml needs its meshes
(`python scripts/fetch_g1.py --meshes`).
"""
import argparse
import glob
import json
import os
import sys

import mujoco
import numpy as np


def check(model, path, max_fk, max_pen):
    problems = []
    z = np.load(path)
    qpos, names, pos_w = z["qpos"], [str(n) for n in z["body_names"]], z["body_pos_w"]
    data = mujoco.MjData(model)
    if qpos.shape[1] != model.nq:
        return [f"{path}: qpos has {qpos.shape[1]} columns, the model nq = {model.nq}"]
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in names]
    missing = [n for n, i in zip(names, ids) if i < 0]
    if missing:
        return [f"{path}: bodies not in the model: {missing}"]
    hinges = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    worst_fk, out_of_range, pen_frames, deepest, lowest = 0.0, 0, 0, 0.0, np.inf
    foot_geoms = [g for g in range(model.ngeom) if "foot" in (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "")]
    for f in range(qpos.shape[0]):
        data.qpos[:] = qpos[f]
        mujoco.mj_fwdPosition(model, data)  # kinematics, then collision (mj_collision alone misses pairs)
        worst_fk = max(worst_fk, float(np.abs(data.xpos[ids] - pos_w[f]).max()))
        for j in hinges:
            if model.jnt_limited[j]:
                v = data.qpos[model.jnt_qposadr[j]]
                lo, hi = model.jnt_range[j]
                out_of_range += int(v < lo - 1e-9 or v > hi + 1e-9)
        d = min([data.contact[c].dist for c in range(data.ncon)], default=0.0)
        if d < -max_pen:
            pen_frames += 1
            deepest = min(deepest, d)
        for g in foot_geoms:
            lowest = min(lowest, data.geom_xpos[g][2] - model.geom_size[g][0]
                         - abs(model.geom_size[g][1] * data.geom_xmat[g].reshape(3, 3)[2, 2]))
    if worst_fk > max_fk:
        problems.append(f"forward kinematics differs from smocap's by {worst_fk:.3g} m (> {max_fk:g})")
    if out_of_range:
        problems.append(f"{out_of_range} joint-frames outside their ranges")
    report = os.path.splitext(path)[0] + ".json"
    said = json.load(open(report))["self_collision_frames"] if os.path.exists(report) else None
    if pen_frames:
        problems.append(f"MuJoCo finds {pen_frames} frames with self-penetration (deepest {-deepest * 1e3:.2f} mm; "
                        f"the report says {said})")
    print(f"{'ok' if not problems else 'FAIL'} {os.path.basename(path)}: {qpos.shape[0]} frames, FK within "
          f"{worst_fk:.2g} m, {out_of_range} out of range, MuJoCo self-penetration frames {pen_frames} "
          f"(report: {said}), lowest foot point {lowest * 1e3:.1f} mm")
    if lowest < -0.01:
        problems.append(f"a foot goes {-lowest * 1e3:.1f} mm below the ground")
    csv = os.path.splitext(path)[0] + ".csv"
    if os.path.exists(csv):
        rows = np.loadtxt(csv, delimiter=",", ndmin=2)
        if rows.shape[1] != model.nq:
            problems.append(f"{csv}: {rows.shape[1]} columns, the model nq = {model.nq}")
        else:
            qpos_csv = np.concatenate([rows[:, :3], rows[:, [6, 3, 4, 5]], rows[:, 7:]], axis=1)
            bad = 0
            for q in qpos_csv:
                data.qpos[:] = q
                mujoco.mj_fwdPosition(model, data)
                for j in hinges:
                    v = data.qpos[model.jnt_qposadr[j]]
                    bad += int(model.jnt_limited[j] and (v < model.jnt_range[j][0] - 1e-9 or v > model.jnt_range[j][1] + 1e-9))
            if bad or not np.allclose(np.linalg.norm(rows[:, 3:7], axis=1), 1.0, atol=1e-9):
                problems.append(f"{csv}: {bad} joint-rows outside their ranges, or a root quaternion not unit")
            print(f"   {os.path.basename(csv)}: {len(rows)} rows at 30 fps into MuJoCo, {bad} outside ranges")
    return [f"{path}: {p}" for p in problems]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mjcf")
    ap.add_argument("dir")
    ap.add_argument("--max-fk-error", type=float, default=1e-6)
    ap.add_argument("--max-penetration", type=float, default=1e-6)
    a = ap.parse_args()
    model = mujoco.MjModel.from_xml_path(a.mjcf)
    files = sorted(glob.glob(os.path.join(a.dir, "**", "*.npz"), recursive=True))
    if not files:
        sys.exit(f"no .npz in {a.dir}")
    problems = [p for f in files for p in check(model, f, a.max_fk_error, a.max_penetration)]
    for p in problems:
        print("FAIL", p)
    print(f"mujoco {mujoco.__version__}: {len(files)} trials, {len(problems)} problems")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
