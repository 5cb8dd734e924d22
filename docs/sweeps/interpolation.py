#!/usr/bin/env python3
"""Interpolation error of swept fields: each field swept at several spacings, its midpoints
baked directly, and `photometeor compare SWEEP MIDPOINTS` measuring the sweep interpolated at
the midpoints (the two neighbouring members mixed with `SweepEntry::shares`) against them.
Writes interpolation.json and interpolation.md beside this script.

    BIN=target/release/photometeor python3 docs/sweeps/interpolation.py [--quality standard]
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BIN = os.environ.get("BIN", str(HERE.parents[1] / "target/release/photometeor"))

# (field, kind, what the field is besides the swept key, key, from, to)
FIELDS = [
    ("cloud", "cloud", 'distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }',
     "r_eff_um", 4.0, 32.0),
    ("rain", "rain", 'distribution = { kind = "lognormal", median_radius_um = 500, sigma_g = 1.4 }',
     "median_radius_um", 200.0, 2000.0),
    ("ice", "ice", 'habit = "column"', "max_dimension_um", 30.0, 500.0),
]
# The spacings measured per field (rain and ice cost more per member).
RATIOS = {
    "cloud": [1.05, 1.1, 1.15, 1.2, 1.3, 1.5, 2.0],
    "rain": [1.2, 1.5, 2.0],
    "ice": [1.2, 1.5, 2.0],
}
ORDERS = [1, 2, 4, 8, 16, 26]


def scene(quality, name, kind, extra, key, lo, hi, count):
    return f"""[scene]
name = "sweep-{name}"
spectral = "spectral"
wavelengths = 31
theta_step_deg = 0.18
n_max = 26
quality = "{quality}"

[[field]]
name = "{name}"
kind = "{kind}"
{extra}
sweep = {{ key = "{key}", from = {lo!r}, to = {hi!r}, count = {count} }}
"""


def bake(work, text, tag):
    path = work / f"{tag}.toml"
    path.write_text(text)
    out = work / tag
    started = time.time()
    subprocess.run([BIN, "bake", str(path), "--out", str(out), "--quiet"], check=True)
    return out, time.time() - started


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--quality", default="standard")
    p.add_argument("--fields", default="cloud,rain,ice")
    a = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name, kind, extra, key, lo, hi in FIELDS:
            if name not in a.fields.split(","):
                continue
            for q in RATIOS[name]:
                count = math.ceil(math.log(hi / lo) / math.log(q)) + 1
                if count > 64:
                    continue
                actual = (hi / lo) ** (1 / (count - 1))
                m_lo, m_hi = lo * math.sqrt(actual), hi / math.sqrt(actual)
                sweep, seconds = bake(work, scene(a.quality, name, kind, extra, key, lo, hi, count),
                                      f"{name}-{count}")
                if count > 2:
                    mids, _ = bake(work, scene(a.quality, name, kind, extra, key, m_lo, m_hi,
                                               count - 1), f"{name}-{count}-mid")
                else:
                    mid_text = scene(a.quality, name, kind, extra, key, m_lo, m_lo * 1.0001, 2)
                    mids, _ = bake(work, mid_text, f"{name}-{count}-mid")
                report = json.loads(subprocess.run(
                    [BIN, "compare", str(sweep), str(mids), "--json"], check=True,
                    capture_output=True, text=True).stdout)
                green = [f for f in report["fields"] if f["channel"] == "G" and f.get("interpolated")]
                manifest = json.loads((sweep / "manifest.json").read_text())
                noise = statistics.median(
                    f["quality"].get("size_noise", f["quality"].get("crystal_noise", {})).get("G", float("nan"))
                    for f in manifest["fields"])
                by_order = {n: max(f["rms_rel_by_order"][n - 1] for f in green) for n in ORDERS}
                rows.append({
                    "field": name, "key": key, "from": lo, "to": hi, "count": count,
                    "ratio": actual,
                    "worst_rms_ams1": max(f["rms_rel_ams1"] for f in green),
                    "median_rms_ams1": statistics.median(f["rms_rel_ams1"] for f in green),
                    "worst_rms_by_order": by_order,
                    "worst_sigma_ext": max(f["rel_sigma_ext"] for f in green),
                    "worst_g": max(f["abs_g"] for f in green),
                    "worst_forward_fraction": max(f["max_abs_forward_fraction"] for f in green),
                    "preset_noise_ams1": noise,
                    "sweep_bake_seconds": seconds,
                })
                r = rows[-1]
                print(f"{name} ×{actual:.3f} ({count} values): Ams_1 rms worst {r['worst_rms_ams1']:.2%}"
                      f" median {r['median_rms_ams1']:.2%}, σ_ext {r['worst_sigma_ext']:.2%},"
                      f" noise {noise:.2%}, {seconds:.1f} s", flush=True)
    (HERE / "interpolation.json").write_text(json.dumps(
        {"quality": a.quality, "binary": BIN, "rows": rows}, indent=1) + "\n")
    lines = [
        f"Interpolation error of swept fields at `{a.quality}` (`docs/sweeps/interpolation.py`): "
        "the sweep mixed at its midpoints against a direct bake there; rms relative error over "
        "θ ≥ 1°, green channel, the worst midpoint of the sweep; the preset's own noise of "
        "Ams_1 (median over the members) beside it.",
        "",
        "| field | key, range | ratio (values) | Ams_1 worst (median) | "
        + " | ".join(f"Ams_{n}" for n in ORDERS[1:])
        + " | σ_ext | \\|Δg\\| | \\|ΔF_n\\| | preset noise |",
        "|---|---|---|---|" + "---|" * (len(ORDERS) - 1) + "---|---|---|---|",
    ]
    for r in rows:
        orders = " | ".join(f"{r['worst_rms_by_order'][n]:.2%}" for n in ORDERS[1:])
        lines.append(
            f"| {r['field']} | {r['key']} {r['from']:g}–{r['to']:g} | ×{r['ratio']:.3f} ({r['count']}) "
            f"| {r['worst_rms_ams1']:.2%} ({r['median_rms_ams1']:.2%}) | {orders} "
            f"| {r['worst_sigma_ext']:.2%} | {r['worst_g']:.1e} | {r['worst_forward_fraction']:.1e} "
            f"| {r['preset_noise_ams1']:.2%} |")
    (HERE / "interpolation.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
