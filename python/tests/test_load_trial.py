"""scripts/load_trial.py (docs/guide/python.md's recipe for converted trials) against
`smocap export --csv`: every coordinate of every frame, the times and the marker RMSE agree."""

import csv
import runpy

import numpy as np

from conftest import REPO

TOML = """[[dataset]]
name = "lab"
root = "data"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 1, trials = 1, frames = 60, seed = 4 }
"""


def test_recipe_matches_export_csv(cli, tmp):
    (tmp / "datasets.toml").write_text(TOML)
    cli("convert", tmp / "datasets.toml", "--out", tmp / "out", "--quiet")
    path = tmp / "out" / "lab" / "subj01" / "walk01.mcap"
    cli("export", path, "--csv", tmp / "walk01.csv")
    load = runpy.run_path(str(REPO / "scripts" / "load_trial.py"))["load"]
    q, stats, subject = load(path)
    with open(tmp / "walk01.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 60 and q.shape == (60, len(subject["coordinates"]))
    for name in q.columns:
        assert np.array_equal(q[name].to_numpy(), [float(r[name]) for r in rows]), name
    assert np.allclose(q.index.to_numpy(), [float(r["time"]) for r in rows], rtol=0, atol=1e-12)
    assert np.array_equal(stats["marker_rmse"].to_numpy(), [float(r["rmse_m"]) for r in rows])
    assert list(stats["status"]) == [r["status"] for r in rows]
    for body, s in subject["scales"].items():
        assert all(0.5 < v < 2.0 for v in s), body
