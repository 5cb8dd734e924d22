"""The README's dense cumulus by riley, max, coupled and the path-traced truth, side by side at
one exposure (the truth's automatic exposure, as `render --png` picks it), each model measured
against the truth by `photometeor compare-render`. The truth is the long part: give it as an
EXR already rendered at the same size (`--truth`), or it is rendered here (`--truth-seconds`).

    python3 docs/renders/four.py [--bin target/release/photometeor] [--truth TRUTH.exr]
"""
import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

from pair import against_truth, grid_2x2, read_exr, render

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
    truth = read_exr(truth_exr)
    frames, report = {}, {"size": [W, H], "truth": truth_exr, "models": {}}
    for model in ["riley", "max", "coupled"]:
        frames[model], report["models"][model] = against_truth(
            a.bin, SCENE, model, size, truth_exr, str(tmp / f"{model}.exr"))
    exposure, img = grid_2x2([(frames["riley"], frames["max"]), (frames["coupled"], truth)], truth)
    # Each pixel shown as 2 × 2 (nearest): the truth's cost grows with the pixels.
    img = img.repeat(2, axis=0).repeat(2, axis=1)
    out = HERE / "dense_cumulus-four.png"
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(out, optimize=True)
    report["exposure"] = exposure
    (HERE / "dense_cumulus-four.json").write_text(json.dumps(report, indent=1) + "\n")
    print(out)


if __name__ == "__main__":
    sys.exit(main())
