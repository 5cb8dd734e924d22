#!/usr/bin/env python3
"""Time photometeor.mie (the Python package) against miepython in one run, on one machine at one
moment: a single sphere m = 1.333 + 1e-8 i (photometeor's sign, κ ≥ 0), x = 1e5, at the 1001
angles θ = 0, 0.18, …, 180° — Q_ext, Q_sca, g, S1, S2 and the phase function
p = (|S1|² + |S2|²)/(2π x² Q_sca) on both sides (workload a. of scripts/bench_miepython.py,
which times miepython for `photometeor bench mie`).

miepython runs with its numba JIT (MIEPYTHON_USE_JIT=1, set before the import; its kernels are
compiled by a warm-up call outside the timing), with its m = n − iκ convention. photometeor runs
with all cores (rayon) and, in a child process with RAYON_NUM_THREADS=1, on one core. Each
figure is the best of --repeat runs. The two results are compared (max relative difference of p)
so that the same work is timed. This is a benchmark, not a test: it prints, it does not judge.

Usage: python3 scripts/bench_python_mie.py [--repeat N] [--json]
"""

import os

os.environ["MIEPYTHON_USE_JIT"] = "1"  # must be set before miepython is imported

import argparse
import json
import subprocess
import sys
import time

import numpy as np

import miepython
import photometeor

M = 1.333 + 1e-8j
X = 1e5
ANGLES_DEG = np.round(0.18 * np.arange(1001), 2)


def folded_cosines(angles_deg):
    """cos θ as photometeor folds it (θ > 90° as −cos(180° − θ)); both codes get these μ."""
    mu = np.where(angles_deg > 90, -np.cos(np.radians(180 - angles_deg)), np.cos(np.radians(angles_deg)))
    return np.where(angles_deg == 90, 0.0, mu)


def run_photometeor():
    r = photometeor.mie(M, X, ANGLES_DEG)
    return r["phase"]


def run_miepython():
    m = M.conjugate()  # miepython's m = n − iκ
    mu = folded_cosines(ANGLES_DEG)
    _, qsca, _, _ = miepython.efficiencies_mx(m, X)
    s1, s2 = miepython.S1_S2(m, X, mu, norm="wiscombe")
    return (np.abs(s1) ** 2 + np.abs(s2) ** 2) / (2 * np.pi * X * X * qsca)


def best_of(fn, repeat):
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), result


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per timing, the best is kept (default 3)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--one-thread-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one_thread_child:
        run_photometeor()  # warm-up
        print(best_of(run_photometeor, args.repeat)[0])
        return

    load0 = os.getloadavg()
    t0 = time.perf_counter()
    run_miepython()  # warm-up: compiles (or loads the cached) numba kernels
    warmup = time.perf_counter() - t0
    run_photometeor()
    t_all, p_ours = best_of(run_photometeor, args.repeat)
    t_mp, p_theirs = best_of(run_miepython, args.repeat)
    child = subprocess.run(
        [sys.executable, __file__, "--one-thread-child", "--repeat", str(args.repeat)],
        env={**os.environ, "RAYON_NUM_THREADS": "1"},
        capture_output=True,
        text=True,
        check=True,
    )
    t_one = float(child.stdout.strip())
    agreement = float(np.max(np.abs(p_ours - p_theirs) / p_theirs))
    out = {
        "workload": "m = 1.333+1e-8i, x = 1e5, 1001 angles: Q, S1, S2, p",
        "photometeor_version": photometeor.__version__,
        "miepython_version": miepython.__version__,
        "cpus": os.cpu_count(),
        "repeat": args.repeat,
        "photometeor_s": t_all,
        "photometeor_1_thread_s": t_one,
        "miepython_jit_s": t_mp,
        "miepython_warmup_s": warmup,
        "speedup": t_mp / t_all,
        "speedup_1_thread": t_mp / t_one,
        "max_relative_difference_of_p": agreement,
        "loadavg_start": list(load0),
        "loadavg_end": list(os.getloadavg()),
    }
    if args.json:
        print(json.dumps(out))
        return
    print(f"{out['workload']} (best of {args.repeat}, {out['cpus']} cpus, load {load0[0]:.2f})")
    print(f"  photometeor.mie {photometeor.__version__}, all cores : {t_all * 1e3:9.1f} ms")
    print(f"  photometeor.mie, 1 thread    : {t_one * 1e3:9.1f} ms")
    print(f"  miepython {miepython.__version__} (numba JIT)   : {t_mp * 1e3:9.1f} ms (warm-up {warmup:.1f} s)")
    print(f"  ratio miepython / photometeor: {out['speedup']:.1f}x all cores, {out['speedup_1_thread']:.1f}x on one thread")
    print(f"  max relative difference of p : {agreement:.1e}")


if __name__ == "__main__":
    main()
