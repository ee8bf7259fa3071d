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

from ._perturb import (
    CameraPerturber,
    LidarPerturber,
    PerturbError,
    __version__,
    apply_encoded,
    catalogue,
    detect,
    report,
    encodings,
)

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

    ``lidar_options`` (``sensor``, ``intensity_max``, ``fields``) apply to LiDAR perturbations.
    """
    entry = next(
        (e for e in catalogue() if id.lower() in (e["id"].lower(), e["name"].lower())), None
    )
    if entry is not None and entry["modality"] == "lidar":
        return LidarPerturber(id, severity, seed, **lidar_options)
    return CameraPerturber(id, severity, seed)
