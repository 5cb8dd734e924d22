//! Argument definitions (clap derive) and the thin layer from arguments to library calls.

use anyhow::{Context, Result, bail};
use clap::{Args as ClapArgs, Parser, Subcommand};
use mie::{
    AngleGrid, BulkRequest, FoldedAngles, Material, NodeCounts, SizeDistribution, Sphere,
    amplitudes, bulk_phase, phase_from_amplitudes,
};
use num_complex::Complex64;
use serde_json::json;

/// Phase functions of cloud droplets, raindrops, ice and snow, and the multiple-scattering
/// tables real-time renderers need.
///
/// Conventions: θ is the scattering angle in degrees (0 = forward); refractive index
/// m = n + iκ with κ ≥ 0 absorbing; size parameter x = 2πr/λ; phase functions in 1/sr,
/// normalized so ∫ p dΩ = 1; radii in µm, wavelengths in nm (vacuum), cross-sections in m².
#[derive(Debug, Parser)]
#[command(name = "photometeor", version, about, long_about)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// One sphere: efficiencies, S1, S2 and the normalized phase function.
    Mie(MieArgs),
    /// A size distribution of water or ice spheres: σ_ext, albedo, g and the phase function
    /// averaged inside the bins of a uniform θ grid, per wavelength.
    Phase(PhaseArgs),
    /// Bake a scene's multiple-scattering tables: one EXR per field (rows Ams_1..Ams_N, columns
    /// θ_k = k·Δθ, channels R, G, B in 1/sr) and manifest.json. Unchanged fields come from the
    /// cache in DIR/.cache.
    Bake(BakeArgs),
    /// Summarize a bake directory (fields, sizes, F_i, n_iso, g, σ_ext, albedo).
    Inspect(InspectArgs),
    /// Compare two bakes of the same scene: rms and max relative error of Ams_1 and of all
    /// rows (bins θ ≥ --min-angle-deg), and the largest F_i difference, per field and channel.
    Compare(CompareArgs),
    /// Check a bake against theory from the fields' own refractive index and sizes: rainbow
    /// angles (Descartes + Airy shift), Alexander's dark band, supernumeraries, glory, first
    /// corona ring (Fraunhofer), 22°/46° halos (prism minimum deviation), snow without halos.
    /// Angles in degrees (scattering angle, 0 = forward). Exits 1 when a check fails.
    Validate(ValidateArgs),
    /// Draw a bake (PNG and SVG): Ams_1 per channel on a log scale (phase function, 1/sr,
    /// against scattering angle in degrees) with an optional reference bake overlaid, zooms on
    /// rainbows/glory/corona/halos, the Ams_n family, F_n against n, sRGB colour strips for
    /// n = 1, 2, 4, 8; and the Pareto front of a `tradeoff` run.
    Plot(crate::plot::PlotArgs),
    /// Measure the speed/accuracy trade: vary each bake knob alone from `standard`, bake and
    /// time each variant, compare it with a reference-quality bake (relative errors of Ams_n
    /// for θ ≥ 1°, |ΔF_i|, peak-angle shifts in degrees) and write a table and tradeoff.json.
    Tradeoff(crate::tradeoff::TradeoffArgs),
    /// Render a scene headless (Riley et al. 2004 §4–5): bake the fields its volumes use, then
    /// slice the volumes with a light buffer and an eye buffer on the GPU (wgpu; --cpu for the
    /// reference renderer), with the analytic sky and aerial perspective. Writes an HDR EXR
    /// (radiance per unit solar irradiance, 1/sr) and optionally a tone-mapped PNG.
    Render(crate::render::RenderArgs),
    /// Time photometeor's Mie workloads (and miepython's, side by side, when available).
    Bench(crate::bench::BenchArgs),
}

#[derive(Debug, ClapArgs)]
struct ValidateArgs {
    /// Bake directory (holding manifest.json).
    #[arg(default_value = "photometeor-tables")]
    dir: std::path::PathBuf,
    /// Print the checks as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, ClapArgs)]
struct BakeArgs {
    /// Scene file (TOML); default: the embedded default scene (cloud, rain, ice, snow).
    scene: Option<std::path::PathBuf>,
    /// Output directory (created if missing).
    #[arg(long, default_value = "photometeor-tables")]
    out: std::path::PathBuf,
    /// Accuracy preset, overriding the scene's. Measured rms error of Ams_1 (θ ≥ 1°) against
    /// `reference`: draft ≤ 5 % for drops (crystals more: Monte Carlo noise), standard ≤ 1 %
    /// for drops (crystals 1–3 %); README "Presets, measured" has the table.
    #[arg(long, value_parser = ["draft", "standard", "reference"])]
    quality: Option<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// No progress bars or summary.
    #[arg(long)]
    quiet: bool,
    /// Print the summary as JSON (fields computed and cached, seconds, peak memory).
    #[arg(long)]
    json: bool,
}

#[derive(Debug, ClapArgs)]
struct CompareArgs {
    /// The bake to judge.
    dir: std::path::PathBuf,
    /// The bake taken as truth (e.g. a `--quality reference` bake of the same scene).
    reference: std::path::PathBuf,
    /// Smallest scattering angle of the error statistics, in degrees (the forward bins hold
    /// the unresolved diffraction peak).
    #[arg(long, default_value_t = 1.0)]
    min_angle_deg: f64,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, ClapArgs)]
struct InspectArgs {
    /// A bake directory (holding manifest.json).
    dir: std::path::PathBuf,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, ClapArgs)]
struct MieArgs {
    /// Refractive index relative to the medium, e.g. 1.333+1e-8i (κ ≥ 0 absorbs).
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["material"])]
    m: Option<String>,
    /// Size parameter x = 2πr/λ, in (0, 2e5].
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
    /// Full grid 0, D, 2D, …, 180 (D in degrees, dividing 180).
    #[arg(long)]
    angles_step_deg: Option<f64>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum MaterialArg {
    Water,
    Ice,
}

impl From<MaterialArg> for Material {
    fn from(m: MaterialArg) -> Self {
        match m {
            MaterialArg::Water => Material::Water,
            MaterialArg::Ice => Material::Ice,
        }
    }
}

#[derive(Debug, ClapArgs)]
struct PhaseArgs {
    /// Particle material.
    #[arg(long, value_enum, default_value = "water")]
    material: MaterialArg,
    /// Lognormal median radius r_g in µm (with --sigma-g).
    #[arg(long, allow_hyphen_values = true, requires = "sigma_g")]
    lognormal_median_um: Option<f64>,
    /// Lognormal geometric standard deviation σ_g, in (1, 5].
    #[arg(long, allow_hyphen_values = true)]
    sigma_g: Option<f64>,
    /// Effective radius in µm (with --v-eff): gamma distribution, or lognormal with --lognormal.
    #[arg(long, allow_hyphen_values = true, requires = "v_eff")]
    r_eff_um: Option<f64>,
    /// Effective variance (with --r-eff-um).
    #[arg(long, allow_hyphen_values = true)]
    v_eff: Option<f64>,
    /// Use a lognormal (instead of gamma) for --r-eff-um/--v-eff.
    #[arg(long)]
    lognormal: bool,
    /// Marshall–Palmer raindrop spectrum for this rain rate in mm/h, [0.1, 500].
    #[arg(long, allow_hyphen_values = true)]
    marshall_palmer_mm_h: Option<f64>,
    /// Vacuum wavelengths in nm, comma-separated (water: 200–1100 nm).
    #[arg(long, allow_hyphen_values = true, required = true)]
    wavelengths_nm: String,
    /// Fixed number of sizes (nodes in ln r); default: adaptive to --tolerance.
    #[arg(long)]
    sizes: Option<usize>,
    /// Fixed Gauss nodes per angular panel (with --sizes; default 4).
    #[arg(long)]
    nodes_per_panel: Option<usize>,
    /// Adaptive refinement stops when one doubling changes the bins (rms, θ ≥ 1°), σ_ext or g
    /// by less than this.
    #[arg(long, default_value_t = 0.01)]
    tolerance: f64,
    /// Angle step of the output bins in degrees (must divide 180).
    #[arg(long, default_value_t = AngleGrid::DEFAULT_STEP_DEG)]
    angles_step_deg: f64,
    /// Water temperature in °C.
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true)]
    temperature_c: f64,
    /// Also report p̄ at these angles (degrees, comma-separated, in [0, 180]) as point values.
    #[arg(long, allow_hyphen_values = true)]
    angles_deg: Option<String>,
    /// Mass fraction of the distribution left outside the truncated size range.
    #[arg(long, default_value_t = 1e-3)]
    tail_mass: f64,
    /// Print JSON instead of a summary.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        Command::Mie(a) => run_mie(a),
        Command::Phase(a) => run_phase(a),
        Command::Bench(a) => crate::bench::run(a),
        Command::Render(a) => crate::render::run_render(a),
        Command::Bake(a) => run_bake(a),
        Command::Inspect(a) => run_inspect(a),
        Command::Compare(a) => run_compare(a),
        Command::Validate(a) => run_validate(a),
        Command::Tradeoff(a) => crate::tradeoff::run_tradeoff(a),
        Command::Plot(a) => crate::plot::run_plot(a),
    }
}

fn run_validate(a: ValidateArgs) -> Result<()> {
    use tables::validate::{Status, validate};
    let report = validate(&a.dir)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let num = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.3}"));
        println!(
            "{:<8} {:<3} {:<58} {:>9} {:>9} {:>7} {:<5} status",
            "field", "ch", "check", "measured", "expected", "± tol", "unit"
        );
        for c in &report.checks {
            let status = match c.status {
                Status::Pass => "pass",
                Status::Fail => "FAIL",
                Status::Info => "info",
            };
            let tol = c.tolerance.filter(|t| t.is_finite());
            println!(
                "{:<8} {:<3} {:<58} {:>9} {:>9} {:>7} {:<5} {status}  {}",
                c.field,
                c.channel,
                c.name,
                num(c.measured),
                num(c.expected),
                num(tol),
                c.unit,
                c.note
            );
        }
    }
    let failures = report.failures();
    if !failures.is_empty() {
        let names: Vec<String> = failures
            .iter()
            .map(|c| format!("{} {} {}", c.field, c.channel, c.name))
            .collect();
        eprintln!(
            "validate: {} check(s) failed: {}",
            failures.len(),
            names.join("; ")
        );
        std::process::exit(1);
    }
    Ok(())
}

fn run_bake(a: BakeArgs) -> Result<()> {
    use tables::scene::{Quality, Scene};
    let scene = Scene::from_file_or_default(a.scene.as_deref())?;
    let quality = match a.quality.as_deref() {
        Some(q) => Quality::parse(q).context("quality preset")?,
        None => scene.quality,
    };
    if a.jobs == Some(0) {
        bail!("--jobs 0 is outside the allowed range [1, ∞)");
    }
    let plan = tables::bake::BakePlan::for_preset(scene, a.out.clone(), quality, a.quiet);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.jobs.unwrap_or(0))
        .build()
        .context("building the thread pool")?;
    let report = pool.install(|| tables::bake::run(&plan))?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else if !a.quiet {
        println!(
            "baked {} into {} in {:.1} s (computed: {:?}, from cache: {:?}); peak memory {}",
            plan.scene.name,
            plan.out_dir.display(),
            report.seconds,
            report.computed,
            report.cached,
            report
                .peak_rss_mib
                .map_or("unknown".to_string(), |m| format!("{m:.0} MiB"))
        );
    }
    Ok(())
}

fn run_compare(a: CompareArgs) -> Result<()> {
    let report = tables::bake::compare(&a.dir, &a.reference, a.min_angle_deg)?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} against {} (θ ≥ {}°):",
        a.dir.display(),
        a.reference.display(),
        a.min_angle_deg
    );
    println!(
        "  {:<10} {:>2}  {:>12} {:>12} {:>12} {:>12} {:>10}",
        "field", "ch", "rms Ams_1", "max Ams_1", "rms all n", "max all n", "max |ΔF_i|"
    );
    for f in &report.fields {
        println!(
            "  {:<10} {:>2}  {:>12.3e} {:>12.3e} {:>12.3e} {:>12.3e} {:>10.2e}",
            f.field,
            f.channel,
            f.rms_rel_ams1,
            f.max_rel_ams1,
            f.rms_rel_all,
            f.max_rel_all,
            f.max_abs_forward_fraction
        );
    }
    Ok(())
}

fn run_inspect(a: InspectArgs) -> Result<()> {
    let manifest = tables::manifest::read_manifest(&a.dir)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&manifest)?);
        return Ok(());
    }
    println!(
        "{}: schema {}, {} {}, Δθ = {}°, {} angles",
        a.dir.display(),
        manifest.schema,
        manifest.tool,
        manifest.tool_version,
        manifest.theta_step_deg,
        manifest.angle_count
    );
    for f in &manifest.fields {
        println!(
            "  {:<10} {:<5} {:<14} N = {:<4} g = {:.4}/{:.4}/{:.4}  σ_ext = {:.3e} m²  F_1 = {:.4}  F_N = {:.4}  n_iso(1e-6) = {:?}",
            f.name,
            f.kind,
            f.file,
            f.n_max,
            f.g.r,
            f.g.g,
            f.g.b,
            f.sigma_ext_m2.g,
            f.forward_fraction.g[0],
            f.forward_fraction.g[f.n_max - 1],
            f.n_isotropic.g.get("1e-6").copied().flatten()
        );
    }
    Ok(())
}

/// Parses "1.333+1e-8i", "1.5-0.1j", "1.33": real part, then an optional signed imaginary part.
pub fn parse_complex(text: &str) -> Result<Complex64> {
    let t = text.trim();
    let bad = || {
        anyhow::anyhow!(
            "refractive index m = {text:?} is not a complex number like 1.333+1e-8i (n + iκ, κ ≥ 0)"
        )
    };
    let body = t.strip_suffix(['i', 'j']);
    let Some(body) = body else {
        return t
            .parse::<f64>()
            .map(|re| Complex64::new(re, 0.0))
            .map_err(|_| bad());
    };
    // The sign that starts the imaginary part: the last + or − not at the start and not
    // directly after an exponent marker.
    let bytes = body.as_bytes();
    let split = (1..bytes.len())
        .rev()
        .find(|&i| (bytes[i] == b'+' || bytes[i] == b'-') && !matches!(bytes[i - 1], b'e' | b'E'))
        .ok_or_else(bad)?;
    let re: f64 = body[..split].parse().map_err(|_| bad())?;
    let im_text = &body[split..];
    let im: f64 = if im_text == "+" || im_text == "-" {
        format!("{im_text}1").parse().map_err(|_| bad())?
    } else {
        im_text.parse().map_err(|_| bad())?
    };
    Ok(Complex64::new(re, im))
}

/// Parses a comma-separated list of numbers; `what` names the list in errors.
pub fn parse_list(what: &str, text: &str, allowed: &str) -> Result<Vec<f64>> {
    let items: Vec<&str> = text
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .collect();
    if items.is_empty() {
        bail!("{what} list is empty; give at least one value in {allowed}");
    }
    items
        .iter()
        .map(|t| {
            t.parse::<f64>().map_err(|_| {
                anyhow::anyhow!("{what} {t:?} is not a number; allowed range {allowed}")
            })
        })
        .collect()
}

fn angles_from(angles_deg: Option<String>, step: Option<f64>) -> Result<(Vec<f64>, Vec<f64>)> {
    if let Some(step) = step {
        let grid = AngleGrid::new(step)?;
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
    // Fold exactly: θ > 90° uses −cos(180° − θ) so ± pairs are shared and 90° gives 0.
    let mu = angles
        .iter()
        .map(|&a| {
            if a == 90.0 {
                0.0
            } else if a > 90.0 {
                -(180.0 - a).to_radians().cos()
            } else {
                a.to_radians().cos()
            }
        })
        .collect();
    Ok((angles, mu))
}

fn run_mie(a: MieArgs) -> Result<()> {
    let (m, x) = match (&a.m, a.x, a.material) {
        (Some(m), Some(x), None) => (parse_complex(m)?, x),
        (Some(_), None, _) => bail!("--m needs --x (size parameter, in (0, 2e5])"),
        (None, _, Some(material)) => {
            let radius = a.radius_um.context("--material needs --radius-um")?;
            let lambda = a
                .wavelength_nm
                .context("--material needs --wavelength-nm")?;
            if !(radius.is_finite() && radius > 0.0) {
                bail!("radius {radius} µm is outside the allowed range (0, ∞)");
            }
            let m = Material::from(material).refractive_index(lambda, a.temperature_c)?;
            (m, 2.0 * std::f64::consts::PI * radius * 1000.0 / lambda)
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

/// Chooses the size distribution from the mutually exclusive flag groups.
fn distribution_from(a: &PhaseArgs) -> Result<SizeDistribution> {
    let chosen = [
        a.lognormal_median_um.is_some(),
        a.r_eff_um.is_some(),
        a.marshall_palmer_mm_h.is_some(),
    ]
    .iter()
    .filter(|&&c| c)
    .count();
    if chosen != 1 {
        bail!(
            "choose exactly one size distribution: --lognormal-median-um with --sigma-g, \
             --r-eff-um with --v-eff, or --marshall-palmer-mm-h"
        );
    }
    let d = if let Some(median) = a.lognormal_median_um {
        SizeDistribution::Lognormal {
            median_radius_um: median,
            sigma_g: a.sigma_g.context("--lognormal-median-um needs --sigma-g")?,
        }
    } else if let Some(r_eff) = a.r_eff_um {
        let v_eff = a.v_eff.context("--r-eff-um needs --v-eff")?;
        if a.lognormal {
            SizeDistribution::lognormal_from_effective(r_eff, v_eff)?
        } else {
            SizeDistribution::Gamma {
                r_eff_um: r_eff,
                v_eff,
            }
        }
    } else {
        SizeDistribution::MarshallPalmer {
            rain_rate_mm_h: a.marshall_palmer_mm_h.unwrap_or_default(),
        }
    };
    Ok(d.validated()?)
}

fn run_phase(a: PhaseArgs) -> Result<()> {
    let wavelengths_nm = parse_list("wavelength (nm)", &a.wavelengths_nm, "[200, 1100] nm")?;
    let distribution = distribution_from(&a)?;
    let nodes = match (a.sizes, a.nodes_per_panel) {
        (Some(sizes), nodes) => {
            if sizes == 0 {
                bail!("--sizes 0 is outside the allowed range [1, ∞)");
            }
            NodeCounts::Fixed {
                sizes,
                nodes_per_panel: nodes.unwrap_or(4).max(1),
            }
        }
        (None, Some(_)) => bail!("--nodes-per-panel needs --sizes (fixed node counts)"),
        (None, None) => {
            if !(a.tolerance > 0.0 && a.tolerance < 1.0) {
                bail!(
                    "--tolerance {} is outside the allowed range (0, 1)",
                    a.tolerance
                );
            }
            NodeCounts::Adaptive {
                tolerance: a.tolerance,
                max_sizes: 1 << 14,
            }
        }
    };
    let (point_angles_deg, point_cosines) = match &a.angles_deg {
        Some(text) => angles_from(Some(text.clone()), None)?,
        None => (Vec::new(), Vec::new()),
    };
    let request = BulkRequest {
        material: a.material.into(),
        temperature_c: a.temperature_c,
        distribution,
        wavelengths_nm,
        grid: AngleGrid::new(a.angles_step_deg)?,
        nodes,
        tail_mass: a.tail_mass,
        point_cosines,
    };
    let result = bulk_phase(&request)?;
    if a.json {
        let out = json!({
            "material": request.material,
            "temperature_c": request.temperature_c,
            "distribution": request.distribution,
            "theta_step_deg": request.grid.step_deg(),
            "angles_deg": request.grid.thetas_deg(),
            "point_angles_deg": point_angles_deg,
            "node_counts": request.nodes,
            "tail_mass": request.tail_mass,
            "wavelengths": result,
        });
        println!("{}", serde_json::to_string(&out)?);
    } else {
        println!(
            "{} {}, {} bins of {}°",
            request.material.name(),
            request.distribution.describe(),
            request.grid.len(),
            request.grid.step_deg()
        );
        println!(
            "{:>8} {:>22} {:>13} {:>10} {:>9} {:>6} {:>6} {:>11}",
            "λ (nm)", "m", "σ_ext (m²)", "albedo", "g", "sizes", "nodes", "energy-1"
        );
        for r in &result {
            println!(
                "{:>8} {:>22} {:>13.6e} {:>10.8} {:>9.6} {:>6} {:>6} {:>11.2e}",
                r.wavelength_nm,
                format!("{:.5}+{:.3e}i", r.m_re, r.m_im),
                r.sigma_ext_m2,
                r.albedo,
                r.g,
                r.sizes,
                r.nodes_per_panel,
                r.energy_closure
            );
        }
        if !point_angles_deg.is_empty() {
            println!("p̄ (1/sr) at the requested angles:");
            for (k, theta) in point_angles_deg.iter().enumerate() {
                let values: Vec<String> = result
                    .iter()
                    .map(|r| format!("{:>14.6e}", r.points[k]))
                    .collect();
                println!("{theta:>10.4}° {}", values.join(" "));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_complex_indices() {
        assert_eq!(
            parse_complex("1.333+1e-8i").unwrap(),
            Complex64::new(1.333, 1e-8)
        );
        assert_eq!(
            parse_complex("1.5-0.1j").unwrap(),
            Complex64::new(1.5, -0.1)
        );
        assert_eq!(parse_complex("1.33").unwrap(), Complex64::new(1.33, 0.0));
        assert_eq!(
            parse_complex("1e0+1E-3i").unwrap(),
            Complex64::new(1.0, 1e-3)
        );
        assert!(parse_complex("1.3+xi").is_err());
        assert!(parse_complex("abc").is_err());
    }
}
