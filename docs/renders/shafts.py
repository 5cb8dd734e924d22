#!/usr/bin/env python3
"""The shafts image of docs/models/miyazaki.md: data/scenes/shafts.toml from `--model miyazaki` (left) and from
`--model riley` (right), side by side at one exposure (miyazaki's automatic one: the 97th
percentile of luminance maps to 1 − e^{−1.5}).

Riley's model refuses a [haze] layer (Riley et al. 2004 §3: "the system does not currently
render haze"), so its half is the same scene with the [haze] table left out: the clouds, their
shadows on the ground, and Rayleigh air only. Both are CPU references at the scene's settings.

Run from the repository root after `cargo build --release`:
    python3 docs/renders/shafts.py      # writes docs/renders/shafts-miyazaki-riley.png
"""
import os, sys, tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.path.join(ROOT, "target", "release", "photometeor")
SCENE = os.path.join(ROOT, "data", "scenes", "shafts.toml")
OUT = os.path.join(ROOT, "docs", "renders", "shafts-miyazaki-riley.png")
sys.path.insert(0, os.path.join(ROOT, "docs", "miyazaki"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare import without_haze  # noqa: E402
from pair import render as run, save_pair  # noqa: E402


def render(scene, model, exr, tables):
    args = [BIN, "render", scene, "--cpu", "--out", exr, "--tables", tables]
    if model != "riley":
        args += ["--model", model]
    return run(args, exr)


def main():
    with tempfile.TemporaryDirectory() as tmp:
        tables = os.path.join(tmp, "tables")
        left = render(SCENE, "miyazaki", os.path.join(tmp, "m.exr"), tables)
        clear = os.path.join(tmp, "shafts-no-haze.toml")
        without_haze(SCENE, clear)
        right = render(clear, "riley", os.path.join(tmp, "r.exr"), tables)
    exposure = save_pair(left, right, OUT)
    print(f"{OUT}: exposure {exposure:.4g}")

if __name__ == "__main__":
    main()
