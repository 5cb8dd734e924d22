"""Shared helpers of the photometeor Python tests (pytest).

The tests compare the package with two things it did not produce: miepython (an independent Mie
code) and the `photometeor` command line built from the same source (the bake must be the same
bytes). The command line is looked for in $PHOTOMETEOR_BIN, else target/{debug,release}/photometeor
of this checkout (the newer of the two); `cargo test --workspace` or `cargo build` makes it.
"""

from __future__ import annotations

import os

# miepython with its numba JIT (as data/reference/generate_mie_reference.py ran it): its pure
# Python path takes a minute on the 1001-angle x = 1e4 case. Set before any test imports it.
os.environ.setdefault("MIEPYTHON_USE_JIT", "1")

import subprocess
from pathlib import Path
from typing import List

import pytest

REPO = Path(__file__).resolve().parents[2]


def cli_path() -> Path:
    given = os.environ.get("PHOTOMETEOR_BIN")
    candidates = [Path(given)] if given else [REPO / "target" / p / "photometeor" for p in ("debug", "release")]
    found = [c for c in candidates if c.is_file()]
    if not found:
        pytest.fail(
            "the photometeor command line was not found (looked for "
            + ", ".join(str(c) for c in candidates)
            + "); build it with `cargo build` (or `cargo test --workspace`), or set PHOTOMETEOR_BIN"
        )
    return max(found, key=lambda p: p.stat().st_mtime)


@pytest.fixture(scope="session")
def cli():
    """Runs `photometeor ARGS…`, returning stdout; fails the test with stderr on a non-zero exit."""
    binary = cli_path()

    def run(args: List[str], cwd: Path = REPO) -> str:
        done = subprocess.run([str(binary), *args], cwd=cwd, capture_output=True, text=True)
        if done.returncode != 0:
            pytest.fail(f"photometeor {' '.join(args)} exited {done.returncode}:\n{done.stderr}")
        return done.stdout

    return run


# A tiny scene for the bake tests (draft quality: about a second): Riley's three wavelengths,
# 4 orders, a cloud and an ice field (the two producers, Mie and the crystal tracer).
TINY_SCENE = """\
[scene]
name = "tiny"
spectral = "rgb3"
theta_step_deg = 0.5
n_max = 4
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
temperature_c = 10
distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }

[[field]]
name = "cirrus"
kind = "ice"
habit = "column"
max_dimension_um = 100
"""

TINY_SCENE_DICT = {
    "scene": {"name": "tiny", "spectral": "rgb3", "theta_step_deg": 0.5, "n_max": 4, "quality": "draft"},
    "field": [
        {
            "name": "cloud",
            "kind": "cloud",
            "temperature_c": 10,
            "distribution": {"kind": "gamma", "r_eff_um": 10, "v_eff": 0.1},
        },
        {"name": "cirrus", "kind": "ice", "habit": "column", "max_dimension_um": 100},
    ],
}
