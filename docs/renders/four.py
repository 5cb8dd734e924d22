"""The README's dense cumulus by riley, max, coupled and the path-traced truth, side by side at
one exposure (the truth's automatic exposure, as `render --png` picks it), each model measured
against the truth by `photometeor compare-render`. The truth is the long part: give it as an
EXR already rendered at the same size (`--truth`), or it is rendered here (`--truth-seconds`).

    python3 docs/renders/four.py [--bin target/release/photometeor] [--truth TRUTH.exr]
"""
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

from pair import LUMA, render, srgb

HERE = Path(__file__).resolve().parent
SCENE = HERE.parents[1] / "data/scenes/dense_cumulus.toml"
W, H = 120, 80


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", default=str(HERE.parents[1] / "target/release/photometeor"))
    p.add_argument("--truth", help="a truth EXR of the scene at 120×80 (render --model truth)")
    p.add_argument("--truth-seconds", type=float, default=720)
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="four-"))
    size = ["--width", str(W), "--height", str(H), "--cpu"]
    truth_exr = a.truth or str(tmp / "truth.exr")
    if not a.truth:
        render([a.bin, "render", str(SCENE), "--model", "truth", *size, "--set", "spp=65536",
                "--set", f"max_seconds={a.truth_seconds}", "--out", truth_exr], truth_exr)
    with __import__("OpenEXR").File(truth_exr, separate_channels=True) as f:
        ch = f.channels()
        truth = np.stack([ch[c].pixels for c in "RGB"], axis=-1).astype(np.float64)
    frames, report = {}, {"size": [W, H], "truth": truth_exr, "models": {}}
    for model in ["riley", "max", "coupled"]:
        exr = str(tmp / f"{model}.exr")
        started = time.time()
        frames[model] = render([a.bin, "render", str(SCENE), "--model", model, *size,
                                "--out", exr], exr)
        seconds = time.time() - started
        out = subprocess.run([a.bin, "compare-render", truth_exr, exr, "--json"],
                             capture_output=True, text=True, check=True)
        report["models"][model] = {"error": json.loads(out.stdout), "wall_s_incl_start": seconds}
        e = report["models"][model]["error"]
        print(f"{model}: bias {e['bias']:+.1%}, median {e['median_rel_error']:.1%}, "
              f"p95 {e['p95_rel_error']:.1%} (truth noise {e['truth_noise']:.1%}), {seconds:.1f} s")
    lum = truth @ LUMA
    exposure = 1.5 / np.sort(lum.ravel())[int((lum.size - 1) * 0.97)]
    gap = np.zeros((H, 4, 3))
    top = np.concatenate([frames["riley"], gap, frames["max"]], axis=1)
    bottom = np.concatenate([frames["coupled"], gap, truth], axis=1)
    grid = np.concatenate([top, np.zeros((4, top.shape[1], 3)), bottom], axis=0)
    img = srgb(1.0 - np.exp(-exposure * np.maximum(grid, 0.0)))
    img[:, W:W + 4] = 1.0
    img[H:H + 4, :] = 1.0
    # Each pixel shown as 2 × 2 (nearest): the truth's cost grows with the pixels.
    img = img.repeat(2, axis=0).repeat(2, axis=1)
    out = HERE / "dense_cumulus-four.png"
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(out, optimize=True)
    report["exposure"] = exposure
    (HERE / "dense_cumulus-four.json").write_text(json.dumps(report, indent=1) + "\n")
    print(out)


if __name__ == "__main__":
    sys.exit(main())
