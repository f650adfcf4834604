#!/usr/bin/env python3
"""Independent checks of the derived body asset (models/body/body.{json,bin}, written by
scripts/derive_body.py), read back from the files alone, with trimesh for the mesh tests.

    python3 -m venv /tmp/bodyvenv && /tmp/bodyvenv/bin/pip install numpy trimesh
    /tmp/bodyvenv/bin/python scripts/check_body_asset.py

Checks: the file table and checksum; the reference shape (all parameters 0.5) is watertight,
winding-consistent, 2-manifold, of positive volume (trimesh); its stature against the header;
skinning weights sum to 1 (65535/65535) with at most 4 influences and valid segment indices; per-
segment vertex counts against shared/design/body_mesh.md §2. Exits non-zero on a failure.
"""
import hashlib
import json
import os
import sys

import numpy as np
import trimesh

HERE = os.path.dirname(os.path.abspath(__file__))
DIR = os.path.join(HERE, "..", "models", "body")
DT = {"f32": "<f4", "f16": "<f2", "u16": "<u2", "u8": "u1"}
# Vertices with any weight per segment, from the design note (sided segments: per side).
EXPECTED_COUNTS = {"pelvis": 1076, "torso": 2124, "head": 4494, "femur": 703, "tibia": 425,
                   "calcn": 555, "toes": 813, "humerus": 661, "ulna": 385, "radius": 227,
                   "hand": 1685}

failures = []


def check(ok, what):
    print("%s %s" % ("ok  " if ok else "FAIL", what))
    if not ok:
        failures.append(what)


def main():
    hdr = json.load(open(os.path.join(DIR, "body.json")))
    data = open(os.path.join(DIR, "body.bin"), "rb").read()
    check(hashlib.sha256(data).hexdigest() == hdr["bin_sha256"], "body.bin matches bin_sha256")
    arr = {}
    end = 0
    for t in hdr["arrays"]:
        a = np.frombuffer(data, dtype=DT[t["dtype"]], count=int(np.prod(t["shape"])),
                          offset=t["offset"]).reshape(t["shape"])
        check(a.nbytes == t["nbytes"], "%s: %s %s" % (t["name"], t["dtype"], t["shape"]))
        arr[t["name"]] = a.astype(np.float64) if t["dtype"].startswith("f") else a
        end = max(end, t["offset"] + t["nbytes"])
    check(end == len(data), "arrays cover body.bin (%d bytes)" % len(data))
    nb = hdr["body_vertices"]
    coeffs = np.array(hdr["reference"]["coeffs"])
    pts = arr["mean"] + np.tensordot(coeffs, arr["components"], axes=1)
    tris = arr["triangles"].astype(np.int64)
    check(tris.max() < nb, "triangles index body vertices only")

    mesh = trimesh.Trimesh(vertices=pts[:nb], faces=tris, process=False)
    print("trimesh: vertices %d faces %d watertight %s winding_consistent %s is_volume %s "
          "euler %d volume %.5f m^3 area %.4f m^2" % (
              len(mesh.vertices), len(mesh.faces), mesh.is_watertight,
              mesh.is_winding_consistent, mesh.is_volume, mesh.euler_number, mesh.volume,
              mesh.area))
    check(mesh.is_watertight, "watertight")
    check(mesh.is_winding_consistent, "winding consistent")
    check(mesh.volume > 0, "positive volume (outward normals)")
    check(mesh.euler_number == 2, "Euler characteristic 2 (a sphere)")
    edges = np.sort(mesh.edges, axis=1)
    _, cnt = np.unique(edges, axis=0, return_counts=True)
    check(bool((cnt == 2).all()), "every edge shared by exactly two triangles (%d edges)" % len(cnt))
    lo, hi = mesh.bounds
    stature = hi[2] - lo[2]
    print("reference bounds (m): x %.4f..%.4f y %.4f..%.4f z %.4f..%.4f" %
          (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
    check(abs(stature - hdr["reference"]["stature_m"]) < 1e-4,
          "reference stature %.4f m (header %.4f m)" % (stature, hdr["reference"]["stature_m"]))
    check(hi[0] - lo[0] < hi[1] - lo[1] < hi[2] - lo[2],
          "Z up, A-pose wider (Y) than deep (X)")
    # the figure faces +X: the toes are ahead of the heels
    joints = hdr["joints"]
    jc = pts[nb:]
    toe, ankle = jc[joints.index("joint-r-foot-2")], jc[joints.index("joint-r-ankle")]
    check(toe[0] > ankle[0] + 0.05, "faces +X (right toe %.3f m ahead of the ankle)" % (toe[0] - ankle[0]))
    lk, rk = jc[joints.index("joint-l-knee")], jc[joints.index("joint-r-knee")]
    check(lk[1] > rk[1], "left is +Y")

    segs = hdr["segments"]
    s, w = arr["skin_segments"], arr["skin_weights"].astype(np.int64)
    check(s.shape == (nb, 4) and w.shape == (nb, 4), "4 influences per vertex")
    check(bool((w.sum(axis=1) == 65535).all()), "weights sum to 65535/65535 for every vertex")
    check(int(s.max()) < len(segs), "segment indices < %d" % len(segs))
    check(bool(((w == 0) <= (s == 0)).all()), "unused slots have segment 0")
    check(bool((np.diff(w, axis=1) <= 0).all()), "weights sorted decreasing")
    n_infl = (w > 0).sum(axis=1)
    print("influences per vertex: %s" % {int(k): int(v) for k, v in zip(*np.unique(n_infl, return_counts=True))})
    counts = {name: int(((s == i) & (w > 0)).any(axis=1).sum()) for i, name in enumerate(segs)}
    print("vertices per segment: %s" % counts)
    for name, n in counts.items():
        exp = EXPECTED_COUNTS[name.split("_")[0]]
        check(abs(n - exp) <= 2, "%s: %d vertices (design note %d)" % (name, n, exp))
    if failures:
        print("%d check(s) failed" % len(failures))
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
