#!/usr/bin/env python3
"""Miyazaki's shadow-view slices against the path-traced truth, with Riley's model beside them,
and the k_multi that minimizes the error.

For each scene: one truth render (`--model truth`, draft tables, at most SPP samples per pixel
or 3 % noise), Riley's CPU reference, and Miyazaki's CPU reference over a grid of k_multi with
the baked Ams_1 and with Cornette–Shanks's phase function; `compare-render` gives each frame's
mean, median and 95th-percentile relative error and bias over the volume's pixels (1 − T_vol >
1 %). The best k_multi is the grid value with the smallest mean relative error, refined by a
golden-section search on the same metric between its neighbours.

Run from the repository root after `cargo build --release`:
    python3 docs/miyazaki/compare.py        # writes docs/miyazaki/compare.json and compare.md
MIYAZAKI_REUSE_TRUTH=1 reuses a truth render of an earlier run in MIYAZAKI_WORK.
"""
import json, math, os, subprocess, sys, time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import repo  # noqa: E402
BIN = os.path.join(ROOT, "target", "release", "photometeor")
WORK = os.environ.get("MIYAZAKI_WORK", "/tmp/photometeor-miyazaki")
SCENES = ["cumulus_dawn", "shafts"]
SIZE = (160, 120)
SPP = int(os.environ.get("MIYAZAKI_TRUTH_SPP", "4096"))
K_GRID = [0.0, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32, 0.64, 1.28, 2.56, 5.12]
OUT = os.path.dirname(os.path.abspath(__file__))


def run(args):
    r = subprocess.run([BIN] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(args)}: {r.stderr}")
    return r


def scene_with(src, dst, keys):
    """`src` with these [render.miyazaki] keys set (replacing the scene's own, if any; the
    table added if the scene has none)."""
    text = open(src).read()
    lines = [l for l in text.splitlines()
             if not any(l.replace(" ", "").startswith(f"{k}=") for k in keys)]
    if "[render.miyazaki]" not in lines:
        lines += ["", "[render.miyazaki]"]
    i = lines.index("[render.miyazaki]")
    lines[i + 1:i + 1] = [f"{k} = {json.dumps(v)}" for k, v in keys.items()]
    open(dst, "w").write("\n".join(lines) + "\n")


def without_haze(src, dst):
    """`src` without its [haze] table (and the [[field]] of kind haze stays, unused)."""
    out, skip = [], False
    for line in open(src).read().splitlines():
        if line.strip().startswith("["):
            skip = line.strip() == "[haze]"
        if not skip:
            out.append(line)
    open(dst, "w").write("\n".join(out) + "\n")


def compare(truth, model, png=None):
    """compare-render over the volume's pixels, with the same over all lit pixels (the air,
    its haze and shafts, and the ground too) under "all_pixels"."""
    args = ["compare-render", truth, model, "--json"] + (["--map", png] if png else [])
    rep = json.loads(run(args).stdout)
    rep["all_pixels"] = json.loads(run(["compare-render", truth, model, "--json",
                                        "--pixels", "all"]).stdout)
    return rep


def main():
    os.makedirs(WORK, exist_ok=True)
    common = ["--width", str(SIZE[0]), "--height", str(SIZE[1]), "--quality", "draft", "--quiet"]
    results = []
    for name in SCENES:
        src = os.path.join(ROOT, "data", "scenes", f"{name}.toml")
        tables = f"{WORK}/tables-{name}"
        truth = f"{WORK}/{name}-truth.exr"
        t0 = time.time()
        line_file = truth + ".txt"
        if os.environ.get("MIYAZAKI_REUSE_TRUTH") and os.path.exists(line_file):
            truth_line, truth_s = open(line_file).read().split("\t")
            truth_s = float(truth_s)
        else:
            r = run(["render", src, "--model", "truth", "--spp", str(SPP), "--noise", "0.03",
                     "--out", truth, "--png", f"{OUT}/{name}-truth.png", "--tables", tables]
                    + common[:-1])
            truth_line = r.stderr.strip().splitlines()[-1]
            truth_s = time.time() - t0
            open(line_file, "w").write(f"{truth_line}\t{truth_s}")
        row = {"scene": name, "truth": truth_line, "truth_seconds": round(truth_s, 1), "models": {}}
        t0 = time.time()
        r = subprocess.run([BIN, "render", src, "--cpu", "--out", f"{WORK}/{name}-riley.exr",
                            "--png", f"{OUT}/{name}-riley.png", "--tables", tables] + common,
                           capture_output=True, text=True)
        if r.returncode == 0:
            row["models"]["riley"] = {"seconds": round(time.time() - t0, 2),
                                      **compare(truth, f"{WORK}/{name}-riley.exr",
                                                f"{OUT}/{name}-riley-error.png")}
        else:
            # Riley's model refuses what it cannot draw (a [haze] layer; Riley et al. 2004 §3:
            # "the system does not currently render haze"). Say so, and measure it on the same
            # scene with the layer left out against the truth with it: what ignoring haze costs.
            refused = r.stderr.strip().splitlines()[-1]
            clear = f"{WORK}/{name}-no-haze.toml"
            without_haze(src, clear)
            t0 = time.time()
            run(["render", clear, "--cpu", "--out", f"{WORK}/{name}-riley.exr",
                 "--png", f"{OUT}/{name}-riley-no-haze.png", "--tables", tables] + common)
            row["models"]["riley"] = {"refused": refused, "seconds": round(time.time() - t0, 2),
                                      **compare(truth, f"{WORK}/{name}-riley.exr",
                                                f"{OUT}/{name}-riley-no-haze-error.png")}

        def miyazaki(k, phase, keep=False):
            path = f"{WORK}/{name}-svs.toml"
            scene_with(src, path, {"k_multi": k, "phase": phase})
            exr = f"{WORK}/{name}-svs.exr"
            t = time.time()
            png = [ "--png", f"{OUT}/{name}-miyazaki-{phase}.png"] if keep else []
            run(["render", path, "--model", "miyazaki", "--cpu", "--out", exr, "--tables", tables]
                + png + common)
            rep = compare(truth, exr, f"{OUT}/{name}-miyazaki-{phase}-error.png" if keep else None)
            rep["seconds"] = round(time.time() - t, 2)
            return rep

        for phase in ["tables", "cornette_shanks"]:
            scan = {str(k): miyazaki(k, phase) for k in K_GRID}
            best = min(K_GRID, key=lambda k: scan[str(k)]["mean_rel_error"])
            i = K_GRID.index(best)
            lo, hi = K_GRID[max(i - 1, 0)], K_GRID[min(i + 1, len(K_GRID) - 1)]
            # Golden-section refinement on the mean relative error.
            g = (math.sqrt(5) - 1) / 2
            a, b = lo, hi
            c, d = b - g * (b - a), a + g * (b - a)
            fc, fd = miyazaki(c, phase)["mean_rel_error"], miyazaki(d, phase)["mean_rel_error"]
            for _ in range(8):
                if fc < fd:
                    b, d, fd = d, c, fc
                    c = b - g * (b - a)
                    fc = miyazaki(c, phase)["mean_rel_error"]
                else:
                    a, c, fc = c, d, fd
                    d = a + g * (b - a)
                    fd = miyazaki(d, phase)["mean_rel_error"]
            k_best = round((a + b) / 2, 5)
            final = miyazaki(k_best, phase, keep=True)
            zero = scan["0.0"]
            row["models"][f"miyazaki-{phase}"] = {"scan": scan, "k_multi_best": k_best,
                                                   "best": final}
            print(f"{name} miyazaki {phase}: k_multi 0: mean {zero['mean_rel_error']*100:.1f} % "
                  f"bias {zero['bias']*100:+.1f} %; best k_multi {k_best}: mean "
                  f"{final['mean_rel_error']*100:.1f} % p95 {final['p95_rel_error']*100:.1f} % "
                  f"bias {final['bias']*100:+.1f} % [{final['seconds']} s]", flush=True)
        rl = row["models"]["riley"]
        if "refused" in rl:
            print(f"{name} riley: {rl['refused']}; with the haze left out: mean "
                  f"{rl['mean_rel_error']*100:.1f} % p95 {rl['p95_rel_error']*100:.1f} % "
                  f"bias {rl['bias']*100:+.1f} %; truth {truth_line}", flush=True)
        else:
            print(f"{name} riley: mean {rl['mean_rel_error']*100:.1f} % p95 {rl['p95_rel_error']*100:.1f} % "
                  f"bias {rl['bias']*100:+.1f} %; truth {truth_line}", flush=True)
        results.append(row)
    json.dump(repo.portable({"size": SIZE, "spp": SPP, "k_grid": K_GRID, "results": results}, ROOT, WORK),
              open(f"{OUT}/compare.json", "w"), indent=1)
    md = ["| scene | model | k_multi (1/sr) | mean rel. error | median | 95th pct | bias | all lit pixels: mean / p95 / bias | seconds (CPU reference) |",
          "|---|---|---|---|---|---|---|---|---|"]
    def every(m):
        a = m["all_pixels"]
        return f"{a['mean_rel_error']*100:.1f} / {a['p95_rel_error']*100:.1f} / {a['bias']*100:+.1f} %"
    for r in results:
        m = r["models"]["riley"]
        label = "riley, [haze] left out (it refuses the layer)" if "refused" in m else "riley (ξ of the scene)"
        md.append(f"| {r['scene']} | {label} | — | {m['mean_rel_error']*100:.1f} % | "
                  f"{m['median_rel_error']*100:.1f} % | {m['p95_rel_error']*100:.1f} % | {m['bias']*100:+.1f} % | {every(m)} | {m['seconds']} |")
        for phase in ["tables", "cornette_shanks"]:
            e = r["models"][f"miyazaki-{phase}"]
            for label, k, m in [("0", 0.0, e["scan"]["0.0"]), ("best", e["k_multi_best"], e["best"])]:
                md.append(f"| {r['scene']} | miyazaki, {phase} | {k} ({label}) | {m['mean_rel_error']*100:.1f} % | "
                          f"{m['median_rel_error']*100:.1f} % | {m['p95_rel_error']*100:.1f} % | {m['bias']*100:+.1f} % | {every(m)} | {m['seconds']} |")
    open(f"{OUT}/compare.md", "w").write("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
