"""Type stubs of smocap's Python API (the binding is the compiled module ``smocap._smocap``)."""

import os
import pathlib
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt
import pandas as pd

__version__: str
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
]

_PathLike = Union[str, "os.PathLike[str]"]
_TrialInput = Union[_PathLike, "Markers"]

class SmocapError(Exception):
    """An error from smocap; the message is the one the command line prints (file, line, what
    was expected)."""

class MarkerFileError(SmocapError):
    """A marker file (TRC, C3D) or marker arrays that cannot be read."""

class ModelError(SmocapError):
    """A model, marker set, profile, OpenSim setup or solver setting that cannot be used."""

class CalibrationError(SmocapError):
    """The subject could not be calibrated (including an implausible height or mass, or an
    unknown sex)."""

class SolveError(SmocapError):
    """A trial could not be solved: no result (e.g. no frame with enough markers, a non-finite
    solution)."""

class ArchiveError(SmocapError):
    """A converted (.mcap) file that cannot be read, or an archive conversion that could not run."""

class SmocapWarning(UserWarning):
    """A result not to be trusted as it is: a ``suspect`` calibration or trial (scales at their
    bounds, most frames at the iteration cap)."""

@final
class Markers:
    """Marker trajectories of one trial, in the file's lab frame and units.

    Built by :func:`read_markers`, or from arrays so that data that never was a file can be
    solved: ``Markers(labels, xyz, rate_hz, units="m")``, ``xyz`` of shape (frames, markers, 3)
    with NaN for gaps; ``times`` (s) default to ``i / rate_hz``; ``up`` is the data's up axis
    (``'x'``, ``'y'``, ``'z'``; detected when solving if ``None``).
    """

    def __new__(
        cls,
        labels: List[str],
        xyz: npt.ArrayLike,
        rate_hz: float,
        units: str = "m",
        up: Optional[str] = None,
        times: Optional[npt.ArrayLike] = None,
        name: Optional[str] = None,
    ) -> "Markers": ...
    @property
    def labels(self) -> List[str]:
        """Marker labels, as in the file."""
    @property
    def rate_hz(self) -> float:
        """Sampling rate (Hz)."""
    @property
    def units(self) -> str:
        """Units of ``xyz``: those given (``read_markers(units=...)``), else the file's."""
    @property
    def up(self) -> Optional[str]:
        """The data's up axis when given; ``None``: detected when solving."""
    @property
    def times(self) -> np.ndarray:
        """Frame times (s), shape (frames,)."""
    @property
    def frame_numbers(self) -> np.ndarray:
        """Frame numbers as in the file (usually from 1), shape (frames,)."""
    @property
    def xyz(self) -> np.ndarray:
        """Positions as read, shape (frames, markers, 3), in ``units``, NaN for gaps."""
    @property
    def warnings(self) -> List[str]:
        """What the reader noticed (header counts, unnamed markers, masked samples)."""
    @property
    def name(self) -> str:
        """The file path, or the name given."""
    def __len__(self) -> int: ...

def read_markers(path: _PathLike, units: Optional[str] = None, up: Optional[str] = None) -> Markers:
    """Reads a marker file (TRC or C3D, by extension).

    ``units`` (``'mm'``, ``'cm'``, ``'m'``) overrides the file header's, ``up`` (``'x'``,
    ``'y'``, ``'z'``) gives the data's up axis (as ``smocap solve --units/--up``); both apply
    when the markers are solved. Raises :class:`MarkerFileError`.
    """

@final
class Model:
    """A model with its marker set, solver profile and OpenSim setups (as ``smocap solve``'s
    ``--model``, ``--markerset``, ``--profile``, ``--scale-setup``, ``--ik-setup``); the shipped
    full-body model when ``path`` is ``None``. Raises :class:`ModelError`."""

    def __new__(
        cls,
        path: Optional[_PathLike] = None,
        markerset: Optional[_PathLike] = None,
        profile: Optional[_PathLike] = None,
        scale_setup: Optional[_PathLike] = None,
        ik_setup: Optional[_PathLike] = None,
    ) -> "Model": ...
    @property
    def path(self) -> Optional[pathlib.Path]:
        """The model file (``None``: the shipped model)."""
    @property
    def coordinates(self) -> List[str]:
        """Coordinate names in model order (the columns of :attr:`Motion.q`)."""
    @property
    def coordinate_units(self) -> List[str]:
        """``'rad'`` or ``'m'`` for each coordinate."""
    @property
    def bodies(self) -> List[str]:
        """Body names in model order."""
    @property
    def markers(self) -> List[str]:
        """Model marker names in model order."""
    @property
    def notes(self) -> List[str]:
        """What loading the files noticed (importer warnings, the IK setup's tasks)."""

def calibrate(
    model: Optional[Model],
    trials: Union[_TrialInput, Iterable[_TrialInput]],
    static: Optional[_TrialInput] = None,
    height: Optional[float] = None,
    mass: Optional[float] = None,
    sex: Optional[str] = None,
    register: bool = True,
    settings: Optional[Dict[str, Any]] = None,
    place_markers: bool = False,
) -> "Subject":
    """Calibrates a subject once, from its static trial (when given, or named by the model's
    Scale setup) and frames of its motion ``trials``, as ``smocap solve`` does.

    Trials are paths (units and up axis from the header / detected) or :class:`Markers`.
    ``height`` (m), ``mass`` (kg) and ``sex`` (``'male'``/``'female'``) condition the
    anthropometric prior; ``register=False`` keeps the model's marker positions;
    ``place_markers`` places them on the static trial (OpenSim's MarkerPlacer); ``settings``
    overrides solver settings (a profile's ``[solver]`` keys, as ``--set KEY=VALUE``). A suspect
    calibration warns (:class:`SmocapWarning`). Raises :class:`CalibrationError`,
    :class:`ModelError`, :class:`MarkerFileError`.
    """

@final
class Subject:
    """A calibrated subject: scale factors, registered markers, calibration report."""

    @property
    def scales(self) -> Dict[str, List[float]]:
        """Calibrated scale factors ``[x, y, z]`` by body name."""
    @property
    def stature_m(self) -> Optional[float]:
        """The calibrated stature (m), measured on the model's landmarks when it has them."""
    @property
    def status(self) -> str:
        """``'ok'`` or ``'suspect'`` (then every trial solved is ``suspect``)."""
    @property
    def warnings(self) -> List[str]:
        """Why the calibration is suspect, and scales far from their prior."""
    @property
    def notes(self) -> List[str]:
        """What setting the subject up noticed."""
    @property
    def report(self) -> Dict[str, Any]:
        """The report's ``calibration`` section, as ``smocap solve --report-json`` writes it."""
    @property
    def coordinates(self) -> List[str]:
        """Coordinate names in model order."""
    def write_osim(self, path: _PathLike) -> pathlib.Path:
        """Writes the scaled OpenSim model and its scale set beside it (``<stem>.scaleset.xml``),
        as ``smocap solve --scaled-model``; returns the scale set's path."""
    def solve(
        self,
        trial: _TrialInput,
        threads: Optional[int] = None,
        backend: str = "cpu",
        lanes: Optional[int] = None,
    ) -> "Motion":
        """Solves every frame of ``trial`` with the calibrated morphology.

        ``threads`` (default: the machine's parallelism) and ``lanes`` change the speed, never
        the result; ``backend`` is ``'cpu'`` (the f64 reference), ``'wgpu'``, ``'wgpu-f64'`` or
        ``'auto'``. The GIL is released while solving. A suspect trial warns
        (:class:`SmocapWarning`); a trial with no result raises :class:`SolveError`.
        """

@final
class Motion:
    """A solved trial."""

    @property
    def q(self) -> pd.DataFrame:
        """Every coordinate per frame (rad or m), columns in model order, index ``time_s``."""
    @property
    def stats(self) -> pd.DataFrame:
        """Per frame: ``rmse`` (m), ``iterations``, ``accepted_steps``, ``energy``,
        ``markers_used``, ``status``, ``bridged``, ``solve_s``."""
    @property
    def report(self) -> Dict[str, Any]:
        """The trial's entry of ``smocap solve --report-json``'s ``trials``."""
    @property
    def status(self) -> str:
        """``'ok'`` or ``'suspect'``."""
    @property
    def name(self) -> str:
        """The trial's path, or the :class:`Markers`' name."""
    @property
    def times(self) -> np.ndarray:
        """Frame times (s)."""
    @property
    def notes(self) -> List[str]:
        """Bridged frames, pre-solved outliers, why it is suspect."""
    def to_mot(self, path: _PathLike) -> None:
        """Writes OpenSim's ``.mot``, byte for byte as ``smocap solve --mot-dir`` does."""
    def __len__(self) -> int: ...

def read_trial(path: _PathLike) -> "Trial":
    """Reads a trial converted by ``smocap convert`` (``.mcap``). Raises :class:`ArchiveError`."""

@final
class Trial:
    """A converted trial read back."""

    @property
    def q(self) -> pd.DataFrame:
        """Every coordinate per frame (rad or m), subject order, index ``time_s`` (as in the
        input file)."""
    @property
    def stats(self) -> pd.DataFrame:
        """Per frame: ``iterations``, ``accepted_steps``, ``energy``, ``rmse``, ``markers_used``,
        ``markers_observed``, ``status``, ``bridged``, ``marker_rmse`` (m), ``solve_s``."""
    @property
    def markers(self) -> np.ndarray:
        """Observed markers, shape (frames, markers, 3) (m, model frame), NaN where not observed."""
    @property
    def marker_names(self) -> List[str]:
        """Names of the second axis of :attr:`markers`."""
    @property
    def times(self) -> np.ndarray:
        """Frame times (s)."""
    @property
    def subject(self) -> Dict[str, Any]:
        """Names (coordinates, bodies, markers, ...) and calibrated ``scales`` by body."""
    @property
    def label_qc(self) -> Optional[Dict[str, Any]]:
        """The label quality control (``/smocap/label_qc``): ``mode``, ``rigid_pairs``,
        ``masked_frames``, ``masked_share``, ``suspect`` and ``events`` (dicts: ``kind``,
        ``markers``, ``first_frame``, ``last_frame``, ``first_time``, ``last_time`` (s),
        ``detected_frames``, ``action``, ``residual_before_mm``, ``residual_after_mm``); None
        for files written without it."""
    @property
    def unfittable(self) -> List[Dict[str, Any]]:
        """The runs of unfittable frames (``/smocap/unfittable``; empty without one): dicts with
        ``first_frame``, ``last_frame``, ``first_time``, ``last_time`` (s), ``frames``,
        ``peak_rmse_mm``, ``limit_mm``, ``markers``, ``marker_error_mm``, ``rigid_move_mm``,
        ``cause`` (``"data"`` or ``"model"``) and ``why``."""
    def to_mot(self, path: _PathLike) -> None:
        """Writes OpenSim's ``.mot`` as ``smocap export --mot`` does."""
    def body(self) -> Tuple[np.ndarray, np.ndarray]:
        """The subject's body mesh posed at every frame (as ``smocap export --mesh``):
        ``(vertices, faces)``, vertices float32 (frames, V, 3) in the Z-up world (m), faces
        uint32 (F, 3), counter-clockwise seen from outside."""
    def retarget(
        self,
        robot: str = "g1",
        mjcf: Optional[_PathLike] = None,
        settings: Optional[_PathLike] = None,
    ) -> pd.DataFrame:
        """Retargets the trial onto a humanoid robot as ``smocap retarget`` does (nothing is
        written): a DataFrame ``q`` of the robot's joint angles, with the report in
        ``q.attrs["report"]``.

        ``q``: MuJoCo's ``qpos`` per frame, index ``time_s`` (as :attr:`q`'s), columns
        ``root_x``, ``root_y``, ``root_z`` (m, Z-up world), ``root_qw``, ``root_qx``, ``root_qy``,
        ``root_qz`` (root orientation, w first as MuJoCo), then one per robot joint (rad, MJCF
        order; ``q.iloc[:, 7:]`` are the joint angles, ``q.to_numpy()`` the ``qpos`` array).
        ``q.attrs["report"]``: the quality report as ``smocap retarget`` writes it (``status``,
        ``reasons``, ``end_effector_median_mm``, ``tracking``, ``feet``, ``range_violations``...).

        ``robot`` is a shipped robot (``"g1"``, the Unitree G1) or a mapping file (TOML, or GMR's
        JSON with ``mjcf``); ``settings`` a TOML file of retargeting settings. Raises
        :class:`ModelError` for a robot or mapping that cannot be read, :class:`SmocapError` when
        the trial's model lacks a body the mapping needs."""
    def __len__(self) -> int: ...

def render(
    trial: _PathLike,
    cameras: Optional[_PathLike] = None,
    size: Optional[Tuple[int, int]] = None,
    frames: Optional[Sequence[int]] = None,
    seed: int = 0,
) -> Dict[str, Any]:
    """Draws a converted trial's subject through a camera rig as ``smocap render`` does (wgpu;
    lavapipe without a GPU), into memory: no file is written. ``cameras`` is a rig file (default:
    the built-in rig, perturbed by ``seed``), ``size`` ``(width, height)`` in pixels for every
    camera (default: each camera's own), ``frames`` trial frame numbers (default: all; the arrays
    hold every frame asked for, so mind the memory).

    Returns a dict: per camera name a dict of ``rgb`` (frames × h × w × 3, uint8), ``mask``
    (frames × h × w, uint16; 0 background, ``1 + body`` the model's bodies), ``depth``
    (frames × h × w, float32, metres along the camera axis, 0 where no body), ``keypoints``
    (frames × k × 3: x, y, COCO visibility), ``keypoint_depths_m`` (frames × k) and ``camera``
    (``K``, ``R``, ``t``… as ``cameras.json``); ``frames`` (the trial frame numbers),
    ``keypoint_names`` and ``keypoint_kinds``. Raises :class:`SmocapError`."""

def convert(
    config: _PathLike,
    out: _PathLike,
    jobs: Optional[int] = None,
    resume: bool = False,
    shard: Optional[str] = None,
    backend: str = "cpu",
    progress: Optional[Callable[[Dict[str, Any]], None]] = None,
    dataset: Optional[str] = None,
    progress_every: float = 1.0,
    lanes: Optional[int] = None,
    robot: Optional[str] = None,
    body: bool = False,
) -> Dict[str, Any]:
    """Converts every trial of the datasets in ``config`` (a ``datasets.toml``) to one MCAP file
    under ``out``, as ``smocap convert``; returns the summary (``--report-json``'s content).

    ``shard`` is ``'I/N'`` (default: from Slurm/Kubernetes variables, as the command line).
    ``progress`` is called with a dict: ``event`` (``'note'``, ``'trial'``: a trial's line,
    ``'progress'``: every ``progress_every`` s, ``'done'``), ``line`` (the command line's text)
    and the counters ``trials_done``, ``trials_total``, ``trials_failed``, ``frames_done``,
    ``frames_total``, ``subjects_calibrated``, ``subjects_total``, ``calibration_s`` and
    ``solve_s`` (the workers' time so far), ``elapsed_s``. Failed trials are listed in the
    summary with their reason;
    a run that cannot start raises :class:`ArchiveError`. ``robot`` (a shipped robot, ``"g1"``,
    or a mapping file; an unknown one raises :class:`ModelError`) retargets every converted trial
    onto it, as ``smocap convert --robot``: ``<trial>.<robot>.pkl``, ``.csv``, ``.npz``,
    ``.json`` beside each ``<trial>.mcap`` and the robot's channels in it; each trial's
    ``robot`` entry (``status``, ``note``) says what became of it. ``body`` measures the
    subject's body mesh on every converted trial, as ``smocap convert --body``:
    ``<trial>.body.json`` beside each file, and each trial's ``body`` entry (``status``,
    ``note``, ``height_minus_stature_mm``, ``landmark_median_off_skin_mm``,
    ``landmark_p90_off_skin_mm``, ``virtual_marker_error_mm``).
    """
