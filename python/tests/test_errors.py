"""Errors are exceptions (`smocap.SmocapError` and subclasses) carrying the command line's
message: the file, the line, what was expected."""

import numpy as np
import pytest

import smocap


def test_a_missing_marker_file_names_the_file(tmp):
    with pytest.raises(smocap.MarkerFileError, match="nope.trc"):
        smocap.read_markers(tmp / "nope.trc")


def test_an_unsupported_extension_lists_the_supported_ones(tmp):
    (tmp / "walk.csv").write_text("x")
    with pytest.raises(smocap.MarkerFileError, match="unsupported marker file type 'csv' .*trc, c3d"):
        smocap.read_markers(tmp / "walk.csv")


def test_a_broken_trc_names_the_file(tmp, synthetic):
    lines = synthetic.read_text().splitlines()
    lines[2] = "sixty\tsixty\t10\t3\tmm"
    (tmp / "broken.trc").write_text("\n".join(lines) + "\n")
    with pytest.raises(smocap.SmocapError, match="broken.trc"):
        smocap.read_markers(tmp / "broken.trc")


def test_every_error_is_a_smocap_error():
    for e in (smocap.MarkerFileError, smocap.ModelError, smocap.CalibrationError, smocap.SolveError, smocap.ArchiveError):
        assert issubclass(e, smocap.SmocapError)
    assert issubclass(smocap.SmocapWarning, UserWarning)


def test_a_missing_model_is_a_model_error(tmp):
    with pytest.raises(smocap.ModelError, match="missing.osim"):
        smocap.Model(tmp / "missing.osim")


def test_a_marker_set_needs_a_model(tmp):
    with pytest.raises(smocap.ModelError, match="needs a model file"):
        smocap.Model(markerset=tmp / "set.xml")


def test_an_implausible_height_is_a_calibration_error(synthetic):
    with pytest.raises(smocap.CalibrationError, match="height"):
        smocap.calibrate(None, [synthetic], height=5.0)


def test_an_unknown_sex_is_a_calibration_error(synthetic):
    with pytest.raises(smocap.CalibrationError):
        smocap.calibrate(None, [synthetic], sex="robot")


def test_an_unknown_setting_lists_the_valid_ones(synthetic):
    with pytest.raises(smocap.ModelError, match="unknown solver setting `no_such_thing` \\(valid: .*max_iterations"):
        smocap.calibrate(None, [synthetic], settings={"no_such_thing": 1})


def test_a_trial_whose_markers_match_none_of_the_model_fails_with_the_labels(synthetic):
    subject = smocap.calibrate(None, [synthetic])
    alien = smocap.Markers(["foo", "bar", "baz"], np.zeros((10, 3, 3)), 100.0, name="alien")
    with pytest.raises(smocap.SolveError, match="alien.*none of its markers matches.*foo"):
        subject.solve(alien)


def test_bad_arrays_and_arguments_are_value_errors(synthetic):
    with pytest.raises(ValueError, match="expected \\(frames, 2, 3\\)"):
        smocap.Markers(["a", "b"], np.zeros((4, 3, 3)), 100.0)
    with pytest.raises(smocap.MarkerFileError, match="sampling rate"):
        smocap.Markers(["a"], np.zeros((4, 1, 3)), -1.0)
    with pytest.raises(smocap.MarkerFileError, match="unknown units"):
        smocap.Markers(["a"], np.zeros((4, 1, 3)), 100.0, units="furlong")
    with pytest.raises(ValueError, match="units"):
        smocap.read_markers(synthetic, units="furlong")
    subject = smocap.calibrate(None, [synthetic])
    with pytest.raises(ValueError, match="backend"):
        subject.solve(synthetic, backend="tpu")
    with pytest.raises(ValueError, match="threads 0"):
        subject.solve(synthetic, threads=0)
    with pytest.raises(ValueError, match="expected a marker file path or smocap.Markers"):
        subject.solve(42)


def test_a_settings_override_changes_the_solve(synthetic):
    # One iteration and no convergence test: every frame stops at the cap, so the trial is
    # suspect, and says so.
    never = {k: 0.0 for k in ("residual_tol_m", "rel_decrease_tol", "model_error_tol", "step_tol")}
    subject = smocap.calibrate(None, [synthetic], settings={"max_iterations": 1, **never})
    with pytest.warns(smocap.SmocapWarning, match="suspect: .*iteration cap"):
        motion = subject.solve(synthetic)
    assert motion.status == "suspect" and "iteration cap" in motion.report["error"]
