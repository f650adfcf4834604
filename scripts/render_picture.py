#!/usr/bin/env python3
"""The guide's picture of `smocap render`: one frame from two cameras, each as RGB beside the mask
(one colour per body) with the keypoints drawn (green visible, red occluded), cropped around the
subject. Needs numpy and OpenCV.

    smocap render TRIAL.mcap --out R --every 50
    python3 scripts/render_picture.py R --frame 100 --out docs/render.png
"""
import argparse
import json
import os

import cv2
import numpy as np


def panel(root, cam, frame, height):
    coco = json.load(open(os.path.join(root, f"{cam}.coco.json")))
    im = next(i for i in coco["images"] if i["frame"] == frame)
    rgb = cv2.imread(os.path.join(root, im["file_name"]))
    mask = cv2.imread(os.path.join(root, im["mask_file"]), cv2.IMREAD_UNCHANGED).astype(int)
    palette = np.random.default_rng(3).integers(60, 255, size=(mask.max() + 1, 3)).astype(np.uint8)
    palette[0] = 0
    seg = palette[mask]
    ann = next(a for a in coco["annotations"] if a["image_id"] == im["id"])
    kinds = coco["categories"][0]["keypoint_kinds"]
    for (x, y, v), kind in zip(np.array(ann["keypoints"]).reshape(-1, 3), kinds):
        if v > 0 and kind != "marker":
            colour = (80, 220, 80) if v == 2 else (60, 60, 230)
            cv2.circle(seg, (int(round(x)), int(round(y))), 3, colour, -1, cv2.LINE_AA)
    bx, by, bw, bh = ann["bbox"]
    cx, cy, half = bx + bw / 2, by + bh / 2, max(bw, bh) * 0.62
    x0, y0 = int(max(cx - half, 0)), int(max(cy - half, 0))
    x1, y1 = int(min(cx + half, rgb.shape[1])), int(min(cy + half, rgb.shape[0]))
    tiles = [cv2.resize(t[y0:y1, x0:x1], (int(height * (x1 - x0) / (y1 - y0)), height), interpolation=cv2.INTER_AREA) for t in (rgb, seg)]
    return np.hstack(tiles)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root")
    ap.add_argument("--frame", type=int, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--height", type=int, default=360)
    a = ap.parse_args()
    cams = [c["name"] for c in json.load(open(os.path.join(a.root, "cameras.json")))["cameras"]][:2]
    cv2.imwrite(a.out, np.hstack([panel(a.root, c, a.frame, a.height) for c in cams]), [cv2.IMWRITE_PNG_COMPRESSION, 9])


if __name__ == "__main__":
    main()
