#!/usr/bin/env python3
"""The README's shafts image: data/scenes/shafts.toml from `--model miyazaki` (left) and from
`--model riley` (right), side by side at one exposure (miyazaki's automatic one: the 97th
percentile of luminance maps to 1 − e^{−1.5}).

Riley's model refuses a [haze] layer (Riley et al. 2004 §3: "the system does not currently
render haze"), so its half is the same scene with the [haze] table left out: the clouds, their
shadows on the ground, and Rayleigh air only. Both are CPU references at the scene's settings.

Run from the repository root after `cargo build --release`:
    python3 docs/renders/shafts.py      # writes docs/renders/shafts-miyazaki-riley.png
"""
import os, subprocess, sys, tempfile

import numpy as np
import OpenEXR
from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.path.join(ROOT, "target", "release", "photometeor")
SCENE = os.path.join(ROOT, "data", "scenes", "shafts.toml")
OUT = os.path.join(ROOT, "docs", "renders", "shafts-miyazaki-riley.png")
sys.path.insert(0, os.path.join(ROOT, "docs", "miyazaki"))
from compare import without_haze  # noqa: E402


def render(scene, model, exr, tables):
    args = [BIN, "render", scene, "--cpu", "--out", exr, "--tables", tables]
    if model != "riley":
        args += ["--model", model]
    r = subprocess.run(args, capture_output=True, text=True)
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
        left = render(SCENE, "miyazaki", os.path.join(tmp, "m.exr"), tables)
        clear = os.path.join(tmp, "shafts-no-haze.toml")
        without_haze(SCENE, clear)
        right = render(clear, "riley", os.path.join(tmp, "r.exr"), tables)
    lum = left @ np.array([0.2126, 0.7152, 0.0722])
    p = np.sort(lum.ravel())[int((lum.size - 1) * 0.97)]
    exposure = 1.5 / p
    gap = np.ones((left.shape[0], 4, 3))
    both = np.concatenate([left, np.zeros_like(gap), right], axis=1)
    img = srgb(1.0 - np.exp(-exposure * np.maximum(both, 0.0)))
    img[:, left.shape[1]:left.shape[1] + 4] = 1.0
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(OUT, optimize=True)
    print(f"{OUT}: exposure {exposure:.4g}")


if __name__ == "__main__":
    main()
