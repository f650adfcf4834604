"""The README's Python example runs as written (from the repository root, `../shared` beside it;
matplotlib's Agg backend) and plots a knee flexion curve."""

import re
import warnings

import pytest

from conftest import GAIT, REPO


def readme_example():
    text = (REPO / "README.md").read_text()
    return re.search(r"^```python run\n(.*?)^```", text, re.S | re.M).group(1)


def test_the_readme_example_calibrates_solves_and_plots_knee_flexion(monkeypatch):
    if not GAIT.is_dir():
        pytest.skip(f"{GAIT} is not here")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    code = readme_example()
    assert len([l for l in code.splitlines() if l.strip()]) <= 10
    monkeypatch.chdir(REPO)
    plt.close("all")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*non-interactive.*")
        exec(compile(code, "README.md", "exec"), {"__name__": "__main__"})
    (line,) = plt.gca().lines
    knee = line.get_ydata()
    assert len(knee) == 151
    # A walk: the knee extends to about 0° at heel strike and flexes to 60–75° in swing.
    assert -10 < min(knee) < 10 and 55 < max(knee) < 80
