"""Fixtures of the Python tests: the `smocap` command line to compare against, the shared data,
a synthetic trial. Run against the installed package (`.ci/run` builds the wheel, installs it in a
fresh venv under target/ and runs `pytest python/tests`)."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"
GAIT = SHARED / "datasets" / "gait2354_subject01"


def _cli():
    """The smocap binary: SMOCAP_BIN, else the one cargo built in this checkout's target dir."""
    env = os.environ.get("SMOCAP_BIN")
    if env:
        return Path(env).resolve()
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    for profile in ("debug", "release"):
        p = target / profile / "smocap"
        if p.is_file():
            return p
    return None


@pytest.fixture(scope="session")
def cli():
    """Runs the command line (`cli("solve", ...)`), failing the test on a non-zero exit."""
    exe = _cli()
    if exe is None or not exe.is_file():
        pytest.fail("no smocap binary: set SMOCAP_BIN or run `cargo build` first")

    def run(*args, cwd=None, ok=(0,)):
        r = subprocess.run([str(exe), *map(str, args)], cwd=cwd, capture_output=True, text=True)
        assert r.returncode in ok, f"smocap {' '.join(map(str, args))}: exit {r.returncode}\n{r.stderr}"
        return r

    return run


@pytest.fixture(scope="session")
def gait():
    if not GAIT.is_dir():
        pytest.skip(f"{GAIT} is not here")
    return GAIT


@pytest.fixture(scope="session")
def synthetic(cli, tmp_path_factory):
    """A synthetic walk of the shipped model (TRC in mm) and its truth."""
    d = tmp_path_factory.mktemp("synth")
    cli("synth", "--frames", 400, "--noise-mm", 2, "--seed", 7, "--out", d / "walk.trc", "--truth", d / "walk.json")
    return d / "walk.trc"


@pytest.fixture(scope="session")
def long_synthetic(cli, tmp_path_factory):
    """A longer synthetic walk (several segments: solved in parallel lanes)."""
    d = tmp_path_factory.mktemp("synth_long")
    cli("synth", "--frames", 2400, "--noise-mm", 2, "--seed", 11, "--out", d / "walk.trc", "--truth", d / "walk.json")
    return d / "walk.trc"


def read_trc_arrays(path):
    """A TRC file's labels, rate, times and positions (frames x markers x 3, as written, NaN for
    empty cells), parsed here with NumPy alone: data that reaches smocap as arrays."""
    import numpy as np

    lines = Path(path).read_text().splitlines()
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = dict(zip(keys, values))
    labels = [c for c in lines[3].split("\t")[2:] if c.strip()]
    rows = []
    for line in lines[5:]:
        if not line.strip():
            continue
        cells = line.split("\t")
        vals = [float(c) if c.strip() else np.nan for c in cells[: 2 + 3 * len(labels)]]
        vals += [np.nan] * (2 + 3 * len(labels) - len(vals))
        rows.append(vals)
    a = np.array(rows)
    return labels, float(header["DataRate"]), header["Units"].strip(), a[:, 1], a[:, 2:].reshape(len(a), len(labels), 3)


@pytest.fixture
def tmp(tmp_path):
    yield tmp_path
    shutil.rmtree(tmp_path, ignore_errors=True)
