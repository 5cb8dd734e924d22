"""Bad input raises before any work starts, naming the value and its allowed range (as the
command line's one-line errors do); a scene error names the key and its line and writes
nothing."""

from __future__ import annotations

import pytest
from conftest import TINY_SCENE

import photometeor


@pytest.mark.parametrize(
    "call,words",
    [
        (lambda: photometeor.mie(1.33, 3e5), ["size parameter x = 300000", "[1e-6, 2e5]"]),
        (lambda: photometeor.mie(1.33, [10, 0.0]), ["size parameter x = 0", "[1e-6, 2e5]"]),
        (lambda: photometeor.mie(1.5 - 0.1j, 10), ["κ = -0.1", "κ ≥ 0"]),
        (lambda: photometeor.mie(11.0, 10), ["n = Re m = 11", "[0.5, 10]"]),
        (lambda: photometeor.mie(1.33, 10, [0, 181]), ["181°", "[0, 180] degrees"]),
        (lambda: photometeor.mie(1.33, 10, [0, 90], angles_step_deg=1), ["not both"]),
        (lambda: photometeor.mie(1.33, 10, angles_step_deg=0.7), ["Δθ = 0.7°", "[0.01, 30] degrees and dividing 180"]),
        (lambda: photometeor.mie(1.33, 10, []), ["angles_deg is empty"]),
        (lambda: photometeor.refractive_index("glass", 550), ["material = \"glass\"", "water"]),
        (lambda: photometeor.refractive_index("water", 1500), ["1500 nm", "[200, 1100]"]),
        (lambda: photometeor.size_parameter(-1, 550), ["radius_um = -1", "(0, ∞) µm"]),
        (lambda: photometeor.phase(wavelengths_nm=[550]), ["exactly one size distribution"]),
        (
            lambda: photometeor.phase(r_eff_um=10, v_eff=0.1, marshall_palmer_mm_h=5, wavelengths_nm=[550]),
            ["exactly one size distribution"],
        ),
        (lambda: photometeor.phase(r_eff_um=10, v_eff=0.7, wavelengths_nm=[550]), ["v_eff", "0.7", "(0, 0.5)"]),
        (
            lambda: photometeor.phase(lognormal_median_um=10, sigma_g=0.9, wavelengths_nm=[550]),
            ["σ_g = 0.9", "(1, 5]"],
        ),
        (lambda: photometeor.phase(r_eff_um=10, v_eff=0.1, wavelengths_nm=[550], sizes=0), ["sizes = 0", "[1, 100000]"]),
        (
            lambda: photometeor.phase(r_eff_um=10, v_eff=0.1, wavelengths_nm=[550], tolerance=2),
            ["tolerance = 2", "(0, 1)"],
        ),
        (lambda: photometeor.phase(r_eff_um=10, v_eff=0.1, wavelengths_nm=[]), ["wavelengths_nm is empty"]),
        (lambda: photometeor.phase(r_eff_um=10, v_eff=0.1, wavelengths_nm=[5000]), ["5000 nm"]),
        (
            lambda: photometeor.phase(distribution={"kind": "gama", "r_eff_um": 10}, wavelengths_nm=[550]),
            ["gama", "gamma"],
        ),
        (lambda: photometeor.crystal_phase(wavelengths_nm=[550], roughness=2), ["roughness δ = 2", "[0, 1]"]),
        (lambda: photometeor.crystal_phase(wavelengths_nm=[550], rays=10), ["rays = 10", "[1000, 1e10]"]),
        (lambda: photometeor.crystal_phase(wavelengths_nm=[550], habit="needle"), ["habit = \"needle\""]),
        (lambda: photometeor.bake(TINY_SCENE, quality="best"), ["quality = \"best\"", "draft"]),
        (lambda: photometeor.bake(TINY_SCENE, jobs=0), ["jobs = 0", "[1, 256]"]),
        (
            lambda: photometeor.bake(TINY_SCENE.replace("n_max = 4", "n_max = 0")),
            ["line 5", "n_max = 0", "[1, 10000]"],
        ),
        (
            lambda: photometeor.bake({"scene": {"name": "x", "theta_step_deg": 0.7}, "field": [{"name": "a", "kind": "cloud"}]}),
            ["theta_step_deg = 0.7", "divide 180°"],
        ),
    ],
)
def test_bad_input_raises_value_error_naming_value_and_range(call, words):
    with pytest.raises(ValueError) as raised:
        call()
    for w in words:
        assert w in str(raised.value), f"{w!r} not in {raised.value}"


def test_a_bad_scene_writes_nothing(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(ValueError, match="line 16: unknown variant `hail`"):
        photometeor.bake(TINY_SCENE.replace('kind = "ice"', 'kind = "hail"'), out)
    assert not out.exists()


def test_missing_files_raise_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.toml"):
        photometeor.bake(tmp_path / "nowhere.toml")
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        photometeor.load(tmp_path)


def test_slow_input_is_refused_before_work_starts():
    # Every x is checked before the first sphere is computed: the bad last value fails at once,
    # although the eight before it (x = 2e5 at 1001 angles, ~40 ms each) would take ~0.2 s.
    import time

    start = time.perf_counter()
    with pytest.raises(ValueError, match="x = -1"):
        photometeor.mie(1.33, [2e5] * 8 + [-1], angles_step_deg=0.18)
    assert time.perf_counter() - start < 0.05
