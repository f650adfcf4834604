"""`Trial.body()`: the subject's body mesh posed at every frame of a converted trial."""

import numpy as np

import smocap

DATASETS = """
[[dataset]]
name = "synthetic"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 1, trials = 1, frames = 40, seed = 3 }
"""


def test_body_of_a_converted_trial(cli, tmp):
    (tmp / "datasets.toml").write_text(DATASETS)
    summary = smocap.convert(tmp / "datasets.toml", tmp / "out", jobs=1)
    first = summary["trials"][0]
    trial = smocap.read_trial(tmp / "out" / "synthetic" / first["trial"].replace(".trc", ".mcap"))
    vertices, faces = trial.body()
    assert vertices.dtype == np.float32 and faces.dtype == np.uint32
    assert vertices.shape == (len(trial), 13_380, 3)
    assert faces.shape == (26_756, 3) and faces.max() == 13_379
    assert np.isfinite(vertices).all()
    # a standing adult: 1.4 to 2.1 m from the lowest to the highest vertex, Z up
    height = vertices[0, :, 2].max() - vertices[0, :, 2].min()
    assert 1.4 < height < 2.1, height
    # closed and outward: the enclosed volume is positive (about 0.05 to 0.12 m³)
    a, b, c = (vertices[0][faces[:, k]].astype(np.float64) for k in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert 0.03 < volume < 0.15, volume
    # it moves: the frames differ
    assert np.abs(vertices[-1] - vertices[0]).max() > 0.01


def test_convert_with_body_measures_it_beside_each_trial(cli, tmp):
    (tmp / "datasets.toml").write_text(DATASETS)
    summary = smocap.convert(tmp / "datasets.toml", tmp / "out", jobs=1, body=True)
    [trial] = summary["trials"]
    body = trial["body"]
    assert body["status"] in ("ok", "suspect"), body
    assert abs(body["height_minus_stature_mm"]) < 50 and body["virtual_marker_error_mm"] < 20, body
    report = tmp / "out" / "synthetic" / trial["trial"].replace(".trc", ".body.json")
    assert report.is_file()

