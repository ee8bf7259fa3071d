"""The optional adapters (torchvision-style transform, albumentations, Dataset wrapper)."""

import numpy as np
import pytest

import perturb
from conftest import need
from perturb import adapters


def test_transform_on_numpy_and_pil(small):
    t = adapters.Transform("C-C7", 2, seed=3, seq=4)
    expected = perturb.CameraPerturber("C-C7", 2, seed=3)(small, 4)
    assert np.array_equal(t(small), expected)
    PIL = need("PIL.Image", "pip install pillow")
    out = t(PIL.fromarray(small))
    assert isinstance(out, PIL.Image) and np.array_equal(np.asarray(out), expected)


def test_albumentations_transform(small):
    A = need("albumentations", "pip install albumentations==2.0.8")
    aug = A.Compose([adapters.albumentations_transform("C-B5", 3, seed=1)])
    out = aug(image=small)["image"]
    assert np.array_equal(out, perturb.CameraPerturber("C-B5", 3, seed=1)(small, 0))
    assert isinstance(adapters.AlbumentationsTransform("C-B5", 3), A.ImageOnlyTransform)


def test_albumentations_keeps_the_seed_through_compose_and_serialisation(small):
    """Issue 33: the seed lived in ``self.seed``, which albumentations 2 owns: after A.Compose
    it read None, and A.to_dict / A.from_dict rebuilt the transform with seed 0."""
    A = need("albumentations", "pip install albumentations==2.0.8")
    want = perturb.CameraPerturber("C-A1", 4, seed=9)(small, 0)
    assert not np.array_equal(want, perturb.CameraPerturber("C-A1", 4, seed=0)(small, 0))
    aug = A.Compose([adapters.albumentations_transform("C-A1", 4, seed=9)], seed=123)
    assert aug.transforms[0].perturb_seed == 9
    assert np.array_equal(aug(image=small)["image"], want)
    saved = A.to_dict(aug)
    assert saved["transform"]["transforms"][0]["perturb_seed"] == 9
    again = A.from_dict(saved)
    assert isinstance(again.transforms[0], adapters.AlbumentationsTransform)
    assert again.transforms[0].perturb_seed == 9
    assert np.array_equal(again(image=small)["image"], want)


def test_pil_16_bit_images_are_refused_not_clipped(small):
    """Issue 33: the PIL path converted 16-bit images to 8 bits silently."""
    PIL = need("PIL.Image", "pip install pillow")
    t = adapters.Transform("C-B5", 2)
    wide = PIL.fromarray((np.arange(48 * 64, dtype=np.uint16).reshape(48, 64) * 20))
    assert wide.mode.startswith("I;16")
    with pytest.raises(perturb.PerturbError, match="16-bit"):
        t(wide)
    # 8-bit modes still work, palette images through RGB.
    assert np.asarray(t(PIL.fromarray(small).convert("P"))).shape == small.shape


def test_perturbed_dataset_uses_the_index_as_seq(small):
    base = [(np.roll(small, k, axis=0), k) for k in range(3)]
    ds = adapters.PerturbedDataset(base, [("C-A1", 2), ("C-C7", 1)], seed=5)
    assert len(ds) == 6
    img, label = ds[3]  # sample 1, second pair
    assert label == 1
    assert np.array_equal(img, perturb.CameraPerturber("C-C7", 1, seed=5)(base[1][0], 1))
    assert np.array_equal(ds[-1][0], ds[5][0])
    with pytest.raises(IndexError):
        ds[6]
    dicts = adapters.PerturbedDataset([{"image": small, "y": 0}], ("C-A1", 2), key="image")
    assert np.array_equal(dicts[0]["image"], perturb.CameraPerturber("C-A1", 2)(small, 0))
