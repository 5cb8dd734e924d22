//! The plane-parallel slabs of the DISORT comparison (`data/reference/truth/slab_disort.json`):
//! their phase functions, tables and frame, shared by the CPU truth's tests (`truth.rs`) and the
//! GPU truth's (`truth_gpu.rs`).

#![allow(dead_code)]

use std::f64::consts::PI;

use glam::DVec3;
use grid::ThetaGrid;
use ndarray::{Array2, Array3};
use render::{Atmosphere, Camera, DensityGrid, Frame, MAX_FIELDS, Sun};
use runtime::{FieldTable, Spectrum, Tables};

/// Bin averages of Henyey–Greenstein g on `grid` (exact integrals over each bin's μ range).
pub fn hg_bins(grid: &ThetaGrid, g: f64) -> Vec<f64> {
    let widths = grid.bin_mu_widths();
    let mut mu_hi = 1.0;
    widths
        .iter()
        .map(|&w| {
            let mu_lo = mu_hi - w;
            let f = |mu: f64| (1.0 + g * g - 2.0 * g * mu).powf(-0.5);
            let p = (1.0 - g * g) / (2.0 * g) * (f(mu_hi) - f(mu_lo));
            mu_hi = mu_lo;
            p / (2.0 * PI * w)
        })
        .collect()
}

/// Tables of one field with the same single-scattering `bins` at every rgb3 wavelength.
pub fn tables_of(bins: &[f64], step: f64, albedo: f64) -> Tables {
    let rows = vec![bins.to_vec(); 3];
    let spectrum = Spectrum {
        wavelengths_nm: vec![650.0, 515.0, 440.0],
        weights: [
            vec![1.0, 0.0, 0.0],
            vec![0.0, 1.0, 0.0],
            vec![0.0, 0.0, 1.0],
        ],
    };
    tables_spectral(&rows, step, &[0.0; 3], &[1.0; 3], &[albedo; 3], spectrum)
}

/// Tables of one field with its own single-scattering `bins`, forward δ, σ_ext and albedo at
/// each wavelength of `spectrum`.
pub fn tables_spectral(
    bins: &[Vec<f64>],
    step: f64,
    delta: &[f64],
    sigma_ext: &[f64],
    albedo: &[f64],
    spectrum: Spectrum,
) -> Tables {
    let grid = ThetaGrid::new(step).unwrap();
    let k = grid.len();
    let iso = 1.0 / (4.0 * PI);
    let image = format::FieldImage {
        field: "slab".into(),
        theta_step_deg: step,
        ams: Array3::from_elem((3, 1, k), iso),
        forward_fraction: Array2::from_elem((3, 1), 0.9),
        extra_layers: Vec::new(),
    };
    let n = bins.len();
    let single = format::SingleScatter {
        field: "slab".into(),
        theta_step_deg: step,
        wavelengths_nm: spectrum.wavelengths_nm.clone(),
        bins: Array2::from_shape_fn((n, k), |(j, kk)| bins[j][kk]),
        forward_delta_fraction: delta.to_vec(),
        sigma_ext_m2: sigma_ext.to_vec(),
        albedo: albedo.to_vec(),
    };
    // The channels' σ as the bake mixes them (Σ_j w_cj σ_j).
    let mix = |v: &dyn Fn(usize) -> f64| -> [f64; 3] {
        std::array::from_fn(|c| (0..n).map(|j| spectrum.weights[c][j] * v(j)).sum())
    };
    let sigma_ext_m2 = mix(&|j| sigma_ext[j]);
    let sigma_sca_m2 = mix(&|j| sigma_ext[j] * albedo[j]);
    Tables {
        dir: "memory".into(),
        theta_step_deg: step,
        angle_count: k,
        fields: vec![FieldTable {
            name: "slab".into(),
            kind: format::FieldKind::Cloud,
            image,
            sigma_sca_m2,
            sigma_ext_m2,
            albedo: std::array::from_fn(|c| sigma_sca_m2[c] / sigma_ext_m2[c]),
            single: Some(single),
            poisson: None,
            transport_factor: None,
            biri: None,
        }],
        spectrum: Some(spectrum),
        sweeps: Vec::new(),
    }
}

/// A frame whose grid is a slab of optical depth `tau` between y = 1 and 2 m, 20 km wide, with
/// the sun at elevation 30° (μ0 = 0.5) and azimuth 0 (light travels towards −z), air off.
pub fn slab_frame(tau: f64) -> Frame {
    let mut data = vec![[0f32; MAX_FIELDS]; 8];
    for v in &mut data {
        v[0] = tau as f32;
    }
    Frame {
        camera: Camera {
            position_m: DVec3::new(0.0, 3.0, 0.0),
            look_at_m: DVec3::new(0.0, 0.0, 0.0),
            fov_deg: 10.0,
            projection: Default::default(),
        },
        sun: Sun {
            elevation_deg: 30.0,
            azimuth_deg: 0.0,
            irradiance: [1.0; 3],
        },
        atmosphere: Atmosphere {
            beta_sea_level_per_m: [0.0; 3],
            scale_height_m: 8000.0,
        },
        width: 1,
        height: 1,
        grid: DensityGrid {
            min_m: DVec3::new(-1e4, 1.0, -1e4),
            max_m: DVec3::new(1e4, 2.0, 1e4),
            dims: [2, 2, 2],
            data,
            periodic: false,
        },
        haze: None,
        ground_albedo: 0.0,
        lights: Vec::new(),
        media: Vec::new(),
        occluders: Vec::new(),
    }
}

/// The slab of `case` seen by an orthographic camera of `w` × `h` pixels, 0.5 m wide, looking
/// against outgoing direction `out` from 0.5 m beyond the slab's face (a point of the image
/// plane per pixel, one direction for all; every point between the slab and the ground).
pub fn orthographic_slab(tau: f64, out: DVec3, (w, h): (usize, usize)) -> Frame {
    let mut frame = slab_frame(tau);
    let face = if out.y > 0.0 {
        DVec3::new(0.0, 2.0, 0.0)
    } else {
        DVec3::new(0.0, 1.0, 0.0)
    };
    frame.camera = Camera {
        position_m: face + 0.5 * out,
        look_at_m: face,
        fov_deg: 60.0,
        projection: render::camera::Projection::Orthographic { width_m: 0.5 },
    };
    (frame.width, frame.height) = (w, h);
    frame
}

/// [`slab_frame`] narrowed to a box `width_m` wide in x and z that repeats without end
/// (`periodic = true`): the same infinite slab.
pub fn periodic_slab(frame: &mut Frame, width_m: f64) {
    frame.grid.min_m.x = -0.5 * width_m;
    frame.grid.min_m.z = -0.5 * width_m;
    frame.grid.max_m.x = 0.5 * width_m;
    frame.grid.max_m.z = 0.5 * width_m;
    frame.grid.periodic = true;
}

/// Per channel: mean and standard error of `n` of the truth's radiance samples along `dir`
/// from `origin` (paths of `seed`'s streams, in parallel).
pub fn radiance_along(
    tracer: &render::truth::Tracer,
    origin: DVec3,
    dir: DVec3,
    n: usize,
    seed: u64,
) -> [(f64, f64); 3] {
    use rayon::prelude::*;
    let sums = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut rng = render::truth::Rng::stream(seed, 0, i as u64);
            let l = tracer.radiance(origin, dir, &mut rng);
            [l, l.map(|v| v * v)]
        })
        .reduce(
            || [[0.0; 3]; 2],
            |a, b| [0, 1].map(|i| std::array::from_fn(|c| a[i][c] + b[i][c])),
        );
    std::array::from_fn(|c| {
        let (s, q) = (sums[0][c], sums[1][c]);
        (s / n as f64, render::truth::std_error(s, q, n as f64))
    })
}

/// The outgoing direction at cosine μ to the normal (`up`: reflected, else transmitted) and
/// azimuth φ (0: the horizontal direction the beam travels, −z).
pub fn outgoing(mu: f64, phi_deg: f64, up: bool) -> DVec3 {
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    let phi = phi_deg.to_radians();
    DVec3::new(s * phi.sin(), if up { mu } else { -mu }, -s * phi.cos())
}

/// One DISORT radiance the camera-side estimator is checked against.
#[derive(Clone)]
pub struct DisortRadiance {
    /// The case's list it is from (`I_up_reflected_top` or `I_down_transmitted_bottom`).
    pub list: &'static str,
    /// Cosine to the normal and azimuth (degrees) of the outgoing direction.
    pub mu: f64,
    pub phi: f64,
    /// Reflected (up) or transmitted (down).
    pub up: bool,
    /// DISORT's radiance.
    pub want: f64,
}

/// A DISORT case's radiances the tests check: at μ 1 (φ 0°) and μ 0.8 (φ 90°), with the
/// scattering angle in [30°, 150°] (≥ 30° from the beam and from the glory, where DISORT's own
/// stream-doubling change is ≤ 0.1 %).
pub fn disort_radiances(case: &serde_json::Value) -> Vec<DisortRadiance> {
    let mut out = Vec::new();
    for (list, up) in [
        ("I_up_reflected_top", true),
        ("I_down_transmitted_bottom", false),
    ] {
        for r in case[list].as_array().unwrap() {
            let (mu, phi) = (r["mu"].as_f64().unwrap(), r["phi_deg"].as_f64().unwrap());
            let theta = r["scattering_angle_deg"].as_f64().unwrap();
            if ((mu == 1.0 && phi == 0.0) || (mu == 0.8 && phi == 90.0))
                && (30.0..=150.0).contains(&theta)
            {
                let want = r["I"].as_f64().unwrap();
                out.push(DisortRadiance {
                    list,
                    mu,
                    phi,
                    up,
                    want,
                });
            }
        }
    }
    out
}

/// The cloud phase function of data/reference/truth/cloud_550nm_phase.json (0.18° bins).
pub fn cloud550_bins() -> Vec<f64> {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/reference/truth/cloud_550nm_phase.json"
    ))
    .unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["bins_per_sr"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Singly scattered radiance per unit F0 leaving a slab of optical depth `tau` lit at cosine
/// `mu0`, at cosine `mu` reflected (`up`) or transmitted, where ω p(Θ) is `omega_p` (1/sr):
/// ω p μ0/(μ0 + μ)(1 − e^{−τ(1/μ0 + 1/μ)}) up, ω p μ0/(μ0 − μ)(e^{−τ/μ0} − e^{−τ/μ}) down.
pub fn single_scatter_slab(omega_p: f64, mu0: f64, mu: f64, tau: f64, up: bool) -> f64 {
    if up {
        omega_p * mu0 / (mu0 + mu) * (1.0 - (-tau * (1.0 / mu0 + 1.0 / mu)).exp())
    } else {
        omega_p * mu0 / (mu0 - mu) * ((-tau / mu0).exp() - (-tau / mu).exp())
    }
}

/// Every DISORT slab of `data/reference/truth/slab_disort.json` (ω 1, 0.9 and 0.99).
fn disort_reference() -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/reference/truth/slab_disort.json"
    ))
    .unwrap();
    let reference: serde_json::Value = serde_json::from_str(&text).unwrap();
    reference["cases"].as_array().unwrap().clone()
}

/// The DISORT slabs the slab tests hold the truth to (ω 1 and 0.9; the ω 0.99 slabs are the
/// baked hg field's, [`disort_case`]), each case with the bins of its phase function
/// (`hg085`: HG g = 0.85; else the 550 nm cloud), on 0.18° bins.
pub fn disort_cases() -> Vec<(serde_json::Value, Vec<f64>)> {
    let hg = hg_bins(&ThetaGrid::new(0.18).unwrap(), 0.85);
    let cloud = cloud550_bins();
    disort_reference()
        .into_iter()
        .filter(|case| case["omega"] != 0.99)
        .map(|case| {
            let bins = if case["phase"] == "hg085" {
                &hg
            } else {
                &cloud
            };
            (case, bins.clone())
        })
        .collect()
}

/// The DISORT slab of `phase` (`hg085`, `cloud550`) at optical depth `tau` and albedo
/// `omega`.
pub fn disort_case(phase: &str, tau: f64, omega: f64) -> serde_json::Value {
    disort_reference()
        .into_iter()
        .find(|c| c["phase"] == phase && c["tau"] == tau && c["omega"] == omega)
        .unwrap_or_else(|| panic!("no DISORT slab {phase} at τ {tau}, ω {omega}"))
}

/// How the scatter of `image`'s pixels' luminance about their mean (pixels that are all the
/// same radiance: a uniform slab through an orthographic camera) compares with the truth's
/// standard error of it: the scatter over the rms of `stderr.Y` (the samples' own luminance),
/// and over the rms of the channels' errors combined as if independent. Both are 1 for a
/// standard error that states the noise.
pub fn luminance_scatter(image: &render::truth::TruthImage) -> (f64, f64) {
    let luma = render::error_map::LUMA;
    let y: Vec<f64> = image
        .image
        .rgb
        .iter()
        .map(|p| (0..3).map(|c| luma[c] * f64::from(p[c])).sum())
        .collect();
    let n = y.len() as f64;
    let mean = y.iter().sum::<f64>() / n;
    let scatter = (y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let rms = |v: &mut dyn Iterator<Item = f64>| (v.map(|e| e * e).sum::<f64>() / n).sqrt();
    let stated = rms(&mut image.luma_error.iter().map(|&e| f64::from(e)));
    let independent = rms(&mut image.std_error.iter().map(|e| {
        (0..3)
            .map(|c| (luma[c] * f64::from(e[c])).powi(2))
            .sum::<f64>()
            .sqrt()
    }));
    (scatter / stated, scatter / independent)
}
