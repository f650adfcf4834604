"""`smocap.convert` runs `smocap convert`; `smocap.read_trial` reads its files back."""

import numpy as np

import smocap

DATASETS = """
[[dataset]]
name = "synthetic"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 1, trials = 2, frames = 120, seed = 3 }
"""


def test_convert_then_read_trial(cli, tmp):
    (tmp / "datasets.toml").write_text(DATASETS)
    events = []
    summary = smocap.convert(tmp / "datasets.toml", tmp / "out", jobs=2, progress=events.append)
    assert [t["status"] for t in summary["trials"]] == ["ok", "ok"]
    assert events[-1]["event"] == "done" and events[-1]["trials_done"] == 2
    assert sum(e["event"] == "trial" for e in events) >= 2
    first = summary["trials"][0]
    path = tmp / "out" / "synthetic" / first["trial"].replace(".trc", ".mcap")
    trial = smocap.read_trial(path)
    assert len(trial) == first["frames"] == 120
    q, stats = trial.q, trial.stats
    assert q.shape == (120, len(trial.subject["coordinates"])) and list(q.columns) == trial.subject["coordinates"]
    assert q.index.name == "time_s" and np.all(np.diff(q.index) > 0)
    assert {"iterations", "rmse", "marker_rmse", "status", "bridged"} <= set(stats.columns)
    assert (stats["status"] == "Converged").mean() > 0.5 and stats["marker_rmse"].max() < 0.05
    assert trial.markers.shape == (120, len(trial.marker_names), 3) == (120, len(trial.subject["markers"]), 3)
    assert np.isfinite(trial.markers).any()
    scales = trial.subject["scales"]
    assert set(scales) == set(trial.subject["bodies"]) and all(0.5 < v < 2 for s in scales.values() for v in s)
    # The label quality control of the trial (clean synthetic labels: screened, nothing found).
    qc = trial.label_qc
    assert qc["mode"] == "repair" and qc["events"] == [] and qc["suspect"] is None and qc["rigid_pairs"] > 0
    # No frame the model cannot fit: no /smocap/unfittable channel, an empty list.
    assert trial.unfittable == []
    # The .mot as `smocap export --mot` writes it.
    trial.to_mot(tmp / "py.mot")
    cli("export", path, "--mot", tmp / "cli.mot")
    assert (tmp / "py.mot").read_bytes() == (tmp / "cli.mot").read_bytes()
    # A second run with resume skips both.
    again = smocap.convert(tmp / "datasets.toml", tmp / "out", resume=True)
    assert [t["status"] for t in again["trials"]] == ["skipped", "skipped"]


def test_a_file_that_is_not_mcap_is_an_archive_error(tmp):
    (tmp / "x.mcap").write_bytes(b"not an mcap file")
    try:
        smocap.read_trial(tmp / "x.mcap")
    except smocap.ArchiveError as e:
        assert "x.mcap" in str(e)
    else:
        raise AssertionError("no error")


def test_a_missing_datasets_file_is_an_archive_error(tmp):
    try:
        smocap.convert(tmp / "none.toml", tmp / "out")
    except smocap.ArchiveError as e:
        assert "none.toml" in str(e)
    else:
        raise AssertionError("no error")


def test_an_exception_in_the_progress_callback_is_raised_after_the_run(tmp):
    (tmp / "datasets.toml").write_text(DATASETS)

    def progress(event):
        raise RuntimeError("callback broke")

    try:
        smocap.convert(tmp / "datasets.toml", tmp / "out", progress=progress)
    except RuntimeError as e:
        assert "callback broke" in str(e)
    else:
        raise AssertionError("no error")
    # The run itself went on: both files are there.
    assert len(list((tmp / "out" / "synthetic").rglob("*.mcap"))) == 2
