//! One sphere: `mie` (efficiencies, S1, S2 and p at given angles, as `photometeor mie`
//! computes them, vectorised over x), `refractive_index` and `size_parameter` (the physical
//! layer: material, radius, wavelength → m, x).

use ::mie::{
    Efficiencies, FoldedAngles, Material, Sphere, ThetaGrid, amplitudes, exact_cosine_deg,
    phase_from_amplitudes,
};
use ndarray::{Array1, Array2};
use num_complex::Complex64;
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLike1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use crate::errors::{out_of_range, to_py};

/// The material named `name` ("water" or "ice").
pub fn material(name: &str) -> PyResult<Material> {
    match name {
        "water" => Ok(Material::Water),
        "ice" => Ok(Material::Ice),
        other => Err(PyValueError::new_err(format!(
            "material = {other:?} is not one of \"water\", \"ice\""
        ))),
    }
}

/// θ (degrees) and their exactly folded cosines, as the CLI's `angles_from`: the full grid of
/// step `step_deg`, or the listed angles (default 0°, 90°, 180°), each checked to lie in
/// [0, 180].
pub fn angles_from(
    angles_deg: Option<Vec<f64>>,
    step_deg: Option<f64>,
) -> PyResult<(Vec<f64>, Vec<f64>)> {
    match (angles_deg, step_deg) {
        (Some(_), Some(_)) => Err(PyValueError::new_err(
            "give angles_deg or angles_step_deg, not both",
        )),
        (None, Some(step)) => {
            let grid = ThetaGrid::new(step).map_err(|e| to_py(&e))?;
            Ok((grid.thetas_deg(), grid.cosines()))
        }
        (angles, None) => {
            let angles = angles.unwrap_or_else(|| vec![0.0, 90.0, 180.0]);
            if angles.is_empty() {
                return Err(PyValueError::new_err(
                    "angles_deg is empty; give at least one scattering angle in [0, 180] degrees",
                ));
            }
            for &a in &angles {
                if !(a.is_finite() && (0.0..=180.0).contains(&a)) {
                    return Err(out_of_range(
                        "scattering angle angles_deg",
                        format!("{a}°"),
                        "[0, 180] degrees",
                    ));
                }
            }
            let mu = angles.iter().map(|&a| exact_cosine_deg(a)).collect();
            Ok((angles, mu))
        }
    }
}

/// A number (`None`) or a 1-D array of numbers (`Some`), as numpy sees `value`.
pub fn scalar_or_vector(value: &Bound<'_, PyAny>, name: &str) -> PyResult<Result<f64, Vec<f64>>> {
    let np = value.py().import("numpy")?;
    let ndim: usize = np.call_method1("ndim", (value,))?.extract()?;
    match ndim {
        0 => Ok(Ok(value.extract::<f64>()?)),
        1 => {
            let array: PyArrayLike1<'_, f64, AllowTypeChange> = value.extract()?;
            Ok(Err(array.as_array().to_vec()))
        }
        _ => Err(PyValueError::new_err(format!(
            "{name} has {ndim} dimensions; give a number or a 1-D array"
        ))),
    }
}

/// One efficiency (or g) of a sphere.
type Quantity = fn(&Efficiencies) -> f64;

/// One sphere's results at the requested angles.
struct One {
    e: Efficiencies,
    s1: Vec<Complex64>,
    s2: Vec<Complex64>,
    phase: Vec<f64>,
}

fn one(sphere: &Sphere, angles: &FoldedAngles) -> One {
    let c = sphere.coefficients();
    let e = c.efficiencies();
    let (s1, s2) = amplitudes(&c, angles);
    let phase = s1
        .iter()
        .zip(&s2)
        .map(|(&a1, &a2)| phase_from_amplitudes(a1, a2, sphere.x(), e.q_sca))
        .collect();
    One { e, s1, s2, phase }
}

/// One homogeneous sphere by Lorenz–Mie theory: efficiencies, amplitudes S1, S2 and the
/// phase function at the given scattering angles (what `photometeor mie --json` prints).
///
/// Parameters
/// ----------
/// m : complex
///     Refractive index of the sphere relative to the medium, m = n + iκ with κ ≥ 0 absorbing
///     (Bohren & Huffman's sign; miepython's m = n − iκ is the conjugate). n in [0.5, 10],
///     κ in [0, 10]; a negative κ is refused.
/// x : float or 1-D array of float
///     Size parameter x = 2πr/λ (dimensionless, r the radius, λ the wavelength in the
///     medium), in [1e-6, 2e5]. With an array every output gets a leading x axis.
/// angles_deg : 1-D array of float, optional
///     Scattering angles θ in degrees, 0 = forward, each in [0, 180] (default 0, 90, 180).
/// angles_step_deg : float, optional
///     Instead of angles_deg: the full grid θ = 0, D, 2D, …, 180 (D in degrees, in
///     [0.01, 30], dividing 180), the table grid of a bake.
///
/// Returns
/// -------
/// dict
///     ``m`` (complex), ``x``, ``angles_deg`` (A,), and per sphere: ``qext``, ``qsca``,
///     ``qabs``, ``qback`` (efficiencies = cross-section / πr², dimensionless; Q_back in the
///     radar convention 4|S1(180°)|²/x²), ``g`` (asymmetry parameter ⟨cos θ⟩), ``n_terms``
///     (Wiscombe's N_stop), ``s1``, ``s2`` (complex, (A,) or (X, A): Bohren & Huffman's
///     dimensionless amplitudes, unnormalized, so Re S(0°) = x² Q_ext / 4) and ``phase``
///     (float, (A,) or (X, A)).
///
/// Normalization of ``phase``: p(θ) = (|S1|² + |S2|²) / (2π x² Q_sca) in 1/sr, the
/// unpolarized phase function normalized so that ∫ p dΩ = 1 over the sphere (miepython's
/// ``i_unpolarized(m, x, mu, norm='one')`` with its m = n − iκ).
///
/// Raises
/// ------
/// ValueError
///     m, x or an angle outside its range, naming the value and the range.
#[pyfunction]
#[pyo3(signature = (m, x, angles_deg = None, *, angles_step_deg = None))]
pub fn mie<'py>(
    py: Python<'py>,
    m: Complex64,
    x: &Bound<'py, PyAny>,
    angles_deg: Option<PyArrayLike1<'py, f64, AllowTypeChange>>,
    angles_step_deg: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (angles, mu) = angles_from(angles_deg.map(|a| a.as_array().to_vec()), angles_step_deg)?;
    let xs = scalar_or_vector(x, "x")?;
    let list = match &xs {
        Ok(x) => vec![*x],
        Err(xs) if xs.is_empty() => {
            return Err(PyValueError::new_err(
                "x is empty; give at least one size parameter in [1e-6, 2e5]",
            ));
        }
        Err(xs) => xs.clone(),
    };
    // Every sphere is checked before any work starts.
    let spheres: Vec<Sphere> = list
        .iter()
        .map(|&x| Sphere::new(m, x))
        .collect::<Result<_, _>>()
        .map_err(|e| to_py(&e))?;
    let folded = FoldedAngles::new(&mu);
    let results: Vec<One> = py.detach(|| spheres.par_iter().map(|s| one(s, &folded)).collect());

    let out = PyDict::new(py);
    out.set_item("m", m)?;
    out.set_item("angles_deg", angles.into_pyarray(py))?;
    let pick =
        |f: fn(&Efficiencies) -> f64| -> Array1<f64> { results.iter().map(|r| f(&r.e)).collect() };
    let keys: [(&str, Quantity); 5] = [
        ("qext", |e| e.q_ext),
        ("qsca", |e| e.q_sca),
        ("qabs", |e| e.q_abs),
        ("qback", |e| e.q_back),
        ("g", |e| e.g),
    ];
    match xs {
        Ok(x) => {
            let [r] = <[One; 1]>::try_from(results).unwrap_or_else(|_| unreachable!());
            out.set_item("x", x)?;
            for (key, f) in keys {
                out.set_item(key, f(&r.e))?;
            }
            out.set_item("n_terms", r.e.n_terms)?;
            out.set_item("s1", r.s1.into_pyarray(py))?;
            out.set_item("s2", r.s2.into_pyarray(py))?;
            out.set_item("phase", r.phase.into_pyarray(py))?;
        }
        Err(xs) => {
            out.set_item("x", xs.into_pyarray(py))?;
            for (key, f) in keys {
                out.set_item(key, pick(f).into_pyarray(py))?;
            }
            let n_terms: Array1<i64> = results.iter().map(|r| r.e.n_terms as i64).collect();
            out.set_item("n_terms", n_terms.into_pyarray(py))?;
            let a_len = mu.len();
            let rows = |f: fn(&One) -> &[Complex64]| {
                Array2::from_shape_fn((results.len(), a_len), |(i, k)| f(&results[i])[k])
            };
            out.set_item("s1", rows(|r| &r.s1).into_pyarray(py))?;
            out.set_item("s2", rows(|r| &r.s2).into_pyarray(py))?;
            let phase = Array2::from_shape_fn((results.len(), a_len), |(i, k)| results[i].phase[k]);
            out.set_item("phase", phase.into_pyarray(py))?;
        }
    }
    Ok(out)
}

/// Refractive index m = n + iκ (κ ≥ 0 absorbing) of water or ice at a vacuum wavelength, as
/// the bake and `photometeor mie --material` use it.
///
/// Parameters
/// ----------
/// material : {"water", "ice"}
///     Water: IAPWS R9-97 real part at the temperature's density, Segelstein 1981 κ
///     (wavelengths 200–1100 nm). Ice: Warren & Brandt 2008.
/// wavelength_nm : float
///     Vacuum wavelength λ in nm.
/// temperature_c : float
///     Water temperature in °C, [-12, 99] (ignored for ice).
///
/// Returns
/// -------
/// complex
///     m = n + iκ (dimensionless).
#[pyfunction]
#[pyo3(signature = (material, wavelength_nm, temperature_c = 20.0))]
pub fn refractive_index(
    material: &str,
    wavelength_nm: f64,
    temperature_c: f64,
) -> PyResult<Complex64> {
    self::material(material)?
        .refractive_index(wavelength_nm, temperature_c)
        .map_err(|e| to_py(&e))
}

/// Size parameter x = 2πr/λ of a sphere of radius ``radius_um`` (µm) at vacuum wavelength
/// ``wavelength_nm`` (nm), in a medium of index 1 (dimensionless).
#[pyfunction]
pub fn size_parameter(radius_um: f64, wavelength_nm: f64) -> PyResult<f64> {
    if !(radius_um.is_finite() && radius_um > 0.0) {
        return Err(out_of_range("radius_um", radius_um, "(0, ∞) µm"));
    }
    if !(wavelength_nm.is_finite() && wavelength_nm > 0.0) {
        return Err(out_of_range("wavelength_nm", wavelength_nm, "(0, ∞) nm"));
    }
    Ok(::mie::size_parameter(radius_um, wavelength_nm))
}
