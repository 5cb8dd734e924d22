#!/usr/bin/env python3
"""Time miepython (numba JIT) on photometeor's two benchmark workloads.

Workloads (angles: 1001 values theta = 0, 0.18, ..., 180 deg):
  a. single sphere, m = 1.333 + 1e-8 i (photometeor sign, kappa >= 0 absorbing), x = 1e5:
     S1 and S2 at all angles and the unpolarized phase function
     p = (|S1|^2 + |S2|^2) / (2 pi x^2 Qsca).
  b. rain lognormal: median radius r_g = 500 um, sigma_g = 1.4, 100 radii log-spaced from
     r_g exp(-3 ln sigma_g) to r_g exp(+3 ln sigma_g) (endpoints included); wavelengths
     650, 550, 450 nm with water m = 1.3317+1.67e-8i, 1.3347+2.46e-9i, 1.3396+8.07e-10i.
     Per wavelength: P(theta) = sum_i w_i (|S1|^2+|S2|^2)_i / (2 pi sum_i w_i x_i^2 Qsca_i),
     i.e. the sigma_sca-weighted lognormal average of the single-size phase functions,
     with w_i = exp(-(ln r_i - ln r_g)^2 / (2 ln^2 sigma_g)) per log step (n(r) dr on the
     log grid).  Timed: all 300 Mie calls (efficiencies + S1/S2 at 1001 angles) and the sums.

miepython's convention is m = n - i kappa, so the index is passed as n - i kappa.  Only
|S1|^2 and |S2|^2 enter, so miepython's complex-conjugated S (see
data/reference/generate_mie_reference.py) does not matter here.

Each workload is timed as the best of 3 runs (1 with --quick) after a warm-up call that
triggers numba compilation.  Prints a JSON object on stdout, human-readable lines on stderr.

Usage: python3 scripts/bench_miepython.py [--quick] [--phase-out FILE]
"""

import os

os.environ["MIEPYTHON_USE_JIT"] = "1"  # must be set before miepython is imported

import argparse
import json
import math
import sys
import time

import numba
import numpy as np

import miepython
from miepython import core as _mie_core

ANGLES_DEG = np.array([round(0.18 * i, 2) for i in range(1001)])
MU = np.cos(np.radians(ANGLES_DEG))
MU[0], MU[-1] = 1.0, -1.0

SINGLE_M = (1.333, 1e-8)
SINGLE_X = 1e5

RAIN_RG_UM = 500.0
RAIN_SIGMA_G = 1.4
RAIN_N = 100
RAIN_WAVELENGTHS_NM = [650.0, 550.0, 450.0]
RAIN_M = [(1.3317, 1.67e-8), (1.3347, 2.46e-9), (1.3396, 8.07e-10)]


def mp_index(m_re, m_im):
    """photometeor's m = n + i kappa (kappa >= 0) -> miepython's n - i kappa."""
    return complex(m_re, -m_im)


def single_workload():
    m = mp_index(*SINGLE_M)
    x = SINGLE_X
    _, qsca, _, _ = miepython.efficiencies_mx(m, x)
    s1, s2 = miepython.S1_S2(m, x, MU, norm="wiscombe")
    return (np.abs(s1) ** 2 + np.abs(s2) ** 2) / (2 * math.pi * x * x * qsca)


def rain_grid():
    ln_s = math.log(RAIN_SIGMA_G)
    ln_r = np.linspace(math.log(RAIN_RG_UM) - 3 * ln_s, math.log(RAIN_RG_UM) + 3 * ln_s, RAIN_N)
    radii = np.exp(ln_r)
    weights = np.exp(-((ln_r - math.log(RAIN_RG_UM)) ** 2) / (2 * ln_s * ln_s))
    return radii, weights


def rain_workload():
    radii, weights = rain_grid()
    phases = []
    for wl_nm, (mr, mi) in zip(RAIN_WAVELENGTHS_NM, RAIN_M):
        m = mp_index(mr, mi)
        acc = np.zeros(MU.size)
        norm = 0.0
        for r_um, w in zip(radii, weights):
            x = 2 * math.pi * r_um / (wl_nm * 1e-3)
            _, qsca, _, _ = miepython.efficiencies_mx(m, x)
            s1, s2 = miepython.S1_S2(m, x, MU, norm="wiscombe")
            acc += w * (np.abs(s1) ** 2 + np.abs(s2) ** 2)
            norm += w * x * x * qsca
        phases.append(acc / (2 * math.pi * norm))
    return phases


def timed(name, fn, reps):
    times, result = [], None
    for i in range(reps):
        t0 = time.perf_counter()
        result = fn()
        dt = time.perf_counter() - t0
        times.append(dt)
        print(f"  {name} run {i + 1}/{reps}: {dt:.3f} s", file=sys.stderr)
    print(f"  {name} best: {min(times):.3f} s", file=sys.stderr)
    return min(times), times, result


def integral_4pi(p):
    """Trapezoid estimate of the integral over 4 pi on the 1001-angle grid (info only).

    The 0.18 deg grid does not resolve the forward diffraction peak (width ~1/x rad), so for
    large drops this is well below 1 (about 0.5 at x = 1e5); it is printed only as a sanity hint.
    """
    th = np.radians(ANGLES_DEG)
    return float(2 * math.pi * np.trapezoid(p * np.sin(th), th))


def main():
    ap = argparse.ArgumentParser(description="time miepython (numba JIT) on photometeor's workloads")
    ap.add_argument("--quick", action="store_true", help="1 repetition per workload instead of 3")
    ap.add_argument("--phase-out", metavar="FILE", help="write the rain workload's 3x1001 phase functions as JSON")
    args = ap.parse_args()
    reps = 1 if args.quick else 3

    jit = bool(miepython.USE_JIT) and isinstance(_mie_core._S1_S2, numba.core.registry.CPUDispatcher)
    if not jit:
        raise SystemExit("miepython numba JIT is not active")
    load0 = os.getloadavg()
    print(f"miepython {miepython.__version__}, numba {numba.__version__}, JIT active: {jit}; "
          f"cpus={os.cpu_count()}, loadavg={load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}", file=sys.stderr)

    t0 = time.perf_counter()  # warm-up: compile (or load cached) numba kernels
    miepython.efficiencies_mx(mp_index(1.333, 1e-8), 50.0)
    miepython.S1_S2(mp_index(1.333, 1e-8), 50.0, MU, norm="wiscombe")
    print(f"warm-up: {time.perf_counter() - t0:.3f} s", file=sys.stderr)

    print(f"a. single sphere m=1.333+1e-8i x=1e5, {MU.size} angles:", file=sys.stderr)
    best_a, runs_a, p_single = timed("single_x1e5", single_workload, reps)
    print(f"   integral p dOmega (trapezoid, info; forward peak unresolved) = {integral_4pi(p_single):.6f}", file=sys.stderr)

    radii, _ = rain_grid()
    print(f"b. rain lognormal r_g={RAIN_RG_UM} um sigma_g={RAIN_SIGMA_G}, {RAIN_N} sizes "
          f"{radii[0]:.3f}..{radii[-1]:.3f} um x 3 wavelengths, {MU.size} angles:", file=sys.stderr)
    best_b, runs_b, phases = timed("rain_lognormal", rain_workload, reps)
    for wl, p in zip(RAIN_WAVELENGTHS_NM, phases):
        print(f"   {wl:.0f} nm: integral P dOmega (trapezoid, info) = {integral_4pi(p):.6f}", file=sys.stderr)

    load1 = os.getloadavg()
    print(f"loadavg at end: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}", file=sys.stderr)

    if args.phase_out:
        radii, weights = rain_grid()
        doc = {
            "generator": "scripts/bench_miepython.py",
            "miepython_version": miepython.__version__,
            "description": ("rain lognormal benchmark result: P(theta) = sum_i w_i (|S1|^2+|S2|^2)_i / "
                            "(2 pi sum_i w_i x_i^2 Qsca_i), 1/sr, integral over 4 pi = 1; "
                            "w_i = exp(-(ln r_i - ln r_g)^2 / (2 ln^2 sigma_g)) on the log radius grid"),
            "median_radius_um": RAIN_RG_UM,
            "sigma_g": RAIN_SIGMA_G,
            "radii_um": [float(r) for r in radii],
            "weights": [float(w) for w in weights],
            "wavelength_nm": RAIN_WAVELENGTHS_NM,
            "m": [{"m_re": mr, "m_im": mi} for mr, mi in RAIN_M],
            "angles_deg": [float(a) for a in ANGLES_DEG],
            "phase": [[float(v) for v in p] for p in phases],
        }
        with open(args.phase_out, "w") as fh:
            json.dump(doc, fh, separators=(",", ":"))
            fh.write("\n")
        print(f"wrote {args.phase_out}", file=sys.stderr)

    out = {
        "tool": "miepython",
        "version": miepython.__version__,
        "jit": jit,
        "single_x1e5_s": best_a,
        "rain_lognormal_s": best_b,
        "runs": {"single_x1e5_s": runs_a, "rain_lognormal_s": runs_b},
        "repetitions": reps,
        "cpus": os.cpu_count(),
        "loadavg_start": list(load0),
        "loadavg_end": list(load1),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
