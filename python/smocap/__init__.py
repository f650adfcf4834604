"""smocap: joint scale–pose canonicalization of marker-based motion capture, from Python.

Calibrate a subject (segment scales, registered markers) and solve its trials frame by frame
with the Rust library that the ``smocap`` command line runs: the same numbers, the same verdicts,
the same files. Arrays are NumPy arrays, tables pandas DataFrames, reports dicts; the GIL is
released while Rust works, so Python threads solve in parallel.

    import smocap
    model = smocap.Model("gait2354_simbody.osim", markerset="gait2354_Scale_MarkerSet.xml")
    subject = smocap.calibrate(model, ["walk.trc"], static="static.trc")
    motion = subject.solve("walk.trc")
    motion.q["knee_angle_r"]        # radians, indexed by time (s)
    motion.to_mot("walk.mot")       # as `smocap solve --mot-dir` writes it

Errors raise :class:`SmocapError` (or a subclass) with the message the command line prints;
results to use with care (a ``suspect`` trial or calibration) warn with :class:`SmocapWarning`.
"""

import os as _os
import sys as _sys
import tempfile as _tempfile

# On a headless Linux machine Mesa's Vulkan drivers, probed for a GPU, print "error:
# XDG_RUNTIME_DIR is invalid or not set" through libwayland: an error that is none. A runtime
# directory for the process silences it (as the command line does).
if _sys.platform.startswith("linux") and not _os.environ.get("XDG_RUNTIME_DIR") and not _os.environ.get(
    "WAYLAND_DISPLAY"
):
    _os.environ["XDG_RUNTIME_DIR"] = _tempfile.gettempdir()

from ._smocap import (
    ArchiveError,
    CalibrationError,
    MarkerFileError,
    Markers,
    Model,
    ModelError,
    Motion,
    SmocapError,
    SmocapWarning,
    SolveError,
    Subject,
    Trial,
    __version__,
    calibrate,
    convert,
    read_markers,
    read_trial,
    render,
)

__all__ = [
    "ArchiveError",
    "CalibrationError",
    "MarkerFileError",
    "Markers",
    "Model",
    "ModelError",
    "Motion",
    "SmocapError",
    "SmocapWarning",
    "SolveError",
    "Subject",
    "Trial",
    "__version__",
    "calibrate",
    "convert",
    "read_markers",
    "read_trial",
    "render",
]
