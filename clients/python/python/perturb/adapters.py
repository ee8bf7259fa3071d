"""Adapters for the training libraries; each is optional and imports its library only when used.

- :class:`Transform`: a torchvision-style transform (a callable on one image) for numpy arrays
  (HxWxC), PIL images and torch uint8 tensors (CxHxW). Works without torchvision.
- :func:`albumentations_transform` / :class:`AlbumentationsTransform`: an albumentations
  ``ImageOnlyTransform`` (only defined when albumentations is installed).
- :class:`PerturbedDataset`: wraps a map-style dataset (a PyTorch ``Dataset`` or anything with
  ``__len__`` and ``__getitem__``) and perturbs each sample's image on the fly, with the sample's
  index as the frame sequence number, so sample *i* is the same on every epoch and every worker.
  It subclasses ``torch.utils.data.Dataset`` when torch is installed.
"""

from __future__ import annotations

from typing import Any, Callable, Optional, Sequence, Tuple, Union

import numpy as np

from . import CameraPerturber
from ._perturb import PerturbError

__all__ = ["Transform", "PerturbedDataset", "albumentations_transform"]


# PIL modes whose samples are wider than 8 bits: refused rather than clipped.
_PIL_WIDE_MODES = {
    "I;16": "16-bit",
    "I;16L": "16-bit",
    "I;16B": "16-bit",
    "I;16N": "16-bit",
    "I": "32-bit integer",
    "F": "32-bit float",
}


def _perturb_any(p: CameraPerturber, image: Any, seq: int) -> Any:
    """Perturbs a numpy array, a PIL image or a torch tensor and returns the same kind."""
    if isinstance(image, np.ndarray):
        return p(image, seq)
    mod = type(image).__module__
    if mod.startswith("PIL."):
        from PIL import Image

        if image.mode in _PIL_WIDE_MODES:
            # As the command line: 8-bit images only through this path (a 16-bit PNG is not
            # squeezed into 8 bits behind the caller's back).
            raise PerturbError(
                f"PIL image mode {image.mode!r} has {_PIL_WIDE_MODES[image.mode]} samples: "
                "perturb works on 8-bit images here (convert it yourself, or perturb a 16-bit "
                "frame's bytes with perturb.apply_encoded(..., 'mono16', ...))"
            )
        rgb = image if image.mode in ("RGB", "RGBA", "L") else image.convert("RGB")
        return Image.fromarray(p(np.asarray(rgb), seq))
    if mod.startswith("torch"):
        import torch

        t = image.detach().cpu()
        if t.dtype != torch.uint8:
            raise TypeError(f"perturb works on uint8 images, got a {t.dtype} tensor (before ToDtype/Normalize)")
        if t.ndim == 3:  # CxHxW -> HxWxC and back
            out = p(np.ascontiguousarray(t.permute(1, 2, 0).numpy()), seq)
            return torch.from_numpy(out).permute(2, 0, 1).contiguous()
        return torch.from_numpy(p(t.numpy(), seq))
    return p(np.asarray(image), seq)


class Transform:
    """A torchvision-style transform: ``Transform("C-C7", 3)(img)``.

    ``seq`` is the frame sequence number used for every call (animated effects and noise depend
    on it); :class:`PerturbedDataset` passes the sample index instead.
    """

    def __init__(self, id: str, severity: int, seed: int = 0, seq: int = 0):
        self.perturber = CameraPerturber(id, severity, seed)
        self.seq = seq

    def __call__(self, image: Any, seq: Optional[int] = None) -> Any:
        return _perturb_any(self.perturber, image, self.seq if seq is None else seq)

    def __repr__(self) -> str:
        p = self.perturber
        return f"perturb.adapters.Transform('{p.id}', {p.severity}, seed={p.seed}, seq={self.seq})"


def albumentations_transform(id: str, severity: int, seed: int = 0, p: float = 1.0):
    """An albumentations ``ImageOnlyTransform`` applying ``id`` at ``severity`` with the
    perturbation's ``seed`` (with probability ``p``); the sequence number is 0 (the draw of
    albumentations decides whether it applies, the perturbation itself is reproducible). The
    seed survives ``A.Compose`` and ``A.to_dict``/``A.from_dict`` (tested with albumentations
    2.0.8)."""
    return AlbumentationsTransform(id, severity, seed, p=p)


try:  # pragma: no cover - depends on the environment
    import albumentations as _A

    class AlbumentationsTransform(_A.ImageOnlyTransform):
        """``perturb``'s perturbation as an albumentations ``ImageOnlyTransform``.

        The perturbation's seed is kept as ``perturb_seed``: albumentations 2 owns a transform's
        ``seed`` attribute (``A.Compose`` resets it, ``A.to_dict`` leaves it out), so a seed kept
        there would be lost. ``A.to_dict``/``A.from_dict`` rebuild the same perturbation.
        """

        def __init__(
            self,
            id: str,
            severity: int,
            seed: int = 0,
            p: float = 1.0,
            *,
            perturb_seed: Optional[int] = None,
            **kwargs: Any,
        ):
            super().__init__(p=p, **kwargs)
            if perturb_seed is not None:
                seed = perturb_seed
            self.perturber = CameraPerturber(id, severity, seed)
            self.id, self.severity, self.perturb_seed = self.perturber.id, self.perturber.severity, self.perturber.seed

        def apply(self, img: np.ndarray, **params: Any) -> np.ndarray:
            return self.perturber(img, 0)

        def get_transform_init_args_names(self) -> Tuple[str, ...]:
            return ("id", "severity", "perturb_seed")

except ImportError:  # albumentations is optional

    class AlbumentationsTransform:  # type: ignore[no-redef]
        """Placeholder: albumentations is not installed."""

        def __init__(self, *args: Any, **kwargs: Any):
            raise ImportError("AlbumentationsTransform needs albumentations: pip install albumentations")


try:  # pragma: no cover - depends on the environment
    from torch.utils.data import Dataset as _Base
except ImportError:
    _Base = object  # type: ignore[assignment,misc]


class PerturbedDataset(_Base):  # type: ignore[misc,valid-type]
    """Wraps a map-style dataset and perturbs each sample's image on the fly.

    ``perturbations`` is one (ID, severity) pair or a list of them; with several, sample *i* of
    the wrapped dataset appears once per pair (index ``i * len(pairs) + j``). ``key`` picks the
    image out of a sample: an int for tuples (default 0, as in ``(image, label)``), a str for
    dicts, or None when the sample is the image itself. The sequence number of sample *i* is
    *i*, so the dataset is the same on every epoch and in every DataLoader worker.
    """

    def __init__(
        self,
        dataset: Any,
        perturbations: Union[Tuple[str, int], Sequence[Tuple[str, int]]],
        seed: int = 0,
        key: Union[int, str, None] = 0,
    ):
        if isinstance(perturbations, tuple) and len(perturbations) == 2 and isinstance(perturbations[0], str):
            perturbations = [perturbations]
        self.dataset = dataset
        self.pairs = [(str(i), int(s)) for i, s in perturbations]
        self.perturbers = [CameraPerturber(i, s, seed) for i, s in self.pairs]
        self.key = key

    def __len__(self) -> int:
        return len(self.dataset) * len(self.perturbers)

    def __getitem__(self, index: int) -> Any:
        if index < 0:
            index += len(self)
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} out of range for {len(self)} samples")
        i, j = divmod(index, len(self.perturbers))
        sample = self.dataset[i]
        p = self.perturbers[j]
        if self.key is None:
            return _perturb_any(p, sample, i)
        if isinstance(sample, dict):
            out = dict(sample)
            out[self.key] = _perturb_any(p, sample[self.key], i)
            return out
        items = list(sample)
        items[self.key] = _perturb_any(p, items[self.key], i)
        return type(sample)(items) if isinstance(sample, tuple) else items
