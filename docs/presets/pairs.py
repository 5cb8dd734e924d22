#!/usr/bin/env python3
"""A preset's noise from two bakes at different seeds, no reference needed (docs/accuracy.md, "Presets that keep their promise").

    python3 docs/presets/pairs.py DIR_SEED_A DIR_SEED_B

Crystal tables are Monte Carlo estimates without bias, so two bakes of the same preset at
different seeds (`photometeor bake --seed`) are independent estimates of equal noise, and the
rms relative difference of their Ams_1 over θ ≥ 1°, divided by √2, is either one's error against
the truth. Prints per field and channel that rms (and the largest single bin's |difference|/√2),
and the worst channel; for rough crystals (roughness > 0) also over 1° ≤ θ ≤ 179°, the bins
their noise target counts (`mie::crystal::noise_skips_pole`), and the largest difference within
1° of 180°. Drops at two seeds have other size nodes: their difference is the size sampling's
noise. Reads the EXRs with the OpenEXR package.
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
        fields = json.load(f)["fields"]
    for field in fields:
        name = field["name"]
        pa, theta = ams1(os.path.join(a, name + ".exr"))
        pb, _ = ams1(os.path.join(b, name + ".exr"))
        rel = (pa / pb - 1.0) / np.sqrt(2.0)

        def report(keep):
            rms = np.sqrt((rel[:, keep] ** 2).mean(axis=1))
            top = np.abs(rel[:, keep]).max(axis=1)
            cells = ", ".join(f"{c} {100 * r:.2f} % ({100 * m:.1f} %)" for c, r, m in zip("RGB", rms, top))
            return f"{cells}; worst {100 * rms.max():.2f} %"

        print(f"{name}: θ ≥ 1°: {report(theta >= 1.0)}")
        if ((field.get("microphysics") or {}).get("crystal") or {}).get("roughness", 0.0) > 0.0:
            print(f"{name}: 1°–179°: {report((theta >= 1.0) & (theta <= 179.0))}")
            pole = theta > 179.0
            print(f"{name}: within 1° of 180°, largest |difference|/√2: {100 * np.abs(rel[:, pole]).max():.1f} %")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
