"""The growing-droplet cumulus of docs/scenes.md (data/scenes/growing_cumulus.toml): droplets
whose effective radius follows the adiabatic law from 6 µm at the base to 14 µm at the top,
seen from above around the glory. Renders riley, coupled and max here, measures each against
the path-traced truth with `photometeor compare-render`, and draws

- `growing_cumulus-four.png`: truth, riley, coupled and max, 2 × 2 at one exposure (the truth's
  automatic exposure, as `render --png` picks it);
- `growing_cumulus-glory.png`: the glory's radial profile (mean luminance against the angle from
  the antisolar point, over 10-12° = 1) of the truth, of the truth of the same cloud with one
  size everywhere (cloud@02, 10.6 µm), of riley and of coupled;
- `growing_cumulus.json`: the figures.

The truths are the long part: give them as EXRs rendered at 384 × 256 (`--truth`,
`--fixed-truth`), or they are rendered here with `--spp` samples (on the GPU where there is
one; on 2 CPU cores 4096 spp would take about half an hour each).

    python3 docs/renders/growing.py [--bin target/release/photometeor] [--truth T.exr]
        [--fixed-truth F.exr] [--spp 4096]
"""
import argparse
import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

from pair import against_truth, grid_2x2, read_exr, render, rings

HERE = Path(__file__).resolve().parent
SCENE = HERE.parents[1] / "data/scenes/growing_cumulus.toml"
W, H, FOV = 384, 256, 36.0


def fixed_scene(tmp):
    """The scene with one size everywhere: the volume holds the member cloud@02 (10.6 µm)."""
    text = SCENE.read_text()
    text = re.sub(r"(?m)^r_eff_um = \{.*\}\n", "", text)
    text = text.replace('field = "cloud"\nshape', 'field = "cloud@02"\nshape')
    path = tmp / "growing_cumulus_fixed.toml"
    path.write_text(text)
    return path


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", default=str(HERE.parents[1] / "target/release/photometeor"))
    p.add_argument("--truth", help="truth EXR of the scene at 384×256")
    p.add_argument("--fixed-truth", help="truth EXR of the one-size cloud at 384×256")
    p.add_argument("--spp", type=int, default=4096)
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="growing-"))
    size = ["--width", str(W), "--height", str(H)]
    truths = {}
    for name, given, scene in [("truth", a.truth, SCENE),
                               ("fixed-truth", a.fixed_truth, fixed_scene(tmp))]:
        exr = given or str(tmp / f"{name}.exr")
        if not given:
            render([a.bin, "render", str(scene), "--model", "truth", *size, "--spp",
                    str(a.spp), "--out", exr], exr)
        truths[name] = exr
    truth = read_exr(truths["truth"])
    frames = {"truth": truth}
    report = {"size": [W, H], "truth": truths["truth"], "models": {}}
    for model in ["riley", "coupled", "max"]:
        frames[model], report["models"][model] = against_truth(
            a.bin, SCENE, model, size, truths["truth"], str(tmp / f"{model}.exr"))
    exposure, img = grid_2x2([(truth, frames["riley"]), (frames["coupled"], frames["max"])], truth)
    out = HERE / "growing_cumulus-four.png"
    Image.fromarray(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(out, optimize=True)
    report["exposure"] = exposure

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    curves = {"truth, 6 → 14 µm with height": truth,
              "truth, 10.6 µm everywhere": read_exr(truths["fixed-truth"]),
              "riley, 6 → 14 µm": frames["riley"], "coupled, 6 → 14 µm": frames["coupled"]}
    fig, ax = plt.subplots(figsize=(7, 3.6), dpi=110)
    report["glory_profile"] = {}
    for (label, rgb), style in zip(curves.items(), ["k-", "k--", "C0-", "C1-"]):
        theta, value = rings(rgb, FOV)
        ax.plot(theta, value, style, label=label)
        report["glory_profile"][label] = [round(v, 4) for v in value]
    report["glory_profile"]["angle_deg"] = [round(t, 3) for t in theta]
    ax.set_xlabel("angle from the antisolar point (°)")
    ax.set_ylabel("mean luminance (10–12° = 1)")
    ax.set_title("glory of the growing-droplet cumulus")
    ax.set_xlim(0, 8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "growing_cumulus-glory.png")
    (HERE / "growing_cumulus.json").write_text(json.dumps(report, indent=1) + "\n")
    print(out)


if __name__ == "__main__":
    sys.exit(main())
