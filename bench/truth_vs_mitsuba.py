#!/usr/bin/env python3
"""Speed of photometeor's path tracer (`render --model truth`) against Mitsuba 3 (scalar_rgb,
volpath) on the same cumulus, at equal per-pixel noise, and a check that both draw the same
image. See bench/README.md.

    python3 bench/truth_vs_mitsuba.py --quick            # 64×64, a couple of minutes
    python3 bench/truth_vs_mitsuba.py                    # 256×256

Writes bench/cumulus/{scene.toml,density.f32}, bench/cumulus/out/ (images) and
bench/truth_vs_mitsuba.json (every number and setting); prints a short table.
"""

import argparse
import json
import math
import os
import platform
import re
import struct
import subprocess
import sys
import time
import zlib

import numpy as np
import OpenEXR

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "scripts"))
import repo  # noqa: E402
CASE = os.path.join(HERE, "cumulus")
OUT = os.path.join(CASE, "out")  # + /<size>
TABLES = os.path.join(CASE, "tables")
SCENE = os.path.join(CASE, "scene.toml")
DENSITY = os.path.join(CASE, "density.f32")
RESULT = os.path.join(HERE, "truth_vs_mitsuba.json")

# ---------------------------------------------------------------------------------------------
# The scene (metres, y up). Both tools get exactly these numbers.
DIMS = (64, 48, 64)  # nx, ny, nz; voxel 20 m
BOX_MIN = np.array([-640.0, 1000.0, 3360.0])
BOX_MAX = np.array([640.0, 1960.0, 4640.0])
CAMERA_POS = np.array([300.0, 1250.0, 0.0])
CAMERA_LOOK_AT = np.array([0.0, 1480.0, 4000.0])
FOV_DEG = 28.0  # vertical
SUN_ELEVATION_DEG = 30.0
SUN_AZIMUTH_DEG = 120.0  # from +z towards +x
THETA_STEP_DEG = 0.18
N_MAX = 4
GREEN = 1  # rgb3 rows: 650, 515, 440 nm


def smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def cumulus_density():
    """A deterministic cumulus-like heap: overlapping spheres with a flat base, a little
    low-frequency lumpiness and smooth edges, peak 1, zero on the box's outer voxels.
    Returns an array of shape (nz, ny, nx) (x fastest in C order)."""
    nx, ny, nz = DIMS
    size = BOX_MAX - BOX_MIN
    ax = [BOX_MIN[a] + (np.arange(n) + 0.5) * size[a] / n for a, n in enumerate(DIMS)]
    z, y, x = np.meshgrid(ax[2], ax[1], ax[0], indexing="ij")
    # (centre as fractions of the box, radius in m)
    blobs = [
        ((0.50, 0.36, 0.50), 360.0),
        ((0.31, 0.28, 0.44), 250.0),
        ((0.69, 0.30, 0.57), 265.0),
        ((0.50, 0.58, 0.48), 250.0),
        ((0.40, 0.50, 0.63), 205.0),
        ((0.61, 0.52, 0.37), 200.0),
        ((0.54, 0.74, 0.52), 150.0),
    ]
    inside = np.full(x.shape, -np.inf)
    for (fx, fy, fz), r in blobs:
        c = BOX_MIN + np.array([fx, fy, fz]) * size
        d = np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
        inside = np.maximum(inside, 1.0 - d / r)
    rng = np.random.default_rng(20240601)
    lump = np.zeros(x.shape)
    for _ in range(6):
        k = rng.normal(size=3)
        k *= 2 * np.pi / rng.uniform(180.0, 420.0) / np.linalg.norm(k)
        lump += np.sin(k[0] * x + k[1] * y + k[2] * z + rng.uniform(0, 2 * np.pi))
    shaped = inside + 0.035 * lump
    base = BOX_MIN[1] + 0.12 * size[1]
    rho = smoothstep(0.0, 0.3, shaped) * smoothstep(base, base + 60.0, y)
    rho[[0, -1], :, :] = 0.0
    rho[:, [0, -1], :] = 0.0
    rho[:, :, [0, -1]] = 0.0
    rho /= rho.max()
    return rho.astype(np.float32)


def toml_list(v):
    return "[" + ", ".join(repr(float(x)) if not isinstance(x, int) else str(x) for x in v) + "]"


def scene_toml(number_density, size=256):
    """The scene; `size` is only its default frame (the script passes --width/--height)."""
    return f"""# Written by bench/truth_vs_mitsuba.py: a cumulus of one cloud field in black space, for the
# speed comparison against Mitsuba 3 (bench/README.md). Regenerated on every run.

[scene]
name = "bench_cumulus"
spectral = "rgb3"
theta_step_deg = {THETA_STEP_DEG}
n_max = {N_MAX}
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
temperature_c = 10
distribution = {{ kind = "gamma", r_eff_um = 10, v_eff = 0.1 }}

[render]
width = {size}
height = {size}
grid_resolution = {max(DIMS)}   # = the file's longest dim: voxel centres coincide, no resampling

[camera]
position_m = {toml_list(CAMERA_POS)}
look_at_m = {toml_list(CAMERA_LOOK_AT)}
fov_deg = {FOV_DEG}

[sun]
elevation_deg = {SUN_ELEVATION_DEG}
azimuth_deg = {SUN_AZIMUTH_DEG}
irradiance = [1.0, 1.0, 1.0]

[sky]
enabled = false

# Mitsuba's scene has no ground: a black one here (the default albedo is 0.1 since
# 2026-12-02; without this line ours read 22 % brighter than Mitsuba).
[ground]
albedo = 0.0

[[volume]]
field = "cloud"
shape = "grid"
number_density_per_m3 = {float(number_density)!r}
file = "density.f32"
dims = {toml_list(DIMS)}
min_m = {toml_list(BOX_MIN)}
max_m = {toml_list(BOX_MAX)}
"""


# ---------------------------------------------------------------------------------------------
# Geometry as photometeor defines it (runtime/render/src/camera.rs).
def camera_axes():
    f = CAMERA_LOOK_AT - CAMERA_POS
    f = f / np.linalg.norm(f)
    r = np.cross(f, [0.0, 1.0, 0.0])
    r = r / np.linalg.norm(r)
    return f, r, np.cross(r, f)


def pixel_rays(w, h):
    """Unit rays through pixel centres, shape (h, w, 3), row 0 at the top."""
    f, r, u = camera_axes()
    tan = math.tan(math.radians(FOV_DEG) / 2)
    i = np.arange(w) + 0.5
    j = np.arange(h) + 0.5
    sx = (2 * i / w - 1) * tan * (w / h)
    sy = (1 - 2 * j / h) * tan
    d = f[None, None, :] + sx[None, :, None] * r[None, None, :] + sy[:, None, None] * u[None, None, :]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def sun_direction():
    e, a = math.radians(SUN_ELEVATION_DEG), math.radians(SUN_AZIMUTH_DEG)
    return np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])


def trilinear(rho, p):
    """photometeor's DensityGrid::sample for points p (..., 3): voxel centres, clamped to the
    edge voxels inside the box, zero outside."""
    nx, ny, nz = DIMS
    n = np.array(DIMS, dtype=float)
    u = (p - BOX_MIN) / (BOX_MAX - BOX_MIN) * n - 0.5
    inside = np.all((p >= BOX_MIN) & (p <= BOX_MAX), axis=-1)
    u = np.clip(u, 0, n - 1)
    lo = np.minimum(np.floor(u).astype(int), np.array(DIMS) - 2)
    t = u - lo
    out = np.zeros(p.shape[:-1])
    for c in range(8):
        dx, dy, dz = c & 1, (c >> 1) & 1, (c >> 2) & 1
        w = (t[..., 0] if dx else 1 - t[..., 0]) * (t[..., 1] if dy else 1 - t[..., 1]) * (
            t[..., 2] if dz else 1 - t[..., 2]
        )
        out += w * rho[lo[..., 2] + dz, lo[..., 1] + dy, lo[..., 0] + dx]
    return np.where(inside, out, 0.0)


def transparency(rho, beta_scale, origin, dirs):
    """T_vol as photometeor's Tracer::transparency: quarter-voxel midpoint march of β_ext."""
    voxel = min((BOX_MAX - BOX_MIN) / np.array(DIMS))
    out = np.ones(len(dirs))
    for k, d in enumerate(dirs):
        with np.errstate(divide="ignore", invalid="ignore"):
            t0s = (BOX_MIN - origin) / d
            t1s = (BOX_MAX - origin) / d
        t0 = np.nanmax(np.minimum(t0s, t1s))
        t1 = np.nanmin(np.maximum(t0s, t1s))
        t0 = max(t0, 0.0)
        if not t1 > t0:
            continue
        steps = int(min(max(math.ceil((t1 - t0) / (0.25 * voxel)), 1), 1 << 16))
        dt = (t1 - t0) / steps
        ts = t0 + (np.arange(steps) + 0.5) * dt
        tau = trilinear(rho, origin + ts[:, None] * d).sum() * beta_scale * dt
        out[k] = math.exp(-tau)
    return out


# ---------------------------------------------------------------------------------------------
# Files.
def read_exr(path):
    f = OpenEXR.File(path, separate_channels=True)
    return {k: np.array(v.pixels, dtype=np.float64) for k, v in f.channels().items()}


def read_single(path):
    f = OpenEXR.File(path, separate_channels=True)
    h = f.header()
    lst = lambda k: [float(v) for v in str(h[k]).split(",")]
    step = h["photometeor/theta_step_deg"]
    step = float(step[0] if isinstance(step, (list, tuple, np.ndarray)) else step)
    return {
        "theta_step_deg": step,
        "wavelengths_nm": lst("photometeor/wavelengths_nm"),
        "sigma_ext_m2": lst("photometeor/sigma_ext_m2"),
        "albedo": lst("photometeor/albedo"),
        "forward_delta_fraction": lst("photometeor/forward_delta_fraction"),
        "bins": np.array(f.channels()["Y"].pixels, dtype=np.float64),
    }


def write_png(path, rgb):
    """8-bit PNG of an (h, w, 3) array in [0, 1]."""
    h, w, _ = rgb.shape
    data = (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)
    raw = b"".join(b"\x00" + data[j].tobytes() for j in range(h))

    def chunk(tag, body):
        c = struct.pack(">I", len(body)) + tag + body
        return c + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n")
        fh.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        fh.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        fh.write(chunk(b"IEND", b""))


# ---------------------------------------------------------------------------------------------
# photometeor.
TRUTH_LINE = re.compile(
    r"path-traced truth: (\d+)×(\d+), (\d+) spp, noise ([\d.]+|inf) % .*?, ([\d.]+) s, ([\d.]+) M paths/s on the CPU \((\d+) threads\)"
)


def run_ours(binary, size, spp, seed, out_exr):
    """One `render --model truth` of size × size pixels."""
    cmd = [binary, "render", SCENE, "--model", "truth", "--cpu", "--spp", str(spp), "--seed", str(seed),
           "--width", str(size), "--height", str(size),
           "--tables", TABLES, "--out", out_exr]
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        sys.exit(f"photometeor failed ({' '.join(cmd)}):\n{p.stderr[-3000:]}")
    m = TRUTH_LINE.search(p.stderr)
    if not m:
        sys.exit(f"no 'path-traced truth' line in photometeor's stderr:\n{p.stderr[-3000:]}")
    W, H, n, noise, secs, mpaths, threads = m.groups()
    paths = int(W) * int(H) * int(n)
    pps = float(mpaths) * 1e6
    return {
        "cmd": " ".join(cmd),
        "spp": int(n),
        "seed": seed,
        "noise_printed": float(noise) / 100,
        "seconds_printed": float(secs),
        # The printed seconds have one decimal; paths/s has 3 significant digits.
        "seconds": paths / pps,
        "paths_per_second": pps,
        "threads": int(threads),
        "wall_seconds": wall,
        "exr": out_exr,
    }


# ---------------------------------------------------------------------------------------------
# Phase function: our bins (piecewise constant in θ) onto Mitsuba's tabphase (piecewise linear on
# a regular grid in cos θ, normalized by Mitsuba).
def bin_edges_mu(step_deg, k):
    d = math.radians(step_deg)
    th = np.arange(k) * d
    mu_hi = np.cos(np.clip(th - d / 2, 0, math.pi))
    mu_lo = np.cos(np.clip(th + d / 2, 0, math.pi))
    return mu_lo, mu_hi


def tabphase_nodes(bins, step_deg, delta, nodes):
    """Node values on μ_i = −1 + 2i/(nodes−1): the average of our p(μ) (per unit μ) over
    [μ_i − h/2, μ_i + h/2] ∩ [−1, 1], computed exactly from our piecewise-linear CDF in μ."""
    mu_lo, mu_hi = bin_edges_mu(step_deg, len(bins))
    omega = 2 * np.pi * (mu_hi - mu_lo)
    p = bins / np.sum(bins * omega)  # the continuous part, normalized to 1 (δ apart)
    edges = np.concatenate([mu_lo[::-1], [1.0]])
    dens = (2 * np.pi * p)[::-1]
    cum = np.concatenate([[0.0], np.cumsum(dens * np.diff(edges))])
    x = np.linspace(-1.0, 1.0, nodes)
    h = x[1] - x[0]
    a, b = np.clip(x - h / 2, -1, 1), np.clip(x + h / 2, -1, 1)
    v = (np.interp(b, edges, cum) - np.interp(a, edges, cum)) / (b - a)
    return x, v, p, (edges, cum)


def phase_checks(x, v, p, cdf, step_deg):
    """Normalization, mean cosine, cone fractions and point values: ours vs the tabphase."""
    mu_lo, mu_hi = bin_edges_mu(step_deg, len(p))
    g_ours = float(np.sum(p * np.pi * (mu_hi ** 2 - mu_lo ** 2)))
    h = x[1] - x[0]
    va, vb, xa = v[:-1], v[1:], x[:-1]
    cell = h * (va + vb) / 2
    z = cell.sum()
    g_tab = float((h * (xa * (va + vb) / 2 + h * (va / 6 + vb / 3))).sum() / z)
    ccdf = np.concatenate([[0.0], np.cumsum(cell)]) / z
    edges, cum = cdf

    def cone_tab(tc):
        m = math.cos(math.radians(tc))
        i = min(int((m + 1) / h), len(x) - 2)
        s = (m - x[i]) / h
        return 1 - (ccdf[i] + h * (va[i] * s + (vb[i] - va[i]) * s * s / 2) / z)

    cones = []
    for tc in [0.1, 0.25, 0.5, 1, 2, 5, 10, 30, 90, 140, 179]:
        ours = 1 - float(np.interp(math.cos(math.radians(tc)), edges, cum))
        tab = float(cone_tab(tc))
        cones.append({"theta_deg": tc, "ours": ours, "tabphase": tab, "rel_diff": tab / ours - 1})
    # Point values at the bin centres θ_k ≥ 1° (where a bin spans several nodes).
    k = np.arange(len(p))
    th = k * math.radians(step_deg)
    sel = th >= math.radians(1.0)
    tab_pt = np.interp(np.cos(th[sel]), x, v) / z / (2 * np.pi)
    rel = tab_pt / p[sel] - 1
    return {
        "nodes": len(x),
        "node_spacing_mu": h,
        "trapezoid_integral_before_mitsuba_normalizes": float(z),
        "g_ours": g_ours,
        "g_tabphase": g_tab,
        "cone_fractions_P_theta_lt": cones,
        "point_values_bin_centres_ge_1deg_max_abs_rel_diff": float(np.max(np.abs(rel))),
        "forward_value_per_sr": {"ours_bin0": float(p[0]), "tabphase_mu1": float(v[-1] / z / (2 * np.pi))},
    }


# ---------------------------------------------------------------------------------------------
# Mitsuba.
def mitsuba_scene(mi, rho, size, spp, beta_scale, albedo, phase_values, rr_depth, grid_res=None):
    T = mi.ScalarTransform4f
    f, r, up = camera_axes()
    res = grid_res or size
    lo, hi = BOX_MIN.tolist(), BOX_MAX.tolist()
    centre = ((BOX_MIN + BOX_MAX) / 2).tolist()
    half = ((BOX_MAX - BOX_MIN) / 2).tolist()
    medium = {
        "type": "heterogeneous",
        "sigma_t": {
            "type": "gridvolume",
            "grid": mi.VolumeGrid(rho[..., None]),  # (z, y, x, 1)
            "filter_type": "trilinear",
            "wrap_mode": "clamp",
            # The grid's unit cube onto our box: voxel centres at min + (i+½)(max−min)/dims.
            "to_world": T().translate(lo).scale((BOX_MAX - BOX_MIN).tolist()),
        },
        "scale": float(beta_scale),  # β_ext = ρ · n · σ_ext, 1/m (scene units are metres)
        "albedo": float(albedo),
        "has_spectral_extinction": False,  # grey σ_t: the cheaper of volpath's two branches
        "phase": {"type": "tabphase", "values": phase_values},
    }
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": int(rr_depth)},
        "sensor": {
            "type": "perspective",
            "fov": FOV_DEG,
            "fov_axis": "y",
            "near_clip": 1.0,
            "far_clip": 1e6,
            "to_world": T().look_at(origin=CAMERA_POS.tolist(), target=CAMERA_LOOK_AT.tolist(),
                                    up=up.tolist()),
            "sampler": {"type": "independent", "sample_count": int(spp)},
            "film": {
                "type": "hdrfilm",
                "width": res,
                "height": res,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
            },
        },
        "sun": {"type": "directional", "direction": (-sun_direction()).tolist(), "irradiance": 1.0},
        "cloud_box": {
            "type": "cube",
            "to_world": T().translate(centre).scale(half),
            "bsdf": {"type": "null"},
            "interior": medium,
        },
    }


def mitsuba_checks(mi, scene, rho, size):
    """Camera rays and density lookups of the loaded Mitsuba scene against ours."""
    sensor = scene.sensors()[0]
    ours = pixel_rays(size, size)
    worst = 0.0
    for (i, j) in [(0, 0), (size - 1, 0), (0, size - 1), (size - 1, size - 1), (size // 3, size // 2),
                   (size // 2, size // 5)]:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((i + 0.5) / size, (j + 0.5) / size),
                                   mi.Point2f(0.5, 0.5))
        # (A vectorized variant gives each component as an array of one value.)
        d = np.array([float(np.ravel(ray.d[k])[0]) for k in range(3)])
        o = ours[j, i]
        worst = max(worst, math.degrees(math.atan2(np.linalg.norm(np.cross(d, o)), float(np.dot(d, o)))))
    medium = scene.shapes()[0].interior_medium()
    rng = np.random.default_rng(5)
    pts = BOX_MIN + rng.random((400, 3)) * (BOX_MAX - BOX_MIN)
    # Include points at voxel centres and near faces (clamping).
    pts[:50] = BOX_MIN + (rng.integers(0, DIMS, size=(50, 3)) + 0.5) * (BOX_MAX - BOX_MIN) / DIMS
    pts[50:60] = BOX_MIN + rng.random((10, 3)) * 0.4 * (BOX_MAX - BOX_MIN) / DIMS
    ref = trilinear(rho, pts)
    worst_rho = 0.0
    mei = mi.MediumInteraction3f()
    for p, r in zip(pts, ref):
        mei.p = mi.Point3f(*(float(v) for v in p))
        mei.medium = medium
        sigma_s, sigma_n, sigma_t = medium.get_scattering_coefficients(mei)
        st = float(np.ravel(sigma_t[1])[0])
        worst_rho = max(worst_rho, abs(st - r * SCALE_FOR_CHECK[0]) / SCALE_FOR_CHECK[0])
    return {"camera_ray_max_angle_deg": worst, "sigma_t_max_abs_diff_over_peak": worst_rho,
            "points_checked": len(pts)}


SCALE_FOR_CHECK = [1.0]


# ---------------------------------------------------------------------------------------------
def median_chi_factor(dof):
    """Median of sqrt(χ²_dof/dof) (Wilson–Hilferty): how much the median of per-pixel standard
    errors estimated from dof+1 samples falls short of the true one, for Gaussian samples."""
    return (1 - 2 / (9 * dof)) ** 1.5


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=256, help="image side in pixels (default 256)")
    ap.add_argument("--spp-ours", type=int, default=768, help="photometeor's samples per pixel in all (split over --k-ours seeds)")
    ap.add_argument("--k-ours", type=int, default=4, help="photometeor renders (seeds) the spp are split over (default 4)")
    ap.add_argument("--spp-mitsuba", type=int, default=28, help="Mitsuba's samples per pixel per render")
    ap.add_argument("--k", type=int, default=8, help="independent Mitsuba renders (seeds), ≥ 4 (default 8)")
    ap.add_argument("--supersample", type=int, default=3, help="agreement check: also render ours at S×S sub-pixel centres and box-average (pixel area, like Mitsuba's box filter); 1: skip")
    ap.add_argument("--tab-nodes", type=int, default=1_000_001, help="tabphase nodes on [−1, 1] (default 1000001)")
    ap.add_argument("--rr-depth", type=int, default=1_000_000, help="Mitsuba's rr_depth (default: no roulette, as ours in practice)")
    ap.add_argument("--tau", type=float, default=15.0, help="peak optical depth along z at 515 nm (default 15)")
    ap.add_argument("--binary", default="/tmp/pm-bench", help="photometeor binary (default /tmp/pm-bench, a copy of target/release/photometeor)")
    ap.add_argument("--json", default=RESULT, help="where to write the results (default bench/truth_vs_mitsuba.json)")
    ap.add_argument("--variant", default="scalar_rgb", help="Mitsuba variant: scalar_rgb (default) or llvm_ad_rgb (vectorized; needs Debian's libllvm19 and DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so)")
    ap.add_argument("--quick", action="store_true", help="64×64, 2048 spp ours, 8×64 Mitsuba: under a minute or two")
    a = ap.parse_args()
    if a.quick:
        a.size, a.spp_ours, a.spp_mitsuba, a.k = 64, 2048, 64, 8
    if a.k < 4:
        sys.exit("--k must be ≥ 4")
    if a.spp_ours % a.k_ours:
        sys.exit("--spp-ours must be a multiple of --k-ours")
    global OUT
    OUT = os.path.join(CASE, "out", str(a.size))
    os.makedirs(OUT, exist_ok=True)
    res = {"settings": vars(a).copy(), "machine": {
        "cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
        "note": "shared machine: another session may be compiling; times are indicative",
        "loadavg_start": os.getloadavg()}}

    # 1. Density, scene, bake.
    rho = cumulus_density()
    rho.tofile(DENSITY)  # little-endian f32, x fastest
    assert sys.byteorder == "little"
    with open(SCENE, "w") as fh:
        fh.write(scene_toml(1e7))
    had_tables = os.path.exists(os.path.join(TABLES, "manifest.json"))
    t = time.perf_counter()
    bake = run_ours(a.binary, 4, 1, 1, os.path.join(OUT, "bake.exr"))
    res["bake"] = {"wall_seconds": time.perf_counter() - t, "tables_existed_before": had_tables,
                   "note": "first photometeor call (4×4, 1 spp): the bake (or cache check) plus startup"}
    single = read_single(os.path.join(TABLES, "cloud.single.exr"))
    sigma_g = single["sigma_ext_m2"][GREEN]
    albedo_g = single["albedo"][GREEN]
    delta_g = single["forward_delta_fraction"][GREEN]
    assert abs(single["wavelengths_nm"][GREEN] - 515) < 1e-9, single["wavelengths_nm"]
    dz = (BOX_MAX[2] - BOX_MIN[2]) / DIMS[2]
    col = rho.astype(np.float64).sum(axis=0).max() * dz  # ∫ρ dz of the densest column, m
    number_density = a.tau / (sigma_g * col)
    with open(SCENE, "w") as fh:
        fh.write(scene_toml(number_density))
    beta_scale = number_density * sigma_g  # β_ext per unit ρ (1/m)
    SCALE_FOR_CHECK[0] = beta_scale * (1 - albedo_g * delta_g)
    res["scene"] = {
        "file": os.path.relpath(SCENE, os.path.dirname(HERE)),
        "dims": DIMS, "box_min_m": BOX_MIN.tolist(), "box_max_m": BOX_MAX.tolist(),
        "camera_position_m": CAMERA_POS.tolist(), "camera_look_at_m": CAMERA_LOOK_AT.tolist(),
        "fov_deg_vertical": FOV_DEG, "sun_elevation_deg": SUN_ELEVATION_DEG,
        "sun_azimuth_deg": SUN_AZIMUTH_DEG, "sun_direction": sun_direction().tolist(),
        "number_density_per_m3": number_density, "sigma_ext_515_m2": sigma_g,
        "albedo_515": albedo_g, "forward_delta_fraction_515": delta_g,
        "peak_tau_along_z_515": a.tau, "beta_ext_peak_per_m": beta_scale,
        "wavelengths_nm": single["wavelengths_nm"], "sigma_ext_m2": single["sigma_ext_m2"],
        "albedo": single["albedo"],
    }

    # 2. Mitsuba's scene (loaded once; its load is not timed as rendering).
    import mitsuba as mi
    mi.set_variant(a.variant)
    bins = single["bins"][GREEN]
    x, v, p, cdf = tabphase_nodes(bins, single["theta_step_deg"], delta_g, a.tab_nodes)
    res["checks"] = {"phase_function": phase_checks(x, v, p, cdf, single["theta_step_deg"])}
    values = ",".join(f"{val:.8g}" for val in v)
    # An exact forward δ of energy f (none in this bake) is the same transport as a medium
    # with σ_t(1 − ωf) and albedo ω(1 − f)/(1 − ωf) (δ-scaling).
    sig_scale = beta_scale * (1 - albedo_g * delta_g)
    alb = albedo_g * (1 - delta_g) / (1 - albedo_g * delta_g)
    t = time.perf_counter()
    scene = mi.load_dict(mitsuba_scene(mi, rho, a.size, a.spp_mitsuba, sig_scale, alb, values, a.rr_depth))
    load_s = time.perf_counter() - t
    res["checks"]["mitsuba_geometry"] = mitsuba_checks(mi, scene, rho, a.size)

    # 3. The timed renders, interleaved so that a change in the machine's load hits both:
    # ours k_ours renders of spp/k_ours each (seeds 1..k_ours; seconds from the tracer's own
    # line), Mitsuba k renders of spp_mitsuba each (seeds 1..k; seconds around mi.render).
    per = a.spp_ours // a.k_ours
    events = sorted([((i + 0.5) / a.k_ours, 0, i) for i in range(a.k_ours)]
                    + [((i + 0.5) / a.k, 1, i) for i in range(a.k)])
    runs, imgs, msecs = [], [], []
    for _, who, i in events:
        if who == 0:
            runs.append(run_ours(a.binary, a.size, per, i + 1, os.path.join(OUT, f"ours_seed{i + 1}.exr")))
            runs[-1]["loadavg_after"] = os.getloadavg()[0]
        else:
            t = time.perf_counter()
            img = mi.render(scene, spp=a.spp_mitsuba, seed=i + 1)
            # The vectorized variants evaluate lazily: the render is done once its image is
            # evaluated and the kernels have finished (a no-op for scalar_rgb).
            import drjit as dr
            dr.eval(img)
            dr.sync_thread()
            msecs.append(time.perf_counter() - t)
            imgs.append(np.array(img, dtype=np.float64))
        print(f"  {'ours' if who == 0 else 'mitsuba'} seed {i + 1}: "
              f"{runs[-1]['seconds'] if who == 0 else msecs[-1]:.1f} s", flush=True)
    exrs = [read_exr(r["exr"]) for r in runs]
    G = np.stack([e["G"] for e in exrs])
    SE = np.stack([e["stderr.G"] for e in exrs])
    A = exrs[0]["A"]
    ours_g = G.mean(axis=0)
    ours_se = np.sqrt((SE ** 2).sum(axis=0)) / a.k_ours  # internal: from each render's stderr.G
    ours_se_between = G.std(axis=0, ddof=1) / math.sqrt(a.k_ours)
    ours_secs = sum(r["seconds"] for r in runs)
    res["ours"] = {"runs": runs, "spp_total": a.spp_ours, "seconds_total": ours_secs,
                   "paths_per_second": a.size * a.size * a.spp_ours / ours_secs}
    MG = np.stack(imgs)[..., 1]
    mit_g = MG.mean(axis=0)
    mit_se = MG.std(axis=0, ddof=1) / math.sqrt(a.k)
    # Relative errors are taken against the same reference for both tools, the average of the
    # two images (each unbiased), so that neither tool's own noisy mean enters its own metric.
    ref = (ours_g + mit_g) / 2
    mask = (1 - A > 0.01) & (ref > 0)
    mit_secs = sum(msecs)
    res["mitsuba"] = {"version": mi.__version__, "variant": mi.variant(), "load_seconds": load_s,
                      "render_seconds": msecs, "seconds_total": mit_secs, "spp_per_render": a.spp_mitsuba,
                      "renders": a.k, "spp_total": a.k * a.spp_mitsuba,
                      "spp_per_second": a.k * a.spp_mitsuba / mit_secs,
                      "samples_per_second": a.size * a.size * a.k * a.spp_mitsuba / mit_secs,
                      "threads": __import__("drjit").thread_count()}

    # Our A channel against an independent ray march of the same grid (camera, grid
    # alignment, σ_ext of the green channel as the binary sees them).
    rays = pixel_rays(a.size, a.size)
    rng = np.random.default_rng(3)
    pick = rng.choice(a.size * a.size, size=min(400, a.size * a.size), replace=False)
    t_py = transparency(rho.astype(np.float64), beta_scale, CAMERA_POS, rays.reshape(-1, 3)[pick])
    t_ours = A.reshape(-1)[pick]
    res["checks"]["A_channel_vs_python_ray_march"] = {
        "pixels": len(pick), "max_abs_diff_T": float(np.max(np.abs(t_py - t_ours))),
        "max_tau_camera_rays": float(-np.log(max(A.min(), 1e-300)))}

    # 4. Noise at the measured cost, and the time to 1 % (1/√n: t · (noise/0.01)²).
    np.seterr(divide="ignore", invalid="ignore")  # 0/0 outside the mask

    def med(rel):
        return float(np.median(rel[mask]))

    def rms(rel):
        return float(np.sqrt(np.mean(rel[mask] ** 2)))

    c_k, c_ko = median_chi_factor(a.k - 1), median_chi_factor(a.k_ours - 1)
    rows = {
        "ours (stderr.G)": (ours_secs, med(ours_se / ref), rms(ours_se / ref)),
        f"ours (between {a.k_ours} seeds)": (ours_secs, med(ours_se_between / ref) / c_ko,
                                               rms(ours_se_between / ref)),
        f"mitsuba (between {a.k} seeds)": (mit_secs, med(mit_se / ref) / c_k, rms(mit_se / ref)),
    }
    noise = {}
    for name, (secs, nm, nr) in rows.items():
        noise[name] = {"seconds": secs, "median_rel_se": nm, "rms_rel_se": nr,
                       "seconds_to_1pct_median": secs * (nm / 0.01) ** 2,
                       "seconds_to_1pct_rms": secs * (nr / 0.01) ** 2}
    res["noise"] = {"pixels_in_mask": int(mask.sum()), "rows": noise,
                    "median_chi_correction": {"mitsuba": c_k, "ours_between": c_ko},
                    "relative_to": "(ours G + Mitsuba G)/2 per pixel",
                    "uncorrected_median_rel_se": {"mitsuba": med(mit_se / ref),
                                                  "ours_between": med(ours_se_between / ref)},
                    "ours_median_rel_se_own_mean": float(np.median(np.where(
                        ours_g[mask] > 0, ours_se[mask] / ours_g[mask], np.inf))),
                    "mitsuba_median_rel_se_own_mean_uncorrected": float(np.median(np.where(
                        mit_g[mask] > 0, mit_se[mask] / mit_g[mask], np.inf)))}
    o, m = noise["ours (stderr.G)"], noise[f"mitsuba (between {a.k} seeds)"]
    res["noise"]["speedup_ours_over_mitsuba_at_equal_noise"] = {
        "median": m["seconds_to_1pct_median"] / o["seconds_to_1pct_median"],
        "rms": m["seconds_to_1pct_rms"] / o["seconds_to_1pct_rms"],
        "median_ours_between_seeds": m["seconds_to_1pct_median"]
        / noise[f"ours (between {a.k_ours} seeds)"]["seconds_to_1pct_median"],
    }
    # The frame's mean G over the mask: the tail-honest measure. A per-pixel median of standard
    # errors estimated from K renders misses a heavy tail that no render has sampled yet; the
    # spread of K frame means (sums over ~10⁴ pixels) does not. Ours from its per-pixel
    # errors (independent pixels), Mitsuba from the spread of its K frame means.
    mean_o = float(ours_g[mask].mean())
    se_o = float(math.sqrt((ours_se[mask] ** 2).sum()) / mask.sum())
    fm = MG[:, mask].mean(axis=1)
    mean_m = float(fm.mean())
    se_m = float(fm.std(ddof=1) / math.sqrt(a.k))
    frame = {"ours": {"mean_G": mean_o, "se": se_o, "seconds": ours_secs,
                      "seconds_to_1pct": ours_secs * (se_o / mean_o / 0.01) ** 2},
             "mitsuba": {"mean_G": mean_m, "se": se_m, "seconds": mit_secs,
                         "seconds_to_1pct": mit_secs * (se_m / mean_m / 0.01) ** 2}}
    res["noise"]["frame_mean"] = frame
    res["noise"]["speedup_ours_over_mitsuba_at_equal_noise"]["frame_mean"] = (
        frame["mitsuba"]["seconds_to_1pct"] / frame["ours"]["seconds_to_1pct"])
    # The median pixel's ratio: far from 1 while the frame means agree, a heavy tail that one
    # tool has sampled and the other not yet.
    res["noise"]["median_pixel_ratio_ours_over_mitsuba"] = float(np.nanmedian(
        ours_g[mask] / np.where(mit_g[mask] > 0, mit_g[mask], np.nan)))

    # 5. Agreement.
    def agreement(og, ose, label):
        n = int(mask.sum())
        mo, mm = og[mask].mean(), mit_g[mask].mean()
        so = math.sqrt((ose[mask] ** 2).sum()) / n
        sm = math.sqrt((mit_se[mask] ** 2).sum()) / n
        ratio = mm / mo
        s_ratio = ratio * math.sqrt((so / mo) ** 2 + (sm / mm) ** 2)
        z = (og - mit_g) / np.sqrt(ose ** 2 + mit_se ** 2)
        within = float(np.mean(np.abs(z[mask]) < 3))
        within_in = float(np.mean(np.abs(z[mask & ~silhouette]) < 3))
        # Expected share if both are right: ours Gaussian with its σ; Mitsuba's σ estimated
        # from K samples (a t-like statistic), simulated per pixel.
        r = np.random.default_rng(11)
        so_p, sm_p = ose[mask], mit_se[mask]
        sims, sims_in = [], []
        inner = ~silhouette[mask]
        for _ in range(20):
            num = r.normal(size=n) * so_p + r.normal(size=n) * sm_p
            sm_hat = sm_p * np.sqrt(r.chisquare(a.k - 1, size=n) / (a.k - 1))
            ok = np.abs(num / np.sqrt(so_p ** 2 + sm_hat ** 2)) < 3
            sims.append(np.mean(ok))
            sims_in.append(np.mean(ok[inner]))
        return {"ours": label, "mean_G_ours": mo, "mean_G_ours_se": so, "mean_G_mitsuba": mm,
                "mean_G_mitsuba_se": sm, "ratio_mitsuba_over_ours": ratio, "ratio_se": s_ratio,
                "ratio_minus_1_in_sigma": (ratio - 1) / s_ratio,
                "share_within_3sigma": within, "share_expected_if_equal": float(np.mean(sims)),
                "interior_pixels": int((mask & ~silhouette).sum()),
                "share_within_3sigma_interior": within_in,
                "share_expected_if_equal_interior": float(np.mean(sims_in)),
                "median_z": float(np.median(z[mask])), "pixels": n}

    # Silhouette pixels: T_vol changes by > 0.05 to a 4-neighbour; there a pixel-centre value
    # and a pixel-area average (Mitsuba's box filter) differ by far more than the noise.
    Ap = np.pad(A, 1, mode="edge")
    silhouette = np.maximum.reduce([np.abs(Ap[1:-1, 2:] - A), np.abs(Ap[1:-1, :-2] - A),
                                    np.abs(Ap[2:, 1:-1] - A), np.abs(Ap[:-2, 1:-1] - A)]) > 0.05
    res["agreement"] = [agreement(ours_g, ours_se, "pixel centres")]
    if a.supersample > 1:
        s = a.supersample
        spp_ss = max(2, a.spp_ours // (s * s))
        rss = run_ours(a.binary, a.size * s, spp_ss, 101, os.path.join(OUT, "ours_supersampled.exr"))
        e = read_exr(rss["exr"])
        gs = e["G"].reshape(a.size, s, a.size, s).mean(axis=(1, 3))
        ses = np.sqrt((e["stderr.G"].reshape(a.size, s, a.size, s) ** 2).sum(axis=(1, 3))) / (s * s)
        res["ours_supersampled"] = rss
        res["agreement"].append(agreement(gs, ses, f"{s}×{s} sub-pixel centres, box-averaged ({spp_ss} spp each)"))
    else:
        gs = None

    # Images: ours | Mitsuba | z-score (red ours brighter, blue darker, ±3σ full).
    expo = 1.0 / max(np.percentile(ours_g[mask], 99), 1e-12)
    tone = lambda g: np.repeat((1 - np.exp(-2 * g * expo))[..., None], 3, axis=-1)
    zz = ((gs if gs is not None else ours_g) - mit_g) / np.sqrt(
        (ses if gs is not None else ours_se) ** 2 + mit_se ** 2)
    zimg = np.zeros(zz.shape + (3,))
    zimg[..., 0] = np.clip(zz / 3, 0, 1)
    zimg[..., 2] = np.clip(-zz / 3, 0, 1)
    zimg[~mask] = 0.15
    write_png(os.path.join(OUT, "ours_mitsuba_z.png"), np.concatenate([tone(ours_g), tone(mit_g), zimg], axis=1))
    np.savez_compressed(os.path.join(OUT, "images.npz"), ours_g=ours_g, ours_se=ours_se, mitsuba_g=mit_g,
                        mitsuba_se=mit_se, A=A, mask=mask)
    res["machine"]["loadavg_end"] = os.getloadavg()
    with open(a.json, "w") as fh:
        json.dump(repo.portable(res, os.path.dirname(HERE), os.path.dirname(a.binary)), fh, indent=2,
                  default=float)

    # Table.
    print(f"\n{a.size}×{a.size}, mask {int(mask.sum())} px (1 − T_vol > 1 %), peak τ(z) {a.tau}, "
          f"shared {os.cpu_count()}-core machine (load {res['machine']['loadavg_start'][0]:.1f} → "
          f"{res['machine']['loadavg_end'][0]:.1f})")
    print(f"photometeor: {a.spp_ours} spp in {a.k_ours} runs, {ours_secs:.1f} s, "
          f"{res['ours']['paths_per_second'] / 1e6:.3f} M paths/s")
    print(f"Mitsuba {mi.__version__} {mi.variant()}: {a.k}×{a.spp_mitsuba} spp, {mit_secs:.1f} s, "
          f"{res['mitsuba']['spp_per_second']:.2f} spp/s ({res['mitsuba']['samples_per_second'] / 1e6:.3f} M samples/s)")
    print(f"{'':34s} {'time s':>8s} {'noise(med)':>11s} {'t→1% (med)':>11s} {'noise(rms)':>11s} {'t→1% (rms)':>11s}")
    for name, r in noise.items():
        print(f"{name:34s} {r['seconds']:8.1f} {100 * r['median_rel_se']:10.2f}% {r['seconds_to_1pct_median']:11.0f} "
              f"{100 * r['rms_rel_se']:10.2f}% {r['seconds_to_1pct_rms']:11.0f}")
    sp = res["noise"]["speedup_ours_over_mitsuba_at_equal_noise"]
    print(f"Mitsuba time / ours time to 1 %: {sp['median']:.2f} (median), {sp['rms']:.2f} (rms), "
          f"{sp['median_ours_between_seeds']:.2f} (median, ours between seeds), "
          f"{sp['frame_mean']:.2f} (the frame's mean G)")
    fr = res["noise"]["frame_mean"]
    print(f"frame mean G: ours {fr['ours']['mean_G']:.5g} ± {fr['ours']['se']:.2g} in {fr['ours']['seconds']:.1f} s, "
          f"Mitsuba {fr['mitsuba']['mean_G']:.5g} ± {fr['mitsuba']['se']:.2g} in {fr['mitsuba']['seconds']:.1f} s; "
          f"median pixel ours/Mitsuba {res['noise']['median_pixel_ratio_ours_over_mitsuba']:.3f}")
    for g in res["agreement"]:
        print(f"agreement [{g['ours']}]: mean G ours {g['mean_G_ours']:.5g} ± {g['mean_G_ours_se']:.2g}, "
              f"Mitsuba {g['mean_G_mitsuba']:.5g} ± {g['mean_G_mitsuba_se']:.2g}, ratio "
              f"{g['ratio_mitsuba_over_ours']:.4f} ± {g['ratio_se']:.4f}; within 3σ {100 * g['share_within_3sigma']:.1f} % "
              f"(expected {100 * g['share_expected_if_equal']:.1f} %); away from the silhouette "
              f"{100 * g['share_within_3sigma_interior']:.1f} % (expected {100 * g['share_expected_if_equal_interior']:.1f} %)")
    c = res["checks"]
    print(f"checks: A vs python march max |ΔT| {c['A_channel_vs_python_ray_march']['max_abs_diff_T']:.2e}; "
          f"camera rays max {c['mitsuba_geometry']['camera_ray_max_angle_deg']:.2e}°; σ_t lookups max "
          f"{c['mitsuba_geometry']['sigma_t_max_abs_diff_over_peak']:.2e} of peak; tabphase g "
          f"{c['phase_function']['g_tabphase']:.6f} vs {c['phase_function']['g_ours']:.6f}")
    print(f"wrote {os.path.relpath(a.json)} and {os.path.relpath(OUT)}/")


if __name__ == "__main__":
    main()
