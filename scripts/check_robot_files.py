#!/usr/bin/env python3
"""Checks the robot motion files of `src/retarget/files.rs` with NumPy alone.

Usage: python scripts/check_robot_files.py DIR

Every `*.pkl` (GMR's pickle), `*.npz` (qpos, fps, body and joint names, body positions) and
`*.csv` (mjlab / BeyondMimic, 30 fps, no header) in DIR is loaded the way its users load it
(`pickle.load`, `np.load` with the default `allow_pickle=False`, `np.loadtxt(..., delimiter=",")`),
with every warning an error, and checked for shapes, dtypes and writability. Files of one stem
(`walk.pkl`, `walk.npz`, `walk.csv`) are checked against each other: `qpos[:, :3]` is GMR's
`root_pos`, its w x y z quaternion is GMR's x y z w `root_rot`, the CSV starts on the first frame,
ends on the last and covers the same duration at 30 fps. Exits 1 on any problem.
"""

import pickle
import sys
import warnings
from pathlib import Path

import numpy as np

CSV_FPS = 30.0
GMR_KEYS = ["fps", "root_pos", "root_rot", "dof_pos", "local_body_pos", "link_body_list"]
NPZ_KEYS = {"qpos", "fps", "body_names", "body_pos_w", "joint_names"}


class Problem(Exception):
    pass


def need(cond, what):
    if not cond:
        raise Problem(what)


def float_array(a, name, ndim):
    need(type(a) is np.ndarray, f"{name} is a {type(a).__name__}, not a numpy.ndarray")
    need(a.dtype == np.float64, f"{name} has dtype {a.dtype}, not float64")
    need(a.ndim == ndim, f"{name} has shape {a.shape}, not {ndim}-D")
    need(np.isfinite(a).all(), f"{name} has non-finite values")


def unit_quaternions(q, name):
    norms = np.linalg.norm(q, axis=1)
    need(np.allclose(norms, 1.0, atol=1e-9), f"{name}: quaternion norms up to {np.abs(norms - 1).max():.3g} off 1")


def load_pkl(path):
    with open(path, "rb") as f:
        d = pickle.load(f)
    need(isinstance(d, dict), f"a {type(d).__name__}, not a dict")
    need(list(d) == GMR_KEYS, f"keys {list(d)}, not {GMR_KEYS}")
    need(isinstance(d["fps"], (int, float)) and d["fps"] > 0, f"fps {d['fps']!r}")
    for k, ndim in [("root_pos", 2), ("root_rot", 2), ("dof_pos", 2)]:
        float_array(d[k], k, ndim)
        need(d[k].flags.writeable, f"{k} is read-only")
        need(len(d[k]) == len(d["root_pos"]), f"{k} has {len(d[k])} frames, root_pos {len(d['root_pos'])}")
    need(d["root_pos"].shape[1] == 3 and d["root_rot"].shape[1] == 4, "root_pos or root_rot of the wrong width")
    need(d["local_body_pos"] is None and d["link_body_list"] is None, "local_body_pos, link_body_list not None")
    unit_quaternions(d["root_rot"], "root_rot")
    d["root_pos"][0, 0] += 0.0  # writable in fact, not only flagged so
    return d


def load_npz(path):
    with np.load(path) as z:
        need(set(z.files) == NPZ_KEYS, f"arrays {sorted(z.files)}, not {sorted(NPZ_KEYS)}")
        d = {k: z[k] for k in z.files}
    float_array(d["qpos"], "qpos", 2)
    float_array(d["fps"], "fps", 0)
    float_array(d["body_pos_w"], "body_pos_w", 3)
    need(float(d["fps"]) > 0, f"fps {d['fps']}")
    for k in ["body_names", "joint_names"]:
        need(d[k].dtype.kind == "U" and d[k].ndim == 1, f"{k}: dtype {d[k].dtype}, shape {d[k].shape}")
    n, width = d["qpos"].shape
    need(width == 7 + len(d["joint_names"]), f"qpos is {width} wide for {len(d['joint_names'])} joints")
    need(d["body_pos_w"].shape == (n, len(d["body_names"]), 3), f"body_pos_w has shape {d['body_pos_w'].shape}")
    need(d["qpos"].flags.writeable, "qpos is read-only")
    unit_quaternions(d["qpos"][:, 3:7], "qpos[:, 3:7]")
    return d


def load_csv(path):
    rows = np.loadtxt(path, delimiter=",", ndmin=2)
    float_array(rows, "rows", 2)
    need(rows.shape[1] >= 7, f"{rows.shape[1]} columns")
    unit_quaternions(rows[:, 3:7], "columns 4-7")
    return rows


def check_pkl_npz(pkl, npz):
    q = npz["qpos"]
    need(float(npz["fps"]) == float(pkl["fps"]), f"fps {float(npz['fps'])} (npz) vs {pkl['fps']} (pkl)")
    need(np.array_equal(q[:, :3], pkl["root_pos"]), "qpos[:, :3] != root_pos")
    need(np.array_equal(q[:, [4, 5, 6, 3]], pkl["root_rot"]), "qpos w x y z != root_rot x y z w")
    need(np.array_equal(pkl["root_rot"][:, [3, 0, 1, 2]], q[:, 3:7]), "GMR's xyzw -> wxyz != qpos")
    need(np.array_equal(q[:, 7:], pkl["dof_pos"]), "qpos[:, 7:] != dof_pos")


def check_csv(csv, fps, q):
    """The 30 fps CSV against qpos (w x y z) at `fps`."""
    need(csv.shape[1] == q.shape[1], f"csv has {csv.shape[1]} columns, qpos {q.shape[1]}")
    duration, covered = (len(q) - 1) / fps, (len(csv) - 1) / CSV_FPS
    need(duration - 1e-9 <= covered < duration + 1 / CSV_FPS - 1e-9, f"csv covers {covered} s of {duration} s")
    as_csv = q[:, [0, 1, 2, 4, 5, 6, 3] + list(range(7, q.shape[1]))]
    need(np.array_equal(csv[0], as_csv[0]), "csv's first row is not the first frame")
    end = as_csv[-1]
    flipped = np.concatenate([end[:3], -end[3:7], end[7:]])
    need(np.array_equal(csv[-1], end) or np.array_equal(csv[-1], flipped), "csv's last row is not the last frame")
    dots = np.einsum("ij,ij->i", csv[1:, 3:7], csv[:-1, 3:7])
    need((dots > 0).all(), f"csv quaternion changes sign {int((dots <= 0).sum())} times")


def check_together(files):
    """Consistency of one stem's files: (what was compared, problem or None) pairs."""
    pkl, npz, csv = files.get(".pkl"), files.get(".npz"), files.get(".csv")
    checks = []
    if pkl is not None and npz is not None:
        checks.append(("pkl=npz", lambda: check_pkl_npz(pkl, npz)))
    if csv is not None and npz is not None:
        checks.append(("csv~npz", lambda: check_csv(csv, float(npz["fps"]), npz["qpos"])))
    elif csv is not None and pkl is not None:
        q = np.hstack([pkl["root_pos"], pkl["root_rot"][:, [3, 0, 1, 2]], pkl["dof_pos"]])
        checks.append(("csv~pkl", lambda: check_csv(csv, float(pkl["fps"]), q)))
    out = []
    for name, check in checks:
        try:
            check()
            out.append((name, None))
        except Problem as e:
            out.append((name, str(e)))
    return out


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__.split("\n\n")[1])
    folder = Path(sys.argv[1])
    loaders = {".pkl": load_pkl, ".npz": load_npz, ".csv": load_csv}
    stems, problems = {}, []
    for path in sorted(folder.rglob("*")):  # every folder below (a convert --robot tree too)
        if path.suffix not in loaders or path.name.endswith(".targets.npz"):
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                stems.setdefault(str(path.with_suffix("")), {})[path.suffix] = loaders[path.suffix](path)
            print(f"ok {path.name}")
        except Exception as e:  # any failure to load is a problem of the file
            problems.append(f"{path.name}: {type(e).__name__}: {e}")
    for stem, files in sorted(stems.items()):
        for name, problem in check_together(files):
            if problem is None:
                print(f"ok {stem}: {name}")
            else:
                problems.append(f"{stem} ({name}): {problem}")
    if not stems and not problems:
        problems.append(f"no .pkl, .npz or .csv in {folder}")
    for p in problems:
        print(f"PROBLEM {p}", file=sys.stderr)
    print(f"numpy {np.__version__}: {sum(map(len, stems.values()))} files, {len(problems)} problems")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
