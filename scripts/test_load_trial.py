#!/usr/bin/env python3
"""Test of the README's Python recipe (scripts/load_trial.py) against `smocap export --csv`:
converts a small synthetic archive with the smocap binary, loads the trial with the official
`mcap` readers and checks that every coordinate of every frame equals the exported CSV's, and
that the frame count, times and marker RMSE agree. Also runs scripts/check_mcap.py on the file.

    python3 scripts/test_load_trial.py [path/to/smocap]     # default: target/release/smocap
    # or with pytest: SMOCAP=path/to/smocap pytest scripts/test_load_trial.py

Needs mcap, mcap-protobuf-support, numpy (pandas optional), in a venv outside the repository.
"""

import csv
import os
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import load_trial  # noqa: E402

TOML = """[[dataset]]
name = "lab"
root = "data"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 1, trials = 1, frames = 60, seed = 4 }
"""


def smocap_binary():
    b = os.environ.get("SMOCAP") or (sys.argv[1] if len(sys.argv) > 1 and __name__ == "__main__" else None)
    return b or str(HERE.parent / "target" / "release" / "smocap")


def test_recipe_matches_export():
    with tempfile.TemporaryDirectory() as d:
        d = pathlib.Path(d)
        (d / "datasets.toml").write_text(TOML)
        exe = smocap_binary()
        subprocess.run([exe, "convert", str(d / "datasets.toml"), "--out", str(d / "out"), "--quiet"], check=True)
        path = d / "out" / "lab" / "subj01" / "walk01.mcap"
        csv_path = d / "walk01.csv"
        subprocess.run([exe, "export", str(path), "--csv", str(csv_path)], check=True)
        q, stats, subject = load_trial.load(path)
        with open(csv_path) as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == 60
        if load_trial.pd is not None:
            qv, times, names, rmse = q.to_numpy(), q.index.to_numpy(), list(q.columns), stats["marker_rmse"].to_numpy()
        else:
            (times, qv, names), (st, cols) = q, stats
            rmse = st[:, cols.index("marker_rmse")]
        assert qv.shape == (60, len(subject.coordinates))
        for name in names:
            col = np.array([float(r[name]) for r in rows])
            j = names.index(name)
            assert np.allclose(qv[:, j], col, rtol=1e-12, atol=1e-12), name
        assert np.allclose(times, [float(r["time"]) for r in rows], atol=1e-9)
        assert np.allclose(rmse, [float(r["rmse_m"]) for r in rows], rtol=1e-12)
        subprocess.run([sys.executable, str(HERE / "check_mcap.py"), str(path)], check=True)


if __name__ == "__main__":
    test_recipe_matches_export()
    print("1 passed, 0 failed")
