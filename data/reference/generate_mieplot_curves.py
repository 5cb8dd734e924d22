#!/usr/bin/env python3
"""Generate MiePlot-style reference curves (phase function vs angle) for photometeor's tests.

Output: ``data/reference/mieplot_curves.json`` (next to this script).

Independent solver: miepython 3.3.0 (numba JIT, ``MIEPYTHON_USE_JIT=1``).  miepython gives the
Mie coefficients a_n, b_n (``miepython.coefficients``), the efficiencies and g
(``miepython.efficiencies_mx``) and the point values of the phase function
(``miepython.S1_S2``).  The bin averages need ~10^5 angles per sphere; for those this script sums
the angular series itself (``intensity_pm`` below: the same Legendre recurrence for pi_n, tau_n
that miepython uses, over miepython's a_n, b_n, with the parity pi_n(-mu) = (-1)^(n-1) pi_n(mu),
tau_n(-mu) = (-1)^n tau_n(mu) so one pass gives mu and -mu).  It is ~13x faster than
miepython.S1_S2 and is checked against miepython.S1_S2 at the 1001 bin centres of every sphere
(check ``kernel_vs_miepython_*``).  Only |S1|^2 + |S2|^2 enters, so miepython's complex
conjugation of S (see generate_mie_reference.py) does not matter here.

Conventions (photometeor's, Bohren & Huffman)
---------------------------------------------
* m = m_re + i m_im, m_im >= 0 absorbing; miepython is called with complex(m_re, -m_im).
  Water: linear interpolation in vacuum wavelength of the n and k columns of
  mie/data/refractive_index/water_segelstein1981.csv (Segelstein 1981, 25 C).
* x = 2 pi r / lambda (vacuum wavelength, medium index 1).
* p(theta) = (|S1|^2 + |S2|^2) / (2 pi x^2 Qsca), 1/sr, integral over 4 pi = 1.
* Angle grid: photometeor's table grid, theta_k = 0.18 k deg, k = 0..1000.  Sample k stands for
  the bin [theta_k - 0.09, theta_k + 0.09] deg clipped to [0, 180] (bins 0 and 1000 are half
  width).  Delta Omega_k = 2 pi (cos lo_k - cos hi_k).
* phase_bin[k] = (1/Delta Omega_k) * integral over bin k of p dOmega (solid-angle bin average);
  phase_point[k] = p(theta_k).
* Lognormal: number density n(r) dr proportional to (1/r) exp(-(ln r - ln r_g)^2 / (2 ln^2 s_g)) dr,
  truncated to |ln r - ln r_g| <= 4 ln s_g, trapezoid rule on a uniform grid in ln r
  (c_i = exp(-(ln r_i - ln r_g)^2 / (2 ln^2 s_g)) * trapezoid weight).  Mixture weighted by the
  scattering cross-section: p_bulk = sum c_i Csca_i p_i / sum c_i Csca_i, which on one
  wavelength is sum c_i F_i / (2 pi sum c_i x_i^2 Qsca_i), F = |S1|^2 + |S2|^2.
  qext, qsca of a distribution are area-weighted efficiencies sum c Cext / sum c pi r^2;
  g = sum c Csca g / sum c Csca.

Bin quadrature
--------------
Gauss-Legendre in mu inside each bin.  With P = x * (0.18 deg in rad) / pi (number of angular
oscillation periods, period pi/x rad = lambda/(2r), per bin) the base node count is
n_base = max(8, 2 * ceil(1.2 P + 3)) per bin; level L uses L * n_base nodes.  Bins near the poles
are split into sub-intervals uniform in theta (GL in mu in each): bins 1, 2 (and 998, 999) into
2L, bins 0 and 1000 into L * max(2, ceil(P)) (the forward diffraction and glory peaks are ~1/x rad
wide, which is only ~1/x^2 in mu).  Spheres: stored with L = 2, checked against L = 1.
Distributions: every radius at L = 1; 17 radii spread over the range also at L = 2 (a
Csca-weighted mixture of positive curves has per-bin relative error <= the largest per-radius
one).  phase_point: miepython.S1_S2 for spheres; for distributions the own angular sum (checked
against miepython.S1_S2 on the same 17 radii).

Checks (the run stops on failure; values go to the file's "checks")
-------------------------------------------------------------------
* |sum_k phase_bin[k] Delta Omega_k - 1| <= 1e-6 for every curve;
* angular quadrature: max over bins of |phase_bin(L=1) / phase_bin(L=2) - 1| <= 1e-7;
* g: from the same quadrature (integral of p mu dOmega) and from the bin averages
  (sum phase_bin Delta Omega mu_mid) against miepython's g (tolerances 1e-6 and 1e-4);
* kernel_vs_miepython: |F_own - F_miepython| <= 1e-9 F + 1e-12 max F at the 1001 centres;
* rainbow: for r = 1000 um spheres and the drizzle distribution, the maximum of phase_bin in
  130-145 deg lies within 1 deg of Descartes' minimum-deviation angle
  theta_D = 180 deg + 2 i - 4 r', cos^2 i = (n^2 - 1)/3, sin r' = sin i / n (n = m_re).
Size grid (recorded, warns but does not stop): radii N and (N+1)/2 (every other one) give
bin-averaged bulk phase functions with relative rms difference <= 1e-3; N is doubled from 65
until this holds or the cap is reached (cloud 32769, drizzle 4097; --max-radii changes it).
The nearly non-absorbing water (kappa ~ 1e-9..1e-8) has a dense forest of narrow
morphology-dependent resonances in x (widths ~0.01 in x and below), so the size average
converges only roughly like N^-1/2..N^-1: the drizzle needs ~32769 radii (~1 h) for 1e-3.

Run:  python3 data/reference/generate_mieplot_curves.py   (see data/reference/README.md for the runtime)
      --only NAME,... (trial, writes nothing unless --out), --max-radii drizzle=32769
"""

import os

os.environ["MIEPYTHON_USE_JIT"] = "1"  # before importing miepython

import argparse
import json
import math
import platform
import sys
import time

import numba
import numpy as np
import scipy
from numba import njit
from scipy.special import roots_legendre

import miepython

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
OUT = os.path.join(HERE, "mieplot_curves.json")
WATER_CSV = os.path.join(REPO, "mie", "data", "refractive_index", "water_segelstein1981.csv")

WAVELENGTHS_NM = [650.0, 550.0, 450.0]
SPHERE_RADII_UM = [1.0, 10.0, 100.0, 1000.0]
# (label, r_g [um], sigma_g, largest number of radii); see the README for why drizzle is capped
LOGNORMALS = [("cloud", 10.0, 1.3, 32769), ("drizzle", 100.0, 1.5, 4097)]
TRUNC_SIGMAS = 4.0           # truncation at +-4 ln(sigma_g) around ln(r_g)
N_RADII_START = 65           # first size grid; doubled (2N-1) until converged or at the cap
SIZE_RMS_TARGET = 1e-3

K = 1001
DTHETA_DEG = 0.18
DTHETA_RAD = math.radians(DTHETA_DEG)

TOL = {
    "normalization": 1e-6,
    "angular_L1_vs_L2_max_rel": 1e-7,
    "g_quadrature_abs": 1e-6,
    "g_bins_abs": 1e-4,
    "kernel_rel": 1e-9,
    "kernel_abs_of_max": 1e-12,
    "rainbow_deg": 1.0,
}


def sig(v, d=10):
    return float(f"{v:.{d}g}")


# ---------------------------------------------------------------------------------
# refractive index
def load_water():
    rows = []
    with open(WATER_CSV) as fh:
        for line in fh:
            line = line.strip()
            if not line or line.startswith("#") or line.startswith("wavelength_nm"):
                continue
            wl, n, k = (float(v) for v in line.split(","))
            rows.append((wl, n, k))
    a = np.array(rows)
    return a[:, 0], a[:, 1], a[:, 2]


def water_index(wl_nm, table):
    wl, n, k = table
    if not (wl[0] <= wl_nm <= wl[-1]):
        raise SystemExit(f"wavelength {wl_nm} nm outside the water table")
    return float(np.interp(wl_nm, wl, n)), float(np.interp(wl_nm, wl, k))


def mp_index(m_re, m_im):
    """photometeor's m = n + i kappa (kappa >= 0) -> miepython's n - i kappa."""
    return complex(m_re, -m_im)


def descartes_primary_deg(n):
    ci = math.sqrt((n * n - 1.0) / 3.0)
    i = math.acos(ci)
    r = math.asin(math.sin(i) / n)
    return math.degrees(math.pi + 2.0 * i - 4.0 * r)


# ---------------------------------------------------------------------------------
# angle grid
def grid():
    k = np.arange(K)
    lo = np.radians(np.clip((2 * k - 1) * 0.09, 0.0, 180.0))
    hi = np.radians(np.clip((2 * k + 1) * 0.09, 0.0, 180.0))
    # cos lo - cos hi, computed without cancellation
    dmu = 2.0 * np.sin(0.5 * (lo + hi)) * np.sin(0.5 * (hi - lo))
    domega = 2.0 * math.pi * dmu
    mu_mid = 0.5 * (np.cos(lo) + np.cos(hi))
    theta_c = np.radians(np.round(DTHETA_DEG * k, 2))
    mu_c = np.cos(theta_c)
    mu_c[0], mu_c[-1] = 1.0, -1.0
    mu_c[500] = 0.0
    return lo, hi, domega, mu_mid, mu_c


LO, HI, DOMEGA, MU_MID, MU_C = grid()
_NODE_CACHE = {}


def periods_per_bin(x):
    """Angular oscillation periods (pi/x rad = lambda/(2r)) per 0.18 deg bin."""
    return x * DTHETA_RAD / math.pi


def n_base_for(x):
    return max(8, 2 * math.ceil(1.2 * periods_per_bin(x) + 3.0))


def s_pole_for(x):
    return max(2, math.ceil(periods_per_bin(x)))


def node_set(nb, sp, level):
    """Nodes with mu >= 0 for bins 0..500 (bin 500: its t > 0 half only).

    level*nb GL nodes per (sub-)interval; bin 0 split into level*sp sub-intervals uniform in
    theta, bins 1 and 2 into 2*level.  Returns mu, weight (in mu), bin index; the mirror -mu
    gives bins 1000..500."""
    key = (nb, sp, level)
    if key in _NODE_CACHE:
        return _NODE_CACHE[key]
    n = level * nb
    t, w = roots_legendre(n)
    mus, ws, bs = [], [], []
    for k in range(501):
        if k == 500:
            half = math.sin(0.5 * (HI[k] - LO[k]))  # cos lo = -cos hi = sin(0.09 deg)
            sel = t > 0
            mus.append(half * t[sel]); ws.append(half * w[sel]); bs.append(np.full(sel.sum(), k))
            continue
        nsub = level * sp if k == 0 else (2 * level if k in (1, 2) else 1)
        edges = np.linspace(LO[k], HI[k], nsub + 1)
        for a, b in zip(edges[:-1], edges[1:]):
            mid = 0.5 * (math.cos(a) + math.cos(b))
            half = math.sin(0.5 * (a + b)) * math.sin(0.5 * (b - a))
            mus.append(mid - half * t)      # t = -1 -> cos a (larger mu); order irrelevant
            ws.append(half * w)
            bs.append(np.full(n, k))
    res = (np.concatenate(mus), np.concatenate(ws), np.concatenate(bs))
    _NODE_CACHE[key] = res
    return res


# ---------------------------------------------------------------------------------
# angular sums over miepython's a_n, b_n
@njit(cache=True)
def intensity_pm(a, b, mu):
    """F = |S1|^2 + |S2|^2 at mu and at -mu, S = sum (2n+1)/(n(n+1)) (a pi + b tau) etc."""
    chunk = 256
    N = a.shape[0]
    M = mu.shape[0]
    Fp = np.empty(M)
    Fm = np.empty(M)
    far = np.empty(N)
    fai = np.empty(N)
    fbr = np.empty(N)
    fbi = np.empty(N)
    for i in range(N):
        n = i + 1.0
        f = (2.0 * n + 1.0) / (n * (n + 1.0))
        far[i] = f * a[i].real
        fai[i] = f * a[i].imag
        fbr[i] = f * b[i].real
        fbi[i] = f * b[i].imag
    p0 = np.empty(chunk)
    p1 = np.empty(chunk)
    s1pr = np.empty(chunk)
    s1pi = np.empty(chunk)
    s2pr = np.empty(chunk)
    s2pi = np.empty(chunk)
    s1mr = np.empty(chunk)
    s1mi = np.empty(chunk)
    s2mr = np.empty(chunk)
    s2mi = np.empty(chunk)
    for c0 in range(0, M, chunk):
        L = min(M, c0 + chunk) - c0
        for j in range(L):
            p0[j] = 0.0
            p1[j] = 1.0
            s1pr[j] = 0.0
            s1pi[j] = 0.0
            s2pr[j] = 0.0
            s2pi[j] = 0.0
            s1mr[j] = 0.0
            s1mi[j] = 0.0
            s2mr[j] = 0.0
            s2mi[j] = 0.0
        sg = 1.0  # (-1)^(n-1)
        for i in range(N):
            n = i + 1.0
            ar = far[i]
            ai = fai[i]
            br = fbr[i]
            bi = fbi[i]
            c2 = (2.0 * n + 1.0) / n
            c3 = (n + 1.0) / n
            for j in range(L):
                u = mu[c0 + j]
                pn = p1[j]
                pm = p0[j]
                tn = n * u * pn - (n + 1.0) * pm
                s1pr[j] += ar * pn + br * tn
                s1pi[j] += ai * pn + bi * tn
                s2pr[j] += ar * tn + br * pn
                s2pi[j] += ai * tn + bi * pn
                s1mr[j] += sg * (ar * pn - br * tn)
                s1mi[j] += sg * (ai * pn - bi * tn)
                s2mr[j] += sg * (br * pn - ar * tn)
                s2mi[j] += sg * (bi * pn - ai * tn)
                p0[j] = pn
                p1[j] = c2 * u * pn - c3 * pm
            sg = -sg
        for j in range(L):
            Fp[c0 + j] = s1pr[j] ** 2 + s1pi[j] ** 2 + s2pr[j] ** 2 + s2pi[j] ** 2
            Fm[c0 + j] = s1mr[j] ** 2 + s1mi[j] ** 2 + s2mr[j] ** 2 + s2mi[j] ** 2
    return Fp, Fm


def bin_integrals(a, b, x, level):
    """Per bin k = 0..1000: integral of F dmu; and the integral of F mu dmu over all angles."""
    mu, w, bi = node_set(n_base_for(x), s_pole_for(x), level)
    Fp, Fm = intensity_pm(a, b, mu)
    ip = np.bincount(bi, w * Fp, 501)
    im = np.bincount(bi, w * Fm, 501)
    I = np.empty(K)
    I[:500] = ip[:500]
    I[1000:500:-1] = im[:500]
    I[500] = ip[500] + im[500]
    Imu = float(np.dot(w * mu, Fp - Fm))
    return I, Imu


def point_F_own(a, b):
    Fp, Fm = intensity_pm(a, b, MU_C[:501].copy())
    F = np.empty(K)
    F[:501] = Fp
    F[1000:500:-1] = Fm[:500]
    return F


def one_sphere(m_re, m_im, x, levels, check_kernel, point_from_miepython):
    """One sphere: efficiencies, bin integrals of F at the given levels, F at the centres."""
    mm = mp_index(m_re, m_im)
    qext, qsca, qback, g = (float(v) for v in miepython.efficiencies_mx(mm, x))
    a, b = miepython.coefficients(mm, x)
    a = np.ascontiguousarray(a, dtype=np.complex128)
    b = np.ascontiguousarray(b, dtype=np.complex128)
    res = {"x": x, "qext": qext, "qsca": qsca, "qback": qback, "g": g,
           "nodes_per_bin": n_base_for(x), "pole_subintervals": s_pole_for(x)}
    for L in levels:
        res[f"I{L}"], res[f"Imu{L}"] = bin_integrals(a, b, x, L)
    Fown = point_F_own(a, b)
    res["F_point"] = Fown
    if check_kernel or point_from_miepython:
        s1, s2 = miepython.S1_S2(mm, x, MU_C, norm="wiscombe")
        Fmp = np.abs(s1) ** 2 + np.abs(s2) ** 2
        d = np.abs(Fown - Fmp)
        res["kernel_max_rel"] = float(np.max(d / Fmp))
        res["kernel_max_rel_to_max"] = float(np.max(d) / np.max(Fmp))
        res["kernel_ok"] = bool(np.all(d <= TOL["kernel_rel"] * Fmp + TOL["kernel_abs_of_max"] * np.max(Fmp)))
        if point_from_miepython:
            res["F_point"] = Fmp
    return res


# ---------------------------------------------------------------------------------
def curve_checks(name, phase_bin, angular_rel, g_ref, g_quad, fails):
    chk = {}
    chk["sum_phase_bin_dOmega_minus_1"] = float(np.sum(phase_bin * DOMEGA) - 1.0)
    if abs(chk["sum_phase_bin_dOmega_minus_1"]) > TOL["normalization"]:
        fails.append(f"{name}: normalization {chk['sum_phase_bin_dOmega_minus_1']:.3e}")
    chk["angular_L1_vs_L2_max_rel"] = float(angular_rel)
    if angular_rel > TOL["angular_L1_vs_L2_max_rel"]:
        fails.append(f"{name}: angular quadrature {angular_rel:.3e}")
    chk["g_quadrature_minus_g"] = float(g_quad - g_ref)
    chk["g_bins_minus_g"] = float(np.sum(phase_bin * DOMEGA * MU_MID) - g_ref)
    if abs(chk["g_quadrature_minus_g"]) > TOL["g_quadrature_abs"]:
        fails.append(f"{name}: g quadrature {chk['g_quadrature_minus_g']:.3e}")
    if abs(chk["g_bins_minus_g"]) > TOL["g_bins_abs"]:
        fails.append(f"{name}: g bins {chk['g_bins_minus_g']:.3e}")
    return chk


def rainbow_check(name, phase_bin, n_re, chk, fails):
    th = DTHETA_DEG * np.arange(K)
    sel = (th >= 130.0) & (th <= 145.0)
    kmax = int(np.arange(K)[sel][np.argmax(phase_bin[sel])])
    th_d = descartes_primary_deg(n_re)
    chk["rainbow_max_deg"] = round(DTHETA_DEG * kmax, 2)
    chk["descartes_deg"] = th_d
    chk["rainbow_minus_descartes_deg"] = chk["rainbow_max_deg"] - th_d
    if abs(chk["rainbow_minus_descartes_deg"]) > TOL["rainbow_deg"]:
        fails.append(f"{name}: rainbow max {chk['rainbow_max_deg']} vs Descartes {th_d:.3f}")


def summary(name, head, chk, extra, t0):
    line = (f"{name:26s} {head} norm-1={chk['sum_phase_bin_dOmega_minus_1']:+.1e} "
            f"ang={chk['angular_L1_vs_L2_max_rel']:.1e} gq-g={chk['g_quadrature_minus_g']:+.1e} "
            f"gb-g={chk['g_bins_minus_g']:+.1e} kern={chk['kernel_vs_miepython_max_rel']:.1e}{extra}")
    if "rainbow_max_deg" in chk:
        line += f" rainbow={chk['rainbow_max_deg']:.2f} (Descartes {chk['descartes_deg']:.3f})"
    print(line + f"  {time.perf_counter() - t0:.1f}s", flush=True)


def sphere_case(r_um, wl_nm, m_re, m_im, fails):
    t0 = time.perf_counter()
    x = 2.0 * math.pi * r_um / (wl_nm * 1e-3)
    s = one_sphere(m_re, m_im, x, levels=(2, 1), check_kernel=True, point_from_miepython=True)
    norm = x * x * s["qsca"]
    phase_bin = s["I2"] / (norm * DOMEGA)
    angular_rel = np.max(np.abs(s["I1"] / s["I2"] - 1.0))
    g_quad = s["Imu2"] / norm
    phase_point = s["F_point"] / (2 * math.pi * norm)
    name = f"sphere_r{r_um:g}um_{wl_nm:.0f}nm"
    chk = curve_checks(name, phase_bin, angular_rel, s["g"], g_quad, fails)
    chk["kernel_vs_miepython_max_rel"] = s["kernel_max_rel"]
    chk["kernel_vs_miepython_max_rel_to_max"] = s["kernel_max_rel_to_max"]
    if not s["kernel_ok"]:
        fails.append(f"{name}: own angular sum vs miepython.S1_S2")
    chk["gl_nodes_per_bin"] = 2 * s["nodes_per_bin"]
    chk["gl_nodes_per_bin_check"] = s["nodes_per_bin"]
    chk["bin0_subintervals"] = 2 * s["pole_subintervals"]
    if r_um == 1000.0:
        rainbow_check(name, phase_bin, m_re, chk, fails)
    case = {
        "name": name, "kind": "sphere", "wavelength_nm": wl_nm, "m_re": m_re, "m_im": m_im,
        "radius_um": r_um, "x": x, "qext": s["qext"], "qsca": s["qsca"], "g": s["g"],
        "checks": chk,
        "phase_bin": [sig(v) for v in phase_bin],
        "phase_point": [sig(v) for v in phase_point],
    }
    summary(name, f"x={x:9.3f} qext={s['qext']:.7f} qsca={s['qsca']:.7f} g={s['g']:.7f}", chk, "", t0)
    return case


def radii_doublings(label, n_max):
    """j with n_max = (N_RADII_START - 1)·2^j + 1; anything else is refused."""
    jmax = round(math.log2(max(n_max - 1, 1) / (N_RADII_START - 1)))
    if jmax < 0 or (N_RADII_START - 1) * 2 ** jmax + 1 != n_max:
        raise SystemExit(f"{label}: max radii must be 64*2^j + 1, got {n_max}")
    return jmax


def lognormal_case(label, r_g, s_g, n_max, wl_nm, m_re, m_im, fails, warnings):
    """Trapezoid in ln r on nested uniform grids (65, 129, 257, ... radii).

    Running sums U = sum_i e_i q_i - (e_0 q_0 + e_N q_N)/2 with e_i = exp(-(ln r_i - ln r_g)^2 /
    (2 ln^2 s_g)); the grid step cancels in every ratio.  Angular nodes: level 1 for every radius;
    level 2 and miepython.S1_S2 on 17 radii spread over the range (every (N_max-1)/16-th of the
    finest grid, incl. both ends) as the angular-quadrature and kernel checks (a Csca-weighted
    mixture of positive curves has per-bin relative error <= the largest per-radius one)."""
    t0 = time.perf_counter()
    name = f"{label}_lognormal_{wl_nm:.0f}nm"
    ln_s = math.log(s_g)
    lo, hi = math.log(r_g) - TRUNC_SIGMAS * ln_s, math.log(r_g) + TRUNC_SIGMAS * ln_s
    jmax = radii_doublings(label, n_max)
    nfine = n_max
    check_every = (nfine - 1) // 16
    st = {"ang": 0.0, "kern": 0.0, "kern_max": 0.0, "nodes_max": 0, "spole_max": 0}
    U = {"I": np.zeros(K), "F": np.zeros(K), "Imu": 0.0, "csca": 0.0, "cext": 0.0, "area": 0.0,
         "gcsca": 0.0}

    def add(idx, factor):
        lnr = lo + (hi - lo) * idx / (nfine - 1)
        x = 2.0 * math.pi * math.exp(lnr) / (wl_nm * 1e-3)
        chk_here = idx % check_every == 0
        s = one_sphere(m_re, m_im, x, levels=(1, 2) if chk_here else (1,), check_kernel=chk_here,
                       point_from_miepython=False)
        if chk_here:
            st["ang"] = max(st["ang"], float(np.max(np.abs(s["I1"] / s["I2"] - 1.0))))
            st["kern"] = max(st["kern"], s["kernel_max_rel"])
            st["kern_max"] = max(st["kern_max"], s["kernel_max_rel_to_max"])
            if not s["kernel_ok"]:
                fails.append(f"{name} x={x}: own angular sum vs miepython.S1_S2")
        st["nodes_max"] = max(st["nodes_max"], s["nodes_per_bin"])
        st["spole_max"] = max(st["spole_max"], s["pole_subintervals"])
        c = factor * math.exp(-((lnr - math.log(r_g)) ** 2) / (2 * ln_s * ln_s))
        x2 = x * x
        U["I"] += c * s["I1"]
        U["F"] += c * s["F_point"]
        U["Imu"] += c * s["Imu1"]
        U["csca"] += c * x2 * s["qsca"]
        U["cext"] += c * x2 * s["qext"]
        U["area"] += c * x2
        U["gcsca"] += c * x2 * s["qsca"] * s["g"]

    def bulk(n):
        return {"n": n,
                "phase_bin": U["I"] / (U["csca"] * DOMEGA),
                "phase_point": U["F"] / (2 * math.pi * U["csca"]),
                "g_quad": U["Imu"] / U["csca"],
                "qext": U["cext"] / U["area"], "qsca": U["csca"] / U["area"],
                "g": U["gcsca"] / U["csca"]}

    step = (nfine - 1) // (N_RADII_START - 1)
    for idx in range(0, nfine, step):
        add(idx, 0.5 if idx in (0, nfine - 1) else 1.0)
    prev = bulk(N_RADII_START)
    history = []
    while True:
        step //= 2
        for idx in range(step, nfine, 2 * step):
            add(idx, 1.0)
        cur = bulk(2 * prev["n"] - 1)
        rel = cur["phase_bin"] / prev["phase_bin"] - 1.0
        relp = cur["phase_point"] / prev["phase_point"] - 1.0
        item = {"n_radii": cur["n"], "n_radii_half": prev["n"],
                "phase_bin_rel_rms": float(np.sqrt(np.mean(rel ** 2))),
                "phase_bin_rel_max": float(np.max(np.abs(rel))),
                "phase_point_rel_rms": float(np.sqrt(np.mean(relp ** 2))),
                "phase_point_rel_max": float(np.max(np.abs(relp))),
                "g_diff": cur["g"] - prev["g"], "qsca_rel": cur["qsca"] / prev["qsca"] - 1.0}
        history.append(item)
        print(f"    {name}: N={cur['n']} vs {prev['n']}: phase_bin rel rms "
              f"{item['phase_bin_rel_rms']:.2e} max {item['phase_bin_rel_max']:.2e}; phase_point rel rms "
              f"{item['phase_point_rel_rms']:.2e}  ({time.perf_counter() - t0:.0f}s)", flush=True)
        if item["phase_bin_rel_rms"] <= SIZE_RMS_TARGET or step == 1:
            break
        prev = cur
    th = DTHETA_DEG * np.arange(K)
    history[-1]["phase_bin_rel_rms_by_band_deg"] = {
        f"{a:g}-{b:g}": float(np.sqrt(np.mean(rel[(th >= a) & (th < b)] ** 2)))
        for a, b in ((0, 10), (10, 60), (60, 120), (120, 150), (150, 180.01))}
    target_met = history[-1]["phase_bin_rel_rms"] <= SIZE_RMS_TARGET
    if not target_met:
        warnings.append(f"{name}: size grid capped at N={cur['n']}: phase_bin rel rms N vs (N+1)/2 = "
                        f"{history[-1]['phase_bin_rel_rms']:.2e} > target {SIZE_RMS_TARGET:g}")
        print("WARNING:", warnings[-1], flush=True)

    chk = curve_checks(name, cur["phase_bin"], st["ang"], cur["g"], cur["g_quad"], fails)
    chk["angular_check_radii"] = 17
    chk["kernel_vs_miepython_max_rel"] = st["kern"]
    chk["kernel_vs_miepython_max_rel_to_max"] = st["kern_max"]
    chk["size_convergence"] = history
    chk["size_target_met"] = target_met
    chk["max_radii_allowed"] = n_max
    chk["gl_nodes_per_bin_max"] = st["nodes_max"]
    chk["bin0_subintervals_max"] = st["spole_max"]
    # fraction of the untruncated number and Csca (~ r^2) weighted distributions that is cut off
    z = TRUNC_SIGMAS
    zs = 2.0 * ln_s  # r^2 weighting shifts the mean of ln r by 2 ln^2 s_g = 2 ln s_g standard deviations
    chk["truncated_fraction_number"] = math.erfc(z / math.sqrt(2))
    chk["truncated_fraction_r2_weighted"] = 0.5 * (math.erfc((z - zs) / math.sqrt(2))
                                                   + math.erfc((z + zs) / math.sqrt(2)))
    if label == "drizzle":
        rainbow_check(name, cur["phase_bin"], m_re, chk, fails)
    case = {
        "name": name, "kind": "lognormal", "wavelength_nm": wl_nm, "m_re": m_re, "m_im": m_im,
        "median_radius_um": r_g, "sigma_g": s_g,
        "truncation": f"ln r in [ln r_g - {TRUNC_SIGMAS:g} ln sigma_g, ln r_g + {TRUNC_SIGMAS:g} ln sigma_g]",
        "radius_min_um": math.exp(lo), "radius_max_um": math.exp(hi),
        "n_radii": cur["n"], "size_quadrature": "trapezoid, uniform in ln r, both ends included",
        "qext": cur["qext"], "qsca": cur["qsca"], "g": cur["g"],
        "checks": chk,
        "phase_bin": [sig(v) for v in cur["phase_bin"]],
        "phase_point": [sig(v) for v in cur["phase_point"]],
    }
    summary(name, f"N={cur['n']} r={math.exp(lo):.3f}..{math.exp(hi):.3f}um qext={cur['qext']:.7f} "
            f"qsca={cur['qsca']:.7f} g={cur['g']:.7f}", chk,
            f" size-rms={history[-1]['phase_bin_rel_rms']:.1e}", t0)
    return case


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help=f"output file (default {OUT})")
    ap.add_argument("--max-radii", action="append", default=[], metavar="LABEL=N",
                    help="largest size grid for a distribution, N = 64*2^j + 1 (defaults: "
                         + ", ".join(f"{l}={n}" for l, _, _, n in LOGNORMALS) + ")")
    ap.add_argument("--only", default=None,
                    help="comma-separated name substrings (e.g. 'sphere_r1000um,cloud'); for trials: "
                         "nothing is written unless --out is given")
    args = ap.parse_args()
    only = args.only.split(",") if args.only else None
    if args.out is None and only is None:
        args.out = OUT

    def wanted(name):
        return only is None or any(o in name for o in only)

    if not miepython.USE_JIT:
        raise SystemExit("miepython JIT not active")
    t_start = time.perf_counter()
    water = load_water()
    caps = {l: n for l, _, _, n in LOGNORMALS}
    for item in args.max_radii:
        l, n = item.split("=")
        if l not in caps:
            raise SystemExit(f"unknown distribution {l}")
        caps[l] = int(n)
        radii_doublings(l, caps[l])  # refuse a bad cap now, not hours into the run
    fails = []
    warnings = []
    cases = []
    index = {}
    for wl in WAVELENGTHS_NM:
        index[wl] = water_index(wl, water)
    for wl in WAVELENGTHS_NM:
        m_re, m_im = index[wl]
        for r in SPHERE_RADII_UM:
            if wanted(f"sphere_r{r:g}um_{wl:.0f}nm"):
                cases.append(sphere_case(r, wl, m_re, m_im, fails))
    for label, r_g, s_g, _ in LOGNORMALS:
        for wl in WAVELENGTHS_NM:
            m_re, m_im = index[wl]
            if wanted(f"{label}_lognormal_{wl:.0f}nm"):
                cases.append(lognormal_case(label, r_g, s_g, caps[label], wl, m_re, m_im, fails, warnings))
    runtime = time.perf_counter() - t_start

    def worst(key):
        return max(abs(c["checks"][key]) for c in cases)

    checks = {
        "tolerances": TOL,
        "size_rms_target": SIZE_RMS_TARGET,
        "max_abs_sum_phase_bin_dOmega_minus_1": worst("sum_phase_bin_dOmega_minus_1"),
        "max_angular_L1_vs_L2_rel": worst("angular_L1_vs_L2_max_rel"),
        "max_abs_g_quadrature_minus_g": worst("g_quadrature_minus_g"),
        "max_abs_g_bins_minus_g": worst("g_bins_minus_g"),
        "max_kernel_vs_miepython_rel": worst("kernel_vs_miepython_max_rel"),
        "lognormal_size_convergence": {
            c["name"]: c["checks"]["size_convergence"][-1] for c in cases if c["kind"] == "lognormal"},
        "rainbow": {c["name"]: {k: c["checks"][k] for k in ("rainbow_max_deg", "descartes_deg",
                                                             "rainbow_minus_descartes_deg")}
                    for c in cases if "rainbow_max_deg" in c["checks"]},
        "refractive_index": {f"{wl:.0f}": {"m_re": index[wl][0], "m_im": index[wl][1]} for wl in WAVELENGTHS_NM},
        "runtime_s": round(runtime, 1),
        "failures": fails,
        "warnings": warnings,
    }
    doc = {
        "generator": "data/reference/generate_mieplot_curves.py",
        "versions": {"python": platform.python_version(), "miepython": miepython.__version__,
                     "numba": numba.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
                     "miepython_jit": bool(miepython.USE_JIT)},
        "convention": (
            "m = m_re + i*m_im, m_im >= 0 absorbing (Bohren & Huffman); miepython called with m_re - i*m_im. "
            "Water index: linear interpolation in wavelength of n and k in "
            "mie/data/refractive_index/water_segelstein1981.csv. x = 2 pi r / lambda. "
            "p(theta) = (|S1|^2 + |S2|^2) / (2 pi x^2 Qsca) in 1/sr, integral over 4 pi = 1. "
            "phase_bin[k] = (1/dOmega_k) * integral of p dOmega over bin k (solid-angle average); "
            "phase_point[k] = p(theta_k). Lognormal: n(r) dr ~ (1/r) exp(-(ln r - ln r_g)^2/(2 ln^2 sigma_g)) dr, "
            "truncated at |ln r - ln r_g| <= 4 ln sigma_g, trapezoid in ln r; mixture weighted by Csca: "
            "p = sum c_i Csca_i p_i / sum c_i Csca_i; qext, qsca area-weighted (sum c Cext / sum c pi r^2); "
            "g = sum c Csca g / sum c Csca. Sphere qext, qsca, g from miepython.efficiencies_mx."),
        "grid": {
            "n_angles": K,
            "theta_deg": "theta_k = 0.18*k, k = 0..1000",
            "bins": "bin k = [theta_k - 0.09, theta_k + 0.09] deg clipped to [0, 180]; bins 0 and 1000 are half width",
            "solid_angle": "dOmega_k = 2 pi (cos lo_k - cos hi_k)",
            "bin_quadrature": ("Gauss-Legendre in mu per bin, 2*n_base nodes, n_base = 2*ceil(x*0.18deg/pi + 8) "
                               "(>= 16); bins 1,2,998,999 split in 4 and bins 0,1000 in 2*max(2, n_base/2-8) "
                               "sub-intervals uniform in theta; check against half the nodes and sub-intervals"),
            "solid_angle_sr": [float(v) for v in DOMEGA],
        },
        "checks": checks,
        "cases": cases,
    }
    if args.out is None:
        print(f"trial run ({runtime:.1f} s), {len(fails)} failure(s); nothing written")
        for f in fails:
            print("FAIL:", f, file=sys.stderr)
        return
    if fails:
        for f in fails:
            print("FAIL:", f, file=sys.stderr)
        bad = args.out + ".failed"
        with open(bad, "w") as fh:
            json.dump(doc, fh, separators=(",", ":"))
        raise SystemExit(f"{len(fails)} check(s) failed; wrote {bad} for inspection, not {args.out}")
    with open(args.out, "w") as fh:
        json.dump(doc, fh, separators=(",", ":"))
        fh.write("\n")
    print(f"wrote {args.out}: {len(cases)} curves, {os.path.getsize(args.out)} bytes, {runtime:.1f} s")


if __name__ == "__main__":
    main()
