#!/usr/bin/env python3
"""A preset's noise from two bakes at different seeds, no reference needed (issue 20).

    python3 docs/presets/pairs.py DIR_SEED_A DIR_SEED_B

Crystal tables are Monte Carlo estimates without bias, so two bakes of the same preset at
different seeds (`photometeor bake --seed`) are independent estimates of equal noise, and the
rms relative difference of their Ams_1 over θ ≥ 1°, divided by √2, is either one's error against
the truth. Prints per field and channel that rms (and the largest single bin's |difference|/√2),
and the worst channel. Reads the EXRs with the OpenEXR package.
"""

import json
import os
import sys

import numpy as np
import OpenEXR


def ams1(path):
    part = OpenEXR.File(path).parts[0]
    rgb = np.asarray(part.channels["RGB"].pixels, dtype=np.float64)
    step = float(np.ravel(part.header["photometeor/theta_step_deg"])[0])
    row = rgb[0].T
    return row, np.arange(row.shape[1]) * step


def main(a, b):
    with open(os.path.join(a, "manifest.json")) as f:
        names = [x["name"] for x in json.load(f)["fields"]]
    for name in names:
        pa, theta = ams1(os.path.join(a, name + ".exr"))
        pb, _ = ams1(os.path.join(b, name + ".exr"))
        keep = theta >= 1.0
        rel = (pa[:, keep] / pb[:, keep] - 1.0) / np.sqrt(2.0)
        rms = np.sqrt((rel**2).mean(axis=1))
        top = np.abs(rel).max(axis=1)
        cells = ", ".join(f"{c} {100 * r:.2f} % ({100 * m:.1f} %)" for c, r, m in zip("RGB", rms, top))
        print(f"{name}: {cells}; worst {100 * rms.max():.2f} %")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
