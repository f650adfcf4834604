#!/usr/bin/env python3
"""Draws docs/retarget.png: the subject and the Unitree G1 at a few frames of a retargeted trial.

A side view (x forward, z up, equal aspect, seen from the right), one pair of figures per chosen
frame laid out along a strip: on the left the subject, a stick figure through the joint centres
`smocap retarget --targets` records (grey; pelvis, hip, knee, ankle = talus, heel = calcn;
lumbar joint = torso, shoulder, elbow, hand; the head is only notional, a circle above the
shoulders), and on its right the G1 posed by MuJoCo from the retargeted `qpos` (blue; its
collision capsules and spheres, over a light silhouette of its visual meshes' vertices). The far
side (left) is drawn darker, behind the near side (right). Each figure is moved along x to its
place in the strip (the subject walks further than the robot, its steps being longer); heights
are kept. A small marker on the ground line, under the subject's heel and under the robot's foot,
shows each foot that `--targets` marks as planted.

Needs numpy, matplotlib and mujoco. How to regenerate the README picture (from the repository
root, the shared data at ../shared):

    smocap convert datasets.toml --dataset rajagopal2016_walk --out /tmp/rt
    smocap retarget /tmp/rt/rajagopal2016_walk/motion_capture_walk.mcap --targets --out /tmp/rt/g1
    python3 scripts/retarget_picture.py /tmp/rt/g1/motion_capture_walk.npz \
        /tmp/rt/g1/motion_capture_walk.targets.npz docs/retarget.png

The robot file holds `qpos` (frames x 36, MuJoCo order) and `fps`; the targets file holds
`human` (frames x tasks x 3, joint centres in world metres, Z up), `human_bodies` (OpenSim
body names) and `contact` (frames x 2, left then right planted flags).
"""

import argparse
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.patches import Polygon  # noqa: E402

# The subject's chains, as OpenSim body names whose joint centres the targets record.
HUMAN_CHAINS = {
    "l": [
        ["pelvis", "femur_l", "tibia_l", "talus_l", "calcn_l"],
        ["pelvis", "torso", "humerus_l", "ulna_l", "hand_l"],
    ],
    "r": [
        ["pelvis", "femur_r", "tibia_r", "talus_r", "calcn_r"],
        ["pelvis", "torso", "humerus_r", "ulna_r", "hand_r"],
    ],
}
HUMAN_COLOUR = {"l": "#6b6b6b", "r": "#a8a8a8"}
ROBOT_COLOUR = {"l": "#1f4e96", "c": "#2f6fc4", "r": "#5d9be6"}
SILHOUETTE = "#c8d3e3"
FEET = ["left_ankle_roll_link", "right_ankle_roll_link"]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("robot_npz")
    p.add_argument("targets_npz")
    p.add_argument("out_png")
    p.add_argument("--frames", default="0,50,100,150,200", help="comma-separated frame numbers")
    p.add_argument("--mjcf", default="models/robots/g1/g1.xml")
    p.add_argument("--spacing", type=float, default=1.6, help="metres between pairs of figures")
    p.add_argument("--gap", type=float, default=0.6, help="metres from the subject to the robot")
    p.add_argument("--title", default="Rajagopal 2016 walk: the subject (grey) and the Unitree G1 "
                   "(blue), smocap retarget")
    return p.parse_args()


def stadium(a, b, r, n=10):
    """The outline of a 2-D capsule from a to b of radius r (the projection of a 3-D one)."""
    d = b - a
    length = np.hypot(*d)
    ang = np.arctan2(d[1], d[0]) if length > 1e-9 else 0.0
    t1 = np.linspace(-np.pi / 2, np.pi / 2, n) + ang
    t2 = np.linspace(np.pi / 2, 3 * np.pi / 2, n) + ang
    return np.vstack([b + r * np.c_[np.cos(t1), np.sin(t1)],
                      a + r * np.c_[np.cos(t2), np.sin(t2)]])


def geom_side(model, g):
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
    body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[g]) or ""
    for s in (name, body):
        if s.startswith("left_"):
            return "l"
        if s.startswith("right_"):
            return "r"
    return "c"


def robot_shapes(model, data, dx):
    """Collision geoms as (depth, polygon, side) and the visual meshes' projected vertices."""
    shapes, verts = [], []
    for g in range(model.ngeom):
        pos, mat = data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3)
        typ = model.geom_type[g]
        if typ == mujoco.mjtGeom.mjGEOM_MESH:
            m = model.geom_dataid[g]
            adr, num = model.mesh_vertadr[m], model.mesh_vertnum[m]
            v = pos + model.mesh_vert[adr:adr + num] @ mat.T
            verts.append(v[:, [0, 2]])
            continue
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        r = model.geom_size[g, 0]
        if typ == mujoco.mjtGeom.mjGEOM_CAPSULE:
            h = model.geom_size[g, 1] * mat[:, 2]
            a, b = (pos - h)[[0, 2]], (pos + h)[[0, 2]]
        elif typ == mujoco.mjtGeom.mjGEOM_SPHERE:
            a = b = pos[[0, 2]]
        else:
            continue
        a, b = a + [dx, 0], b + [dx, 0]
        shapes.append((pos[1], stadium(a, b, r), geom_side(model, g)))
    verts = np.vstack(verts) + [dx, 0] if verts else np.zeros((0, 2))
    return shapes, verts


def main():
    args = parse_args()
    robot = np.load(args.robot_npz)
    tg = np.load(args.targets_npz)
    qpos, fps = robot["qpos"], float(robot["fps"])
    human, contact = tg["human"], tg["contact"]
    hidx = {n: i for i, n in enumerate(tg["human_bodies"])}
    frames = [int(f) for f in args.frames.split(",") if f.strip()]
    frames = [f for f in frames if 0 <= f < len(qpos)]
    if not frames:
        raise SystemExit(f"no frames in range 0..{len(qpos) - 1}")

    model = mujoco.MjModel.from_xml_path(args.mjcf)
    data = mujoco.MjData(model)
    foot_ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f) for f in FEET]

    width = args.spacing * len(frames)
    lo, hi = -0.5 * args.spacing - 0.05, width - 0.5 * args.spacing + 0.05
    zlo, zhi = -0.28, 1.95
    px_per_m = min(1370.0 / (hi - lo), 180.0)
    size = ((hi - lo) * px_per_m / 100 / 0.98, (zhi - zlo) * px_per_m / 100 / 0.8)
    fig = plt.figure(figsize=size, dpi=100)
    ax = fig.add_axes([0.01, 0.03, 0.98, 0.8])
    ax.set_aspect("equal")
    ax.axis("off")

    ax.fill_between((lo, hi), [-0.07, -0.07], [0, 0], color="#eeeae2", zorder=0, lw=0)
    ax.plot((lo, hi), [0, 0], color="#8a8170", lw=1.2, zorder=1)

    for k, f in enumerate(frames):
        data.qpos[:] = qpos[f]
        mujoco.mj_fwdPosition(model, data)
        centre = k * args.spacing
        dx = centre + args.gap / 2 - data.qpos[0]
        hx = centre - args.gap / 2 - human[f, hidx["pelvis"], 0]

        # The subject, on the left of the pair.
        for side in ("l", "r"):
            z = 2 if side == "l" else 3
            for chain in HUMAN_CHAINS[side]:
                idx = [hidx[n] for n in chain if n in hidx]
                pts = human[f, idx][:, [0, 2]] + [hx, 0]
                ax.plot(pts[:, 0], pts[:, 1], "-", color=HUMAN_COLOUR[side], lw=3.4,
                        solid_capstyle="round", solid_joinstyle="round", zorder=z)
                ax.plot(pts[:, 0], pts[:, 1], "o", ms=4.5, color=HUMAN_COLOUR[side],
                        mec="white", mew=0.6, zorder=z)

        # A notional head: a circle on the line from the lumbar joint through mid-shoulders.
        if all(n in hidx for n in ("torso", "humerus_l", "humerus_r")):
            base = human[f, hidx["torso"]][[0, 2]] + [hx, 0]
            neck = 0.5 * (human[f, hidx["humerus_l"]] + human[f, hidx["humerus_r"]])[[0, 2]]
            neck = neck + [hx, 0]
            up = (neck - base) / np.linalg.norm(neck - base)
            centre_h = neck + 0.2 * up
            ax.plot(*np.c_[neck, centre_h - 0.1 * up], "-", color=HUMAN_COLOUR["l"], lw=3.4,
                    solid_capstyle="round", zorder=3)
            ax.add_patch(plt.Circle(centre_h, 0.1, fc="#ececec", ec=HUMAN_COLOUR["l"], lw=2.0,
                                    zorder=3))

        # The robot, on the right: mesh silhouette, then collision geoms far (left, +y) to near.
        shapes, verts = robot_shapes(model, data, dx)
        ax.scatter(verts[::2, 0], verts[::2, 1], s=0.15, c=SILHOUETTE, lw=0, zorder=4,
                   rasterized=True)
        shapes.sort(key=lambda s: -s[0])
        patches = [Polygon(p, closed=True) for _, p, _ in shapes]
        colours = [ROBOT_COLOUR[s] for _, _, s in shapes]
        ax.add_collection(PatchCollection(patches, facecolors=colours, edgecolors="white",
                                          linewidths=0.4, alpha=0.95, zorder=5))

        # Planted feet (flags from the subject's feet): under the heel and under the robot's foot.
        for i, (fid, side) in enumerate(zip(foot_ids, ("l", "r"))):
            if contact[f, i] > 0.5:
                heel = human[f, hidx["calcn_" + side], 0] + hx
                ax.plot(heel, -0.03, "^", ms=7, color=HUMAN_COLOUR[side], mec="white", mew=0.6,
                        zorder=6)
                ax.plot(data.xpos[fid, 0] + dx, -0.03, "^", ms=7, color=ROBOT_COLOUR[side],
                        mec="white", mew=0.6, zorder=6)

        if k == 0:
            ax.text(centre - args.gap / 2, 1.86, "subject", ha="center", va="bottom",
                    fontsize=9.5, color="#555555", style="italic")
            ax.text(centre + args.gap / 2, 1.45, "G1", ha="center", va="bottom", fontsize=9.5,
                    color=ROBOT_COLOUR["l"], style="italic")
        ax.text(centre, -0.12, f"frame {f}  ·  {f / fps:.2f} s", ha="center", va="top",
                fontsize=10, color="#444444")

    ax.set_xlim(lo, hi)
    ax.set_ylim(zlo, zhi)
    fig.suptitle(args.title, fontsize=12.5, y=0.975)
    fig.text(0.5, 0.895, "side view, walking to the right; far (left) side darker; "
             "▲ foot planted", ha="center", fontsize=9.5, color="#555555")
    os.makedirs(os.path.dirname(os.path.abspath(args.out_png)), exist_ok=True)
    fig.savefig(args.out_png, dpi=100, metadata={"Software": None}, facecolor="white")


if __name__ == "__main__":
    main()
