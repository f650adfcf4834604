"""`Trial.retarget` puts a converted trial on the Unitree G1 as `smocap retarget` does."""

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import smocap
from conftest import REPO

DATASETS = """
[[dataset]]
name = "synthetic"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 1, trials = 1, frames = 120, seed = 3 }
"""


def g1_joint_ranges():
    """The G1's hinge joints in MJCF order with their ranges (rad), from the shipped g1.xml."""
    root = ET.parse(REPO / "models" / "robots" / "g1" / "g1.xml").getroot()
    joints = [j for j in root.find("worldbody").iter("joint") if j.get("type", "hinge") == "hinge"]
    return {j.get("name"): tuple(map(float, j.get("range").split())) for j in joints}


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    d = tmp_path_factory.mktemp("retarget")
    (d / "datasets.toml").write_text(DATASETS)
    summary = smocap.convert(d / "datasets.toml", d / "out", jobs=2)
    assert [t["status"] for t in summary["trials"]] == ["ok"]
    return d / "out" / "synthetic" / "subj01" / "walk01.mcap"


def test_retarget_gives_qpos_in_the_g1s_joint_ranges_and_the_report(converted):
    trial = smocap.read_trial(converted)
    q = trial.retarget("g1")
    report = q.attrs["report"]
    ranges = g1_joint_ranges()
    root = ["root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz"]
    assert list(q.columns) == root + list(ranges)
    assert q.shape == (len(trial), 7 + 29)
    assert q.index.name == "time_s" and np.allclose(q.index, trial.q.index)
    joints = q.iloc[:, 7:]
    lo = np.array([r[0] for r in ranges.values()])
    hi = np.array([r[1] for r in ranges.values()])
    assert np.all(joints.to_numpy() >= lo - 1e-9) and np.all(joints.to_numpy() <= hi + 1e-9)
    assert np.allclose(np.linalg.norm(q[root[3:]].to_numpy(), axis=1), 1.0)
    assert 0.4 < q["root_z"].median() < 1.0, "the pelvis at a G1's standing height"
    assert report["frames"] == len(trial) and report["status"] in ("ok", "suspect")
    # (How close the robot tracks is the solver's business, docs/RETARGET.md; here only sane.)
    assert report["range_violations"] == 0 and 0 <= report["end_effector_median_mm"] < 100


def test_retarget_report_is_the_command_lines(cli, converted, tmp_path):
    report = smocap.read_trial(converted).retarget().attrs["report"]
    cli("retarget", converted, "--out", tmp_path, ok=(0, 2))
    assert report == json.loads((tmp_path / "walk01.json").read_text())


def test_an_unknown_robot_is_a_model_error(converted):
    with pytest.raises(smocap.ModelError, match="neither a shipped robot"):
        smocap.read_trial(converted).retarget("h1_from_nowhere")


def test_convert_with_a_robot_writes_its_files_beside_each_trial_as_the_command_line(tmp_path):
    (tmp_path / "datasets.toml").write_text(DATASETS)
    summary = smocap.convert(tmp_path / "datasets.toml", tmp_path / "out", jobs=2, robot="g1")
    [trial] = summary["trials"]
    assert trial["robot"]["status"] in ("ok", "suspect"), trial["robot"]
    stem = tmp_path / "out" / "synthetic" / "subj01" / "walk01.g1"
    for ext in ("pkl", "csv", "npz", "json"):
        assert stem.with_name(f"walk01.g1.{ext}").is_file(), ext
    report = json.loads(stem.with_name("walk01.g1.json").read_text())
    assert report["frames"] == 120 and report["range_violations"] == 0
    with np.load(stem.with_name("walk01.g1.npz")) as z:
        assert z["qpos"].shape == (120, 7 + 29)


def test_convert_with_an_unknown_robot_is_a_model_error(tmp_path):
    (tmp_path / "datasets.toml").write_text(DATASETS)
    with pytest.raises(smocap.ModelError, match="neither a shipped robot"):
        smocap.convert(tmp_path / "datasets.toml", tmp_path / "out", robot="h1_from_nowhere")
