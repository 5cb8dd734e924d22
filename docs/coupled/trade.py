#!/usr/bin/env python3
"""The trade a user picks from: each model's error against the truth over the sweep of
docs/coupled/sweep.json (the soft ball, cloud and rain, tau 0.1 ... 64, four suns, and the
held-out clouds) against its frame cost in that same run (the CPU reference's wall time per
frame at 48 x 48, process start and table load included; all models timed case by case, one
after the other, so their ratios are fair). Writes docs/coupled/trade.md and trade.png.

    .venv/bin/python docs/coupled/trade.py
"""
import json, os, statistics

HERE = os.path.dirname(os.path.abspath(__file__))
data = json.load(open(os.path.join(HERE, "sweep.json")))
rows = data["results"]
models = data["models"]


def summary(model, select):
    cases = [r[model] for r in rows if model in r and select(r)]
    if not cases:
        return None
    bias = [abs(c["bias"]) for c in cases]
    return {
        "cases": len(cases),
        "median_abs_bias": statistics.median(bias),
        "worst_abs_bias": max(bias),
        "within_10": sum(b <= 0.10 for b in bias) / len(bias),
        "median_error": statistics.median(c["median_rel_error"] for c in cases),
        # The noise-debiased rms, where the run recorded it (the rows rendered since it exists).
        "debiased": statistics.median(c["debiased_rms"] for c in cases)
        if all("debiased_rms" in c for c in cases) else None,
        "seconds": statistics.median(c["seconds"] for c in cases),
    }


groups = {
    "all": lambda r: True,
    "thin (τ ≤ 2)": lambda r: r["tau"] <= 2,
    "dense (τ ≥ 8)": lambda r: r["tau"] >= 8,
}
md = ["| model | cases | frame (s, median) | " + " | ".join(
    f"{g}: median abs. bias / worst / share within 10 % / median per-pixel error / median "
    "noise-debiased rms" for g in groups) + " |",
      "|" + "---|" * (3 + len(groups))]
points = {}
for m in models:
    cells = []
    base = summary(m, groups["all"])
    if base is None:
        continue
    for name, sel in groups.items():
        s = summary(m, sel)
        cells.append("—" if s is None else
                     f"{s['median_abs_bias']*100:.1f} % / {s['worst_abs_bias']*100:.0f} % / "
                     f"{s['within_10']*100:.0f} % / {s['median_error']*100:.1f} % / "
                     + ("—" if s["debiased"] is None else f"{s['debiased']*100:.1f} %"))
    md.append(f"| {m} | {base['cases']} | {base['seconds']:.2f} | " + " | ".join(cells) + " |")
    points[m] = (base["seconds"], summary(m, groups["dense (τ ≥ 8)"])["median_abs_bias"] * 100)
PRESETS = ["coupled-realtime", "coupled-balanced", "coupled-reference"]
if any(p in points for p in PRESETS):
    md += ["", "coupled-realtime, coupled-balanced and coupled-reference are coupled's presets "
           "(`preset = \"…\"`; balanced is the default, the coupled row, rendered again), "
           "timed side by side in one later run than the other rows; compare their frame times "
           "with each other, and with the other rows only roughly. The noise-debiased rms, "
           "((mean d² − mean σ²)⁺)^½ / mean Y, is in the rows rendered since compare-render "
           "has given it (a pixel within the truth's noise counts as exact in the median "
           "per-pixel error, not in it)."]
open(os.path.join(HERE, "trade.md"), "w").write("\n".join(md) + "\n")

import matplotlib  # noqa: E402
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
fig, ax = plt.subplots(figsize=(6, 4))
# Labels of the points near each other (coupled's variants) alternate above and below.
for k, (m, (x, y)) in enumerate(sorted(points.items(), key=lambda p: p[1][0])):
    ax.scatter([x], [y])
    ax.annotate(m, (x, y), textcoords="offset points", xytext=(5, 5 if k % 2 else -11),
                fontsize=8)
front = [points[p] for p in PRESETS if p in points]
if len(front) > 1:
    ax.plot([x for x, _ in front], [y for _, y in front], "k--", lw=0.8,
            label="coupled's presets (one run)")
    ax.legend(fontsize=8)
ax.set_xlabel("frame time, CPU reference at 48² (s, median over the sweep)")
ax.set_ylabel("median |bias| against the truth, τ ≥ 8 (%)")
ax.set_yscale("log")
ax.set_title("Error against cost: the soft-ball sweep")
ax.grid(alpha=0.3)
fig.tight_layout()
fig.savefig(os.path.join(HERE, "trade.png"), dpi=110)
print("\n".join(md))
