#!/usr/bin/env python3
"""Check one photometeor field EXR with the OpenEXR reference library (the EXR contract).

Usage: python3 tables/format/tests/exr_openexr.py FIELD.exr EXPECTED.json

EXPECTED.json (written by the Rust test `openexr_reference_library_reads_our_file`):
    {"field": str, "theta_step_deg": float, "n_max": int, "angle_count": int, "schema": 1,
     "channels": {"R": [[...K] x N], "G": ..., "B": ..., <extra layer>: ...},
     "forward_fraction": {"R": [F_1..F_N], "G": ..., "B": ...}}
Channel values are the f32 values written, so the comparison is exact.

Checks: single part; scanline (not tiled, not deep); channels exactly R, G, B (+ the extra
layers named in the JSON), each 32-bit FLOAT with sampling 1x1; data window (0, 0)-(K-1, N-1);
the photometeor/* attributes (schema, field, theta_step_deg, n_max, forward_fraction_R/G/B as
comma-separated decimals); every pixel equal to the JSON.

Needs the `OpenEXR` (3.x, with `OpenEXR.File`) and `numpy` packages:
    python3 -m pip install OpenEXR numpy
Prints "OK ..." and exits 0 on success; prints every failed check and exits 1 otherwise;
exits 2 if a package is missing.
"""

import json
import sys

PIP_HINT = "python3 -m pip install OpenEXR numpy"

try:
    import numpy as np
    import OpenEXR
except ImportError as e:  # pragma: no cover - environment problem, reported loudly
    print(f"missing Python package ({e}); install it with `{PIP_HINT}`", file=sys.stderr)
    sys.exit(2)

if not hasattr(OpenEXR, "File"):
    print(
        f"OpenEXR {getattr(OpenEXR, '__version__', '?')} lacks OpenEXR.File (need 3.x); "
        f"upgrade with `{PIP_HINT} --upgrade`",
        file=sys.stderr,
    )
    sys.exit(2)


def main(exr_path: str, json_path: str) -> int:
    with open(json_path, encoding="utf-8") as f:
        expected = json.load(f)
    failures = []

    def check(ok, what):
        if not ok:
            failures.append(what)
        return ok

    k, n = expected["angle_count"], expected["n_max"]
    exr = OpenEXR.File(exr_path, separate_channels=True)

    check(len(exr.parts) == 1, f"single part: found {len(exr.parts)} parts")
    part = exr.parts[0]
    check(part.type() == OpenEXR.scanlineimage, f"scanline image: found type {part.type()}")
    header = part.header

    (xmin, ymin), (xmax, ymax) = (tuple(int(v) for v in p) for p in header["dataWindow"])
    check((xmin, ymin) == (0, 0), f"data window origin (0, 0): found ({xmin}, {ymin})")
    width, height = xmax - xmin + 1, ymax - ymin + 1
    check(width == k, f"width = K = {k}: found {width}")
    check(height == n, f"height = N = {n}: found {height}")
    check(part.width() == k and part.height() == n, "part.width()/height() agree")

    names = sorted(part.channels.keys())
    want = sorted(expected["channels"].keys())
    check(names == want, f"channels exactly {want}: found {names}")
    for name, channel in part.channels.items():
        check(channel.type() == OpenEXR.FLOAT, f"channel {name} is FLOAT: found {channel.type()}")
        check(
            (channel.xSampling, channel.ySampling) == (1, 1),
            f"channel {name} sampling 1x1: found {channel.xSampling}x{channel.ySampling}",
        )
        pixels = channel.pixels
        check(pixels.dtype == np.float32, f"channel {name} dtype float32: found {pixels.dtype}")
        if name in expected["channels"]:
            ref = np.asarray(expected["channels"][name], dtype=np.float32)
            if check(pixels.shape == ref.shape, f"channel {name} shape {ref.shape}: found {pixels.shape}"):
                bad = np.argwhere(pixels != ref)
                if bad.size:
                    r, c = bad[0]
                    check(
                        False,
                        f"channel {name}: {len(bad)} pixels differ, first at row {r} column {c}: "
                        f"{pixels[r, c]!r} != {ref[r, c]!r}",
                    )

    def attribute(name):
        if check(name in header, f"attribute {name} present"):
            return header[name]
        return None

    schema = attribute("photometeor/schema")
    check(schema in (1, "1"), f"photometeor/schema = 1: found {schema!r}")
    field = attribute("photometeor/field")
    check(field == expected["field"], f"photometeor/field = {expected['field']!r}: found {field!r}")
    step = attribute("photometeor/theta_step_deg")
    # The binding returns an EXR `double` as a 1-element float64 array (a Python float would
    # round-trip as `float`); a scalar is accepted too.
    step = None if step is None else np.asarray(step, dtype=np.float64).reshape(-1)
    check(
        step is not None and step.size == 1 and step[0] == expected["theta_step_deg"],
        f"photometeor/theta_step_deg = {expected['theta_step_deg']} (double): found {step!r}",
    )
    n_max = attribute("photometeor/n_max")
    check(n_max == n, f"photometeor/n_max = {n}: found {n_max!r}")
    for c in ("R", "G", "B"):
        name = f"photometeor/forward_fraction_{c}"
        text = attribute(name)
        if text is None:
            continue
        values = [float(v) for v in str(text).split(",")]
        check(
            values == expected["forward_fraction"][c],
            f"{name} = {expected['forward_fraction'][c]}: found {values}",
        )

    if failures:
        print(f"{exr_path}: {len(failures)} check(s) failed:", file=sys.stderr)
        for what in failures:
            print(f"  - {what}", file=sys.stderr)
        return 1
    print(
        f"OK {exr_path}: single-part scanline, {width}x{height}, channels {names} FLOAT, "
        f"photometeor/* attributes and all pixels match (OpenEXR {OpenEXR.__version__}, numpy {np.__version__})"
    )
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1], sys.argv[2]))
