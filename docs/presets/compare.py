#!/usr/bin/env python3
"""The presets' errors against references whose own noise is measured (docs/accuracy.md, "Presets that keep their promise").

    python3 docs/presets/compare.py OUT.json MODE=DIR ... 

Each MODE is a spectral mode's set of bakes in DIR: DIR/draft, DIR/standard (the presets, seed
0), DIR/ref (a reference bake of every field) and DIR/ref_s1, DIR/ref_s1_*, … (reference bakes
of some fields at other seeds: each field's reference noise comes from the first that has it).
A reference must not share the presets' random streams (crystals at seed 0 trace the same first
chunks as the presets), so the crystals' `ref` is a bake at another seed. For every field and channel, over the bins θ ≥ 1° of Ams_1
(the forward bin holds the diffraction peak), this prints and writes:

- a preset's rms and max relative error against `ref`: what `photometeor compare` reports;
- the reference's own noise: the rms relative difference of `ref` and `ref_s1` divided by √2
  (two independent estimates of equal noise);
- the preset's error against the truth, estimated as √(rms² − noise²) (the preset's and the
  reference's errors are independent).

Reads the EXRs with the OpenEXR package (the reference library's bindings), not with
photometeor's reader.
"""

import json
import math
import os
import sys

import numpy as np
import OpenEXR


def ams1(path):
    """Ams_1 per channel (3 × K, 1/sr) and θ in degrees: row 0 of the EXR (rows Ams_n)."""
    part = OpenEXR.File(path).parts[0]
    rgb = np.asarray(part.channels["RGB"].pixels, dtype=np.float64)  # N × K × 3
    step = float(np.ravel(part.header["photometeor/theta_step_deg"])[0])
    row = rgb[0].T
    return row, np.arange(row.shape[1]) * step


def fields(d):
    with open(os.path.join(d, "manifest.json")) as f:
        return [x["name"] for x in json.load(f)["fields"]]


def errors(a, b, theta):
    keep = theta >= 1.0
    rel = a[:, keep] / b[:, keep] - 1.0
    return np.sqrt((rel**2).mean(axis=1)), np.abs(rel).max(axis=1)


def main(out, modes):
    report = {}
    for mode, root in modes:
        ref_fields = fields(os.path.join(root, "ref"))
        others = sorted(d for d in os.listdir(root) if d.startswith("ref_s"))
        other_of = {}
        for d in others:
            for name in fields(os.path.join(root, d)):
                other_of.setdefault(name, os.path.join(root, d))
        rows = {}
        for name in ref_fields:
            ref, theta = ams1(os.path.join(root, "ref", name + ".exr"))
            row = {}
            if name in other_of:
                other, _ = ams1(os.path.join(other_of[name], name + ".exr"))
                rms, _ = errors(other, ref, theta)
                row["reference_noise"] = (rms / math.sqrt(2)).tolist()
            for preset in ("draft", "standard"):
                path = os.path.join(root, preset, name + ".exr")
                if not os.path.exists(path):
                    continue
                got, _ = ams1(path)
                rms, mx = errors(got, ref, theta)
                entry = {"rms": rms.tolist(), "max": mx.tolist()}
                if "reference_noise" in row:
                    noise = np.array(row["reference_noise"])
                    entry["against_truth"] = np.sqrt(np.maximum(rms**2 - noise**2, 0.0)).tolist()
                row[preset] = entry
            rows[name] = row
            pct = lambda v: "/".join(f"{100 * x:.2f}" for x in v)
            line = f"{mode:5} {name:6}"
            for preset in ("draft", "standard"):
                if preset in row:
                    e = row[preset]
                    line += f"  {preset} rms {pct(e['rms'])} % (max {pct(e['max'])} %)"
            if "reference_noise" in row:
                line += f"  reference noise {pct(row['reference_noise'])} %"
            print(line)
        report[mode] = rows
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
    print(f"wrote {out}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    main(sys.argv[1], [a.split("=", 1) for a in sys.argv[2:]])
