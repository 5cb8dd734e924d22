#!/usr/bin/env python3
"""Check `photometeor export` output in the programs that consume it, independently of our code.

Usage: python3 tests/check_export.py BAKE_DIR NPY_DIR MITSUBA_DIR BEVY_DIR

- NumPy: NPY_DIR/theta_deg.npy and <field>.ams.npy (orders x R, G, B x bins) equal the bake's
  EXR rows read with the OpenEXR reference library (the npy holds the f32 values exactly).
- Mitsuba 3 (variant scalar_rgb): each exported tabphase (MITSUBA_DIR/mitsuba.json, the values
  the XML holds), loaded with mi.load_dict and evaluated through Mitsuba's own PhaseFunction at
  our bin centres, equals the table read linearly in cos theta here (so Mitsuba's direction
  convention and normalisation are what export.json states), and its light in a wrong bin,
  1/2 sum_k Omega_k |p_mitsuba(theta_k) - p_k| against the bake's Ams_n, stays within the
  `moved` export.json reports + 10^-4 (point values at bin centres against bin averages).
- Bevy EXR: BEVY_DIR/<field>.ams<n>.exr read with OpenEXR is width x 1, channels R, G, B, A,
  and its texels equal the mitsuba values for the same field, order and sample count.

Needs `python3 -m pip install OpenEXR numpy mitsuba`. Prints "OK ..." and exits 0, or every
failed check and exits 1; exits 2 if a package is missing.
"""

import json
import math
import os
import sys

PIP_HINT = "python3 -m pip install OpenEXR numpy mitsuba"

try:
    import mitsuba as mi
    import numpy as np
    import OpenEXR
except ImportError as e:  # pragma: no cover - environment problem, reported loudly
    print(f"missing Python package ({e}); install it with `{PIP_HINT}`", file=sys.stderr)
    sys.exit(2)

mi.set_variant("scalar_rgb")


def bins(step, count):
    k = np.arange(count)
    lo = np.radians(np.clip((k - 0.5) * step, 0.0, 180.0))
    hi = np.radians(np.clip((k + 0.5) * step, 0.0, 180.0))
    return 2.0 * math.pi * (np.cos(lo) - np.cos(hi))


def read_rows(path):
    part = OpenEXR.File(path, separate_channels=True).parts[0]
    return {c: np.asarray(part.channels[c].pixels, dtype=np.float64) for c in part.channels}


def main(bake, npy_dir, mitsuba_dir, bevy_dir):
    failures = []

    def check(ok, what):
        if not ok:
            failures.append(what)
        return ok

    manifest = json.load(open(os.path.join(bake, "manifest.json"), encoding="utf-8"))
    step, k_len = manifest["theta_step_deg"], manifest["angle_count"]
    omega = bins(step, k_len)
    theta = np.load(os.path.join(npy_dir, "theta_deg.npy"))
    check(np.array_equal(theta, np.arange(k_len) * step), "theta_deg.npy is k * step")
    npy_report = json.load(open(os.path.join(npy_dir, "export.json"), encoding="utf-8"))
    exr_rows = {f["name"]: read_rows(os.path.join(bake, f["file"])) for f in manifest["fields"]}
    for name, entry in npy_report["fields"].items():
        ams = np.load(os.path.join(npy_dir, f"{name}.ams.npy"))
        orders = [int(o) for o in entry["orders"]]
        check(ams.shape == (len(orders), 3, k_len), f"{name}.ams.npy shape {ams.shape}")
        for i, n in enumerate(orders):
            for c, ch in enumerate("RGB"):
                want = exr_rows[name][ch][n - 1]
                check(np.array_equal(ams[i, c], want), f"{name} Ams_{n} {ch}: npy = EXR row")

    report = json.load(open(os.path.join(mitsuba_dir, "export.json"), encoding="utf-8"))
    tables = json.load(open(os.path.join(mitsuba_dir, "mitsuba.json"), encoding="utf-8"))
    ctx = mi.PhaseFunctionContext()
    mei = mi.MediumInteraction3f()
    mei.wi = mi.Vector3f(0, 0, 1)  # towards where the light goes on: wo = -wi is forward
    mei.sh_frame = mi.Frame3f(mei.wi)
    centres = np.radians(np.arange(k_len) * step)
    worst_eval, worst_margin = 0.0, -1.0
    for name, orders in tables["fields"].items():
        for order, per in orders.items():
            for c, ch in enumerate("RGB"):
                values = np.asarray(per[ch], dtype=np.float64)
                n = len(values)
                phase = mi.load_dict(
                    {"type": "tabphase", "values": ", ".join(repr(float(v)) for v in values)}
                )
                got = np.empty(k_len)
                for k, t in enumerate(centres):
                    wo = mi.Vector3f(math.sin(t), 0.0, -math.cos(t))
                    got[k] = phase.eval_pdf(ctx, mei, wo)[1]
                mu_grid = np.linspace(-1.0, 1.0, n)
                mu = np.cos(centres)
                linear = np.interp(mu, mu_grid, values)
                # Mitsuba finds the cell in f32: the position u = (mu + 1)/2 (n - 1) is off by
                # up to ~n 2^-24 cells, which moves the value by that share of the cell's step.
                cell = np.clip(((mu + 1.0) / 2.0 * (n - 1)).astype(int), 0, n - 2)
                step_v = np.abs(values[cell + 1] - values[cell])
                allowed = 4.0 * n * 2.0**-24 * step_v + 2e-6 * linear
                excess = np.max((np.abs(got - linear) - allowed) / np.maximum(linear, 1e-30))
                worst_eval = max(worst_eval, float(np.max(np.abs(got - linear) / linear)))
                check(
                    excess <= 0.0,
                    f"{name} Ams_{order} {ch}: Mitsuba vs linear in cos beyond f32 position "
                    f"rounding by {excess:.2e} of the value",
                )
                ours = exr_rows[name][ch][int(order) - 1]
                moved = 0.5 * float(np.sum(omega * np.abs(got - ours)))
                reported = report["fields"][name]["orders"][order]["channels"][ch]["moved"]
                worst_margin = max(worst_margin, moved - reported)
                check(
                    moved <= reported + 1e-4,
                    f"{name} Ams_{order} {ch}: Mitsuba's wrong-bin light {moved:.4%} > reported "
                    f"{reported:.4%} + 0.01 %",
                )
                exr = os.path.join(bevy_dir, f"{name}.ams{order}.exr")
                if os.path.exists(exr):
                    part = OpenEXR.File(exr, separate_channels=True).parts[0]
                    check(
                        sorted(part.channels) == ["A", "B", "G", "R"] and part.height() == 1,
                        f"{exr}: one row of R, G, B, A",
                    )
                    texels = np.asarray(part.channels[ch].pixels, dtype=np.float32).ravel()
                    check(
                        np.array_equal(texels, values.astype(np.float32)),
                        f"{exr} {ch}: texels = the mitsuba values",
                    )
    if failures:
        print("\n".join(failures))
        return 1
    print(
        f"OK: npy = EXR rows; Mitsuba tabphase = linear in cos theta (worst {worst_eval:.1e}, f32 "
        f"cell position); "
        f"its wrong-bin light exceeds the reported by at most {worst_margin:+.2e}"
    )
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 5:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(*sys.argv[1:]))
