"""photometeor.phase (spheres over a size distribution) and photometeor.crystal_phase (ice
crystals and snow): against miepython's bin averages of single spheres, against the command
line's own numbers, and through invariants no producer can fake (normalization over the sphere
computed here from the grid's definition, the prism minimum deviation of the 22° halo)."""

from __future__ import annotations

import json
import math

import miepython
import numpy as np
import pytest

import photometeor


def solid_angles(step_deg: float, count: int) -> np.ndarray:
    """Ω_k of bin k = [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°] (docs/commands.md, "Conventions")."""
    k = np.arange(count)
    lo = np.radians(np.clip((k - 0.5) * step_deg, 0.0, 180.0))
    hi = np.radians(np.clip((k + 0.5) * step_deg, 0.0, 180.0))
    return 2 * math.pi * (np.cos(lo) - np.cos(hi))


def miepython_bin_averages(m: complex, x: float, step_deg: float, nodes: int = 32) -> np.ndarray:
    """miepython's p (norm='one', its m = n − iκ) averaged over each bin in solid angle, i.e.
    uniformly in μ, with `nodes` Gauss–Legendre nodes per bin."""
    count = int(round(180 / step_deg)) + 1
    k = np.arange(count)
    mu_hi = np.cos(np.radians(np.clip((k - 0.5) * step_deg, 0.0, 180.0)))
    mu_lo = np.cos(np.radians(np.clip((k + 0.5) * step_deg, 0.0, 180.0)))
    t, w = np.polynomial.legendre.leggauss(nodes)
    mu = 0.5 * (mu_hi - mu_lo)[:, None] * t[None, :] + 0.5 * (mu_hi + mu_lo)[:, None]
    p = miepython.i_unpolarized(m.conjugate(), x, mu.ravel(), norm="one").reshape(mu.shape)
    return 0.5 * (p * w[None, :]).sum(axis=1)


@pytest.mark.parametrize("radius_um,wavelength_nm", [(1.0, 450.0), (10.0, 550.0), (30.0, 650.0)])
def test_single_sphere_bins_agree_with_miepython(radius_um, wavelength_nm):
    r = photometeor.phase(
        distribution={"kind": "monodisperse", "radius_um": radius_um},
        wavelengths_nm=[wavelength_nm],
        sizes=1,
        nodes_per_panel=16,
    )
    m = complex(r["m"][0])
    assert m == photometeor.refractive_index("water", wavelength_nm, 20.0)
    x = photometeor.size_parameter(radius_um, wavelength_nm)
    theirs = miepython_bin_averages(m, x, 0.18)
    ours = r["bins"][0]
    worst = float(np.max(np.abs(ours - theirs) / theirs))
    # Measured worst 1.8e-11 (r = 30 µm at 650 nm, x = 290: ~0.3 ripples per bin); the two
    # sides integrate each bin with different Gauss nodes.
    assert worst < 4e-11, f"bins: worst relative difference {worst:.2e}"
    qext, qsca, _, g = miepython.efficiencies_mx(m.conjugate(), x)
    area_m2 = math.pi * (radius_um * 1e-6) ** 2
    # Measured worst: σ_ext 2.2e-14 relative, albedo 0, g 1.0e-14.
    assert r["sigma_ext_m2"][0] == pytest.approx(qext * area_m2, rel=1e-13)
    assert r["albedo"][0] == pytest.approx(qsca / qext, rel=1e-13)
    assert r["g"][0] == pytest.approx(g, abs=5e-14)


def test_the_cli_prints_the_same_numbers(cli):
    args = dict(lognormal_median_um=10.0, sigma_g=1.3, wavelengths_nm=[650.0, 450.0], sizes=48, angles_deg=[0, 30, 180])
    ours = photometeor.phase(**args)
    out = json.loads(
        cli(
            [
                "phase",
                "--lognormal-median-um",
                "10",
                "--sigma-g",
                "1.3",
                "--wavelengths-nm",
                "650,450",
                "--sizes",
                "48",
                "--angles-deg",
                "0,30,180",
                "--json",
            ]
        )
    )
    np.testing.assert_array_equal(ours["theta_deg"], out["angles_deg"])
    assert ours["distribution"] == out["distribution"]
    for j, w in enumerate(out["wavelengths"]):
        assert ours["wavelengths_nm"][j] == w["wavelength_nm"]
        assert ours["m"][j] == complex(w["m_re"], w["m_im"])
        for key in ("sigma_ext_m2", "sigma_sca_m2", "albedo", "g", "energy_closure", "sizes", "nodes_per_panel"):
            assert ours[key][j] == w[key], key
        np.testing.assert_array_equal(ours["bins"][j], w["bins"])
        np.testing.assert_array_equal(ours["points"][j], w["points"])


def test_distribution_as_keywords_or_as_a_scene_table_is_the_same():
    by_keywords = photometeor.phase(r_eff_um=10, v_eff=0.1, wavelengths_nm=[550], sizes=32)
    by_table = photometeor.phase(
        distribution={"kind": "gamma", "r_eff_um": 10, "v_eff": 0.1}, wavelengths_nm=[550], sizes=32
    )
    np.testing.assert_array_equal(by_keywords["bins"], by_table["bins"])
    assert by_keywords["distribution"] == {"kind": "gamma", "r_eff_um": 10.0, "v_eff": 0.1}
    lognormal = photometeor.phase(r_eff_um=10, v_eff=0.1, lognormal=True, wavelengths_nm=[550], sizes=32)
    assert lognormal["distribution"]["kind"] == "lognormal"
    # r_eff = r_g exp(2.5 ln²σ_g) and v_eff = exp(ln²σ_g) − 1 (Hansen & Travis 1974).
    s2 = math.log(lognormal["distribution"]["sigma_g"]) ** 2
    assert lognormal["distribution"]["median_radius_um"] * math.exp(2.5 * s2) == pytest.approx(10.0)
    assert math.exp(s2) - 1 == pytest.approx(0.1)


def test_adaptive_bins_integrate_to_one_and_a_cloud_is_forward():
    r = photometeor.phase(r_eff_um=10, v_eff=0.1, wavelengths_nm=[550], tolerance=0.02, angles_step_deg=0.5)
    omega = solid_angles(0.5, r["bins"].shape[1])
    total = float(r["bins"][0] @ omega)
    # Σ bins Ω − 1 is the quadrature's closure, and is reported as such.
    assert abs(total - 1 - r["energy_closure"][0]) < 1e-12
    # Measured closure −1.0e-9.
    assert abs(total - 1) < 1e-8
    # The refinement doubled the sizes from 32 until one doubling changed less than 2 %.
    assert r["sizes"][0] > 32 and r["last_change"][0] < 0.02
    assert 0.8 < r["g"][0] < 0.9 and np.argmax(r["bins"][0]) == 0


def test_ice_halos_sit_at_the_prism_minimum_deviation():
    r = photometeor.crystal_phase(wavelengths_nm=[550], dimension_sigma_g=1.0, rays=200_000, angles_step_deg=0.1)
    n = float(r["m"][0].real)
    # 22° halo: light through two prism faces at 60°; D = 2 asin(n sin 30°) − 60°.
    d22 = math.degrees(2 * math.asin(n * math.sin(math.radians(30)))) - 60
    theta = r["theta_deg"]
    bins = r["bins"][0]
    window = (theta > 18) & (theta < 26)
    peak = float(theta[window][np.argmax(bins[window])])
    # Measured: the maximum in the bin centred 0.08° past D (docs/physics.md §12.2: 0.03–0.06° on 0.05° bins).
    assert d22 - 0.05 <= peak <= d22 + 0.3, f"22° halo at {peak}°, theory {d22:.3f}°"
    omega = solid_angles(0.1, len(theta))
    assert abs(float(bins @ omega) - 1) < 1e-12
    assert 0 < r["albedo"][0] <= 1 and r["lost"][0] < 1e-4
    # On 1° bins the halo stands 68 standard errors above its neighbours 3° away (measured);
    # snow (rough aggregates, δ = 0.7) has none: 1.6 standard errors measured.
    def bump(r):
        t, p, se = r["theta_deg"], r["bins"][0], r["bins_std_error"][0]
        i = int(np.argmin(np.abs(t - round(d22))))
        return (p[i] - 0.5 * (p[i - 3] + p[i + 3])) / se[i]

    pristine = photometeor.crystal_phase(wavelengths_nm=[550], rays=200_000, angles_step_deg=1.0)
    snow = photometeor.crystal_phase(kind="snow", wavelengths_nm=[550], rays=200_000, angles_step_deg=1.0)
    assert bump(pristine) > 20, "no 22° halo in pristine columns"
    assert bump(snow) < 5, "a 22° halo in snow"


def test_crystal_traces_are_seeded():
    a = photometeor.crystal_phase(wavelengths_nm=[450, 650], rays=20_000, angles_step_deg=1.0)
    b = photometeor.crystal_phase(wavelengths_nm=[450, 650], rays=20_000, angles_step_deg=1.0)
    c = photometeor.crystal_phase(wavelengths_nm=[450, 650], rays=20_000, angles_step_deg=1.0, seed=7)
    np.testing.assert_array_equal(a["bins"], b["bins"])
    assert not np.array_equal(a["bins"], c["bins"])
    # Each wavelength its own stream: the two rows are not the same draw.
    assert a["g"][0] != a["g"][1]


def test_two_seeds_share_no_stream():
    # Four equal wavelengths: a stream shared between (seed 1, wavelength i) and (seed 2,
    # wavelength j) would give equal rows, and two seeds' difference would understate the noise.
    same = [550.0] * 4
    one = photometeor.crystal_phase(wavelengths_nm=same, rays=2_000, angles_step_deg=1.0, seed=1)
    two = photometeor.crystal_phase(wavelengths_nm=same, rays=2_000, angles_step_deg=1.0, seed=2)
    for i in range(4):
        for j in range(4):
            assert not np.array_equal(one["bins"][i], two["bins"][j]), (i, j)


def test_seed_defaults_to_zero():
    default = photometeor.crystal_phase(wavelengths_nm=[450, 650], rays=2_000, angles_step_deg=1.0)
    zero = photometeor.crystal_phase(wavelengths_nm=[450, 650], rays=2_000, angles_step_deg=1.0, seed=0)
    np.testing.assert_array_equal(default["bins"], zero["bins"])
