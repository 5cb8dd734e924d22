#!/usr/bin/env python3
"""Check a whole photometeor bake with the OpenEXR reference library, independently of our reader.

Usage: python3 tests/check_bake_openexr.py BAKE_DIR

Reads BAKE_DIR/manifest.json and every field's EXR through the `OpenEXR` Python package (the
Academy Software Foundation's bindings of the reference C++ library), independently of
photometeor's own reader, and checks the EXR contract of docs/engines.md:
  - one part, scanline, channels exactly R, G, B (more only as dotted layer names), each
    32-bit FLOAT, sampling 1x1;
  - width = manifest angle_count = 180/theta_step_deg + 1, height = the field's n_max;
  - header attributes photometeor/schema, /field, /theta_step_deg, /n_max and
    /forward_fraction_R|G|B, equal to the manifest;
  - every row of every channel: finite, energy sum_k v_k Omega_k = 1 within 1e-6, no value below
    -1e-6 x the row maximum, and F_i recomputed from the bins (the forward hemisphere, the bin
    straddling 90 deg counted by its mu >= 0 part) equal to the manifest's within 1e-4.
Bin solid angles are computed here from the grid definition (bin k covers
[theta_k - d/2, theta_k + d/2] clipped to [0, 180] deg).

Needs `python3 -m pip install OpenEXR numpy`. Prints "OK ..." and exits 0, or prints every
failed check and exits 1; exits 2 if a package is missing.
"""

import json
import math
import os
import sys

PIP_HINT = "python3 -m pip install OpenEXR numpy"

try:
    import numpy as np
    import OpenEXR
except ImportError as e:  # pragma: no cover - environment problem, reported loudly
    print(f"missing Python package ({e}); install it with `{PIP_HINT}`", file=sys.stderr)
    sys.exit(2)

if not hasattr(OpenEXR, "File"):
    print(f"OpenEXR lacks OpenEXR.File (need 3.x); `{PIP_HINT} --upgrade`", file=sys.stderr)
    sys.exit(2)


def bin_geometry(step_deg, count):
    """Solid angle of each bin and the part of it in the forward hemisphere (mu >= 0)."""
    k = np.arange(count)
    lo = np.radians(np.clip((k - 0.5) * step_deg, 0.0, 180.0))
    hi = np.radians(np.clip((k + 0.5) * step_deg, 0.0, 180.0))
    omega = 2.0 * math.pi * (np.cos(lo) - np.cos(hi))
    forward = 2.0 * math.pi * (np.cos(lo) - np.cos(np.minimum(hi, math.pi / 2)))
    forward = np.where(lo < math.pi / 2, forward, 0.0)
    return omega, forward


def main(bake_dir):
    with open(os.path.join(bake_dir, "manifest.json"), encoding="utf-8") as f:
        manifest = json.load(f)
    failures = []

    def check(ok, what):
        if not ok:
            failures.append(what)
        return ok

    step = manifest["theta_step_deg"]
    k_len = manifest["angle_count"]
    check(k_len == round(180.0 / step) + 1, f"angle_count {k_len} = 180/{step} + 1")
    omega, forward = bin_geometry(step, k_len)
    check(abs(omega.sum() - 4 * math.pi) < 1e-12, "bin solid angles sum to 4 pi")
    worst = {"energy": 0.0, "negative": 0.0, "forward_fraction": 0.0}
    for field in manifest["fields"]:
        name, n_max = field["name"], field["n_max"]
        exr = OpenEXR.File(os.path.join(bake_dir, field["file"]), separate_channels=True)
        check(len(exr.parts) == 1, f"{name}: one part, found {len(exr.parts)}")
        part = exr.parts[0]
        check(part.type() == OpenEXR.scanlineimage, f"{name}: scanline image")
        header = part.header
        check(part.width() == k_len, f"{name}: width {part.width()} = {k_len}")
        check(part.height() == n_max, f"{name}: height {part.height()} = N = {n_max}")
        rgb = [c for c in part.channels if "." not in c]
        check(sorted(rgb) == ["B", "G", "R"], f"{name}: channels R, G, B, found {sorted(rgb)}")
        check(int(header.get("photometeor/schema", -1)) == 1, f"{name}: photometeor/schema = 1")
        check(header.get("photometeor/field") == name, f"{name}: photometeor/field")
        # A double attribute comes back as a one-element float64 array.
        step_attr = np.atleast_1d(np.asarray(header.get("photometeor/theta_step_deg", [-1.0])))
        check(
            step_attr.dtype == np.float64 and step_attr.size == 1 and step_attr[0] == step,
            f"{name}: photometeor/theta_step_deg = {step} (double), found {step_attr!r}",
        )
        check(int(header.get("photometeor/n_max", -1)) == n_max, f"{name}: photometeor/n_max")
        for c in "RGB":
            channel = part.channels.get(c)
            if not check(channel is not None, f"{name}: channel {c} present"):
                continue
            check(channel.type() == OpenEXR.FLOAT, f"{name}.{c}: 32-bit FLOAT")
            check((channel.xSampling, channel.ySampling) == (1, 1), f"{name}.{c}: sampling 1x1")
            rows = channel.pixels.astype(np.float64)
            manifest_f = np.array(field["forward_fraction"][c])
            attr = header.get(f"photometeor/forward_fraction_{c}", "")
            attr_f = np.array([float(v) for v in str(attr).split(",") if v])
            check(
                attr_f.shape == manifest_f.shape and np.array_equal(attr_f, manifest_f),
                f"{name}.{c}: photometeor/forward_fraction_{c} equals the manifest",
            )
            check(np.isfinite(rows).all(), f"{name}.{c}: finite")
            for n in range(n_max):
                row = rows[n]
                energy = float(row @ omega)
                negative = float(-min(row.min(), 0.0) / row.max())
                f_bins = float(row @ forward)
                df = abs(f_bins - manifest_f[n])
                worst["energy"] = max(worst["energy"], abs(energy - 1.0))
                worst["negative"] = max(worst["negative"], negative)
                worst["forward_fraction"] = max(worst["forward_fraction"], df)
                check(abs(energy - 1.0) <= 1e-6, f"{name}.{c} Ams_{n + 1}: energy {energy!r}")
                check(negative <= 1e-6, f"{name}.{c} Ams_{n + 1}: min/max {-negative!r}")
                check(df <= 1e-4, f"{name}.{c} F_{n + 1}: bins {f_bins!r} vs {manifest_f[n]!r}")
    if failures:
        for f in failures:
            print("FAIL", f)
        return 1
    names = [f["name"] for f in manifest["fields"]]
    print(
        f"OK {names}: |energy - 1| <= {worst['energy']:.2e}, "
        f"negative share <= {worst['negative']:.2e}, |F_bins - F| <= {worst['forward_fraction']:.2e}"
    )
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1]))
