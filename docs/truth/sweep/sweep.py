#!/usr/bin/env python3
"""Riley's model against the path-traced truth over optical depth, light direction and ξ.

A soft ball of cloud or rain (density sqrt(1 - r), 48^3 voxels over a 1 km box, draft rgb3
tables, sky off, black ground), optical depth tau through its centre in green, seen from 3 km;
the sun 20 degrees up at azimuth 0 (behind the ball: forward scattering, 20 degrees from the
view), 45 (48 degrees from the view), 90 (side) or 180 (behind the camera: back scattering). For each case the truth is rendered once (--noise 0.03,
at most 8192 spp) and Riley's model (CPU reference, 256 slices, continuum light update) at
several xi; compare-render gives each one's median and 95th-percentile error and bias (the best
xi is the one with the smallest |bias|). `--table-only` re-derives the table from sweep.json.

Run from the repository root after `cargo build --release`:
    python3 docs/truth/sweep/sweep.py            # writes docs/truth/sweep/sweep.json and .md
Needs nothing beyond the photometeor binary (OpenEXR is not needed: compare-render reads EXR).
"""
import json, os, subprocess, sys, time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import repo  # noqa: E402
BIN = os.path.join(ROOT, "target", "release", "photometeor")
WORK = os.environ.get("SWEEP_WORK", "/tmp/photometeor-sweep")
TAUS = [0.1, 0.5, 2, 8, 32, 50]
# The sun 20° up; the angle between the view direction (+z) and the direction to the sun is
# acos(cos 20° cos azimuth): 20°, 48°, 90°, 160°.
AZIMUTHS = {"behind the ball, 20° from the view (forward)": 0, "48° from the view": 45,
            "side, 90° from the view": 90, "behind the camera, 160° from the view (back)": 180}
XIS = [0.0, 0.003, 0.01, 0.03, 0.1]
FIELDS = {
    "cloud": 'distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }',
    "rain": 'distribution = { kind = "lognormal", median_radius_um = 500, sigma_g = 1.4 }',
}
SIZE = int(os.environ.get("SWEEP_SIZE", "48"))


def scene(field, tau, azimuth, sigma_ext_g, xi):
    # ∫ sqrt(1 - |x|) dx over the diameter = 4/3 of the radius: τ = N σ · 666 m.
    density = tau / (0.666 * 1000 * sigma_ext_g) if sigma_ext_g else 1.0
    head = f"""[scene]
name = "sweep-{field}"
spectral = "rgb3"
theta_step_deg = 0.18
n_max = 96
quality = "draft"

[[field]]
name = "{field}"
kind = "{field}"
{FIELDS[field]}

"""
    tail = f"""
[render.riley]
slices = 256
light_resolution = {SIZE}
xi = {xi}
"""
    return repo.soft_ball(head, field, density, azimuth, SIZE, tail)


def best_xi(row):
    """The ξ whose frame has the smallest |bias| (the share of light gained or lost), ties broken
    by the median error."""
    rep = row["riley"]
    return min(XIS, key=lambda x: (abs(rep[str(x)]["bias"]), rep[str(x)]["median_rel_error"]))


def table(results):
    md = ["| field | τ | sun | ξ = 0: median error | 95th pct | bias | best ξ (smallest abs. bias) | its median | its bias | truth noise |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        a, b = r["riley"]["0.0"], r["riley"][str(r["best_xi"])]
        md.append(f"| {r['field']} | {r['tau']} | {r['light']} | {a['median_rel_error']*100:.1f} % | "
                  f"{a['p95_rel_error']*100:.1f} % | {a['bias']*100:+.1f} % | {r['best_xi']} | "
                  f"{b['median_rel_error']*100:.1f} % | {b['bias']*100:+.1f} % | {a['truth_noise']*100:.1f} % |")
    return "\n".join(md) + "\n"


def run(args):
    r = subprocess.run([BIN] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(args)}: {r.stderr}")
    return r


def main():
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sweep.json")
    if "--table-only" in sys.argv:
        # Re-derive the best ξ and the table from a finished run's JSON.
        data = json.load(open(out))
        for row in data["results"]:
            row["best_xi"] = best_xi(row)
        json.dump(data, open(out, "w"), indent=1)
        open(out.replace(".json", ".md"), "w").write(table(data["results"]))
        return
    os.makedirs(WORK, exist_ok=True)
    results = []
    for field in FIELDS:
        tables = f"{WORK}/tables-{field}"
        path = f"{WORK}/{field}.toml"
        open(path, "w").write(scene(field, 1, 0, 0, 0))
        run(["render", path, "--cpu", "--out", f"{WORK}/probe.exr", "--tables", tables, "--quiet"])
        sigma = json.load(open(f"{tables}/manifest.json"))["fields"][0]["sigma_ext_m2"]["G"]
        for tau in TAUS:
            for light, az in AZIMUTHS.items():
                open(path, "w").write(scene(field, tau, az, sigma, 0))
                truth = f"{WORK}/truth.exr"
                t0 = time.time()
                r = run(["render", path, "--model", "truth", "--spp", "8192", "--noise", "0.03",
                         "--out", truth, "--tables", tables])
                seconds = time.time() - t0
                line = r.stderr.strip().splitlines()[-1]
                row = {"field": field, "tau": tau, "light": light, "azimuth_deg": az,
                       "truth": line, "truth_seconds": round(seconds, 1), "riley": {}}
                for xi in XIS:
                    open(path, "w").write(scene(field, tau, az, sigma, xi))
                    model = f"{WORK}/riley.exr"
                    run(["render", path, "--cpu", "--out", model, "--tables", tables, "--quiet"])
                    rep = json.loads(run(["compare-render", truth, model, "--json"]).stdout)
                    row["riley"][str(xi)] = rep
                best = best_xi(row)
                row["best_xi"] = best
                r0, rb = row["riley"]["0.0"], row["riley"][str(best)]
                print(f"{field:5s} τ {tau:5} {light:26s} ξ=0: median {r0['median_rel_error']*100:6.1f} % "
                      f"p95 {r0['p95_rel_error']*100:6.1f} % bias {r0['bias']*100:+6.1f} %; best ξ {best} "
                      f"(bias {rb['bias']*100:+.1f} %) [{seconds:.0f} s]", flush=True)
                results.append(row)
    json.dump({"taus": TAUS, "xis": XIS, "size": SIZE, "results": results}, open(out, "w"), indent=1)
    open(out.replace(".json", ".md"), "w").write(table(results))


if __name__ == "__main__":
    main()
