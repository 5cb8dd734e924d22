#!/usr/bin/env python3
"""The glory's rings and the fogbow at a game's frame size: coupled's CPU render of the glory
scene (and of it without the sky, and seen with a 100° view for the fogbow) at 1920 × 1080,
at the `realtime` and `balanced` presets, its ring contrast measured as examples.py measures it
(the same rings, windows and formula), against the truth's and coupled's own at the examples'
sizes (examples.json: 256² for the glory, 192² for the fogbow). The gather marches each pixel's
ray on its own, so a larger frame samples the same lighting more finely: what this checks is
that the rings stay as sharp at 1080p (contrast within 10 % of the truth's, relative).

Writes docs/coupled/rings1080.json and rings1080.md. Run from the repository root after
`cargo build --release`, with the test
venv's Python (numpy, OpenEXR):
    .venv/bin/python docs/coupled/rings1080.py
    .venv/bin/python docs/coupled/rings1080.py --markdown-only  # rings1080.md from the JSON
"""
import argparse, json, os, sys, time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from examples import (FOGBOW_FOV, WORK, cases, contrast, file_stem,  # noqa: E402
                      lower_rings, run)

WIDTH, HEIGHT = 1920, 1080
PRESETS = ["realtime", "balanced"]
# The cases of examples.json with rings, and the vertical field of view each is seen with.
CASES = [("glory", 36.0), ("glory (sky off)", 36.0), ("glory (fogbow)", FOGBOW_FOV)]


def measure(name, rgb, fov):
    """(darkest ring's angle, brightest's, contrast) as examples.py measures this case."""
    from pair import rings
    if name == "glory (fogbow)":
        theta, value = lower_rings(rgb, fov)
        return contrast(theta, value, dark=(28.0, 36.0), bright=(36.0, 44.0))
    theta, value = rings(rgb, fov)
    return contrast(theta, value)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--markdown-only", action="store_true")
    a = p.parse_args()
    out = os.path.join(HERE, "rings1080.json")
    if a.markdown_only:
        write_markdown(json.load(open(out)))
        return
    from pair import read_exr
    examples = json.load(open(os.path.join(HERE, "examples.json")))["scenes"]
    report = {"size": [WIDTH, HEIGHT], "quality": "draft", "cases": {}}
    scenes = {name: scene for name, scene, _, _ in cases()}
    for name, fov in CASES:
        rings = examples[name]["rings"]
        row = {"examples_size": examples[name]["size"],
               "truth": rings["truth"]["contrast"],
               "coupled_examples_size": rings["coupled"]["contrast"], "presets": {}}
        for preset in PRESETS:
            exr = f"{WORK}/{file_stem(name)}-coupled-{preset}-{WIDTH}x{HEIGHT}.exr"
            t0 = time.time()
            run(["render", scenes[name], "--model", "coupled", "--cpu", "--quality", "draft",
                 "--width", str(WIDTH), "--height", str(HEIGHT), "--set",
                 f'preset="{preset}"', "--out", exr])
            seconds = time.time() - t0
            lo, hi, c = measure(name, read_exr(exr), fov)
            row["presets"][preset] = {"minimum_deg": lo, "peak_deg": hi, "contrast": c,
                                      "against_truth": c / row["truth"] - 1.0,
                                      "render_s": round(seconds, 1)}
            print(f"{name} {preset}: minimum {lo:.3f}°, peak {hi:.3f}°, contrast {c:+.1%} "
                  f"(truth {row['truth']:+.1%}, {c / row['truth'] - 1:+.1%} of it) "
                  f"[{seconds:.0f} s]", flush=True)
        report["cases"][name] = row
    json.dump(report, open(out, "w"), indent=1)
    write_markdown(report)


def write_markdown(report):
    w, h = report["size"]
    md = [f"Ring contrasts at {w}×{h} (coupled, CPU render, draft tables; `rings1080.py`) against "
          "the truth's at the examples' size ([examples.md](examples.md)):", "",
          "| case | truth (examples' size) | coupled (examples' size) | "
          + " | ".join(f"coupled {p}, {w}×{h}" for p in PRESETS) + " |",
          "|" + "---|" * (3 + len(PRESETS))]
    for name, row in report["cases"].items():
        size = "×".join(str(v) for v in row["examples_size"])
        cells = [f"{r['contrast']:+.1%} ({r['against_truth']:+.1%} of the truth's; "
                 f"ring at {r['peak_deg']:.3f}°)" for r in
                 (row["presets"][p] for p in PRESETS)]
        md.append(f"| {name} | {row['truth']:+.1%} ({size}) | "
                  f"{row['coupled_examples_size']:+.1%} | " + " | ".join(cells) + " |")
    open(os.path.join(HERE, "rings1080.md"), "w").write("\n".join(md).replace("%", " %") + "\n")


if __name__ == "__main__":
    main()
