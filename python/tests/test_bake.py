"""photometeor.bake and photometeor.load: a bake through Python is the command line's bake, byte
for byte; its arrays are the EXR's pixels as the OpenEXR reference library reads them; every row
integrates to 1 over the sphere; load() refuses a file of another generation; progress reaches
a callback; the GIL is free while the work runs."""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from conftest import TINY_SCENE, TINY_SCENE_DICT

import photometeor


def files(d: Path):
    """The published files of a bake directory (not its cache or lock)."""
    return sorted(p.name for p in d.iterdir() if p.is_file() and not p.name.startswith("."))


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """The tiny scene baked by Python and by the command line, and the scene file."""
    root = tmp_path_factory.mktemp("bake")
    scene = root / "tiny.toml"
    scene.write_text(TINY_SCENE)
    return root, scene


def test_python_and_cli_write_the_same_bytes(baked, cli):
    root, scene = baked
    py = photometeor.bake(scene, root / "py", quality="draft")
    cli(["bake", str(scene), "--out", str(root / "cli"), "--quality", "draft", "--quiet"])
    names = files(root / "cli")
    assert names == files(root / "py")
    # Four files per field (Ams_n, single scattering, Poisson mixtures, Biri kernel) + manifest.
    assert len(names) == 4 * 2 + 1 and "manifest.json" in names
    for name in names:
        assert (root / "py" / name).read_bytes() == (root / "cli" / name).read_bytes(), name
    assert py.report["computed"] == ["cloud", "cirrus"] and py.report["cached"] == []
    # The same scene given as TOML text or as a dict is the same bake.
    for i, scene_as in enumerate([TINY_SCENE, TINY_SCENE_DICT]):
        other = root / f"as{i}"
        photometeor.bake(scene_as, other, quality="draft")
        for name in names:
            assert (other / name).read_bytes() == (root / "cli" / name).read_bytes(), (i, name)


def test_arrays_are_the_exr_pixels_and_rows_integrate_to_one(baked):
    root, scene = baked
    b = photometeor.bake(scene, root / "py2", quality="draft")
    assert list(b.fields) == ["cloud", "cirrus"]
    k = int(round(180 / 0.5)) + 1
    np.testing.assert_array_equal(b.theta_deg, 0.5 * np.arange(k))
    lo = np.radians(np.clip(b.theta_deg - 0.25, 0, 180))
    hi = np.radians(np.clip(b.theta_deg + 0.25, 0, 180))
    omega = 2 * math.pi * (np.cos(lo) - np.cos(hi))
    for name, f in b.fields.items():
        assert f.ams.shape == (4, k, 3) and f.forward_fraction.shape == (4, 3) and f.n_max == 4
        exr = OpenEXR.File(str(root / "py2" / f"{name}.exr"), separate_channels=True)
        for c, channel in enumerate("RGB"):
            pixels = exr.parts[0].channels[channel].pixels.astype(np.float64)
            np.testing.assert_array_equal(f.ams[:, :, c], pixels)
            np.testing.assert_array_equal(f.forward_fraction[:, c], f.entry["forward_fraction"][channel])
        # Every Ams_n row integrates to 1; measured worst 6e-8 (32-bit texels).
        energy = np.einsum("nkc,k->nc", f.ams, omega)
        assert np.max(np.abs(energy - 1)) < 2e-7, name
        assert f.single is not None and f.single.bins.shape == (3, k)
        np.testing.assert_array_equal(f.single.wavelengths_nm, [650.0, 515.0, 440.0])
        assert np.all(f.albedo <= 1) and np.all(f.sigma_ext_m2 > 0)
    # An unchanged re-bake reads every field from the cache.
    again = photometeor.bake(scene, root / "py2", quality="draft")
    assert again.report["computed"] == [] and again.report["cached"] == ["cloud", "cirrus"]
    for name in b.fields:
        np.testing.assert_array_equal(again.fields[name].ams, b.fields[name].ams)


def test_load_reads_a_bake_and_refuses_a_tampered_file(baked, tmp_path):
    root, scene = baked
    made = photometeor.bake(scene, tmp_path / "t", quality="draft")
    loaded = photometeor.load(tmp_path / "t")
    assert loaded.report is None and loaded.dir == tmp_path / "t"
    assert loaded.manifest == json.loads((tmp_path / "t" / "manifest.json").read_text())
    for name in made.fields:
        np.testing.assert_array_equal(loaded.fields[name].ams, made.fields[name].ams)
    # out=None bakes into a temporary directory, removed once loaded.
    temporary = photometeor.bake(scene)
    assert temporary.dir is None
    np.testing.assert_array_equal(temporary.fields["cloud"].ams, made.fields["cloud"].ams)
    # One byte changed inside the EXR: the CRC-32 no longer matches the manifest.
    exr = tmp_path / "t" / "cloud.exr"
    data = bytearray(exr.read_bytes())
    data[-10] ^= 0x01
    exr.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="cloud.exr"):
        photometeor.load(tmp_path / "t")


def test_progress_reaches_a_callback_in_order(baked, tmp_path, capfd):
    _, scene = baked
    calls = []
    photometeor.bake(scene, tmp_path / "p", progress=lambda *a: calls.append(a))
    for name in ("cloud", "cirrus"):
        mine = [c for c in calls if c[0] == name]
        done = [c[1] for c in mine]
        total = mine[0][2]
        # rgb3: 3 wavelengths + 3 steps of Legendre and RGB (photometeor-bake's bar).
        assert total == 6 and done[0] == 0 and done[-1] == total and mine[-1][3] == "done"
        assert done == sorted(done), done
    # An exception in the callback stops the calls and is raised when the bake returns.
    seen = []

    def failing(*a):
        seen.append(a)
        raise KeyError("stop here")

    with pytest.raises(KeyError, match="stop here"):
        photometeor.bake(scene, tmp_path / "q", progress=failing)
    assert len(seen) == 1
    # progress=True draws a bar per field on stderr.
    photometeor.bake(scene, tmp_path / "r", progress=True)
    err = capfd.readouterr().err
    assert "   cloud [" in err and "6/6 done" in err


def ticks_while(work) -> tuple[int, float]:
    """Runs `work` in a thread; counts this thread's loop turns while the native call runs."""
    span = {}

    def run():
        span["start"] = time.perf_counter()
        work()
        span["end"] = time.perf_counter()

    thread = threading.Thread(target=run)
    stamps = []
    thread.start()
    while thread.is_alive():
        stamps.append(time.perf_counter())
    thread.join()
    # Skip 50 ms after the start: a thread holding the GIL may still yield it for one switch
    # interval (5 ms) before entering the native call.
    inside = [t for t in stamps if span["start"] + 0.05 < t < span["end"]]
    return len(inside), span["end"] - span["start"]


def test_the_gil_is_released_during_long_work(baked, tmp_path):
    _, scene = baked
    for work in (
        lambda: photometeor.mie(1.333 + 1e-8j, [2e5] * 12, angles_step_deg=0.18),
        lambda: photometeor.bake(scene, tmp_path / "gil"),
    ):
        ticks, seconds = ticks_while(work)
        assert seconds > 0.1, f"the work took {seconds:.3f} s, too short to tell"
        # Held, the GIL would stop this thread for the whole call: no tick inside it.
        assert ticks > 100, f"{ticks} ticks during {seconds:.2f} s of work"


SWEEP_SCENE = """[scene]
name = "sweep"
spectral = "rgb3"
n_max = 4

[[field]]
name = "cloud"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }
sweep = { key = "r_eff_um", from = 5, to = 20, count = 3 }
"""


def test_a_swept_field_is_its_members_and_mixes_between_them(tmp_path):
    b = photometeor.bake(SWEEP_SCENE, tmp_path / "sweep", quality="draft")
    assert list(b.fields) == ["cloud@00", "cloud@01", "cloud@02"]
    s = b.sweeps["cloud"]
    assert (s.key, s.spacing) == ("r_eff_um", "log")
    np.testing.assert_allclose(s.values, [5.0, 10.0, 20.0], rtol=1e-12)
    assert [m.name for m in s.members] == list(b.fields)
    assert b.fields["cloud@01"].entry["microphysics"]["distribution"]["r_eff_um"] == pytest.approx(10.0)
    # At a member's value, that member; beyond the ends, the end members.
    for k, v in enumerate(s.values):
        np.testing.assert_array_equal(s.ams_at(v), s.members[k].ams)
    np.testing.assert_array_equal(s.ams_at(100.0), s.members[2].ams)
    # Between them: the extinction log-linear in the size, each row still normalized.
    value = 7.0
    (k0, w0), (k1, w1) = s.shares(value)
    t = math.log(value / 5.0) / math.log(2.0)
    sigma = [m.sigma_ext_m2[1] for m in s.members]
    assert (k0, k1) == (0, 1)
    assert w0 * sigma[0] + w1 * sigma[1] == pytest.approx(sigma[0] ** (1 - t) * sigma[1] ** t, rel=1e-12)
    ams = s.ams_at(value)
    half = b.theta_step_deg / 2
    lo = np.radians(np.clip(b.theta_deg - half, 0, 180))
    hi = np.radians(np.clip(b.theta_deg + half, 0, 180))
    energy = np.einsum("nkc,k->nc", ams, 2 * math.pi * (np.cos(lo) - np.cos(hi)))
    assert np.max(np.abs(energy - 1)) < 2e-7
    lo = np.minimum(s.members[0].ams, s.members[1].ams)
    hi = np.maximum(s.members[0].ams, s.members[1].ams)
    assert np.all(ams >= lo - 1e-12) and np.all(ams <= hi + 1e-12)
