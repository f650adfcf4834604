#!/usr/bin/env python3
"""smocap's retargeting beside mink (the differential-IK library GMR is built on), driven with the
same targets on the same trials; every figure computed here, the same way for both.

    smocap retarget TRIAL.mcap... --robot g1 --targets --out DIR
    python scripts/compare_mink.py models/robots/g1/g1.xml DIR [--mapping models/robots/g1/opensim.toml]

For every `<trial>.targets.npz` in DIR (smocap's per-frame task targets and planted feet) mink
solves the same position/orientation tasks (FrameTask, costs = smocap's weights), a light
PostureTask, its ConfigurationLimit (joint ranges) and VelocityLimit (the mapping's limits),
as GMR drives it (solver daqp, damping 0.5, steps of the model's timestep until the error stops
falling by 1 mm, at most 10 per frame); no foot pins, no ground, no self-collision (GMR has none).
Then, for smocap's `<trial>.npz` and mink's result alike: joint-frames outside their ranges,
joint-steps over their velocity limits (over the frame interval), mean foot slide while planted
(smocap's contact flags), deepest foot penetration, frames where MuJoCo's mj_collision finds two
robot geoms overlapping, end-effector tracking median (pelvis, ankles, wrists; mm), frames/s
(mink: this script's solve loop, Python; smocap: from its report line, or --smocap-fps).
Needs mujoco, mink, numpy (and g1.xml's meshes: scripts/fetch_g1.py --meshes).
"""
import argparse
import fnmatch
import glob
import json
import os
import time
import tomllib

import mink
import mujoco
import numpy as np

EFFECTORS = ("pelvis", "ankle_pitch_link", "wrist_yaw_link")


def velocity_limits(model, mapping):
    pats = tomllib.load(open(mapping, "rb")).get("velocity", {})
    out = {}
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            for p, v in pats.items():
                if fnmatch.fnmatch(name, p):
                    out[name] = v
                    break
    return out


def solve_mink(model, t, vlim):
    cfg = mink.Configuration(model)
    names, w, pos, rot = list(t["robot_bodies"]), t["weights"], t["pos"], t["rot"]
    tasks = [mink.FrameTask(n, "body", position_cost=float(w[k, 0]), orientation_cost=float(w[k, 1]), lm_damping=1.0)
             for k, n in enumerate(names)]
    posture = mink.PostureTask(model, cost=1e-2)
    q0 = np.zeros(model.nq)
    q0[3] = 1.0
    q0[:3] = pos[0, 0]
    cfg.update(q0)
    posture.set_target_from_configuration(cfg)
    limits = [mink.ConfigurationLimit(model), mink.VelocityLimit(model, vlim)]
    dt = model.opt.timestep
    out = np.zeros((pos.shape[0], model.nq))
    start = time.perf_counter()
    for f in range(pos.shape[0]):
        for k, task in enumerate(tasks):
            task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(rot[f, k]), pos[f, k]))
        err = lambda: sum(np.linalg.norm(task.compute_error(cfg)) for task in tasks)
        prev, steps = err(), 0
        while steps < (100 if f == 0 else 10):
            vel = mink.solve_ik(cfg, [*tasks, posture], dt, solver="daqp", damping=0.5, limits=limits)
            cfg.integrate_inplace(vel, dt)
            steps += 1
            now = err()
            if prev - now < 1e-3:
                break
            prev = now
        out[f] = cfg.q
    return out, pos.shape[0] / (time.perf_counter() - start)


def measure(model, qpos, t, vlim):
    data = mujoco.MjData(model)
    fps = float(t["fps"])
    names = list(t["robot_bodies"])
    eff = [k for k, n in enumerate(names) if n.endswith(EFFECTORS) and t["weights"][k, 0] > 0]
    body = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n)
    feet = [body(n) for n in t["feet"]]
    foot_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] in feet and model.geom_contype[g]]
    hinges = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    vmax = np.array([vlim.get(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j), np.inf) for j in hinges])
    adr = np.array([model.jnt_qposadr[j] for j in hinges])
    lo, hi = model.jnt_range[hinges].T
    q = qpos[:, adr]
    ranges = int(((q < lo - 1e-9) | (q > hi + 1e-9)).sum())
    vel = int((np.abs(np.diff(q, axis=0)) * fps > vmax + 1e-9).sum())
    errs, foot_xy, lowest, collide = [], [], [], 0
    for f in range(len(qpos)):
        data.qpos[:] = qpos[f]
        mujoco.mj_fwdPosition(model, data)  # kinematics, then collision (mj_collision alone misses pairs)
        errs += [np.linalg.norm(data.xpos[body(names[k])] - t["pos"][f, k]) for k in eff]
        foot_xy.append([data.xpos[b][:2].copy() for b in feet])
        low = np.inf
        for g in foot_geoms:
            axis = data.geom_xmat[g].reshape(3, 3)[:, 2] * model.geom_size[g][1]
            low = min(low, data.geom_xpos[g][2] - abs(axis[2]) - model.geom_size[g][0])
        lowest.append(low)
        collide += int(any(data.contact[c].dist < 0 for c in range(data.ncon)))
    foot_xy, c = np.array(foot_xy), t["contact"] > 0.5
    slides = []
    for k in range(len(feet)):
        both = c[1:, k] & c[:-1, k]
        slides += list(np.linalg.norm(np.diff(foot_xy[:, k], axis=0), axis=1)[both] * fps)
    return {"range_violations": ranges, "velocity_violations": vel,
            "slide_mean_cm_s": float(np.mean(slides)) * 100 if slides else 0.0,
            "penetration_max_mm": max(0.0, -min(lowest)) * 1e3, "self_collision_frames": collide,
            "end_effector_median_mm": float(np.median(errs)) * 1e3}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mjcf")
    ap.add_argument("dir")
    ap.add_argument("--mapping", default=os.path.join(os.path.dirname(__file__), "..", "models/robots/g1/opensim.toml"))
    ap.add_argument("--json", help="write the table as JSON here")
    a = ap.parse_args()
    model = mujoco.MjModel.from_xml_path(a.mjcf)
    vlim = velocity_limits(model, a.mapping)
    rows = []
    for tf in sorted(glob.glob(os.path.join(a.dir, "**", "*.targets.npz"), recursive=True)):
        stem = tf[: -len(".targets.npz")]
        t = np.load(tf)
        ours = measure(model, np.load(stem + ".npz")["qpos"], t, vlim)
        q, fps = solve_mink(model, t, vlim)
        theirs = measure(model, q, t, vlim)
        theirs["frames_per_s"] = fps
        rows.append({"trial": os.path.basename(stem), "frames": int(len(q)), "smocap": ours, "mink": theirs})
        print(f"{os.path.basename(stem)} ({len(q)} frames)")
        for who, m in (("smocap", ours), ("mink", theirs)):
            print(f"  {who:7s} range {m['range_violations']:4d}  velocity {m['velocity_violations']:4d}  "
                  f"slide {m['slide_mean_cm_s']:6.2f} cm/s  penetration {m['penetration_max_mm']:6.1f} mm  "
                  f"self-collision frames {m['self_collision_frames']:4d}  effectors {m['end_effector_median_mm']:6.1f} mm"
                  + (f"  {m['frames_per_s']:.0f} frames/s" if "frames_per_s" in m else ""))
    if a.json:
        json.dump(rows, open(a.json, "w"), indent=1)


if __name__ == "__main__":
    main()
