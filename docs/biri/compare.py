#!/usr/bin/env python3
"""Biri et al.'s analytic single scattering against the path-traced truth on beams.toml.

Renders data/scenes/beams.toml at SIZE with `--model biri` (exact and polynomial kernels, and
the exact one without its ambient fog) and with `--model truth` twice: restricted to single
scattering (`--max-scatterings 1`, what the model computes, so the two should agree to the
truth's noise) and with full multiple scattering (what the ambient term stands in for).
`compare-render --pixels all` gives each frame's mean, median, 95th-percentile relative error
and bias over every lit pixel (the scene has no density volume, so no volume mask), and the
share of pixels within 3σ of the truth.

Run from the repository root after `cargo build --release`:
    python3 docs/biri/compare.py        # writes docs/biri/compare.json, compare.md and PNGs
BIRI_TRUTH_SPP sets the truth's samples per pixel (default 512); BIRI_REUSE_TRUTH=1 reuses
the truth renders of an earlier run in BIRI_WORK. The ambient fog that minimizes the mean
relative error against the full truth is found on a grid (scaling the scene's own colour).
"""
import json, os, subprocess, sys, time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import repo  # noqa: E402
BIN = os.environ.get("PHOTOMETEOR_BIN", os.path.join(ROOT, "target", "release", "photometeor"))
WORK = os.environ.get("BIRI_WORK", "/tmp/photometeor-biri")
SCENE = os.path.join(ROOT, "data", "scenes", "beams.toml")
SIZE = (160, 120)
SPP = int(os.environ.get("BIRI_TRUTH_SPP", "512"))
OUT = os.path.dirname(os.path.abspath(__file__))


def run(args):
    t = time.time()
    r = subprocess.run([BIN] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(args)}: {r.stderr}")
    return r, time.time() - t


def compare(truth, model, png=None):
    args = ["compare-render", truth, model, "--json", "--pixels", "all"]
    return json.loads(run(args + (["--map", png] if png else []))[0].stdout)


def main():
    os.makedirs(WORK, exist_ok=True)
    common = ["--width", str(SIZE[0]), "--height", str(SIZE[1]), "--tables", f"{WORK}/tables",
              "--quiet"]
    no_ambient = f"{WORK}/beams-no-ambient.toml"
    text = open(SCENE).read()
    text = "\n".join(l for l in text.splitlines() if not l.replace(" ", "").startswith("ambient="))
    # The mesh's path is relative to the scene: make it absolute for the copy in WORK.
    text = text.replace('file = "beams/', f'file = "{ROOT}/data/scenes/beams/')
    open(no_ambient, "w").write(text + "\n")
    truths = {}
    for label, extra in [("single", ["--max-scatterings", "1"]), ("full", [])]:
        exr = f"{WORK}/truth-{label}.exr"
        if os.environ.get("BIRI_REUSE_TRUTH") and os.path.exists(exr + ".s"):
            s = float(open(exr + ".s").read())
        else:
            r, s = run(["render", SCENE, "--model", "truth", "--spp", str(SPP), "--out", exr,
                        "--png", f"{OUT}/beams-truth-{label}.png"] + extra + common)
            open(exr + ".s", "w").write(str(s))
        truths[label] = {"exr": exr, "seconds": round(s, 1)}
        print(f"truth ({label} scattering): {SPP} spp, {s:.1f} s", flush=True)
    rows = []
    models = [("biri, exact", SCENE, ["--biri-kernel", "exact"]),
              ("biri, polynomial", SCENE, ["--biri-kernel", "polynomial"]),
              ("biri, exact, no ambient", no_ambient, ["--biri-kernel", "exact"])]
    for label, scene, extra in models:
        slug = label.replace("biri, ", "").replace(", ", "-").replace(" ", "-")
        exr = f"{WORK}/biri-{slug}.exr"
        _, s = run(["render", scene, "--model", "biri", "--out", exr,
                    "--png", f"{OUT}/beams-biri-{slug}.png"] + extra + common)
        for against in ["single", "full"]:
            png = f"{OUT}/beams-biri-{slug}-vs-{against}-error.png" if slug == "exact" else None
            rep = compare(truths[against]["exr"], exr, png)
            rows.append({"model": label, "truth": against, "seconds": round(s, 3), **rep})
            print(f"{label} against truth ({against}): mean {rep['mean_rel_error']*100:.1f} % "
                  f"p95 {rep['p95_rel_error']*100:.1f} % bias {rep['bias']*100:+.1f} %", flush=True)
    # The ambient fog that best stands in for multiple scattering: a scale of the scene's own
    # colour, on a doubling grid, against the full truth.
    colour = [0.004, 0.004, 0.005]
    scan = {}
    for k in [0.0, 1, 2, 4, 8, 16, 32, 64]:
        amb = [round(c * k, 6) for c in colour]
        scene = f"{WORK}/beams-ambient.toml"
        text = open(SCENE).read().replace("ambient = [0.004, 0.004, 0.005]", f"ambient = {amb}")
        text = text.replace('file = "beams/', f'file = "{ROOT}/data/scenes/beams/')
        open(scene, "w").write(text)
        exr = f"{WORK}/biri-ambient.exr"
        run(["render", scene, "--model", "biri", "--out", exr] + common)
        scan[str(amb)] = compare(truths["full"]["exr"], exr)
    best = min(scan, key=lambda a: scan[a]["mean_rel_error"])
    print(f"best ambient against the full truth: {best}: mean "
          f"{scan[best]['mean_rel_error']*100:.1f} % bias {scan[best]['bias']*100:+.1f} %")
    rows.append({"model": f"biri, exact, best ambient {best}", "truth": "full",
                 "seconds": rows[0]["seconds"], **scan[best]})
    json.dump(repo.portable({"size": SIZE, "spp": SPP, "truth": truths, "rows": rows, "ambient_scan": scan}, ROOT, WORK),
              open(f"{OUT}/compare.json", "w"), indent=1)
    md = ["| model | against the truth with | mean rel. error | median | 95th pct | bias | within 3σ | seconds |",
          "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        within = r.get("resolved")
        md.append(f"| {r['model']} | {r['truth']} scattering | {r['mean_rel_error']*100:.1f} % | "
                  f"{r['median_rel_error']*100:.1f} % | {r['p95_rel_error']*100:.1f} % | "
                  f"{r['bias']*100:+.1f} % | "
                  f"{'' if within is None else f'{within*100:.0f} %'} | {r['seconds']} |")
    open(f"{OUT}/compare.md", "w").write("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
