"""Type stubs of photometeor (units in the docstrings of the functions themselves)."""

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

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

_Floats = Union[float, Sequence[float], npt.NDArray[np.floating[Any]]]
_Angles = Union[Sequence[float], npt.NDArray[np.floating[Any]], npt.NDArray[np.integer[Any]]]
_Scene = Union[str, "os.PathLike[str]", Mapping[str, Any], None]
_ProgressCallback = Callable[[str, int, int, str], Any]

def mie(
    m: complex,
    x: _Floats,
    angles_deg: Optional[_Angles] = None,
    *,
    angles_step_deg: Optional[float] = None,
) -> Dict[str, Any]:
    """One sphere: qext, qsca, qabs, qback, g, n_terms, s1, s2 (complex), phase (1/sr);
    m = n + iκ (κ ≥ 0), x = 2πr/λ, angles in degrees (0 = forward)."""

def refractive_index(
    material: str, wavelength_nm: float, temperature_c: float = 20.0
) -> complex:
    """m = n + iκ of "water" or "ice" at a vacuum wavelength in nm (water at °C)."""

def size_parameter(radius_um: float, wavelength_nm: float) -> float:
    """x = 2πr/λ, r in µm, λ in nm."""

def phase(
    *,
    wavelengths_nm: _Angles,
    material: str = "water",
    distribution: Optional[Mapping[str, Any]] = None,
    lognormal_median_um: Optional[float] = None,
    sigma_g: Optional[float] = None,
    r_eff_um: Optional[float] = None,
    v_eff: Optional[float] = None,
    lognormal: bool = False,
    marshall_palmer_mm_h: Optional[float] = None,
    sizes: Optional[int] = None,
    nodes_per_panel: Optional[int] = None,
    tolerance: float = 0.01,
    angles_step_deg: float = 0.18,
    temperature_c: float = 20.0,
    angles_deg: Optional[_Angles] = None,
    tail_mass: float = 0.001,
) -> Dict[str, Any]:
    """Spheres over a size distribution, per wavelength: sigma_ext_m2, albedo, g, bins (W, K)."""

def crystal_phase(
    *,
    wavelengths_nm: _Angles,
    kind: str = "ice",
    habit: Optional[str] = None,
    aspect_ratio: Optional[float] = None,
    max_dimension_um: Optional[float] = None,
    dimension_sigma_g: float = 1.5,
    roughness: Optional[float] = None,
    rays: int = 600000,
    seed: int = 0,
    angles_step_deg: float = 0.18,
) -> Dict[str, Any]:
    """Ice crystals and snow by ray tracing, per wavelength: sigma_ext_m2, albedo, g, bins."""

@dataclass(frozen=True)
class SingleScattering:
    wavelengths_nm: np.ndarray
    bins: np.ndarray
    forward_delta_fraction: np.ndarray
    sigma_ext_m2: np.ndarray
    albedo: np.ndarray

@dataclass(frozen=True)
class Field:
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
    def n_max(self) -> int: ...

@dataclass(frozen=True)
class Sweep:
    name: str
    key: str
    spacing: str
    values: np.ndarray
    members: List[Field]
    def shares(self, value: float) -> List[Tuple[int, float]]: ...
    def ams_at(self, value: float) -> np.ndarray: ...

@dataclass(frozen=True)
class Bake:
    fields: Dict[str, Field]
    theta_deg: np.ndarray
    theta_step_deg: float
    manifest: Dict[str, Any]
    dir: Optional[Path]
    report: Optional[Dict[str, Any]] = None
    sweeps: Dict[str, Sweep] = ...

def load(dir: Union[str, "os.PathLike[str]"]) -> Bake:
    """Read and check a bake directory."""

def bake(
    scene: _Scene = None,
    out: Union[str, "os.PathLike[str]", None] = None,
    quality: Optional[str] = "draft",
    *,
    jobs: Optional[int] = None,
    progress: Union[bool, _ProgressCallback, None] = None,
) -> Bake:
    """Bake a scene (path, TOML text, dict or None = default) and load the tables."""
