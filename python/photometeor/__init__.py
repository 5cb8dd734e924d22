"""photometeor: Mie phase functions of cloud droplets, raindrops, ice crystals and snow, and the
multiple-scattering tables Ams_n / F_n that real-time renderers need, as numpy arrays.

The Rust library does the work (``photometeor._native``); this package parses and checks the
arguments, releases the GIL while it computes and hands back numpy arrays. The numbers are the
command line's: ``photometeor.mie`` is ``photometeor mie``, ``photometeor.phase`` is
``photometeor phase``, ``photometeor.bake`` is ``photometeor bake`` (the same bytes on disk).

Functions
---------
mie(m, x, angles_deg)            one sphere: Q_ext, Q_sca, Q_abs, Q_back, g, S1, S2, p(θ)
refractive_index(material, λ)    m = n + iκ of water or ice
size_parameter(radius_um, λ)     x = 2πr/λ
phase(wavelengths_nm=…, …)       spheres over a size distribution, per wavelength
crystal_phase(wavelengths_nm=…)  ice crystals and snow by ray tracing, per wavelength
bake(scene, out=None)            a scene's tables Ams_n, F_n → Bake
load(dir)                        an existing bake directory → Bake

Conventions
-----------
θ is the scattering angle in degrees, θ = 0 forward. Refractive index m = n + iκ with κ ≥ 0
absorbing (Bohren & Huffman; miepython's m = n − iκ is the conjugate). Size parameter
x = 2πr/λ; radii in µm, wavelengths in nm (vacuum), cross-sections in m². Phase functions in
1/sr, normalized ∫ p dΩ = 1. Table grids: θ_k = k·Δθ; a table value is the average over bin
[θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°] in solid angle.

Errors: an input outside its range raises ValueError naming the value and its allowed range,
before any work starts; a file the system cannot read raises OSError (FileNotFoundError, …).
"""

from __future__ import annotations

import collections.abc
import json
import os
import sys
import tempfile
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, Union

import numpy as np

from . import _native
from ._native import crystal_phase, mie, phase, refractive_index, size_parameter

__version__: str = _native.__version__

__all__ = [
    "Bake",
    "Field",
    "SingleScattering",
    "Sweep",
    "bake",
    "crystal_phase",
    "load",
    "mie",
    "phase",
    "refractive_index",
    "size_parameter",
]

#: What ``bake`` accepts as a scene: a TOML file's path, TOML text, or the same as a dict.
_Scene = Union[str, "os.PathLike[str]", Mapping[str, Any], None]

#: ``progress(field, done, total, message)``.
_ProgressCallback = Callable[[str, int, int, str], Any]


@dataclass(frozen=True)
class SingleScattering:
    """A field's single-scattering optics per wavelength j, before mixing to R, G, B
    (``<field>.single.exr``): what a spectral path tracer samples.

    Attributes
    ----------
    wavelengths_nm : (W,) float array, nm
    bins : (W, K) float array, 1/sr: the phase function averaged over bin k, Σ_k bins Ω_k = 1
    forward_delta_fraction : (W,) share of the scattered light in the exact forward δ (in bin 0)
    sigma_ext_m2 : (W,) mean extinction cross-section per particle, m²
    albedo : (W,) single-scattering albedo σ_sca/σ_ext
    """

    wavelengths_nm: np.ndarray
    bins: np.ndarray
    forward_delta_fraction: np.ndarray
    sigma_ext_m2: np.ndarray
    albedo: np.ndarray


@dataclass(frozen=True)
class Field:
    """One particle field of a bake.

    Attributes
    ----------
    name : str
        The field's name in the scene (its table is ``<name>.exr``).
    kind : str
        cloud | rain | haze | ice | snow.
    ams : (N, K, 3) float array, 1/sr
        ``ams[n - 1, k, c]`` = Ams_n(θ_k) of channel c (R, G, B, linear sRGB): the phase
        function of light scattered exactly n times, each row integrating to 1 over the sphere
        (Riley et al. 2004). The values are the EXR's 32-bit floats.
    forward_fraction : (N, 3) float array
        ``forward_fraction[n - 1, c]`` = F_n, the share of Ams_n in the forward hemisphere.
    sigma_ext_m2, albedo, g : (3,) float arrays
        Per channel: mean extinction cross-section per particle (m²), single-scattering
        albedo and asymmetry parameter (σ_sca-weighted over the channel's wavelengths).
    entry : dict
        The field's entry in manifest.json (microphysics, quality, n_isotropic, …).
    single : SingleScattering or None
        The per-wavelength single-scattering optics, where the bake has them.
    """

    name: str
    kind: str
    ams: np.ndarray
    forward_fraction: np.ndarray
    sigma_ext_m2: np.ndarray
    albedo: np.ndarray
    g: np.ndarray
    entry: Dict[str, Any]
    single: Optional[SingleScattering]

    @property
    def n_max(self) -> int:
        """N, the number of orders Ams_1..Ams_N."""
        return int(self.ams.shape[0])


@dataclass(frozen=True)
class Sweep:
    """A field swept over one microphysical key: its member fields, one per value.

    Attributes
    ----------
    name : str
        The swept field's name in the scene.
    key : str
        The swept key (``r_eff_um``, ``median_radius_um``, ``radius_um``, ``rain_rate_mm_h``,
        ``max_dimension_um`` or ``roughness``), in its unit.
    spacing : str
        ``"log"`` or ``"linear"``.
    values : (M,) float array
        The values, increasing.
    members : list of Field
        The member fields (``<name>@00`` …), one per value.
    """

    name: str
    key: str
    spacing: str
    values: np.ndarray
    members: List[Field]

    def shares(self, value: float) -> List[Tuple[int, float]]:
        """The two members around ``value`` and their number-density shares, as renderers mix
        them (docs/scenes.md, "Swept fields"): t linear in ln value (log spacing) or value, clamped to
        the ends; extinction σ_k^(1−t)·σ_k+1^t (green channel)."""
        v = self.values
        value = float(np.clip(value, v[0], v[-1]))
        k = int(np.clip(np.searchsorted(v, value, side="right"), 1, len(v) - 1)) - 1
        at = np.log if self.spacing == "log" else (lambda x: x)
        t = float(np.clip((at(value) - at(v[k])) / (at(v[k + 1]) - at(v[k])), 0.0, 1.0))
        s0, s1 = self.members[k].sigma_ext_m2[1], self.members[k + 1].sigma_ext_m2[1]
        sigma = s0 ** (1.0 - t) * s1**t
        return [(k, (1.0 - t) * sigma / s0), (k + 1, t * sigma / s1)]

    def ams_at(self, value: float) -> np.ndarray:
        """Ams_n (N, K, 3) at ``value``: the two members around it mixed with their
        :meth:`shares`, each weighted by share × σ_sca per channel."""
        parts = [(self.members[k], w) for k, w in self.shares(value)]
        weights = np.array([w * m.sigma_ext_m2 * m.albedo for m, w in parts])  # (2, 3)
        weights /= weights.sum(axis=0)
        return sum(w[None, None, :] * m.ams for (m, _), w in zip(parts, weights))


@dataclass(frozen=True)
class Bake:
    """A bake: every field's tables, checked against the manifest, in memory.

    Attributes
    ----------
    fields : dict of str → Field
        In the manifest's (the scene's) order.
    theta_deg : (K,) float array, degrees
        θ_k = k·Δθ, the column angles of every table (0 = forward).
    theta_step_deg : float
        Δθ in degrees.
    manifest : dict
        manifest.json as read and checked.
    dir : pathlib.Path or None
        The bake directory (None for a bake made into a temporary directory, now removed).
    report : dict or None
        For a bake made by :func:`bake`: fields computed and read from the cache, seconds,
        peak memory (``photometeor bake --json``); None for :func:`load`.
    sweeps : dict of str → Sweep
        The swept fields by name (their members are in ``fields`` too).
    """

    fields: Dict[str, Field]
    theta_deg: np.ndarray
    theta_step_deg: float
    manifest: Dict[str, Any]
    dir: Optional[Path]
    report: Optional[Dict[str, Any]] = None
    sweeps: Dict[str, Sweep] = dataclasses.field(default_factory=dict)

    def __repr__(self) -> str:
        names = ", ".join(f"{f.name} ({f.kind}, N = {f.n_max})" for f in self.fields.values())
        return f"Bake({self.dir or 'in memory'}: {names}; Δθ = {self.theta_step_deg}°)"


def _per_channel(value: Mapping[str, Any]) -> np.ndarray:
    return np.array([value["R"], value["G"], value["B"]], dtype=float)


def load(dir: Union[str, "os.PathLike[str]"]) -> Bake:
    """Read a bake directory (``photometeor bake``'s output) into numpy arrays.

    Every check of the bake format is made before anything is returned: manifest.json (schema,
    grid, shapes, physical ranges), then each field's EXR against its manifest entry (field name,
    Δθ, K, N, F_1..F_N bit for bit, file size and CRC-32), so a file of another bake or
    generation is refused; so is a directory whose last bake stopped while publishing.

    Parameters
    ----------
    dir : str or path
        The bake directory (holding manifest.json).

    Returns
    -------
    Bake
        ``.fields[name].ams`` is (N, K, 3) in 1/sr, ``.theta_deg`` (K,) in degrees.

    Raises
    ------
    FileNotFoundError
        No manifest.json or a listed file is missing.
    ValueError
        A file fails a check; the message names the file and the check.
    """
    raw = _native.load_bake(os.fspath(dir))
    return _bake_from(raw, Path(dir), None)


def _bake_from(raw: Dict[str, Any], dir: Optional[Path], report: Optional[Dict[str, Any]]) -> Bake:
    manifest = json.loads(raw["manifest_json"])
    entries = {e["name"]: e for e in manifest["fields"]}
    fields: Dict[str, Field] = {}
    for f in raw["fields"]:
        entry = entries[f["name"]]
        single = f["single"]
        fields[f["name"]] = Field(
            name=f["name"],
            kind=entry["kind"],
            ams=f["ams"],
            forward_fraction=f["forward_fraction"],
            sigma_ext_m2=_per_channel(entry["sigma_ext_m2"]),
            albedo=_per_channel(entry["albedo"]),
            g=_per_channel(entry["g"]),
            entry=entry,
            single=None if single is None else SingleScattering(**single),
        )
    sweeps = {
        s["name"]: Sweep(
            name=s["name"],
            key=s["key"],
            spacing=s["spacing"],
            values=np.array(s["values"], dtype=float),
            members=[fields[m] for m in s["fields"]],
        )
        for s in manifest.get("sweeps", [])
    }
    return Bake(
        sweeps=sweeps,
        fields=fields,
        theta_deg=raw["theta_deg"],
        theta_step_deg=raw["theta_step_deg"],
        manifest=manifest,
        dir=dir,
        report=report,
    )


def _print_progress(field: str, done: int, total: int, message: str) -> None:
    width = 30
    filled = width * done // max(total, 1)
    bar = "=" * filled + " " * (width - filled)
    print(f"\r{field:>8} [{bar}] {done}/{total} {message:<40}", end="", file=sys.stderr)
    if done >= total:
        print(file=sys.stderr)


def _scene_arguments(scene: _Scene) -> Dict[str, Any]:
    if scene is None:
        return {}
    if isinstance(scene, collections.abc.Mapping):
        return {"scene_json": json.dumps(scene)}
    if isinstance(scene, os.PathLike):
        return {"scene_path": os.fspath(scene)}
    if isinstance(scene, str):
        # TOML text has a table header or a newline; a path has neither.
        if "\n" in scene or "[scene]" in scene:
            return {"scene_text": scene}
        return {"scene_path": scene}
    raise TypeError(
        f"scene must be a TOML file's path, TOML text, a dict or None, not {type(scene).__name__}"
    )


def bake(
    scene: _Scene = None,
    out: Union[str, "os.PathLike[str]", None] = None,
    quality: Optional[str] = "draft",
    *,
    jobs: Optional[int] = None,
    progress: Union[bool, _ProgressCallback, None] = None,
) -> Bake:
    """Bake a scene's multiple-scattering tables and load them (``photometeor bake``).

    Each particle field of the scene becomes Ams_1..Ams_N (the phase function of light
    scattered exactly n times) and F_1..F_N per channel R, G, B, written as ``<field>.exr``
    and manifest.json into ``out`` exactly as ``photometeor bake SCENE --out OUT --quality Q``
    writes them (the same bytes), then read back with every check of :func:`load`.

    Parameters
    ----------
    scene : str, path, dict or None
        A scene TOML file's path, TOML text (anything with a newline or ``[scene]``), a dict of
        the same keys (``{"scene": {...}, "field": [{...}, ...]}``), or None for the embedded
        default scene (cloud, rain, ice, snow). Keys: docs/scenes.md.
    out : str or path, optional
        The bake directory (created if missing; its ``.cache`` makes an unchanged re-bake
        instant). None: a temporary directory, removed once the tables are loaded.
    quality : {"draft", "standard", "reference"} or None
        Accuracy preset (node counts and rays; docs/scenes.md, "Presets, measured"). Default "draft"
        (seconds per field); None uses the scene's own ``quality``.
    jobs : int, optional
        Worker threads, [1, 256] (default: all cores).
    progress : callable or bool, optional
        ``progress(field, done, total, message)`` is called from worker threads as each field
        advances; True prints a bar per field on stderr. An exception it raises stops further
        calls and is raised when the bake returns.

    Returns
    -------
    Bake
        ``.fields[name].ams`` (N, K, 3) in 1/sr, ``.fields[name].forward_fraction`` (N, 3),
        ``.theta_deg`` (K,) in degrees, ``.manifest``, ``.report``.

    Raises
    ------
    ValueError
        A scene key or an argument outside its range, naming it (and the line, for TOML);
        nothing is written.
    FileNotFoundError
        The scene file does not exist.
    RuntimeError
        Another process is baking into ``out``.
    """
    arguments = _scene_arguments(scene)
    callback: Optional[_ProgressCallback]
    if progress is True:
        callback = _print_progress
    elif progress is False or progress is None:
        callback = None
    elif callable(progress):
        callback = progress
    else:
        raise TypeError(f"progress must be a callable or a bool, not {type(progress).__name__}")
    if out is None:
        with tempfile.TemporaryDirectory(prefix="photometeor-bake-") as tmp:
            report = _native.bake_scene(
                tmp, quality=quality, jobs=jobs, progress=callback, **arguments
            )
            return _bake_from(_native.load_bake(tmp), None, json.loads(report))
    report = _native.bake_scene(
        os.fspath(out), quality=quality, jobs=jobs, progress=callback, **arguments
    )
    return _bake_from(_native.load_bake(os.fspath(out)), Path(out), json.loads(report))
