#!/usr/bin/env python3
"""A phase-function table written by an independent Mie code, for the `kind = "tabulated"` test.

Writes ``water_reff4um_miepython.csv`` (θ in degrees, then p at 650, 515 and 440 nm, Riley et
al. 2004's R, G, B) and ``water_reff4um_miepython.json`` (the optics miepython gives for the
same droplets: Q_ext and Q_sca per unit geometric cross-section, g, and the extinction
cross-section per particle) next to this file.
Regenerate with

    python3 -m venv /tmp/mvenv && /tmp/mvenv/bin/pip install miepython==3.3.0 numpy
    /tmp/mvenv/bin/python data/reference/tabulated/generate_miepython_table.py

Droplets: water, refractive index 1.333 + 0i at every wavelength (a fixed index keeps the
reference about the table, not about water's dispersion), a gamma distribution of radii
n(r) ∝ r^{(1 − 3v)/v} exp(−r/(r_eff v)) with r_eff = 4 µm and v_eff = 0.1 (a small cloud
droplet population: its ripples average out, its corona, fogbow and glory stay), integrated by
the trapezoid rule on 600 radii from 0.5 to 12 µm. Each column is Σ_i w_i π r_i² p_i / Σ_i w_i
π r_i² with p_i miepython's unpolarized intensity at norm = "qsca": its integral over the sphere
is the population's Q_sca (about 2), deliberately not 1, so that the bake must find the
normalization and report it. θ from 0 to 180° every 0.05° (3 601 rows): fine next to the
features (the forward lobe is about 1/x ≈ 1° wide at x ≈ 57).
"""

import json
import os

import miepython
import numpy as np

R_EFF_UM = 4.0
V_EFF = 0.1
RADII_UM = np.linspace(0.5, 12.0, 600)
M = complex(1.333, 0.0)
WAVELENGTHS_NM = [650.0, 515.0, 440.0]
STEP_DEG = 0.05

here = os.path.dirname(os.path.abspath(__file__))
theta = np.linspace(0.0, 180.0, int(round(180.0 / STEP_DEG)) + 1)
mu = np.cos(np.radians(theta))
# Trapezoid weights times the gamma density (its normalization cancels).
trapezoid = np.full(RADII_UM.size, RADII_UM[1] - RADII_UM[0])
trapezoid[[0, -1]] *= 0.5
number = trapezoid * RADII_UM ** ((1 - 3 * V_EFF) / V_EFF) * np.exp(-RADII_UM / (R_EFF_UM * V_EFF))
area_um2 = np.pi * RADII_UM ** 2
columns, optics = [], []
for lam in WAVELENGTHS_NM:
    p = np.zeros_like(theta)
    ext = sca = sca_g = 0.0
    for r, n, a in zip(RADII_UM, number, area_um2):
        x = 2 * np.pi * r * 1e3 / lam
        qext, qsca, qback, g = miepython.efficiencies_mx(M, x)
        p += n * a * miepython.i_unpolarized(M, x, mu, norm="qsca")
        ext += n * a * qext
        sca += n * a * qsca
        sca_g += n * a * qsca * g
    area = float(np.sum(number * area_um2))
    columns.append(p / area)
    optics.append({
        "wavelength_nm": lam,
        "q_ext": ext / area,
        "q_sca": sca / area,
        "g": sca_g / sca,
        "extinction_m2": ext / float(np.sum(number)) * 1e-12,
    })

with open(os.path.join(here, "water_reff4um_miepython.csv"), "w") as f:
    f.write("theta_deg,p_650nm,p_515nm,p_440nm\n")
    for i, t in enumerate(theta):
        f.write("%.2f,%s\n" % (t, ",".join("%.10e" % c[i] for c in columns)))
with open(os.path.join(here, "water_reff4um_miepython.json"), "w") as f:
    json.dump({
        "generator": "generate_miepython_table.py",
        "software": "miepython %s, numpy %s" % (miepython.__version__, np.__version__),
        "distribution": {"kind": "gamma", "r_eff_um": R_EFF_UM, "v_eff": V_EFF,
                         "radii_um": [RADII_UM[0], RADII_UM[-1], RADII_UM.size]},
        "refractive_index": [M.real, M.imag],
        "norm": "qsca (the table integrates to Q_sca over the sphere)",
        "step_deg": STEP_DEG,
        "channels": optics,
    }, f, indent=1)
    f.write("\n")
print(json.dumps(optics, indent=1))
