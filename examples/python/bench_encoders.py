"""Seconds per image of modesuite's image encoders (`modesuite encode`, release build) against
the numpy reference forward pass of the encoder tests (float64, numpy's BLAS) on the same
images: the cost of image policies on a CPU. Issue 31's benchmark.

    python examples/python/bench_encoders.py [--bin target/release/modesuite] [--images 10]

Cases (one JSON object each, best of ``--repeats``):
- ``dinov2_rust``: DINOv2 ViT-S/14 (random weights of the published shapes, from the tests'
  generator) on ``--images`` 128 x 128 PNGs in one process, minus the same command on one
  image (the weights' loading), per image;
- ``dinov2_numpy``: the reference forward pass per image (resize, patches, 12 blocks), with a
  vectorised erf in its GELU;
- ``pooled_rust``: the weights-free encoder per image (the process's start included).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "python" / "tests"))
import test_encoders as ref  # noqa: E402


def timed(cmd: list[str]) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bin", default=os.path.expanduser("~/.cache/modesuite-target/release/modesuite"))
    p.add_argument("--images", type=int, default=10)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    d = Path(tempfile.mkdtemp(prefix="modesuite-bench-enc-"))
    w = ref.random_weights()
    ref.write_safetensors(d / "w.safetensors", w)
    images = []
    for i in range(args.images):
        rgb = ref.make_image(i + 1)
        ref.write_png(d / f"i{i}.png", rgb)
        images.append(rgb)
    paths = [str(d / f"i{i}.png") for i in range(args.images)]
    dino = [args.bin, "encode", "--encoder", "dinov2", "--weights", str(d / "w.safetensors")]
    best = lambda f: min(f() for _ in range(args.repeats))  # noqa: E731
    many = best(lambda: timed(dino + paths))
    one = best(lambda: timed(dino + paths[:1]))
    per = (many - one) / (args.images - 1)
    load = os.getloadavg()[0]
    print(json.dumps({"case": "dinov2_rust", "s_per_image": per, "weights_load_s": one - per,
                      "images": args.images, "loadavg": load}))
    t = best(lambda: _numpy(w, images))
    print(json.dumps({"case": "dinov2_numpy", "s_per_image": t / len(images), "images": len(images),
                      "loadavg": os.getloadavg()[0]}))
    pooled = best(lambda: timed([args.bin, "encode", *paths]))
    print(json.dumps({"case": "pooled_rust", "s_per_image": pooled / args.images,
                      "images": args.images, "loadavg": os.getloadavg()[0]}))


def _fast_gelu(x):
    """Exact-form GELU with a vectorised erf (Abramowitz and Stegun 7.1.26, |error| < 1.5e-7):
    the tests' reference calls math.erf per element, which would time Python, not numpy."""
    import numpy as np
    z = np.abs(x) / np.sqrt(2.0)
    t = 1.0 / (1.0 + 0.3275911 * z)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
    erf = np.sign(x) * (1.0 - poly * np.exp(-z * z))
    return 0.5 * x * (1.0 + erf)


def _numpy(w: dict, images: list) -> float:
    ref.gelu = _fast_gelu
    t = time.perf_counter()
    for rgb in images:
        ref.reference_features(w, rgb)
    return time.perf_counter() - t


if __name__ == "__main__":
    main()
