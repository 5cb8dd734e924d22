#!/usr/bin/env python3
"""Plane slabs against the truth: a uniform slab of cloud 400 m thick filling a 2.4 km box
(96 x 16 x 96 voxels), seen straight down from 3 km through a 4 degree field (8 x 8 pixels round
the nadir), sun 60 or 20 degrees up; tau 8 and 32 vertically. Prints each model's mean against
the truth's. Truths (16384 spp at most, 2 % noise) are cached in $SLAB_WORK.

    python3 docs/coupled/slab.py [models, default coupled,riley,max]
"""
import json, os, subprocess, sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("PHOTOMETEOR", os.path.join(ROOT, "target", "release", "photometeor"))
WORK = os.environ.get("SLAB_WORK", "/tmp/slab")
TABLES = os.environ.get("SLAB_TABLES", f"{WORK}/tables-cloud")
CASES = [(8, 60, "slab8a"), (8, 20, "slab8b"), (32, 60, "slab32a")]


def scene(density, elevation):
    return f'''[scene]
name = "slab"
spectral = "rgb3"
theta_step_deg = 0.18
n_max = 96
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
distribution = {{ kind = "gamma", r_eff_um = 10, v_eff = 0.1 }}

[render]
width = 8
height = 8
grid_resolution = 96

[camera]
position_m = [0, 3000, 0]
look_at_m = [0, 0, 1]
fov_deg = 4

[sun]
elevation_deg = {elevation}
azimuth_deg = 0

[sky]
enabled = false

[ground]
albedo = 0.0

[[volume]]
field = "cloud"
shape = "grid"
file = "ones.f32"
dims = [4, 4, 4]
min_m = [-1200, 0, -1200]
max_m = [1200, 400, 1200]
number_density_per_m3 = {density}
'''


def mean_g(path):
    out = subprocess.run([BIN, "compare-render", truth_of(path), path, "--json"],
                         capture_output=True, text=True)
    return json.loads(out.stdout)["bias"] if out.returncode == 0 else None


def truth_of(path):
    return path.rsplit("-", 1)[0] + "-truth.exr"


def main():
    models = sys.argv[1].split(",") if len(sys.argv) > 1 else ["coupled", "riley", "max"]
    os.makedirs(WORK, exist_ok=True)
    open(f"{WORK}/ones.f32", "wb").write(b"\x00\x00\x80\x3f" * 64)
    if not os.path.exists(f"{TABLES}/manifest.json"):
        open(f"{WORK}/probe.toml", "w").write(scene(1e8, 60))
        subprocess.run([BIN, "render", f"{WORK}/probe.toml", "--cpu", "--tables", TABLES,
                        "--out", f"{WORK}/probe.exr", "--quiet"], check=True)
    sigma = json.load(open(f"{TABLES}/manifest.json"))["fields"][0]["sigma_ext_m2"]["G"]
    for tau, elevation, name in CASES:
        path = f"{WORK}/{name}.toml"
        open(path, "w").write(scene(tau / (400 * sigma), elevation))
        truth = f"{WORK}/{name}-truth.exr"
        if not os.path.exists(truth):
            subprocess.run([BIN, "render", path, "--model", "truth", "--spp", "16384", "--noise",
                            "0.02", "--tables", TABLES, "--out", truth], check=True)
        for m in models:
            out = f"{WORK}/{name}-{m}.exr"
            subprocess.run([BIN, "render", path, "--cpu", "--model", m, "--tables", TABLES,
                            "--out", out, "--quiet"], check=True)
            print(f"{name}: τ {tau}, sun {elevation}° up, {m}: bias {mean_g(out) * 100:+.1f} %")


if __name__ == "__main__":
    main()
