"""The binding gives the command line's results: `Motion.to_mot` writes the bytes `smocap solve
--mot-dir` writes, the reports agree, and `Markers` built from arrays solve as the file does."""

import json

import numpy as np
import pytest

import smocap
from conftest import read_trc_arrays

# Report fields that are wall-clock timings (they differ between any two runs).
TIMINGS = {"ms_per_frame", "solve_wall_s", "seconds"}


def without_timings(d):
    """`d` without its timings, at any depth (a calibration's cost per stage holds some)."""
    if isinstance(d, dict):
        return {k: without_timings(v) for k, v in d.items() if k not in TIMINGS}
    if isinstance(d, list):
        return [without_timings(v) for v in d]
    return d


def cli_solve(cli, tmp, trials, *args):
    out = tmp / "cli"
    cli("solve", *trials, *args, "--backend", "cpu", "--mot-dir", out, "--report-json", out / "report.json", ok=(0, 3))
    return out, json.loads((out / "report.json").read_text())


def test_to_mot_is_byte_identical_to_the_cli_on_a_synthetic_trial(cli, synthetic, tmp):
    out, report = cli_solve(cli, tmp, [synthetic], "--threads", "2")
    subject = smocap.calibrate(None, [synthetic])
    motion = subject.solve(synthetic, threads=1)  # threads change the speed, not the result
    motion.to_mot(tmp / "py.mot")
    assert (tmp / "py.mot").read_bytes() == (out / "walk.mot").read_bytes()
    # The same report: the trial's entry and the calibration section, timings aside.
    assert without_timings(motion.report) == without_timings(report["trials"][0])
    assert without_timings(subject.report) == without_timings(report["calibration"])
    assert motion.status == "ok" and subject.status == "ok"


def test_to_mot_and_scaled_model_are_byte_identical_to_the_cli_on_gait2354_with_its_setups(cli, gait, tmp):
    osim, setup, ik = gait / "gait2354_simbody.osim", gait / "subject01_Setup_Scale.xml", gait / "subject01_Setup_IK.xml"
    static, walk = gait / "subject01_static.trc", gait / "subject01_walk1.trc"
    out, report = cli_solve(
        cli, tmp, [walk], "--model", osim, "--scale-setup", setup, "--ik-setup", ik, "--static", static,
        "--scaled-model", tmp / "cli" / "subject01.osim",
    )
    model = smocap.Model(osim, scale_setup=setup, ik_setup=ik)
    subject = smocap.calibrate(model, [walk], static=static)
    motion = subject.solve(walk)
    motion.to_mot(tmp / "py.mot")
    assert (tmp / "py.mot").read_bytes() == (out / "subject01_walk1.mot").read_bytes()
    scaleset = subject.write_osim(tmp / "py.osim")
    assert (tmp / "py.osim").read_bytes() == (out / "subject01.osim").read_bytes()
    assert open(scaleset, "rb").read() == (out / "subject01.scaleset.xml").read_bytes()
    assert without_timings(motion.report) == without_timings(report["trials"][0])
    assert subject.stature_m == report["calibration"]["prior"]["stature_m"]


def test_q_is_the_mot_in_radians_and_metres(gait, tmp):
    model = smocap.Model(gait / "gait2354_simbody.osim", markerset=gait / "gait2354_Scale_MarkerSet.xml")
    walk = gait / "subject01_walk1.trc"
    motion = smocap.calibrate(model, walk, static=gait / "subject01_static.trc").solve(walk)
    motion.to_mot(tmp / "walk.mot")
    lines = (tmp / "walk.mot").read_text().splitlines()
    start = lines.index("endheader") + 1
    columns = lines[start].split("\t")
    table = np.array([[float(v) for v in line.split("\t")] for line in lines[start + 1 :]])
    q = motion.q
    assert list(q.columns) == model.coordinates == columns[1:]
    assert q.index.name == "time_s" and np.array_equal(q.index.to_numpy(), table[:, 0])
    for name, unit in zip(model.coordinates, model.coordinate_units):
        got = q[name].to_numpy()
        mot = table[:, columns.index(name)]
        # Rotations in degrees in the .mot (coupled coordinates stay radians, as OpenSim writes).
        assert np.allclose(got, mot, rtol=0, atol=1e-12) or np.allclose(np.degrees(got), mot, rtol=1e-14, atol=1e-12), name
    stats = motion.stats
    assert len(stats) == len(motion) == len(q)
    assert {"rmse", "iterations", "status", "bridged"} <= set(stats.columns)
    assert stats["rmse"].median() * 1e3 == pytest.approx(motion.report["marker_rmse_mm"]["p50"])


def test_markers_from_arrays_solve_as_the_file(gait, tmp):
    static, walk = gait / "subject01_static.trc", gait / "subject01_walk1.trc"
    model = smocap.Model(gait / "gait2354_simbody.osim", markerset=gait / "gait2354_Scale_MarkerSet.xml")
    from_files = smocap.calibrate(model, [walk], static=static)
    from_files.solve(walk).to_mot(tmp / "file.mot")

    def arrays(path):
        labels, rate, units, times, xyz = read_trc_arrays(path)
        return smocap.Markers(labels, xyz, rate, units=units, times=times, name=str(path))

    walk_m = arrays(walk)
    from_arrays = smocap.calibrate(model, [walk_m], static=arrays(static))
    from_arrays.solve(walk_m).to_mot(tmp / "arrays.mot")
    assert (tmp / "arrays.mot").read_bytes() == (tmp / "file.mot").read_bytes()
    assert from_arrays.scales == from_files.scales


def test_read_markers_round_trips_through_markers(synthetic):
    m = smocap.read_markers(synthetic)
    assert m.xyz.shape == (len(m), len(m.labels), 3) and m.units == "mm" and m.rate_hz > 0
    labels, rate, units, times, xyz = read_trc_arrays(synthetic)
    assert m.labels == labels and np.array_equal(m.times, times)
    np.testing.assert_allclose(m.xyz, xyz, rtol=1e-15, atol=0)
    again = smocap.Markers(m.labels, m.xyz, m.rate_hz, units=m.units)
    np.testing.assert_allclose(again.xyz, m.xyz, rtol=1e-15, atol=0)
    assert np.allclose(again.times, np.arange(len(m)) / m.rate_hz)
    metres = smocap.Markers(m.labels, m.xyz / 1000, m.rate_hz)
    assert metres.units == "m" and np.allclose(metres.xyz * 1000, m.xyz, equal_nan=True)
