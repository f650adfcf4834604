#!/usr/bin/env python3
"""Draws docs/body.png: the subject's body posed at a few frames of a trial, seen from the side.

Reads the OBJ files `smocap export --mesh` writes (metres, Z-up world) and draws them with flat
shading by the triangles' normals (painter's order, matplotlib). Needs numpy and matplotlib.

How to run it (from the repository root, the shared data at ../shared):

    smocap convert datasets.toml --dataset rajagopal2016_walk --out /tmp/body-pic
    smocap export /tmp/body-pic/rajagopal2016_walk/motion_capture_walk.mcap \
        --mesh /tmp/body-pic/meshes --frames 0,55,110,165,220
    python3 scripts/body_picture.py /tmp/body-pic/meshes/*.obj --out docs/body.png

The figures are drawn where the trial has them, seen square to the direction of walking
(the horizontal direction along which their centres spread), from the subject's left.
"""

import argparse
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                f.append([int(t.split("/")[0]) - 1 for t in line.split()[1:4]])
    return np.array(v), np.array(f)


def frame_number(path):
    m = re.search(r"_(\d+)\.obj$", path)
    return int(m.group(1)) if m else 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("objs", nargs="+", help="OBJ files written by `smocap export --mesh`")
    ap.add_argument("--out", default="docs/body.png")
    ap.add_argument("--dpi", type=int, default=110)
    args = ap.parse_args()
    meshes = [read_obj(p) for p in sorted(args.objs, key=frame_number)]
    centres = np.array([v.mean(axis=0) for v, _ in meshes])
    # the direction of walking: the horizontal spread of the figures' centres
    d = centres[-1, :2] - centres[0, :2]
    if np.linalg.norm(d) < 1e-6:
        d = np.array([1.0, 0.0])
    d /= np.linalg.norm(d)
    across = np.array([-d[1], d[0]])  # the subject's left when walking along d
    light = np.array([0.45, 0.35, 0.82])  # in view coordinates: (along, up, towards the viewer)
    light /= np.linalg.norm(light)
    polys, shades, depths = [], [], []
    for v, f in meshes:
        # view coordinates: x along the walk, y up, z towards the viewer (on the subject's left)
        x = v[:, :2] @ d
        y = v[:, 2]
        z = v[:, :2] @ across
        p = np.stack([x, y, z], axis=1)
        t = p[f]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
        front = n[:, 2] > 0  # counter-clockwise seen from outside: facing the viewer
        t, n = t[front], n[front]
        polys.append(t[:, :, :2])
        shades.append(np.clip(n @ light, 0.0, 1.0))
        depths.append(t[:, :, 2].mean(axis=1))
    polys = np.concatenate(polys)
    shades = np.concatenate(shades)
    order = np.argsort(np.concatenate(depths))  # far first
    base = np.array([0.80, 0.62, 0.50])
    colours = np.clip(base[None, :] * (0.30 + 0.75 * shades[order, None]), 0, 1)
    xy = polys.reshape(-1, 2)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    w, h = hi - lo
    fig = plt.figure(figsize=(max(3.0, 3.2 * w / h), 3.2))
    ax = fig.add_axes([0, 0, 1, 1])
    ax.add_collection(PolyCollection(polys[order], facecolors=colours, edgecolors=colours, linewidths=0.2))
    ground = lo[1]
    ax.plot([lo[0] - 0.1, hi[0] + 0.1], [ground, ground], color="0.6", lw=1)
    ax.set_xlim(lo[0] - 0.1, hi[0] + 0.1)
    ax.set_ylim(ground - 0.05, hi[1] + 0.05)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.savefig(args.out, dpi=args.dpi, facecolor="white")
    print(f"wrote {args.out} ({len(meshes)} figures, {len(polys)} triangles drawn)")


if __name__ == "__main__":
    main()
