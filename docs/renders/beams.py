#!/usr/bin/env python3
"""The beams image of docs/models/biri.md: data/scenes/beams.toml from `--model biri --cpu` with the exact kernel
(left) and the paper's quartic (right), side by side at one exposure (the exact one's
automatic exposure: the 97th percentile of luminance maps to 1 − e^{−1.5}). Negative radiance,
which the quartic's integral gives where it undershoots, shows as black.

Run from the repository root after `cargo build --release`:
    python3 docs/renders/beams.py      # writes docs/renders/beams-exact-polynomial.png
PHOTOMETEOR_BIN overrides the binary.
"""
import os, sys, tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("PHOTOMETEOR_BIN", os.path.join(ROOT, "target", "release", "photometeor"))
SCENE = os.path.join(ROOT, "data", "scenes", "beams.toml")
OUT = os.path.join(ROOT, "docs", "renders", "beams-exact-polynomial.png")
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pair import render as run, save_pair  # noqa: E402


def render(kernel, exr, tables):
    return run([BIN, "render", SCENE, "--model", "biri", "--cpu", "--biri-kernel", kernel, "--out", exr,
                "--tables", tables], exr)


def main():
    with tempfile.TemporaryDirectory() as tmp:
        tables = os.path.join(tmp, "tables")
        left = render("exact", os.path.join(tmp, "e.exr"), tables)
        right = render("polynomial", os.path.join(tmp, "p.exr"), tables)
    exposure = save_pair(left, right, OUT)
    neg = (right < 0).any(axis=-1).mean()
    rel = np.abs(right - left).sum(axis=-1) / np.maximum(left.sum(axis=-1), 1e-30)
    print(f"{OUT}: exposure {exposure:.4g}; polynomial: {neg*100:.1f} % of pixels negative, "
          f"|poly − exact|/exact median {np.median(rel)*100:.1f} %, 95th pct "
          f"{np.percentile(rel, 95)*100:.1f} %")


if __name__ == "__main__":
    main()
