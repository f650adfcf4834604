"""`smocap.render` against `smocap render`: the same pixels in memory as in the written files."""

import json

import numpy as np
import pytest

import smocap


TOML = """[[dataset]]
name = "lab"
root = "data"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 1, trials = 1, frames = 20, seed = 4 }
"""


def _png(path):
    image = pytest.importorskip("PIL.Image")  # with matplotlib
    return np.array(image.open(path))


def test_render_in_memory_matches_the_command_line(cli, tmp_path):
    (tmp_path / "datasets.toml").write_text(TOML)
    cli("convert", tmp_path / "datasets.toml", "--out", tmp_path / "out", "--quiet")
    synthetic_trial = tmp_path / "out" / "lab" / "subj01" / "walk01.mcap"
    out = tmp_path / "r"
    r = cli("render", synthetic_trial, "--out", out, "--size", "160x120", "--every", "5", "--seed", "4", "-q", ok=(0, 1))
    if r.returncode != 0 and "no adapter" in r.stderr:
        pytest.skip("no wgpu adapter")
    assert r.returncode == 0, r.stderr
    coco = json.loads((out / "frontal.coco.json").read_text())
    frames = [im["frame"] for im in coco["images"]][:2]
    got = smocap.render(str(synthetic_trial), size=(160, 120), frames=frames, seed=4)
    assert got["frames"] == frames
    front = got["frontal"]
    assert front["rgb"].shape == (2, 120, 160, 3) and front["rgb"].dtype == np.uint8
    assert front["mask"].shape == (2, 120, 160) and front["depth"].dtype == np.float32
    k = len(coco["categories"][0]["keypoints"])
    assert front["keypoints"].shape == (2, k, 3)
    np.testing.assert_allclose(front["keypoints"][0].ravel(), coco["annotations"][0]["keypoints"])
    np.testing.assert_allclose(front["keypoint_depths_m"][0], coco["annotations"][0]["keypoint_depths_m"])
    assert got["keypoint_names"] == coco["categories"][0]["keypoints"]
    assert (front["mask"] > 0).sum() > 100
    mask = _png(out / "frontal" / "mask" / f"{frames[0]:06d}.png")
    np.testing.assert_array_equal(mask, front["mask"][0])
    depth = _png(out / "frontal" / "depth" / f"{frames[0]:06d}.png")
    np.testing.assert_array_equal(depth, np.clip(np.round(front["depth"][0].astype(np.float64) * 1000), 0, 65535))
    rgb = _png(out / "frontal" / "rgb" / f"{frames[0]:06d}.png")
    np.testing.assert_array_equal(rgb, front["rgb"][0])
