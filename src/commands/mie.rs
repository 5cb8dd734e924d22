//! `photometeor mie`: one sphere's efficiencies, amplitudes and phase function.

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use mie::{
    FoldedAngles, Material, Sphere, ThetaGrid, amplitudes, exact_cosine_deg, phase_from_amplitudes,
    size_parameter,
};
use num_complex::Complex64;
use serde_json::json;

use crate::cli::{MaterialArg, parse_complex, parse_list};

#[derive(Debug, ClapArgs)]
pub struct MieArgs {
    /// Refractive index relative to the medium, e.g. 1.333+1e-8i (κ ≥ 0 absorbs).
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["material"])]
    m: Option<String>,
    /// Size parameter x = 2πr/λ, in [1e-6, 2e5].
    #[arg(long, allow_hyphen_values = true, requires = "m")]
    x: Option<f64>,
    /// Material instead of --m: water (IAPWS R9-97 + Segelstein) or ice (Warren & Brandt 2008).
    #[arg(long, value_enum, requires_all = ["radius_um", "wavelength_nm"])]
    material: Option<MaterialArg>,
    /// Sphere radius in µm (with --material).
    #[arg(long, allow_hyphen_values = true)]
    radius_um: Option<f64>,
    /// Vacuum wavelength in nm (with --material).
    #[arg(long, allow_hyphen_values = true)]
    wavelength_nm: Option<f64>,
    /// Water temperature in °C, [-12, 99] (default 20).
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true)]
    temperature_c: f64,
    /// Scattering angles in degrees, comma-separated, each in [0, 180].
    #[arg(long, allow_hyphen_values = true, conflicts_with = "angles_step_deg")]
    angles_deg: Option<String>,
    /// Full grid 0, D, 2D, …, 180 (D in degrees, in [0.01, 30] and dividing 180).
    #[arg(long, allow_hyphen_values = true)]
    angles_step_deg: Option<f64>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// θ (degrees) and their exactly folded cosines: a full grid of step `step`, or the listed
/// angles (default 0°, 90°, 180°).
pub fn angles_from(angles_deg: Option<String>, step: Option<f64>) -> Result<(Vec<f64>, Vec<f64>)> {
    if let Some(step) = step {
        let grid = ThetaGrid::new(step)?;
        return Ok((grid.thetas_deg(), grid.cosines()));
    }
    let angles = match angles_deg {
        Some(text) => parse_list("scattering angle", &text, "[0, 180] degrees")?,
        None => vec![0.0, 90.0, 180.0],
    };
    for &a in &angles {
        if !(a.is_finite() && (0.0..=180.0).contains(&a)) {
            bail!("scattering angle {a}° is outside the allowed range [0, 180] degrees");
        }
    }
    let mu = angles.iter().map(|&a| exact_cosine_deg(a)).collect();
    Ok((angles, mu))
}

pub fn run(a: MieArgs) -> Result<()> {
    let (m, x) = match (&a.m, a.x, a.material) {
        (Some(m), Some(x), None) => (parse_complex(m)?, x),
        (Some(_), None, _) => bail!("--m needs --x (size parameter, in [1e-6, 2e5])"),
        (None, _, Some(material)) => {
            let radius = a.radius_um.context("--material needs --radius-um")?;
            let lambda = a
                .wavelength_nm
                .context("--material needs --wavelength-nm")?;
            if !(radius.is_finite() && radius > 0.0) {
                bail!("radius {radius} µm is outside the allowed range (0, ∞)");
            }
            let m = Material::from(material).refractive_index(lambda, a.temperature_c)?;
            (m, size_parameter(radius, lambda))
        }
        _ => bail!("give either --m and --x, or --material with --radius-um and --wavelength-nm"),
    };
    let (angles, mu) = angles_from(a.angles_deg, a.angles_step_deg)?;
    let sphere = Sphere::new(m, x)?;
    let c = sphere.coefficients();
    let e = c.efficiencies();
    let (s1, s2) = amplitudes(&c, &FoldedAngles::new(&mu));
    let phase: Vec<f64> = s1
        .iter()
        .zip(&s2)
        .map(|(&a1, &a2)| phase_from_amplitudes(a1, a2, x, e.q_sca))
        .collect();
    if a.json {
        let pairs = |s: &[Complex64]| s.iter().map(|c| [c.re, c.im]).collect::<Vec<_>>();
        let out = json!({
            "m_re": m.re, "m_im": m.im, "x": x, "n_terms": e.n_terms,
            "qext": e.q_ext, "qsca": e.q_sca, "qabs": e.q_abs, "qback": e.q_back, "g": e.g,
            "angles_deg": angles, "phase": phase, "s1": pairs(&s1), "s2": pairs(&s2),
        });
        println!("{}", serde_json::to_string(&out)?);
    } else {
        println!("m = {} + {}i, x = {x}, terms = {}", m.re, m.im, e.n_terms);
        println!(
            "Q_ext = {:.9e}  Q_sca = {:.9e}  Q_abs = {:.9e}  Q_back = {:.9e}  g = {:.9}",
            e.q_ext, e.q_sca, e.q_abs, e.q_back, e.g
        );
        println!(
            "{:>10}  {:>16}  {:>34}  {:>34}",
            "θ (deg)", "p (1/sr)", "S1", "S2"
        );
        for k in 0..angles.len() {
            println!(
                "{:>10.4}  {:>16.9e}  {:>16.9e} {:>+16.9e}i  {:>16.9e} {:>+16.9e}i",
                angles[k], phase[k], s1[k].re, s1[k].im, s2[k].re, s2[k].im
            );
        }
    }
    Ok(())
}
