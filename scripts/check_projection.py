#!/usr/bin/env python3
"""smocap's pinhole projection against OpenCV's cv2.projectPoints, on random points and rigs.

Writes seeded random camera rigs (TOML: cameras given by look_at, with and without `up`, and by
rotation matrices; random focal lengths, sensor widths and image sizes) and random world points,
projects them with `smocap project --points`, and projects the same points with
cv2.projectPoints from the K, R, t that smocap wrote (cameras.json; no distortion). Fails if any
pixel coordinate differs by more than 1e-6 px, or if smocap's K does not follow from the rig's
focal length, sensor width and image size.

Needs numpy and OpenCV (`pip install opencv-python-headless numpy`, e.g. into a virtual
environment outside the repository). SMOCAP_BIN names a built smocap (default: cargo run).
    python3 scripts/check_projection.py [--rigs 20] [--points 500] [--seed 1]
"""
import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
import tempfile

import cv2
import numpy as np


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def vec(v):
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def rig_toml(rng, n):
    out = []
    for i in range(n):
        pos = rng.uniform(-6, 6, size=3)
        out.append("[[cameras]]")
        out.append(f'name = "cam{i}"')
        out.append(f"position = {vec(pos)}")
        kind = i % 3
        if kind == 2:
            r = random_rotation(rng)
            out.append("rotation = [" + ", ".join(vec(row) for row in r) + "]")
        else:
            out.append(f"look_at = {vec(rng.uniform(-1, 1, size=3))}")
            if kind == 1:
                out.append(f"up = {vec(rng.normal(size=3))}")
        out.append(f"focal_mm = {float(rng.uniform(8, 85))!r}")
        out.append(f"sensor_width_mm = {float(rng.uniform(6, 40))!r}")
        out.append(f"width_px = {int(rng.integers(64, 4096))}")
        out.append(f"height_px = {int(rng.integers(64, 4096))}")
        out.append("")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rigs", type=int, default=20)
    ap.add_argument("--cameras", type=int, default=6, help="cameras per rig")
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    smocap = shlex.split(os.environ.get("SMOCAP_BIN", "cargo run --release --quiet --"))
    rng = np.random.default_rng(a.seed)
    worst, compared = 0.0, 0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.rigs):
            rig = os.path.join(tmp, f"rig{k}.toml")
            with open(rig, "w") as f:
                f.write(rig_toml(rng, a.cameras))
            pts = rng.uniform(-3, 3, size=(a.points, 3))
            pcsv = os.path.join(tmp, f"points{k}.csv")
            with open(pcsv, "w") as f:
                f.write("name,x,y,z\n")
                for i, p in enumerate(pts):
                    f.write(f"p{i},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}\n")
            out = os.path.join(tmp, f"out{k}")
            run = subprocess.run(smocap + ["project", "--points", pcsv, "--cameras", rig, "--out", out],
                                 capture_output=True, text=True)
            if run.returncode != 0:
                print(f"check_projection: smocap project failed on {rig}:\n{run.stderr}")
                return 1
            cams = {c["name"]: c for c in json.load(open(os.path.join(out, "cameras.json")))["cameras"]}
            rows = list(csv.DictReader(open(os.path.join(out, "points.csv"))))
            for name, c in cams.items():
                K, R, t = np.array(c["K"]), np.array(c["R"]), np.array(c["t"])
                fx = c["focal_mm"] / c["sensor_width_mm"] * c["width"]
                want_k = np.array([[fx, 0, (c["width"] - 1) / 2], [0, fx, (c["height"] - 1) / 2], [0, 0, 1]])
                assert np.allclose(K, want_k, rtol=0, atol=1e-9), (name, K, want_k)
                assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0, (name, R)
                mine = [r for r in rows if r["camera"] == name]
                xyz = np.array([[float(r["x_m"]), float(r["y_m"]), float(r["z_m"])] for r in mine])
                uv = np.array([[float(r["u_px"]), float(r["v_px"])] for r in mine])
                depth = (R @ xyz.T).T[:, 2] + t[2]
                keep = depth > 0.1  # in front of the camera, away from the singular plane
                if not keep.any():
                    continue
                rvec, _ = cv2.Rodrigues(R)
                cv, _ = cv2.projectPoints(xyz[keep], rvec, t, K, np.zeros(5))
                d = np.abs(cv.reshape(-1, 2) - uv[keep])
                worst = max(worst, float(d.max()))
                compared += int(keep.sum())
    print(f"check_projection: {compared} points over {a.rigs} rigs × {a.cameras} cameras: "
          f"max |smocap − cv2.projectPoints| = {worst:.3e} px (OpenCV {cv2.__version__})")
    if worst > 1e-6:
        print("check_projection: FAILED: more than 1e-6 px apart")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
