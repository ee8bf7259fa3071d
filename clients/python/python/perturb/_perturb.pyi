"""Type stubs of the compiled module ``perturb._perturb``."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, "PathLike[str]"]

class PerturbError(ValueError):
    """A perturbation could not be configured or applied (the message is the core's)."""

class Entry(TypedDict):
    id: str
    name: str
    modality: str
    family: str
    severities: List[int]
    description: str
    reference: str

# ``class`` is ``vehicle``, ``pedestrian`` or ``other`` (a keyword: the functional syntax).
Detection = TypedDict(
    "Detection",
    {
        "center": Tuple[float, float, float],
        "size": Tuple[float, float, float],
        "yaw": float,
        "class": str,
        "points": int,
    },
)

def catalogue(modality: Optional[str] = None) -> List[Entry]:
    """Every perturbation (of ``modality``, ``"camera"`` or ``"lidar"``, if given)."""

class CameraPerturber:
    """A camera perturbation configured by ID (or name), severity and seed."""

    def __init__(self, id: str, severity: int, seed: int = 0) -> None: ...
    def __call__(
        self, image: npt.ArrayLike, seq: int = 0, *, format: Optional[str] = None
    ) -> npt.NDArray[np.uint8]:
        """The perturbed copy of an HxWx3 (rgb8), HxWx4 (rgba8) or HxW (mono8) uint8 array."""
    def apply_(
        self, image: npt.NDArray[np.uint8], seq: int = 0, *, format: Optional[str] = None
    ) -> npt.NDArray[np.uint8]:
        """Perturbs ``image`` in place and returns it."""
    @property
    def id(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def severity(self) -> int: ...
    @property
    def seed(self) -> int: ...

class LidarPerturber:
    """A LiDAR perturbation configured by ID (or name), severity, seed and sensor model."""

    def __init__(
        self,
        id: str,
        severity: int,
        seed: int = 0,
        sensor: Optional[str] = None,
        intensity_max: Optional[float] = None,
        *,
        fields: Optional[Sequence[str]] = None,
        forward: Optional[str] = None,
    ) -> None: ...
    def __call__(self, points: npt.ArrayLike, seq: int = 0) -> npt.NDArray[np.float32]:
        """The perturbed copy of an (N, k) float32 array; N may change."""
    @property
    def id(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def severity(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def sensor(self) -> str: ...
    @property
    def forward(self) -> str:
        """The axis the sensor's frame looks along (``+x``, ``-x``, ``+y`` or ``-y``)."""
    @property
    def intensity_max(self) -> float: ...

def detect(
    points: npt.ArrayLike,
    *,
    objects: bool = False,
    fields: Optional[Sequence[str]] = None,
    sensor: Optional[str] = None,
    forward: Optional[str] = None,
    intensity_max: Optional[float] = None,
    class_: Optional[str] = None,
) -> List[Detection]:
    """The clustering detector's boxes (``perturb detect --json``), in the cloud's frame."""

class Encoding(TypedDict):
    name: str
    aliases: List[str]
    layout: str
    bits: int
    bytes_per_pixel: int
    tile: List[int]
    working: str
    opencv: Optional[str]
    summary: str

def encodings() -> List[Encoding]:
    """The ``sensor_msgs/Image`` encodings the package reads and writes (one table for all)."""

def apply_encoded(
    data: bytes,
    encoding: str,
    width: int,
    height: int,
    step: int,
    id: str,
    severity: int,
    seed: int = 0,
    seq: int = 0,
    *,
    is_bigendian: int = 0,
    bit_depth: Optional[int] = None,
) -> bytes:
    """The perturbed bytes of a frame in ``encoding`` (same length, encoding, step, byte order)."""

def input_is_copied(array: npt.ArrayLike, *, cloud: bool = False) -> bool:
    """True if the package copies ``array`` before reading it (its strides are not packed)."""

def plan_batch(
    input: _Path,
    out: _Path,
    *,
    ids: Sequence[str] = ...,
    families: Sequence[str] = ...,
    modality: Optional[str] = None,
    severities: Sequence[int] = ...,
    seed: int = 0,
    sensor: Optional[str] = None,
    intensity_max: Optional[float] = None,
    shard: Optional[str] = None,
    forward: Optional[str] = None,
) -> Dict[str, Any]:
    """Plans a folder batch as ``perturb batch`` and writes ``OUT/batch.json``."""

def report(
    study_dir: _Path,
    output: _Path = "report.html",
    *,
    title: Optional[str] = None,
    resamples: int = 10000,
    seed: int = 0,
) -> Dict[str, Any]:
    """Writes the study report (``perturb report``): one self-contained HTML page with the
    paper's tables and figures from the outputs in ``study_dir``, and ``<stem>.json`` and
    ``<stem>-<table>.csv`` beside it. Returns ``html``, ``json``, ``csv``, ``present``,
    ``missing`` (section -> why its input is missing) and ``used``."""

def mark_done(dir: _Path, files: int) -> None:
    """Writes a set's ``.done`` marker."""

class BatchWorker:
    """The per-file worker of ``perturb batch`` (one perturber per (ID, severity))."""

    def __init__(
        self,
        root: _Path,
        first_file: _Path,
        seed: int = 0,
        sensor: Optional[str] = None,
        intensity_max: Optional[float] = None,
        forward: Optional[str] = None,
    ) -> None: ...
    def run(self, rel: _Path, seq: int, id: str, severity: int, dir: _Path) -> bool: ...
