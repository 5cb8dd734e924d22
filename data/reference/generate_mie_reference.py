#!/usr/bin/env python3
"""Generate Mie-scattering reference data for photometeor with the independent solver miepython.

Output: ``data/reference/mie_miepython.json`` (next to this script).

Package versions used to produce the committed file
---------------------------------------------------
Python 3.11.7, miepython 3.3.0 (numba JIT path, MIEPYTHON_USE_JIT=1), numba 0.68.1,
numpy 2.4.6, scipy 1.17.1 (Gauss-Legendre nodes for the checks only).
The exact versions of the run are also written into the JSON file.

Conventions in the JSON file (photometeor's, Bohren & Huffman 1983)
--------------------------------------------------------------------
* Refractive index m = m_re + i*m_im with m_im >= 0 meaning absorbing.
  miepython (like Wiscombe's MIEV0) uses m = n - i*kappa, so this script calls
  miepython with ``complex(m_re, -m_im)``.  (miepython would silently conjugate a
  positive imaginary part itself; we do not rely on that.)
* x = 2*pi*r/lambda.  Angles theta in degrees, 0 = forward; mu = cos(theta).
* s1, s2: the Bohren & Huffman amplitude functions, UNnormalized:
      S1 = sum (2n+1)/(n(n+1)) (a_n pi_n + b_n tau_n)
      S2 = sum (2n+1)/(n(n+1)) (a_n tau_n + b_n pi_n)
  with B&H a_n, b_n (m = n + i kappa, time factor exp(-i omega t)), so that the
  optical theorem reads Re S1(0) = Re S2(0) = x^2 Qext / 4 and Im a_1 < 0 for a
  small dielectric sphere.
  miepython.S1_S2(m, x, mu, norm='wiscombe') is unnormalized (its normalization
  factor is exactly 1; 'bohren' divides by 1/2, i.e. doubles S) but it returns the
  COMPLEX CONJUGATE of the B&H amplitudes: its kernel sums with the B&H a_n, b_n and
  then conjugates the sums (``return np.conjugate(S1), np.conjugate(S2)``).  This
  script therefore stores conj(S_miepython).  This is verified at run time against
  an independent B&H-style implementation (``bh_reference`` below), and the run
  aborts if the sign check fails.
* qext, qsca, qback, g: miepython.efficiencies_mx.  qback is the radar convention
  |sum (2n+1)(-1)^n (a_n - b_n)|^2 / x^2 = 4 |S1(180 deg)|^2 / x^2 (checked).
* phase: p(theta) = (|S1|^2 + |S2|^2) / (2 pi x^2 qsca), 1/sr, integral over 4 pi = 1.
* Floats are written with full precision (Python repr).

Checks run for every case (results stored per case under "checks")
------------------------------------------------------------------
* optical theorem: Re S1(0) vs x^2 Qext/4, and S1(0) == S2(0);
* qback vs 4|S1(180)|^2/x^2;
* normalization: integral of p over 4 pi by Gauss-Legendre in mu with
  N_stop + 2 nodes (exact for the degree-2 N_stop polynomial |S|^2), and g from
  the same quadrature; done for x <= 3e4 (x = 1e5 only with --gl-1e5, ~5+ min).
  Its accuracy is limited by double-precision mu near mu = 1 (the forward peak is
  ~1/x^2 wide in mu): ~1e-9 at x = 1e3 for any node set, growing ~x^2;
* norm consistency: S(norm='one') * x sqrt(pi qsca) == S(norm='wiscombe');
* an independent implementation (Bohren & Huffman BHMIE algorithm: D_n by downward
  recurrence started from 0 far above max(N, |mx|), psi/chi by upward recurrence,
  written here in numba) at the case's angles: relative differences of
  qext, qsca, qback, g and of S1, S2;
* Wiscombe MIEV0 published values (docs/physics.md table) where a case coincides.
A case whose checks fail the tolerances in ``TOL`` is dropped and listed in "notes".

Run:  python3 data/reference/generate_mie_reference.py [--gl-1e5]
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
OUT = os.path.join(HERE, "mie_miepython.json")

# ---------------------------------------------------------------------------------
# cases (our convention: m_im >= 0 absorbing)
M_LIST = [(1.333, 1e-8), (1.33, 1e-5), (1.5, 0.1), (1.5, 1.0), (0.75, 0.0), (2.5, 0.5)]
X_LIST = [0.2, 1.0, 5.213, 10.0, 100.0, 1000.0, 1e4]
X_EXTRA = {(1.333, 1e-8): [3e4, 1e5], (1.5, 0.1): [3e4, 1e5]}
FULL_GRID = [((1.333, 1e-8), 1000.0), ((1.333, 1e-8), 1e4)]

SPARSE_ANGLES = [0.0, 0.18, 0.5, 1.0, 2.0, 5.0] + [float(a) for a in range(10, 171, 10)] + [
    175.0, 178.0, 179.0, 179.82, 180.0]
FULL_ANGLES = [round(0.18 * i, 2) for i in range(1001)]  # 0, 0.18, ..., 180 exactly

# Wiscombe MIEV0 test values (docs/physics.md §2; Wiscombe sign m = n - i k, here in ours)
WISCOMBE = {
    (0.75, 0.0, 10.0): (2.232265e00, 2.232265e00, 2.001164e00),
    (0.75, 0.0, 1000.0): (1.997908e00, 1.997908e00, 1.688121e00),
    (1.33, 1e-5, 1.0): (9.395198e-02, 9.392330e-02, 1.733048e-02),
    (1.33, 1e-5, 100.0): (2.101321e00, 2.096594e00, 1.821854e00),
    (1.33, 1e-5, 1e4): (2.004089e00, 1.723857e00, 1.564987e00),
    (1.5, 1.0, 1.0): (2.336321e00, 6.634538e-01, 1.274736e-01),
    (1.5, 1.0, 100.0): (2.097502e00, 1.283697e00, 1.091466e00),
    (1.5, 1.0, 1e4): (2.004368e00, 1.236574e00, 1.046525e00),
}

# acceptance tolerances (relative)
TOL = {
    "optical_theorem": 1e-10,
    "qback_vs_s1": 1e-8,
    # Gauss-Legendre in mu: limited by double-precision mu near mu = 1, where the forward
    # peak is only ~1/x^2 wide in mu (scipy vs numpy nodes differ by 4e-9 at x = 1e3);
    # tolerance = gl_norm_base + gl_norm_x2 * x^2, for the integral and for g alike
    "gl_norm_base": 1e-11,
    "gl_norm_x2": 1e-13,
    "indep_q": 1e-6,      # qext, qsca, g; qback compared separately (cancellation)
    "indep_qback": 1e-5,
    "indep_s": 1e-5,      # |S - S_indep| / max|S| over the case's angles
    "wiscombe": 2e-6,     # table has 7 significant digits
}


def n_stop(x):
    """Wiscombe's number of terms, as used by miepython."""
    return int(x + 4.05 * x ** 0.33333 + 2.0)


# ---------------------------------------------------------------------------------
# independent implementation (Bohren & Huffman BHMIE algorithm, B&H sign m = n + ik)
@njit(cache=True)
def _bh_coefficients(m, x, nstop):
    y = m * x
    ay = abs(y)
    # downward D_n from D = 0, started far above max(N, |mx|) (docs/physics.md §2)
    nmx = int(max(float(nstop), ay) + 30.0 + 12.0 * ay ** (1.0 / 3.0))
    d = np.zeros(nmx + 1, dtype=np.complex128)
    for n in range(nmx, 1, -1):
        en = n / y
        d[n - 1] = en - 1.0 / (d[n] + en)
    a = np.zeros(nstop, dtype=np.complex128)
    b = np.zeros(nstop, dtype=np.complex128)
    psi0 = math.cos(x)
    psi1 = math.sin(x)
    chi0 = -math.sin(x)
    chi1 = math.cos(x)
    xi1 = complex(psi1, -chi1)
    for n in range(1, nstop + 1):
        psi = (2.0 * n - 1.0) * psi1 / x - psi0
        chi = (2.0 * n - 1.0) * chi1 / x - chi0
        xi = complex(psi, -chi)
        t = d[n] / m + n / x
        a[n - 1] = (t * psi - psi1) / (t * xi - xi1)
        t = m * d[n] + n / x
        b[n - 1] = (t * psi - psi1) / (t * xi - xi1)
        psi0 = psi1
        psi1 = psi
        chi0 = chi1
        chi1 = chi
        xi1 = complex(psi1, -chi1)
    return a, b


@njit(cache=True)
def _bh_amplitudes(a, b, mu):
    nang = mu.shape[0]
    s1 = np.zeros(nang, dtype=np.complex128)
    s2 = np.zeros(nang, dtype=np.complex128)
    for k in range(nang):
        u = mu[k]
        p0 = 0.0
        p1 = 1.0
        acc1 = 0.0 + 0.0j
        acc2 = 0.0 + 0.0j
        for n in range(1, a.shape[0] + 1):
            tau = n * u * p1 - (n + 1.0) * p0
            fn = (2.0 * n + 1.0) / (n * (n + 1.0))
            acc1 += fn * (a[n - 1] * p1 + b[n - 1] * tau)
            acc2 += fn * (a[n - 1] * tau + b[n - 1] * p1)
            p2 = ((2.0 * n + 1.0) * u * p1 - (n + 1.0) * p0) / n
            p0 = p1
            p1 = p2
        s1[k] = acc1
        s2[k] = acc2
    return s1, s2


def bh_reference(m_ours, x, mu):
    """Independent B&H-convention result: (qext, qsca, qback, g, S1, S2)."""
    N = n_stop(x)
    a, b = _bh_coefficients(complex(m_ours), float(x), N)
    n = np.arange(1, N + 1, dtype=float)
    x2 = x * x
    qext = 2.0 / x2 * math.fsum((2 * n + 1) * (a.real + b.real))
    qsca = 2.0 / x2 * math.fsum((2 * n + 1) * (abs(a) ** 2 + abs(b) ** 2))
    sgn = np.where(n % 2 == 1, -1.0, 1.0)
    terms = sgn * (2 * n + 1) * (a - b)
    qback = abs(complex(math.fsum(terms.real), math.fsum(terms.imag))) ** 2 / x2
    c1 = n[:-1] * (n[:-1] + 2) / (n[:-1] + 1)
    c2 = (2 * n + 1) / (n * (n + 1))
    gq = math.fsum(c1 * (a[:-1] * np.conj(a[1:]) + b[:-1] * np.conj(b[1:])).real)
    gq += math.fsum(c2 * (a * np.conj(b)).real)
    g = 4.0 / x2 * gq / qsca
    s1, s2 = _bh_amplitudes(a, b, np.asarray(mu, dtype=float))
    return qext, qsca, qback, g, s1, s2


# ---------------------------------------------------------------------------------
def mp_index(m_re, m_im):
    """Our m = n + i k (k >= 0)  ->  miepython's m = n - i k."""
    if m_im < 0:
        raise ValueError("m_im must be >= 0 (absorbing) in photometeor's convention")
    return complex(m_re, -m_im)


def mp_amplitudes(m_re, m_im, x, mu, norm="wiscombe"):
    """B&H amplitudes from miepython: conj of S1_S2(norm='wiscombe') (see docstring)."""
    s1, s2 = miepython.S1_S2(mp_index(m_re, m_im), x, np.asarray(mu, dtype=float), norm=norm)
    return np.conj(s1), np.conj(s2)


def angles_to_mu(angles_deg):
    mu = np.cos(np.radians(np.asarray(angles_deg, dtype=float)))
    mu[np.asarray(angles_deg) == 0.0] = 1.0
    mu[np.asarray(angles_deg) == 180.0] = -1.0
    mu[np.asarray(angles_deg) == 90.0] = 0.0
    return mu


_GL_CACHE = {}


def gl_nodes(K):
    if K not in _GL_CACHE:
        _GL_CACHE.clear()
        _GL_CACHE[K] = roots_legendre(K)
    return _GL_CACHE[K]


def rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


def verify_conjugation():
    """Decide empirically whether miepython's S1/S2 are B&H or conjugated."""
    out = {}
    mu = angles_to_mu(SPARSE_ANGLES)
    for (mr, mi, x) in [(1.5, 0.1, 5.213), (1.33, 1e-5, 10.0), (2.5, 0.5, 1.0)]:
        s1, s2 = miepython.S1_S2(mp_index(mr, mi), x, mu, norm="wiscombe")
        *_, r1, r2 = bh_reference(complex(mr, mi), x, mu)
        scale = np.max(np.abs(r1))
        d_same = np.max(np.abs(s1 - r1)) / scale
        d_conj = np.max(np.abs(np.conj(s1) - r1)) / scale
        out[f"m={mr}+{mi}i x={x}"] = (d_same, d_conj)
        if not (d_conj < 1e-8 and d_same > 1e-3):
            raise SystemExit(f"conjugation check failed: {out}")
    # B&H small-sphere sign: Im a_1 < 0 for a dielectric sphere with m = n + ik
    a, b = miepython.coefficients(mp_index(1.5, 0.0), 0.1)
    ab, _ = _bh_coefficients(complex(1.5, 0.0), 0.1, n_stop(0.1))
    out["a1_miepython"] = complex(a[0])
    out["a1_indep"] = complex(ab[0])
    return out


def run_case(m_re, m_im, x, angles, grid_name, gl_1e5):
    t0 = time.time()
    mm = mp_index(m_re, m_im)
    qext, qsca, qback, g = (float(v) for v in miepython.efficiencies_mx(mm, x))
    mu = angles_to_mu(angles)
    s1, s2 = mp_amplitudes(m_re, m_im, x, mu)
    phase = (np.abs(s1) ** 2 + np.abs(s2) ** 2) / (2 * math.pi * x * x * qsca)

    chk = {}
    fails = []
    # optical theorem (angles[0] == 0)
    assert angles[0] == 0.0 and angles[-1] == 180.0
    ot = x * x * qext / 4
    chk["optical_theorem_rel"] = rel(s1[0].real, ot)
    chk["s1_s2_forward_rel"] = abs(s1[0] - s2[0]) / abs(s1[0])
    if chk["optical_theorem_rel"] > TOL["optical_theorem"] or chk["s1_s2_forward_rel"] > 1e-12:
        fails.append("optical theorem")
    chk["qback_vs_4|S1(180)|^2/x^2_rel"] = rel(4 * abs(s1[-1]) ** 2 / (x * x), qback)
    if chk["qback_vs_4|S1(180)|^2/x^2_rel"] > TOL["qback_vs_s1"]:
        fails.append("qback vs S1(180)")
    # norm consistency ('one' -> unit integral)
    s1o, _ = miepython.S1_S2(mm, x, mu[:3], norm="one")
    chk["norm_one_consistency_rel"] = float(
        np.max(np.abs(np.conj(s1o) * x * math.sqrt(math.pi * qsca) - s1[:3])) / np.max(np.abs(s1[:3])))
    # Gauss-Legendre normalization and g
    if x <= 3.1e4 or gl_1e5:
        K = n_stop(x) + 2
        nodes, w = gl_nodes(K)
        q1, q2 = miepython.S1_S2(mm, x, nodes, norm="wiscombe")
        f = np.abs(q1) ** 2 + np.abs(q2) ** 2
        integ = 2 * math.pi * math.fsum(w * f) / (2 * math.pi * x * x * qsca)
        gg = 2 * math.pi * math.fsum(w * f * nodes) / (2 * math.pi * x * x * qsca)
        chk["gl_nodes"] = K
        chk["integral_p_dOmega_minus_1"] = integ - 1.0
        chk["g_from_quadrature_rel"] = rel(gg, g) if g != 0 else abs(gg)
        tol_gl = TOL["gl_norm_base"] + TOL["gl_norm_x2"] * x * x
        if abs(integ - 1) > tol_gl:
            fails.append("integral of p")
        if chk["g_from_quadrature_rel"] > tol_gl and abs(gg - g) > 1e-10:
            fails.append("g from quadrature")
    # independent implementation
    ie, is_, ib, ig, r1, r2 = bh_reference(complex(m_re, m_im), x, mu)
    chk["indep_qext_rel"] = rel(qext, ie)
    chk["indep_qsca_rel"] = rel(qsca, is_)
    chk["indep_qback_rel"] = rel(qback, ib)
    chk["indep_g_abs"] = abs(g - ig)
    sc = max(np.max(np.abs(r1)), np.max(np.abs(r2)))
    chk["indep_s_rel_to_max"] = float(max(np.max(np.abs(s1 - r1)), np.max(np.abs(s2 - r2))) / sc)
    chk["indep_phase_pointwise_max_rel"] = float(np.max(
        np.abs((np.abs(r1) ** 2 + np.abs(r2) ** 2) - (np.abs(s1) ** 2 + np.abs(s2) ** 2))
        / (np.abs(r1) ** 2 + np.abs(r2) ** 2)))
    if max(chk["indep_qext_rel"], chk["indep_qsca_rel"], chk["indep_g_abs"]) > TOL["indep_q"]:
        fails.append("independent qext/qsca/g")
    if chk["indep_qback_rel"] > TOL["indep_qback"]:
        fails.append("independent qback")
    if chk["indep_s_rel_to_max"] > TOL["indep_s"]:
        fails.append("independent S1/S2")
    key = (m_re, m_im, x)
    if key in WISCOMBE:
        we, ws, wg = WISCOMBE[key]
        chk["wiscombe_qext_rel"] = rel(qext, we)
        chk["wiscombe_qsca_rel"] = rel(qsca, ws)
        chk["wiscombe_gqsca_rel"] = rel(g * qsca, wg)
        if max(chk["wiscombe_qext_rel"], chk["wiscombe_qsca_rel"], chk["wiscombe_gqsca_rel"]) > TOL["wiscombe"]:
            fails.append("Wiscombe table")
    chk = {k: (float(v) if not isinstance(v, int) else v) for k, v in chk.items()}
    case = {
        "m_re": m_re,
        "m_im": m_im,
        "x": x,
        "grid": grid_name,
        "n_terms": n_stop(x),
        "qext": qext,
        "qsca": qsca,
        "qback": qback,
        "g": g,
        "angles_deg": list(angles),
        "phase": [float(v) for v in phase],
        "s1": [[float(z.real), float(z.imag)] for z in s1],
        "s2": [[float(z.real), float(z.imag)] for z in s2],
        "checks": chk,
    }
    print(f"m={m_re}+{m_im}i x={x:g} {grid_name:6s} qext={qext:.9g} qsca={qsca:.9g} "
          f"qback={qback:.9g} g={g:.9g}  {time.time() - t0:.1f}s  "
          + ("OK" if not fails else "FAIL: " + ", ".join(fails)), file=sys.stderr)
    print("    " + " ".join(f"{k}={v:.2e}" for k, v in chk.items() if isinstance(v, float)), file=sys.stderr)
    return case, fails


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gl-1e5", action="store_true",
                    help="also run the Gauss-Legendre normalization check at x = 1e5 (slow)")
    ap.add_argument("--out", default=OUT)
    args = ap.parse_args()
    if not miepython.USE_JIT:
        raise SystemExit("miepython JIT not active")

    conj = verify_conjugation()
    print("conjugation check (max|S_mp - S_BH|, max|conj(S_mp) - S_BH|)/max|S|:", conj, file=sys.stderr)

    jobs = []
    for (mr, mi) in M_LIST:
        for x in X_LIST + X_EXTRA.get((mr, mi), []):
            jobs.append((mr, mi, x, SPARSE_ANGLES, "sparse"))
    for (mr, mi), x in FULL_GRID:
        jobs.append((mr, mi, x, FULL_ANGLES, "full"))

    cases, notes = [], []
    for mr, mi, x, ang, gname in jobs:
        case, fails = run_case(mr, mi, x, ang, gname, args.gl_1e5)
        if fails:
            notes.append(f"DROPPED m={mr}+{mi}i x={x:g} ({gname}): failed {', '.join(fails)}; "
                         f"checks={case['checks']}")
        else:
            cases.append(case)

    if not args.gl_1e5:
        notes.append("x = 1e5: Gauss-Legendre normalization check not run (needs ~1e5 nodes); "
                     "validated by optical theorem, qback vs S1(180) and the independent implementation.")
    notes.append("Tolerances used to accept a case: " + json.dumps(TOL))
    notes.append("'checks' per case: *_rel = relative difference; indep_* = against an independent "
                 "BHMIE-algorithm implementation in the generator (D_n downward from 0, psi/chi upward); "
                 "indep_phase_pointwise_max_rel can be large only at deep minima of |S|^2.")

    doc = {
        "generator": "data/reference/generate_mie_reference.py",
        "miepython_version": miepython.__version__,
        "versions": {"python": platform.python_version(), "miepython": miepython.__version__,
                     "numba": numba.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
                     "miepython_jit": bool(miepython.USE_JIT)},
        "convention": (
            "m = m_re + i*m_im, m_im >= 0 absorbing (Bohren & Huffman); miepython was called with "
            "m_re - i*m_im. x = 2 pi r / lambda. angles_deg: scattering angle, 0 = forward. "
            "s1, s2: unnormalized Bohren & Huffman amplitudes S1 = sum (2n+1)/(n(n+1)) (a_n pi_n + "
            "b_n tau_n), S2 = sum (2n+1)/(n(n+1)) (a_n tau_n + b_n pi_n), as [re, im]; optical theorem "
            "Re S(0) = x^2 qext / 4. They are the COMPLEX CONJUGATE of miepython.S1_S2(m_re - i m_im, x, "
            "mu, norm='wiscombe') (miepython returns conj of the B&H sums). phase = (|S1|^2 + |S2|^2) / "
            "(2 pi x^2 qsca) in 1/sr, integral over 4 pi = 1. qext, qsca, qback, g from "
            "miepython.efficiencies_mx; qback radar convention |sum (2n+1)(-1)^n (a_n - b_n)|^2 / x^2 "
            "= 4 |S1(180)|^2 / x^2. n_terms = int(x + 4.05 x^0.33333 + 2) (Wiscombe, miepython)."),
        "conjugation_check": {k: (str(v) if isinstance(v, complex) else list(v)) for k, v in conj.items()},
        "notes": notes,
        "cases": cases,
    }
    with open(args.out, "w") as fh:
        json.dump(doc, fh, indent=None, separators=(",", ":"))
        fh.write("\n")
    print(f"wrote {args.out}: {len(cases)} cases, {os.path.getsize(args.out)} bytes; "
          f"{len(notes)} notes", file=sys.stderr)
    for n in notes:
        print("NOTE:", n, file=sys.stderr)


if __name__ == "__main__":
    main()
