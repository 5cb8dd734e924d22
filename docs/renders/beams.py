#!/usr/bin/env python3
"""The README's beams image: data/scenes/beams.toml from `--model biri` with the exact kernel
(left) and the paper's quartic (right), side by side at one exposure (the exact one's
automatic exposure: the 97th percentile of luminance maps to 1 − e^{−1.5}). Negative radiance,
which the quartic's integral gives where it undershoots, shows as black.

Run from the repository root after `cargo build --release`:
    python3 docs/renders/beams.py      # writes docs/renders/beams-exact-polynomial.png
PHOTOMETEOR_BIN overrides the binary.
"""
import os, subprocess, sys, tempfile

import numpy as np
import OpenEXR
from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("PHOTOMETEOR_BIN", os.path.join(ROOT, "target", "release", "photometeor"))
SCENE = os.path.join(ROOT, "data", "scenes", "beams.toml")
OUT = os.path.join(ROOT, "docs", "renders", "beams-exact-polynomial.png")


def render(kernel, exr, tables):
    r = subprocess.run([BIN, "render", SCENE, "--model", "biri", "--biri-kernel", kernel,
                        "--out", exr, "--tables", tables], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(r.stderr)
    print(r.stderr.strip().splitlines()[-1])
    with OpenEXR.File(exr, separate_channels=True) as f:
        ch = f.channels()
        return np.stack([ch[c].pixels for c in "RGB"], axis=-1).astype(np.float64)


def srgb(v):
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)


def main():
    with tempfile.TemporaryDirectory() as tmp:
        tables = os.path.join(tmp, "tables")
        left = render("exact", os.path.join(tmp, "e.exr"), tables)
        right = render("polynomial", os.path.join(tmp, "p.exr"), tables)
    lum = left @ np.array([0.2126, 0.7152, 0.0722])
    exposure = 1.5 / np.sort(lum.ravel())[int((lum.size - 1) * 0.97)]
    w = left.shape[1]
    both = np.concatenate([left, np.zeros((left.shape[0], 4, 3)), right], axis=1)
    img = srgb(1.0 - np.exp(-exposure * np.maximum(both, 0.0)))
    img[:, w:w + 4] = 1.0
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(OUT, optimize=True)
    neg = (right < 0).any(axis=-1).mean()
    rel = np.abs(right - left).sum(axis=-1) / np.maximum(left.sum(axis=-1), 1e-30)
    print(f"{OUT}: exposure {exposure:.4g}; polynomial: {neg*100:.1f} % of pixels negative, "
          f"|poly − exact|/exact median {np.median(rel)*100:.1f} %, 95th pct "
          f"{np.percentile(rel, 95)*100:.1f} %")


if __name__ == "__main__":
    main()
