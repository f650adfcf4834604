#!/usr/bin/env python3
"""`smocap render` against an independent rasterization, and its COCO files against pycocotools.

For each trial (the synthetic dataset of ./datasets.toml and, where ../shared has them, the
shared gait2354 and Rajagopal trials, converted first): renders every N-th frame with
`smocap render`, writes the same posed body mesh with `smocap export --mesh` (OBJ), projects its
vertices with cv2.projectPoints from the K, R, t, dist of the render's cameras.json, fills every
triangle with cv2.fillConvexPoly (1/256 px sub-pixel precision) at 8 x 8 samples a pixel, a pixel in where
half its samples are, and compares that silhouette with the rendered mask (label > 0): IoU >= 0.98
for every camera and frame (the IoU against a plain one-sample fill, which also fills every pixel an
edge passes through, is printed too). Then the keypoints,
re-read from the written files (depth PNG in mm: 0.5 mm quantization allowed): v=0 only outside
the image or behind the camera; every v=1 keypoint lies more than 1 cm behind the depth buffer
(but a surface keypoint behind a sliver thinner than a pixel: counted apart, confirmed by casting
its ray against the posed OBJ mesh); a surface keypoint (nose, eyes, ears, toes, heels) with v=2
lies in the mask within 1 cm of the buffer, or on an outline (its pixel's centre sees the
background or a farther surface, a neighbouring pixel the surface it is on), or on a rim (its
neighbours see a nearer flank: its ray, cast against the mesh, meets nothing 1 cm in front of
it), the last two counted apart; a marker with v=2 is not more
than 1 cm behind the buffer; a joint centre with v=1 is not on its own segment. pycocotools loads every COCO file; every box contains its visible keypoints.

Needs numpy, OpenCV and pycocotools (`pip install opencv-python-headless numpy pycocotools`).
SMOCAP_BIN names a built smocap (default: cargo run --release).
    python3 scripts/check_render.py [--every 25] [--size 640x480]
"""
import argparse
import contextlib
import io
import json
import os
import shlex
import subprocess
import sys
import tempfile

import cv2
import numpy as np
from pycocotools.coco import COCO

TOL_M = 0.01
QUANT_M = 0.0005
RAY_M = 0.0001  # the point rebuilt from its pixel coordinates and depth


def run(smocap, *args):
    r = subprocess.run(smocap + list(args), capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"smocap {' '.join(args)} failed:\n{r.stderr}")
    return r.stderr


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                f.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(v), np.array(f)


def silhouette(verts, faces, cam, ss):
    """The mesh's silhouette: triangles filled at `ss` x `ss` samples a pixel, a pixel in where at
    least half its samples are (ss = 1: cv2.fillConvexPoly's own rule, which also fills every
    pixel an edge passes through)."""
    k, r, t = np.array(cam["K"]), np.array(cam["R"]), np.array(cam["t"])
    rvec, _ = cv2.Rodrigues(r)
    uv, _ = cv2.projectPoints(verts.reshape(-1, 1, 3), rvec, t, k, np.array(cam["dist"], dtype=float))
    assert ((verts @ r.T + t)[:, 2] > 0.05).all(), "a vertex behind the camera"
    # pixel x spans [x - 0.5, x + 0.5]: sample pixels ss*x .. ss*x + ss - 1
    fine = ss * (uv.reshape(-1, 2) + 0.5) - 0.5
    fixed = np.round(fine * 256).astype(np.int32)
    h, w = cam["height"], cam["width"]
    img = np.zeros((h * ss, w * ss), np.uint8)
    for tri in faces:
        cv2.fillConvexPoly(img, fixed[tri], 1, lineType=cv2.LINE_8, shift=8)
    return img.reshape(h, ss, w, ss).mean(axis=(1, 3)) >= 0.5


def on_outline(mask, depth, px, py, d, tol=TOL_M + QUANT_M):
    """Whether (px, py) or a pixel next to it shows a body within `tol` of depth d."""
    win = (slice(max(py - 1, 0), py + 2), slice(max(px - 1, 0), px + 2))
    return bool(((mask[win] != 0) & (np.abs(depth[win] - d) <= tol)).any())


def occluded(verts, faces, cam, x, y, d, tol):
    """Whether a triangle crosses the ray from the camera centre to the point seen at pixel
    (x, y) and depth d (m along the camera axis) more than `tol` in front of it (Moller-Trumbore,
    every face at once)."""
    k, r, t = np.array(cam["K"]), np.array(cam["R"]), np.array(cam["t"])
    assert not np.any(cam["dist"]), "the point is rebuilt without lens distortion"
    p = r.T @ (d * np.linalg.solve(k, [x, y, 1.0]) - t)
    o = -r.T @ t
    ray = p - o
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    e1, e2 = b - a, c - a
    h = np.cross(ray, e2)
    det = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(det) > 1e-15
    det = np.where(ok, det, 1.0)
    s = (o - a) / det[:, None]
    u = np.einsum("ij,ij->i", s, h)
    q = np.cross(s, e1)
    v = q @ ray
    hit = np.einsum("ij,ij->i", e2, q)
    return bool((ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (hit > 0) & (hit < 1 - tol / d)).any())


def count(report, key):
    report[key] = report.get(key, 0) + 1


def check_keypoints(root, cam, coco_path, meshes, report):
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(coco_path)
    data = json.load(open(coco_path))
    cats = {c["id"]: c for c in data["categories"]}
    images = {i["id"]: i for i in data["images"]}
    for ann in data["annotations"]:
        im = images[ann["image_id"]]
        mask = cv2.imread(os.path.join(root, im["mask_file"]), cv2.IMREAD_UNCHANGED).astype(int)
        depth = cv2.imread(os.path.join(root, im["depth_file"]), cv2.IMREAD_UNCHANGED).astype(float) / 1000.0
        cat = cats[ann["category_id"]]
        first = cat["mask_labels"]["first"]
        kp = np.array(ann["keypoints"], dtype=float).reshape(-1, 3)
        bx, by, bw, bh = ann["bbox"]
        for j, ((x, y, v), d) in enumerate(zip(kp, ann["keypoint_depths_m"])):
            kind = cat["keypoint_kinds"][j]
            if v == 0:
                report["v0"] += 1
                continue
            px, py = int(np.floor(x + 0.5)), int(np.floor(y + 0.5))
            inside = 0 <= px < im["width"] and 0 <= py < im["height"] and d > 0
            if not inside:
                report["bad"].append(f"{coco_path} ann {ann['id']} kp {j}: v={v} outside the image")
                continue
            m, dd = mask[py, px], depth[py, px]
            if v == 2 and not (bx - 1e-6 <= x <= bx + bw + 1e-6 and by - 1e-6 <= y <= by + bh + 1e-6):
                report["bad"].append(f"{coco_path} ann {ann['id']} kp {j}: visible outside its bbox")
            count(report, f"{kind} v={int(v)}")
            behind = m != 0 and d > dd + TOL_M - QUANT_M
            verts, faces = meshes[im["frame"]]
            if v == 1 and kind == "surface" and not behind:
                if on_outline(mask, depth, px, py, d, TOL_M - QUANT_M):
                    report["bad"].append(f"{coco_path} ann {ann['id']} surface {j}: v=1 but the surface is drawn there")
                elif occluded(verts, faces, cam, x, y, d, TOL_M - RAY_M):
                    count(report, "surface v=1 behind a sliver thinner than a pixel (ray cast)")
                else:
                    report["bad"].append(f"{coco_path} ann {ann['id']} surface {j}: v=1 but nothing in front (ray cast)")
            elif v == 1 and not behind:
                report["bad"].append(f"{coco_path} ann {ann['id']} {kind} {j}: v=1 but not behind the buffer (depth {d:.4f} m, buffer {dd:.4f} m, label {m})")
            if kind == "surface" and v == 2:
                if m != 0 and abs(d - dd) <= TOL_M + QUANT_M:
                    count(report, "surface v=2 in the mask within 1 cm")
                elif on_outline(mask, depth, px, py, d):
                    # its pixel's centre sees the background or a surface behind the one it is on
                    count(report, "surface v=2 on an outline (a 3x3 neighbour within 1 cm)")
                elif not occluded(verts, faces, cam, x, y, d, TOL_M + RAY_M):
                    # on a rim: its pixel sees past the edge, its neighbours a nearer flank
                    count(report, "surface v=2 on a rim (ray cast: nothing 1 cm in front)")
                else:
                    report["bad"].append(f"{coco_path} ann {ann['id']} surface {j}: v=2, depth {d:.4f} m, buffer {dd:.4f} m")
            if kind == "marker" and v == 2 and m != 0 and d > dd + TOL_M + QUANT_M:
                report["bad"].append(f"{coco_path} ann {ann['id']} marker {j}: v=2 behind the buffer (depth {d:.4f} m, buffer {dd:.4f} m)")
            if kind == "joint" and v == 1 and m == first + (j - cat["keypoint_kinds"].index("joint")):
                report["bad"].append(f"{coco_path} ann {ann['id']} joint {j}: v=1 on its own segment")
    return len(coco.getAnnIds())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--every", type=int, default=25)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--supersample", type=int, default=8, help="samples a pixel edge for the reference")
    a = ap.parse_args()
    smocap = shlex.split(os.environ.get("SMOCAP_BIN", "cargo run --release --quiet --"))
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    shared = os.path.join(repo, "..", "shared", "datasets")
    worst, failures, checked, naive = 1.0, [], 0, 1.0
    report = {"v0": 0, "bad": []}
    with tempfile.TemporaryDirectory() as tmp:
        conv = os.path.join(tmp, "conv")
        datasets = ["synthetic"] + [d for d in ("gait2354_subject01", "rajagopal2016_walk") if os.path.isdir(os.path.join(shared, d))]
        for d in datasets:
            run(smocap, "convert", os.path.join(repo, "datasets.toml"), "--dataset", d, "--out", conv, "--quiet")
        trials = sorted(os.path.join(dp, f) for dp, _, fs in os.walk(conv) for f in fs if f.endswith(".mcap"))
        for n, trial in enumerate(trials):
            out = os.path.join(tmp, f"render{n}")
            run(smocap, "render", trial, "--out", out, "--every", str(a.every), "--size", a.size, "--quiet")
            cams = json.load(open(os.path.join(out, "cameras.json")))["cameras"]
            frames = sorted({im["frame"] for im in json.load(open(os.path.join(out, cams[0]["name"] + ".coco.json")))["images"]})
            meshes = os.path.join(tmp, f"mesh{n}")
            run(smocap, "export", trial, "--mesh", meshes, "--frames", ",".join(map(str, frames)))
            stem = os.path.splitext(os.path.basename(trial))[0]
            lo = 1.0
            posed = {}
            for f in frames:
                verts, faces = read_obj(os.path.join(meshes, f"{stem}_{f}.obj"))
                posed[f] = (verts, faces)
                for cam in cams:
                    mask = cv2.imread(os.path.join(out, cam["name"], "mask", f"{f:06d}.png"), cv2.IMREAD_UNCHANGED) > 0
                    ref = silhouette(verts, faces, cam, a.supersample)
                    iou = (mask & ref).sum() / max((mask | ref).sum(), 1)
                    plain = silhouette(verts, faces, cam, 1)
                    naive = min(naive, (mask & plain).sum() / max((mask | plain).sum(), 1))
                    lo = min(lo, iou)
                    checked += 1
                    if iou < 0.98:
                        failures.append(f"{trial} frame {f} camera {cam['name']}: IoU {iou:.4f}")
            anns = sum(check_keypoints(out, c, os.path.join(out, c["name"] + ".coco.json"), posed, report) for c in cams)
            print(f"{os.path.relpath(trial, conv)}: {len(frames)} frames x {len(cams)} cameras, IoU min {lo:.4f}, {anns} annotations")
            worst = min(worst, lo)
    bad = report.pop("bad")
    print(f"silhouettes: {checked} compared, IoU min {worst:.4f} (>= 0.98 required) against {a.supersample}x{a.supersample} "
          f"supersampled fills; {naive:.4f} against plain cv2.fillConvexPoly (it also fills the pixels edges pass through)")
    print("keypoints:", ", ".join(f"{k} {v}" for k, v in sorted(report.items())))
    for line in (failures + bad)[:20]:
        print("FAIL", line)
    if failures or bad:
        sys.exit(f"{len(failures)} silhouettes below IoU 0.98, {len(bad)} keypoint violations")


if __name__ == "__main__":
    main()
