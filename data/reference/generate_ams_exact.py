#!/usr/bin/env python3
"""Exact Ams_n bin averages of a cloud-droplet phase function: the reference for the j >= 2
terms of photometeor's Ams_n (tables/tests/ams_exact.rs; docs/accuracy.md).

    python3 -m pip install miepython==3.3.0 numpy
    python3 data/reference/generate_ams_exact.py     # ~30 min on one core; writes data/reference/ams_exact_cloud.csv

Nothing here comes from photometeor. The phase function P is a cloud's: water spheres with a
gamma distribution of radii (r_eff = 10 um, v_eff = 0.1: n(r) ~ r^7 e^{-r/1 um}, the default
scene's cloud), at 450 nm (the default scene's narrowest diffraction lobe, and the channel with
the largest bias the preset study reported), m = 1.3374 (water near 10 C; any m would do: what is
tested is the convolution, and both sides use this one P). Its amplitudes come from miepython
(Bohren & Huffman's series; miepython takes m = n - i k, so the real m is passed as is).

1. P(theta) is evaluated at Gauss-Legendre nodes, 12 per half-bin panel of the 0.18 deg grid
   (the panels end on the bin edges, (k +- 1/2) 0.18 deg), summed over 480 radii from 0.5 to
   45 um (trapezoid in r; the weights are the number density times nothing else: the
   intensity |S1|^2 + |S2|^2 already carries the cross-section), and normalised so that
   integral P dOmega = 1.
2. Bin averages of P over each bin's solid angle by the same quadrature: Ams_1 exactly.
3. chi_l = 2 pi integral P P_l dmu for l = 0..L by the same quadrature (L = 4000; chi_L is below
   1e-12 of chi_0 for this P).
4. Ams_n = sum_l (2l+1)/(4 pi) chi_l^n P_l: the n-fold spherical convolution by Funk-Hecke,
   exact; its bin averages use the exact bin integrals of P_l,
   integral_{mu_a}^{mu_b} P_l dmu = [P_{l+1} - P_{l-1}]_{mu_a}^{mu_b} / (2l + 1).
   The same series at n = 1 reproduces step 2's bins (the check printed and written in the
   header), which bounds the truncation and quadrature error of the chi_l.

Output: a header of '#' lines (this description, the parameters, the check), then one row per
bin k = 0..1000: theta_deg, then Ams_n bin averages (1/sr) for n = 1 (step 2), 2, 3, 4, 6, 8, 12,
16, 26, written with 17 significant digits.
"""

import os
import sys

import miepython
import numpy as np

STEP_DEG = 0.18
K = int(round(180 / STEP_DEG)) + 1
NODES_PER_PANEL = 12
WAVELENGTH_UM = 0.45
M = 1.3374
R_EFF_UM, V_EFF = 10.0, 0.1
RADII = np.linspace(0.5, 45.0, 480)
L_MAX = 4000
ORDERS = [2, 3, 4, 6, 8, 12, 16, 26]
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "ams_exact_cloud.csv")


def edges_rad():
    """The K + 1 bin edges: 0, step/2, 3 step/2, ..., 180 - step/2, 180 degrees."""
    e = [0.0] + [(k + 0.5) * STEP_DEG for k in range(K - 1)] + [180.0]
    return np.radians(np.array(e))


def nodes():
    """Gauss-Legendre nodes in theta, NODES_PER_PANEL per half-bin panel, with weights of
    integral f dmu = integral f sin(theta) dtheta, and the bin each node lies in."""
    e = edges_rad()
    panels = []
    for k in range(K):
        a, b = e[k], e[k + 1]
        mid = 0.5 * (a + b)
        for lo, hi in ((a, mid), (mid, b)):
            panels.append((lo, hi, k))
    x, w = np.polynomial.legendre.leggauss(NODES_PER_PANEL)
    theta, weight, which = [], [], []
    for lo, hi, k in panels:
        t = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
        theta.append(t)
        weight.append(0.5 * (hi - lo) * w * np.sin(t))
        which.append(np.full(NODES_PER_PANEL, k))
    return np.concatenate(theta), np.concatenate(weight), np.concatenate(which)


def phase(theta):
    """P(theta) of the gamma distribution, unnormalised."""
    mu = np.cos(theta)
    alpha = 1.0 / V_EFF - 3.0
    b = 1.0 / (R_EFF_UM * V_EFF)
    n_r = RADII**alpha * np.exp(-b * RADII)
    dr = np.gradient(RADII)
    trap = n_r * dr
    trap[0] *= 0.5
    trap[-1] *= 0.5
    total = np.zeros_like(mu)
    for r, w in zip(RADII, trap):
        x = 2 * np.pi * r / WAVELENGTH_UM
        s1, s2 = miepython.S1_S2(complex(M, 0.0), x, mu, norm="bohren")
        total += w * (np.abs(s1) ** 2 + np.abs(s2) ** 2)
    return total


def legendre_rows(mu, l_max):
    """P_0..P_{l_max}(mu) row by row (a generator), by the three-term recurrence."""
    p_prev, p = np.ones_like(mu), mu.copy()
    yield p_prev
    yield p
    for l in range(1, l_max):
        p_prev, p = p, ((2 * l + 1) * mu * p - l * p_prev) / (l + 1)
        yield p


def main():
    theta, weight, which = nodes()
    mu = np.cos(theta)
    p = phase(theta)
    p /= 2 * np.pi * np.sum(p * weight)  # integral P dOmega = 1
    e = edges_rad()
    mu_edge = np.cos(e)
    d_mu = mu_edge[:-1] - mu_edge[1:]
    ams1 = np.bincount(which, weights=p * weight, minlength=K) / d_mu

    # chi_l and the exact bin integrals of P_l, degree by degree.
    rows = {n: np.zeros(K) for n in [1] + ORDERS}
    p_edge = list(legendre_rows(mu_edge, L_MAX + 1))
    chi0 = None
    chi_last = 0.0
    for l, pl in enumerate(legendre_rows(mu, L_MAX)):
        chi = 2 * np.pi * np.sum(p * pl * weight)
        if chi0 is None:
            chi0 = chi
        chi_last = chi
        upper = p_edge[l + 1] - (p_edge[l - 1] if l > 0 else np.ones_like(mu_edge))
        if l == 0:
            integral = mu_edge[:-1] - mu_edge[1:]
        else:
            integral = (upper[:-1] - upper[1:]) / (2 * l + 1)
        for n, row in rows.items():
            row += (2 * l + 1) / (4 * np.pi) * chi**n * integral / d_mu
    check = np.max(np.abs(rows[1] / ams1 - 1))
    print(f"chi_0 = {chi0:.15f}, |chi_L| = {abs(chi_last):.2e}; series n = 1 vs bins: {check:.2e}")
    if check > 1e-8:
        sys.exit("the Legendre series does not reproduce the bins: raise L_MAX or the nodes")

    header = [line.rstrip() for line in __doc__.strip().splitlines()]
    header += [
        "",
        f"miepython {miepython.__version__}, numpy {np.__version__}, Python {sys.version.split()[0]}",
        f"chi_0 = {chi0:.15f}; |chi_L| = {abs(chi_last):.2e} at L = {L_MAX}",
        f"check: the series at n = 1 against the bins, worst relative difference {check:.2e}",
        "columns: theta_deg, ams1, " + ", ".join(f"ams{n}" for n in ORDERS),
    ]
    with open(OUT, "w", encoding="utf-8") as f:
        for line in header:
            f.write(("# " + line).rstrip() + "\n")
        for k in range(K):
            values = [ams1[k]] + [rows[n][k] for n in ORDERS]
            f.write(f"{k * STEP_DEG:.2f}," + ",".join(f"{v:.17g}" for v in values) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
