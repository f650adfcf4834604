"""The Python examples of the docs run as written.

Every fenced block whose info string is `python run` in README.md and docs/guide/*.md is executed,
the blocks of one page in order in one namespace (a later block may use an earlier one's names and
files), in a scratch folder laid out like a checkout: `T/repo/` with links to the repository's
files (datasets.toml copied: its paths resolve against its folder), `T/shared` a link to the real
`../shared`; `smocap` (the binary under test, as `cli` finds it) first on PATH; matplotlib on its
Agg backend. Blocks that mention `../shared` are skipped where it is absent. The shell blocks
(`sh run`) are run by `cargo test --test docs` (tests/docs.rs).
"""

import os
import re
import shutil
import warnings

import pytest

from conftest import REPO, SHARED, _cli

LINKED = ["models", "examples", "scripts", "docs", "proto", "shaders", "python", "src", "tests",
          "benches", "Cargo.toml", "Cargo.lock", "pyproject.toml", "README.md", "BENCHMARKS.md"]
COPIED = ["datasets.toml"]
FENCE = re.compile(r"^[ \t]*(`{3,})[ \t]*([^\n`]*)\n(.*?)^[ \t]*\1[ \t]*$", re.S | re.M)


def pages():
    names = ["README.md"] + sorted(f"docs/guide/{p.name}" for p in (REPO / "docs" / "guide").glob("*.md"))
    return [n for n in names if (REPO / n).is_file()]


def python_blocks(page):
    """(line of the opening fence, code) of each `python run` block of a page."""
    text = (REPO / page).read_text()
    out = []
    for m in FENCE.finditer(text):
        if m.group(2).split() == ["python", "run"]:
            out.append((text.count("\n", 0, m.start()) + 1, m.group(3)))
    return out


RUNNABLE = [p for p in pages() if python_blocks(p)]


def scratch(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    for name in LINKED:
        if (REPO / name).exists():
            (repo / name).symlink_to(REPO / name)
    for name in COPIED:
        if (REPO / name).exists():
            shutil.copy(REPO / name, repo / name)
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED.resolve())
    return repo


def test_the_docs_have_python_examples():
    assert "README.md" in RUNNABLE and "docs/guide/python.md" in RUNNABLE


@pytest.mark.parametrize("page", RUNNABLE)
def test_every_python_example_in_the_docs_runs(page, tmp_path, monkeypatch):
    exe = _cli()
    if exe is not None:
        monkeypatch.setenv("PATH", f"{exe.parent}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    try:
        import matplotlib

        matplotlib.use("Agg")
    except ImportError:
        pass
    monkeypatch.chdir(scratch(tmp_path))
    have_shared = (SHARED / "datasets").is_dir()
    namespace = {"__name__": "__main__"}
    ran = 0
    for line, code in python_blocks(page):
        if "../shared" in code and not have_shared:
            print(f"{page}:{line}: skipped, {SHARED / 'datasets'} is not here")
            continue
        if "smocap" in code and "subprocess" in code and exe is None:
            pytest.fail(f"{page}:{line} runs the smocap binary: set SMOCAP_BIN or run `cargo build` first")
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*non-interactive.*")
            try:
                exec(compile(code, f"{page}:{line}", "exec"), namespace)
            except Exception as e:
                raise AssertionError(f"{page}:{line}: {type(e).__name__}: {e}\n--- block\n{code}") from e
        ran += 1
        print(f"{page}:{line}: ok")
    if ran == 0:
        pytest.skip(f"{page}: every block needs {SHARED / 'datasets'}")
