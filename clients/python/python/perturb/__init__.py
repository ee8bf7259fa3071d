"""Camera and LiDAR perturbations for testing autonomous driving systems, on numpy arrays.

The same perturbation code as the ``perturbd`` daemon and ``perturb apply``: for the same
perturbation ID, severity, seed and frame sequence number the output is identical byte for byte.

>>> import numpy as np, perturb
>>> rain = perturb.CameraPerturber("C-C7", 3, seed=42)
>>> frame = np.zeros((48, 64, 3), np.uint8)
>>> out = rain(frame, seq=7)          # a new array; rain.apply_(frame, 7) works in place
>>> bool((out == rain(frame, seq=7)).all())
True

- :func:`catalogue` lists the 73 perturbations (ID, name, modality, family, severities, ...).
- :class:`CameraPerturber` perturbs HxWx3 (rgb8), HxWx4 (rgba8) or HxW (mono8) uint8 arrays.
- :class:`LidarPerturber` perturbs (N, k) float32 point arrays (x, y, z, intensity, extras).
- :func:`detect` runs the LiDAR clustering detector (``perturb detect``).
- :func:`encodings` lists the ``sensor_msgs/Image`` encodings; :func:`apply_encoded` perturbs a
  frame's bytes in any of them (Bayer, YUV 4:2:2, 16-bit) and returns them in that encoding.
- :func:`report` writes the study report (``perturb report``): the paper's tables and figures
  in one self-contained HTML page from a folder of the study tools' outputs.
- :mod:`perturb.ray` perturbs Ray Datasets and runs ``perturb batch`` on a Ray cluster.
- :mod:`perturb.adapters` wraps perturbers as torchvision / albumentations transforms and a
  PyTorch ``Dataset``.

Errors raise :class:`PerturbError`, a ``ValueError`` carrying the core's message. Inputs are read
in place when their pixels (points) are packed; the GIL is released while a frame is perturbed
and a perturber may be shared by threads.
"""

from typing import Any, Optional, Sequence

import numpy as _np

from . import _perturb
from ._perturb import (
    PerturbError,
    __version__,
    apply_encoded,
    catalogue,
    detect,
    report,
    encodings,
)


class CameraPerturber(_perturb.CameraPerturber):
    """A camera perturbation configured by ID (or name), severity and seed.

    ``p(image, seq=0)`` returns the perturbed copy of an HxWx3 (rgb8), HxWx4 (rgba8) or HxW
    (mono8) uint8 array; ``p.apply_(image, seq=0)`` perturbs it in place. The output is a pure
    function of (image, ID, severity, seed, seq), byte-identical to ``perturb apply`` and the
    daemon. Safe to call from many threads; the GIL is released during the work. Every bad
    argument raises :class:`PerturbError` naming it.
    """

    __slots__ = ()

    def __new__(cls, id: str, severity: int, seed: int = 0) -> "CameraPerturber":
        return super().__new__(cls, id, severity, seed)

    def __call__(
        self, image: Any, seq: int = 0, *, format: Optional[str] = None
    ) -> _np.ndarray:
        """The perturbed copy of ``image`` at frame sequence number ``seq``. ``format`` names
        the pixel order of a 3- or 4-channel array: ``rgb8`` (default), ``bgr8`` (OpenCV),
        ``rgba8``, ``bgra8``."""
        return _perturb.CameraPerturber.__call__(self, image, seq, format=format)


class LidarPerturber(_perturb.LidarPerturber):
    """A LiDAR perturbation configured by ID (or name), severity, seed and sensor model.

    ``p(points, seq=0)`` returns the perturbed copy of an (N, k) float32 array (x, y, z,
    intensity, then extra columns, carried through); points may be removed or added. ``sensor``
    (``vlp32c`` by default, ``vlp16``, ``hdl32e``, ``hdl64e``: KITTI is ``hdl64e``),
    ``intensity_max`` (1 or 255) and ``forward`` (``+x`` by default; ``+y`` for nuScenes'
    LIDAR_TOP) say how to read the cloud, as the options of ``perturb apply`` do; ``fields``
    names the columns. Every bad argument raises :class:`PerturbError` naming it.
    """

    __slots__ = ()

    def __new__(
        cls,
        id: str,
        severity: int,
        seed: int = 0,
        sensor: Optional[str] = None,
        intensity_max: Optional[float] = None,
        *,
        fields: Optional[Sequence[str]] = None,
        forward: Optional[str] = None,
    ) -> "LidarPerturber":
        return super().__new__(
            cls, id, severity, seed, sensor, intensity_max, fields=fields, forward=forward
        )

    def __call__(self, points: Any, seq: int = 0) -> _np.ndarray:
        """The perturbed copy of ``points`` at frame sequence number ``seq`` (N may change)."""
        return _perturb.LidarPerturber.__call__(self, points, seq)


__all__ = [
    "CameraPerturber",
    "LidarPerturber",
    "PerturbError",
    "__version__",
    "apply_encoded",
    "catalogue",
    "detect",
    "report",
    "encodings",
    "perturber",
]


def perturber(id: str, severity: int, seed: int = 0, **lidar_options):
    """The camera or LiDAR perturber of ``id`` (ID or name), whichever its modality is.

    ``lidar_options`` (``sensor``, ``intensity_max``, ``fields``, ``forward``) apply to LiDAR
    perturbations.
    """
    if not isinstance(id, str):
        raise PerturbError(f"id must be a str (an ID such as C-C7, or a name), got {id!r}")
    entry = next(
        (e for e in catalogue() if id.lower() in (e["id"].lower(), e["name"].lower())), None
    )
    if entry is not None and entry["modality"] == "lidar":
        return LidarPerturber(id, severity, seed, **lidar_options)
    if lidar_options:
        raise PerturbError(
            f"{id} is a camera perturbation: the LiDAR options {sorted(lidar_options)} do not apply"
        )
    return CameraPerturber(id, severity, seed)
