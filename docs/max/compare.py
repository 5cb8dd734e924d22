#!/usr/bin/env python3
"""Max et al.'s diffusion + Poisson-edge model against the path-traced truth, with Riley's
model on the same truths.

Scenes: `cumulus_dawn` (160 x 120, draft tables, skylight on) and the soft cloud ball of the
tau sweep (docs/truth/sweep: sqrt(1 - r) density, 48^3 voxels over a 1 km box, sky off) at
optical depth 32 and 64 through its centre, side-lit (sun 20 deg up, 90 deg from the view) and
back-lit (behind the camera), 64 x 64. For each: one truth (`--model truth`, --noise 0.03, at
most SPP samples per pixel), Riley's CPU reference, and `--model max` at several thresholds T
(`[render.max] threshold`, the voxel optical depth where diffusion takes over); compare-render
gives the mean, median and 95th-percentile relative error and the bias over the volume's pixels.

Run from the repository root after `cargo build --release`:
    python3 docs/max/compare.py           # writes docs/max/compare.json, compare.md, PNGs
MAX_REUSE_TRUTH=1 reuses the truth renders of an earlier run in MAX_WORK.
"""
import json, os, subprocess, sys, time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import repo  # noqa: E402
BIN = os.path.join(ROOT, "target", "release", "photometeor")
WORK = os.environ.get("MAX_WORK", "/tmp/photometeor-max")
OUT = os.path.dirname(os.path.abspath(__file__))
SPP = int(os.environ.get("MAX_TRUTH_SPP", "4096"))
THRESHOLDS = [0.25, 1.0, 4.0]


def run(args):
    r = subprocess.run([BIN] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(args)}: {r.stderr}")
    return r


def ball_scene(tau, azimuth, sigma_ext_g, threshold=1.0):
    density = tau / (0.666 * 1000 * sigma_ext_g) if sigma_ext_g else 1.0
    head = """[scene]
name = "max-ball"
spectral = "rgb3"
theta_step_deg = 0.18
n_max = 96
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }

"""
    tail = f"""
[render.riley]
slices = 256
light_resolution = 64

[render.max]
threshold = {threshold}
"""
    return repo.soft_ball(head, "cloud", density, azimuth, 64, tail)


def with_threshold(src, dst, threshold):
    """`src` with [render.max] threshold set (the table added if the scene has none)."""
    lines = [l for l in open(src).read().splitlines() if not l.replace(" ", "").startswith("threshold=")]
    if "[render.max]" not in lines:
        lines += ["", "[render.max]"]
    i = lines.index("[render.max]")
    lines.insert(i + 1, f"threshold = {threshold}")
    open(dst, "w").write("\n".join(lines) + "\n")


def compare(truth, model, png=None):
    args = ["compare-render", truth, model, "--json"] + (["--map", png] if png else [])
    return json.loads(run(args).stdout)


def case(name, scene_path, tables, size_args, pngs):
    truth = f"{WORK}/{name}-truth.exr"
    line_file = truth + ".txt"
    if os.environ.get("MAX_REUSE_TRUTH") and os.path.exists(line_file):
        truth_line, truth_s = open(line_file).read().split("\t")
    else:
        t0 = time.time()
        r = run(["render", scene_path, "--model", "truth", "--spp", str(SPP), "--noise", "0.03",
                 "--out", truth, "--tables", tables] + size_args
                + (["--png", f"{OUT}/{name}-truth.png"] if pngs else []))
        truth_line, truth_s = r.stderr.strip().splitlines()[-1], time.time() - t0
        open(line_file, "w").write(f"{truth_line}\t{truth_s}")
    row = {"scene": name, "truth": truth_line, "truth_seconds": round(float(truth_s), 1), "models": {}}
    t0 = time.time()
    exr = f"{WORK}/{name}-riley.exr"
    run(["render", scene_path, "--cpu", "--out", exr, "--tables", tables, "--quiet"] + size_args
        + (["--png", f"{OUT}/{name}-riley.png"] if pngs else []))
    row["models"]["riley"] = {"seconds": round(time.time() - t0, 2),
                              **compare(truth, exr, f"{OUT}/{name}-riley-error.png" if pngs else None)}
    for t in THRESHOLDS:
        path = f"{WORK}/{name}-max.toml"
        with_threshold(scene_path, path, t)
        exr = f"{WORK}/{name}-max-{t}.exr"
        keep = pngs and t == 1.0
        t0 = time.time()
        r = run(["render", path, "--model", "max", "--out", exr, "--tables", tables] + size_args
                + (["--png", f"{OUT}/{name}-max.png"] if keep else []))
        row["models"][f"max T={t}"] = {"seconds": round(time.time() - t0, 2),
                                       "report": r.stderr.strip().splitlines()[-1],
                                       **compare(truth, exr, f"{OUT}/{name}-max-error.png" if keep else None)}
    for m, rep in row["models"].items():
        print(f"{name:24s} {m:10s} mean {rep['mean_rel_error']*100:5.1f} % median "
              f"{rep['median_rel_error']*100:5.1f} % p95 {rep['p95_rel_error']*100:5.1f} % bias "
              f"{rep['bias']*100:+6.1f} % [{rep['seconds']} s]", flush=True)
    return row


def main():
    os.makedirs(WORK, exist_ok=True)
    results = []
    src = os.path.join(ROOT, "data", "scenes", "cumulus_dawn.toml")
    results.append(case("cumulus_dawn", src, f"{WORK}/tables-cumulus_dawn",
                        ["--width", "160", "--height", "120", "--quality", "draft"], True))
    tables = f"{WORK}/tables-ball"
    probe = f"{WORK}/ball-probe.toml"
    open(probe, "w").write(ball_scene(1, 90, 0))
    run(["render", probe, "--cpu", "--out", f"{WORK}/probe.exr", "--tables", tables, "--quiet"])
    sigma = json.load(open(f"{tables}/manifest.json"))["fields"][0]["sigma_ext_m2"]["G"]
    for tau in [32, 64]:
        for light, az in [("side", 90), ("back", 180)]:
            name = f"ball-tau{tau}-{light}"
            path = f"{WORK}/{name}.toml"
            open(path, "w").write(ball_scene(tau, az, sigma))
            results.append(case(name, path, tables, [], tau == 32 and light == "side"))
    json.dump({"spp": SPP, "thresholds": THRESHOLDS, "results": results},
              open(f"{OUT}/compare.json", "w"), indent=1)
    md = ["| scene | model | mean rel. error | median | 95th pct | bias | seconds (2 cores) |",
          "|---|---|---|---|---|---|---|"]
    for r in results:
        for m, rep in r["models"].items():
            md.append(f"| {r['scene']} | {m} | {rep['mean_rel_error']*100:.1f} % | "
                      f"{rep['median_rel_error']*100:.1f} % | {rep['p95_rel_error']*100:.1f} % | "
                      f"{rep['bias']*100:+.1f} % | {rep['seconds']} |")
    md.append("")
    md += [f"- {r['scene']}: truth {r['truth']}" for r in results]
    open(f"{OUT}/compare.md", "w").write("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
