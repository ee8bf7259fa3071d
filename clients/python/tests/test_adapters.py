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
    A = need("albumentations", "pip install albumentations")
    aug = A.Compose([adapters.albumentations_transform("C-B5", 3, seed=1)])
    out = aug(image=small)["image"]
    assert np.array_equal(out, perturb.CameraPerturber("C-B5", 3, seed=1)(small, 0))
    assert isinstance(adapters.AlbumentationsTransform("C-B5", 3), A.ImageOnlyTransform)


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
