//! Populations, one phase function per wavelength: `phase` (spheres over a size distribution,
//! the options of `photometeor phase`) and `crystal_phase` (ice crystals and snow by ray
//! tracing, the keys of a scene's ice or snow field).

use mie::crystal::{CrystalField, crystal_phase as trace_crystals};
use mie::{BulkRequest, NodeCounts, PhaseFunction, SizeDistribution, ThetaGrid, bulk_phase};
use ndarray::{Array1, Array2};
use num_complex::Complex64;
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLike1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyMapping};

use crate::errors::{out_of_range, to_py};
use crate::sphere::{angles_from, material};

/// Largest `sizes`: as `photometeor phase --sizes` (25× the reference preset's 4096).
const MAX_SIZES: usize = 100_000;
/// Largest `nodes_per_panel`: as `photometeor phase --nodes-per-panel`.
const MAX_NODES_PER_PANEL: usize = 64;
/// Most size nodes the adaptive refinement tries, as `photometeor phase`.
const ADAPTIVE_MAX_SIZES: usize = 1 << 14;
/// Rays per wavelength allowed for crystals: below 1000 the standard errors are meaningless,
/// above 10¹⁰ a call runs for hours.
const RAYS_RANGE: (u64, u64) = (1_000, 10_000_000_000);

/// The size distribution from the mutually exclusive keyword groups
/// ([`mie::DistributionOptions`], as the CLI), or from a scene-style mapping `{"kind": …, …}`.
fn distribution_from(
    distribution: Option<&Bound<'_, PyMapping>>,
    options: mie::DistributionOptions,
) -> PyResult<SizeDistribution> {
    let other = Some(("distribution={\"kind\": …}", distribution.is_some()));
    if let Some(d) = options
        .choose(str::to_string, other)
        .map_err(|e| to_py(&e))?
    {
        return Ok(d);
    }
    // The other group: the scene's inline table, e.g. {"kind": "gamma", "r_eff_um": 10,
    // "v_eff": 0.1}.
    let mapping = distribution.expect("the only group left");
    let json: String = mapping
        .py()
        .import("json")?
        .call_method1("dumps", (mapping.as_any(),))?
        .extract()?;
    let d = serde_json::from_str::<SizeDistribution>(&json)
        .map_err(|e| PyValueError::new_err(format!("distribution {json}: {e}")))?;
    d.validated().map_err(|e| to_py(&e))
}

/// The node counts: fixed with `sizes`, adaptive to `tolerance` without (the CLI's rules).
fn node_counts(
    sizes: Option<usize>,
    nodes_per_panel: Option<usize>,
    tolerance: f64,
) -> PyResult<NodeCounts> {
    match (sizes, nodes_per_panel) {
        (Some(sizes), nodes) => {
            if !(1..=MAX_SIZES).contains(&sizes) {
                return Err(out_of_range("sizes", sizes, "[1, 100000]"));
            }
            let nodes_per_panel = nodes.unwrap_or(4);
            if !(1..=MAX_NODES_PER_PANEL).contains(&nodes_per_panel) {
                return Err(out_of_range("nodes_per_panel", nodes_per_panel, "[1, 64]"));
            }
            Ok(NodeCounts::Fixed {
                sizes,
                nodes_per_panel,
            })
        }
        (None, Some(_)) => Err(PyValueError::new_err(
            "nodes_per_panel needs sizes (fixed node counts)",
        )),
        (None, None) => {
            if !(tolerance > 0.0 && tolerance < 1.0) {
                return Err(out_of_range("tolerance", tolerance, "(0, 1)"));
            }
            Ok(NodeCounts::Adaptive {
                tolerance,
                max_sizes: ADAPTIVE_MAX_SIZES,
            })
        }
    }
}

/// The fields every population has, one row per wavelength.
fn common<'py>(
    py: Python<'py>,
    result: &[PhaseFunction],
    grid: ThetaGrid,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let column = |f: fn(&PhaseFunction) -> f64| -> Array1<f64> { result.iter().map(f).collect() };
    out.set_item(
        "wavelengths_nm",
        column(|p| p.wavelength_nm).into_pyarray(py),
    )?;
    let m: Array1<Complex64> = result
        .iter()
        .map(|p| Complex64::new(p.m_re, p.m_im))
        .collect();
    out.set_item("m", m.into_pyarray(py))?;
    out.set_item("sigma_ext_m2", column(|p| p.sigma_ext_m2).into_pyarray(py))?;
    out.set_item("sigma_sca_m2", column(|p| p.sigma_sca_m2).into_pyarray(py))?;
    out.set_item("albedo", column(|p| p.albedo).into_pyarray(py))?;
    out.set_item("g", column(|p| p.g).into_pyarray(py))?;
    out.set_item(
        "forward_delta_fraction",
        column(|p| p.forward_delta_fraction).into_pyarray(py),
    )?;
    out.set_item("theta_step_deg", grid.step_deg())?;
    out.set_item("theta_deg", grid.thetas_deg().into_pyarray(py))?;
    let bins = Array2::from_shape_fn((result.len(), grid.len()), |(j, k)| result[j].bins[k]);
    out.set_item("bins", bins.into_pyarray(py))?;
    Ok(out)
}

/// Wavelengths as a list, refusing an empty one.
fn wavelengths(list: PyArrayLike1<'_, f64, AllowTypeChange>) -> PyResult<Vec<f64>> {
    let list = list.as_array().to_vec();
    if list.is_empty() {
        return Err(PyValueError::new_err(
            "wavelengths_nm is empty; give at least one vacuum wavelength in nm",
        ));
    }
    Ok(list)
}

/// The angle grid of the bins.
fn grid(angles_step_deg: f64) -> PyResult<ThetaGrid> {
    ThetaGrid::new(angles_step_deg).map_err(|e| to_py(&e))
}

/// Size-averaged optics of water or ice spheres, per wavelength: σ_ext, σ_sca, albedo, g and
/// the phase function averaged inside the bins of a θ grid (``photometeor phase``, with its
/// options as keyword arguments).
///
/// Give exactly one size distribution: ``distribution`` (a scene's inline table, e.g.
/// ``{"kind": "gamma", "r_eff_um": 10, "v_eff": 0.1}``; kinds lognormal
/// (median_radius_um, sigma_g), gamma, marshall_palmer (rain_rate_mm_h), monodisperse
/// (radius_um)), or ``lognormal_median_um`` with ``sigma_g``, ``r_eff_um`` with ``v_eff``
/// (gamma; lognormal with ``lognormal=True``), or ``marshall_palmer_mm_h``.
///
/// Parameters
/// ----------
/// wavelengths_nm : 1-D array of float
///     Vacuum wavelengths λ in nm (water: 200–1100 nm).
/// material : {"water", "ice"}
///     Sphere material (default water).
/// lognormal_median_um : float, optional
///     Lognormal median radius r_g in µm (> 0), with ``sigma_g`` in (1, 5].
/// r_eff_um, v_eff : float, optional
///     Effective radius in µm and effective variance in (0, 0.5).
/// marshall_palmer_mm_h : float, optional
///     Marshall–Palmer raindrop spectrum for this rain rate in mm/h, [0.1, 500].
/// sizes : int, optional
///     Fixed number of sizes (nodes in ln r), [1, 100000]; default: adaptive to ``tolerance``.
/// nodes_per_panel : int, optional
///     Fixed Gauss nodes per angular panel, [1, 64] (with ``sizes``; default 4).
/// tolerance : float
///     Adaptive refinement stops when one doubling changes the bins (rms over θ ≥ 1°), σ_ext
///     and g by less than this, in (0, 1) (default 0.01).
/// angles_step_deg : float
///     Bin width Δθ in degrees, dividing 180, in [0.01, 30] (default 0.18).
/// temperature_c : float
///     Water temperature in °C, [-12, 99] (default 20).
/// angles_deg : 1-D array of float, optional
///     Also report p̄ at these scattering angles (degrees, in [0, 180]) as point values.
/// tail_mass : float
///     Mass fraction of the distribution left outside the truncated size range, (0, 0.5).
///
/// Returns
/// -------
/// dict
///     Per wavelength j (leading axis W): ``wavelengths_nm``, ``m`` (complex n + iκ),
///     ``sigma_ext_m2`` and ``sigma_sca_m2`` (mean cross-sections per particle, m²),
///     ``albedo``, ``g``, ``forward_delta_fraction`` (0 for spheres), ``bins`` (W, K): the
///     phase function in 1/sr averaged over bin k = [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°] in
///     solid angle, Σ_k bins_k Ω_k = 1; ``energy_closure`` (that sum − 1), ``sizes``,
///     ``nodes_per_panel``, ``last_change`` (the quadrature used); and ``theta_deg`` (K,)
///     = θ_k, ``theta_step_deg``, ``distribution`` (the distribution used, as a dict), and
///     with ``angles_deg``: ``point_angles_deg`` (P,) and ``points`` (W, P) in 1/sr.
///
/// Raises
/// ------
/// ValueError
///     An option outside its range or a wrong combination, naming the value and range.
/// RuntimeError
///     The adaptive refinement did not reach ``tolerance`` within 16384 sizes.
#[pyfunction]
#[pyo3(signature = (
    *,
    wavelengths_nm,
    material = "water",
    distribution = None,
    lognormal_median_um = None,
    sigma_g = None,
    r_eff_um = None,
    v_eff = None,
    lognormal = false,
    marshall_palmer_mm_h = None,
    sizes = None,
    nodes_per_panel = None,
    tolerance = 0.01,
    angles_step_deg = 0.18,
    temperature_c = 20.0,
    angles_deg = None,
    tail_mass = 1e-3,
))]
#[allow(clippy::too_many_arguments)]
pub fn phase<'py>(
    py: Python<'py>,
    wavelengths_nm: PyArrayLike1<'py, f64, AllowTypeChange>,
    material: &str,
    distribution: Option<&Bound<'py, PyMapping>>,
    lognormal_median_um: Option<f64>,
    sigma_g: Option<f64>,
    r_eff_um: Option<f64>,
    v_eff: Option<f64>,
    lognormal: bool,
    marshall_palmer_mm_h: Option<f64>,
    sizes: Option<usize>,
    nodes_per_panel: Option<usize>,
    tolerance: f64,
    angles_step_deg: f64,
    temperature_c: f64,
    angles_deg: Option<PyArrayLike1<'py, f64, AllowTypeChange>>,
    tail_mass: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let wavelengths_nm = wavelengths(wavelengths_nm)?;
    let distribution = distribution_from(
        distribution,
        mie::DistributionOptions {
            lognormal_median_um,
            sigma_g,
            r_eff_um,
            v_eff,
            lognormal,
            marshall_palmer_mm_h,
        },
    )?;
    let nodes = node_counts(sizes, nodes_per_panel, tolerance)?;
    let (point_angles_deg, point_cosines) = match angles_deg {
        Some(a) => angles_from(Some(a.as_array().to_vec()), None)?,
        None => (Vec::new(), Vec::new()),
    };
    let request = BulkRequest {
        material: self::material(material)?,
        temperature_c,
        distribution,
        wavelengths_nm,
        grid: grid(angles_step_deg)?,
        nodes,
        tail_mass,
        point_cosines,
    };
    let result = py.detach(|| bulk_phase(&request)).map_err(|e| to_py(&e))?;
    let out = common(py, &result, request.grid)?;
    let mie_column = |f: fn(&mie::MieOrigin) -> f64| -> Array1<f64> {
        result.iter().map(|p| p.mie().map_or(f64::NAN, f)).collect()
    };
    out.set_item(
        "energy_closure",
        mie_column(|m| m.energy_closure).into_pyarray(py),
    )?;
    out.set_item(
        "last_change",
        mie_column(|m| m.last_change).into_pyarray(py),
    )?;
    let count = |f: fn(&mie::MieOrigin) -> usize| -> Array1<i64> {
        result.iter().map(|p| p.mie().map_or(0, f) as i64).collect()
    };
    out.set_item("sizes", count(|m| m.sizes).into_pyarray(py))?;
    out.set_item(
        "nodes_per_panel",
        count(|m| m.nodes_per_panel).into_pyarray(py),
    )?;
    let json = serde_json::to_string(&request.distribution).map_err(|e| {
        PyValueError::new_err(format!("the distribution cannot be written as JSON: {e}"))
    })?;
    out.set_item(
        "distribution",
        py.import("json")?.call_method1("loads", (json,))?,
    )?;
    if !point_angles_deg.is_empty() {
        let points = Array2::from_shape_fn((result.len(), point_angles_deg.len()), |(j, k)| {
            result[j].points[k]
        });
        out.set_item("point_angles_deg", point_angles_deg.into_pyarray(py))?;
        out.set_item("points", points.into_pyarray(py))?;
    }
    Ok(out)
}

/// Randomly oriented hexagonal ice prisms (ice crystals; snow with roughness) by
/// geometric-optics ray tracing plus Fraunhofer diffraction, per wavelength: σ_ext, σ_sca,
/// albedo, g and the phase function averaged inside the bins of a θ grid. The defaults are a
/// scene's ``ice`` or ``snow`` field's (``kind``); the refractive index is ice's
/// (Warren & Brandt 2008).
///
/// Parameters
/// ----------
/// wavelengths_nm : 1-D array of float
///     Vacuum wavelengths λ in nm.
/// kind : {"ice", "snow"}
///     Sets the defaults: ice = pristine columns of 100 µm; snow = aggregates (AR 1) of
///     2000 µm with roughness 0.7.
/// habit : {"plate", "column", "aggregate"}, optional
///     Sets the default aspect ratio: plate 0.2, column 2, aggregate 1.
/// aspect_ratio : float, optional
///     L/(2a) of the hexagonal prism, [0.01, 100] (< 1 plates, > 1 columns).
/// max_dimension_um : float, optional
///     Median of the maximum dimension max(2a, L) in µm, [1, 100000].
/// dimension_sigma_g : float
///     Geometric standard deviation of the maximum dimension (lognormal), [1, 4]; 1 = one
///     size (default 1.5).
/// roughness : float, optional
///     Macke's distortion δ, [0, 1] (0 pristine: halos; 0.7 snow).
/// rays : int
///     Rays traced per wavelength, [1000, 1e10] (default 600000; the bake's presets trace to a
///     noise target instead).
/// seed : int
///     Seed of the random streams, [0, 2⁶⁴), as ``photometeor bake --seed``: 0 (default) traces
///     the streams the presets' bakes trace (each wavelength its own), another seed other
///     streams for every wavelength, so two seeds' difference measures the noise.
/// angles_step_deg : float
///     Bin width Δθ in degrees, dividing 180, in [0.01, 30] (default 0.18).
///
/// Returns
/// -------
/// dict
///     As :func:`phase` (``wavelengths_nm``, ``m``, ``sigma_ext_m2``, ``sigma_sca_m2`` in m²,
///     ``albedo``, ``g``, ``bins`` (W, K) in 1/sr with Σ_k bins_k Ω_k = 1, ``theta_deg``,
///     ``theta_step_deg``), and ``forward_delta_fraction`` (the share of the scattered light
///     leaving exactly forward through parallel faces, held in bin 0), ``g_std_error``,
///     ``bins_std_error`` (W, K) (Monte Carlo standard errors), ``diffraction_fraction``,
///     ``rays`` (rays that hit the crystal), ``lost`` (energy share of paths cut off) and
///     ``crystal`` (the crystal population used, as a dict).
///
/// Raises
/// ------
/// ValueError
///     A value outside its range, naming the value and range.
#[pyfunction]
#[pyo3(signature = (
    *,
    wavelengths_nm,
    kind = "ice",
    habit = None,
    aspect_ratio = None,
    max_dimension_um = None,
    dimension_sigma_g = 1.5,
    roughness = None,
    rays = 600_000,
    seed = 0,
    angles_step_deg = 0.18,
))]
#[allow(clippy::too_many_arguments)]
pub fn crystal_phase<'py>(
    py: Python<'py>,
    wavelengths_nm: PyArrayLike1<'py, f64, AllowTypeChange>,
    kind: &str,
    habit: Option<&str>,
    aspect_ratio: Option<f64>,
    max_dimension_um: Option<f64>,
    dimension_sigma_g: f64,
    roughness: Option<f64>,
    rays: u64,
    seed: u64,
    angles_step_deg: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let wavelengths_nm = wavelengths(wavelengths_nm)?;
    // The defaults of a scene's ice or snow field (photometeor-bake's scene.rs).
    let snow = match kind {
        "ice" => false,
        "snow" => true,
        other => {
            return Err(PyValueError::new_err(format!(
                "kind = {other:?} is not one of \"ice\", \"snow\""
            )));
        }
    };
    let default_aspect_ratio = match habit.unwrap_or(if snow { "aggregate" } else { "column" }) {
        "plate" => 0.2,
        "column" => 2.0,
        "aggregate" => 1.0,
        other => {
            return Err(PyValueError::new_err(format!(
                "habit = {other:?} is not one of \"plate\", \"column\", \"aggregate\""
            )));
        }
    };
    let field = CrystalField {
        aspect_ratio: aspect_ratio.unwrap_or(default_aspect_ratio),
        max_dimension_um: max_dimension_um.unwrap_or(if snow { 2000.0 } else { 100.0 }),
        sigma_g: dimension_sigma_g,
        roughness: roughness.unwrap_or(if snow { 0.7 } else { 0.0 }),
    }
    .validated()
    .map_err(|e| to_py(&e))?;
    if !(RAYS_RANGE.0..=RAYS_RANGE.1).contains(&rays) {
        return Err(out_of_range("rays", rays, "[1000, 1e10]"));
    }
    let grid = grid(angles_step_deg)?;
    // Every wavelength's index is looked up before any ray is traced.
    for &lambda in &wavelengths_nm {
        mie::Material::Ice
            .refractive_index(lambda, -20.0)
            .map_err(|e| to_py(&e))?;
    }
    let result: Vec<PhaseFunction> = py
        .detach(|| {
            wavelengths_nm
                .iter()
                .enumerate()
                .map(|(j, &lambda)| {
                    let rays = mie::crystal::Rays::random(rays, bake::crystal_stream(seed, j));
                    trace_crystals(&field, lambda, grid, rays)
                })
                .collect::<Result<_, _>>()
        })
        .map_err(|e| to_py(&e))?;
    let out = common(py, &result, grid)?;
    let stats = |f: fn(&mie::CrystalOrigin) -> f64| -> Array1<f64> {
        result
            .iter()
            .map(|p| p.crystal().map_or(f64::NAN, f))
            .collect()
    };
    out.set_item("g_std_error", stats(|c| c.g_std_error).into_pyarray(py))?;
    out.set_item(
        "diffraction_fraction",
        stats(|c| c.diffraction_fraction).into_pyarray(py),
    )?;
    out.set_item("lost", stats(|c| c.trace.lost).into_pyarray(py))?;
    let hits: Array1<i64> = result
        .iter()
        .map(|p| p.crystal().map_or(0, |c| c.trace.rays as i64))
        .collect();
    out.set_item("rays", hits.into_pyarray(py))?;
    let std_error = Array2::from_shape_fn((result.len(), grid.len()), |(j, k)| {
        result[j]
            .crystal()
            .map_or(f64::NAN, |c| c.bins_std_error[k])
    });
    out.set_item("bins_std_error", std_error.into_pyarray(py))?;
    let crystal = PyDict::new(py);
    crystal.set_item("aspect_ratio", field.aspect_ratio)?;
    crystal.set_item("max_dimension_um", field.max_dimension_um)?;
    crystal.set_item("dimension_sigma_g", field.sigma_g)?;
    crystal.set_item("roughness", field.roughness)?;
    out.set_item("crystal", crystal)?;
    Ok(out)
}
