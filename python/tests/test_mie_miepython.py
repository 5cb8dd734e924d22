"""photometeor.mie against miepython, an independent Mie code, on the cases the Rust suite uses
(mie/tests/miepython.rs, data/reference/generate_mie_reference.py): m in {1.333+1e-8i,
1.33+1e-5i, 1.5+0.1i, 1.5+1i, 0.75, 2.5+0.5i} × x in {0.2, 1, 5.213, 10, 100, 1000, 1e4}, plus
x = 3e4 and 1e5 for 1.333+1e-8i and 1.5+0.1i, at 28 angles from 0° to 180°, and the full
0.18° grid (1001 angles) for 1.333+1e-8i at x = 1e3 and 1e4. miepython runs live here.

Conversions (miepython 3.x):
- its refractive index is m = n − iκ: photometeor's n + iκ is passed as its conjugate;
- ``S1_S2(m, x, mu, norm='wiscombe')`` is unnormalized, like ours, but returns the complex
  conjugate of Bohren & Huffman's amplitudes (its kernel conjugates the sums), so our s1 is
  compared with conj(its S1);
- our ``phase`` p = (|S1|² + |S2|²)/(2π x² Q_sca), ∫ p dΩ = 1, is its
  ``i_unpolarized(m, x, mu, norm='one')``;
- ``efficiencies_mx`` gives Q_ext, Q_sca, Q_back (radar convention 4|S1(180°)|²/x², ours too)
  and g.
"""

from __future__ import annotations

import math

import miepython
import numpy as np
import pytest

import photometeor

M_LIST = [1.333 + 1e-8j, 1.33 + 1e-5j, 1.5 + 0.1j, 1.5 + 1.0j, 0.75 + 0j, 2.5 + 0.5j]
X_LIST = [0.2, 1.0, 5.213, 10.0, 100.0, 1000.0, 1e4]
X_EXTRA = {1.333 + 1e-8j: [3e4, 1e5], 1.5 + 0.1j: [3e4, 1e5]}
SPARSE_ANGLES = [0.0, 0.18, 0.5, 1.0, 2.0, 5.0] + [float(a) for a in range(10, 171, 10)] + [
    175.0,
    178.0,
    179.0,
    179.82,
    180.0,
]
CASES = [(m, x) for m in M_LIST for x in X_LIST] + [(m, x) for m, xs in X_EXTRA.items() for x in xs]


def cosines(angles_deg):
    """cos θ as photometeor folds it (θ > 90° as −cos(180° − θ)), so both codes see one μ."""
    a = np.asarray(angles_deg, dtype=float)
    mu = np.where(a > 90.0, -np.cos(np.radians(180.0 - a)), np.cos(np.radians(a)))
    return np.where(a == 90.0, 0.0, mu)


def miepython_case(m: complex, x: float, angles_deg):
    """miepython's results in photometeor's conventions."""
    m_mp = m.conjugate()
    mu = cosines(angles_deg)
    qext, qsca, qback, g = miepython.efficiencies_mx(m_mp, x)
    s1, s2 = miepython.S1_S2(m_mp, x, mu, norm="wiscombe")
    phase = miepython.i_unpolarized(m_mp, x, mu, norm="one")
    return dict(qext=qext, qsca=qsca, qback=qback, g=g, s1=np.conj(s1), s2=np.conj(s2), phase=phase)


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.abs(np.asarray(b))))


def disagreement(m, x, angles):
    ours = photometeor.mie(m, x, angles)
    theirs = miepython_case(m, x, angles)
    scale = float(np.max(np.abs(theirs["s1"])))
    return {
        "n_terms": ours["n_terms"] - int(x + 4.05 * x ** (1 / 3) + 2),
        "qext": rel(ours["qext"], theirs["qext"]),
        "qsca": rel(ours["qsca"], theirs["qsca"]),
        "g": rel(ours["g"], theirs["g"]),
        "qback": rel(ours["qback"], theirs["qback"]),
        "phase": rel(ours["phase"], theirs["phase"]),
        "s": max(
            float(np.max(np.abs(ours["s1"] - theirs["s1"]))),
            float(np.max(np.abs(ours["s2"] - theirs["s2"]))),
        )
        / scale,
    }


# Tolerances: just above the worst disagreement measured over all cases (miepython 3.3.0 with
# its numba JIT, numpy 2.4.6), each named in its comment.
TOLERANCE = {
    "qext": 2e-11,  # measured worst 9.6e-12 (1.333+1e-8i, x = 1e5)
    "qsca": 2e-11,  # measured worst 8.4e-12 (x = 1e5)
    "g": 3e-10,  # measured worst 1.45e-10 (x = 1e5)
    "qback": 4e-6,  # measured worst 2.5e-6 (x = 1e5: the back-scatter sum cancels)
    "phase": 4e-6,  # measured worst 2.5e-6 (at 180°, as Q_back)
    "s": 2e-10,  # |S − S_miepython| / max|S1|, measured worst 8.8e-11 (x = 1e5)
}


@pytest.mark.parametrize("m,x", CASES, ids=[f"m={m}-x={x:g}" for m, x in CASES])
def test_sparse_angles_agree_with_miepython(m, x):
    d = disagreement(m, x, SPARSE_ANGLES)
    # Wiscombe's N_stop = x + 4.05 x^(1/3) + 2 terms, as miepython sums.
    assert d["n_terms"] == 0
    for key, tolerance in TOLERANCE.items():
        assert d[key] < tolerance, f"m = {m}, x = {x}: {key} {d[key]:.2e} (tolerance {tolerance:.0e})"


@pytest.mark.parametrize("x", [1e3, 1e4])
def test_full_table_grid_agrees_with_miepython(x):
    angles = np.round(0.18 * np.arange(1001), 2)
    d = disagreement(1.333 + 1e-8j, x, angles)
    for key in ("phase", "s"):
        assert d[key] < TOLERANCE[key], f"x = {x}: {key} {d[key]:.2e}"
    # angles_step_deg=0.18 is this grid (θ_k = k·0.18°, cosines folded exactly).
    grid = photometeor.mie(1.333 + 1e-8j, x, angles_step_deg=0.18)
    np.testing.assert_allclose(grid["angles_deg"], angles, rtol=0, atol=1e-12)
    assert rel(grid["phase"], miepython_case(1.333 + 1e-8j, x, grid["angles_deg"])["phase"]) < TOLERANCE["phase"]


def test_an_array_of_x_gives_each_sphere_as_alone():
    xs = np.array([0.2, 5.213, 100.0, 1e4])
    many = photometeor.mie(1.5 + 0.1j, xs, SPARSE_ANGLES)
    assert many["s1"].shape == (4, len(SPARSE_ANGLES)) and many["qext"].shape == (4,)
    for i, x in enumerate(xs):
        one = photometeor.mie(1.5 + 0.1j, float(x), SPARSE_ANGLES)
        for key in ("qext", "qsca", "qabs", "qback", "g", "n_terms"):
            assert many[key][i] == one[key], key
        for key in ("s1", "s2", "phase"):
            np.testing.assert_array_equal(many[key][i], one[key])


def test_the_cli_prints_the_same_numbers(cli):
    import json

    out = json.loads(cli(["mie", "--m", "1.5+0.1i", "--x", "1000", "--angles-deg", "0,0.18,90,179.82,180", "--json"]))
    ours = photometeor.mie(1.5 + 0.1j, 1000, [0, 0.18, 90, 179.82, 180])
    for key in ("qext", "qsca", "qabs", "qback", "g", "n_terms"):
        assert ours[key] == out[key], key
    np.testing.assert_array_equal(ours["phase"], out["phase"])
    np.testing.assert_array_equal(ours["s1"], [complex(re, im) for re, im in out["s1"]])


def test_help_states_the_units_and_conventions():
    doc = photometeor.mie.__doc__
    for words in ("n + iκ", "κ ≥ 0", "x = 2πr/λ", "degrees", "0 = forward", "1/sr", "∫ p dΩ = 1"):
        assert words in doc, words
    assert math.isclose(photometeor.size_parameter(1.0, 1000.0 * 2 * math.pi), 1.0)
