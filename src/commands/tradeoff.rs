//! `photometeor tradeoff`: the measured speed/accuracy trade. Every knob of the bake is varied
//! alone from the `standard` preset, each variant is baked from scratch and timed, and its
//! tables are compared with a `reference`-quality bake of the same scene: rms and max relative
//! error of Ams_1 and of all rows (θ ≥ 1°), the largest |ΔF_i|, and the largest shift of a
//! validated peak angle (rainbows, glory/corona ring, halos). Drop knobs are varied on the
//! scene's sphere fields and the ray count on its crystal fields, so no variant pays for work
//! its knob does not touch.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bake::compare::{ChannelError, compare};
use bake::scene::SpectralMode as Spectral;
use bake::validate::{Report as ValidationReport, validate};
use bake::{BakePlan, FieldKind, Knobs, Quality, Scene, Silent};
use clap::Args as ClapArgs;
use serde::Serialize;

#[derive(Debug, ClapArgs)]
pub struct TradeoffArgs {
    /// Scene file (TOML); default: the embedded default scene.
    scene: Option<PathBuf>,
    /// Working directory: one bake per variant, the reference bake and tradeoff.json.
    #[arg(long, default_value = "photometeor-tradeoff")]
    out: PathBuf,
    /// Use this existing reference-quality bake of the same scene instead of baking one.
    #[arg(long)]
    reference: Option<PathBuf>,
    /// Fewer variants (one step each way from standard) for a quick look.
    #[arg(long)]
    quick: bool,
}

/// One measured variant.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Which knob was varied ("preset" for the presets themselves).
    pub knob: String,
    pub value: String,
    /// "drops" or "crystals": the fields this variant baked.
    pub fields: &'static str,
    pub seconds: f64,
    pub rms_rel_ams1: f64,
    pub max_rel_ams1: f64,
    pub rms_rel_all: f64,
    pub max_abs_forward_fraction: f64,
    /// Largest |Δ| of a validated peak angle against the reference (degrees); None without one.
    pub max_peak_shift_deg: Option<f64>,
}

struct Variant {
    knob: &'static str,
    value: String,
    drops: bool,
    knobs: Knobs,
    wavelengths: Option<usize>,
}

/// Runs `photometeor tradeoff`.
pub fn run(a: TradeoffArgs) -> Result<()> {
    let scene = Scene::from_file_or_default(a.scene.as_deref())?;
    if scene.fields.iter().all(|f| group(f.kind).is_none()) {
        anyhow::bail!(
            "scene {}: nothing to trade: its fields are given phase functions (hg, tabulated), \
             which no knob of the bake changes",
            scene.name
        );
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let reference = reference_bake(&a, &scene)?;
    let reference_checks = validate(&reference)?;
    let standard = standard_knobs(&scene);
    let variants = variants(&scene, standard, a.quick);
    let mut rows = Vec::new();
    for (i, v) in variants.iter().enumerate() {
        eprintln!(
            "tradeoff: {} = {} on {} ({}/{})",
            v.knob,
            v.value,
            fields_name(v.drops),
            i + 1,
            variants.len()
        );
        let dir = a.out.join(format!("variant-{i:02}"));
        rows.push(measure(&scene, v, &dir, &reference, &reference_checks)?);
    }
    print_table(&rows);
    write_json(&a.out, &scene, &reference, standard, &rows)
}

/// The reference bake: `--reference`, or a bake at reference quality into the working
/// directory.
fn reference_bake(a: &TradeoffArgs, scene: &Scene) -> Result<PathBuf> {
    Ok(match &a.reference {
        Some(r) => r.clone(),
        None => {
            let dir = a.out.join("reference");
            eprintln!("tradeoff: baking the reference ({})", dir.display());
            bake_variant(
                scene,
                &dir,
                Quality::Reference,
                Quality::Reference.knobs_for(&scene.spectral),
            )?;
            dir
        }
    })
}

/// The group a field of this kind is traded in: drops (spheres, `Some(true)`) or crystals
/// (`Some(false)`); none for a given phase function (hg, tabulated), which no knob changes.
fn group(kind: FieldKind) -> Option<bool> {
    match kind {
        FieldKind::Cloud | FieldKind::Rain | FieldKind::Haze => Some(true),
        FieldKind::Ice | FieldKind::Snow => Some(false),
        FieldKind::Hg | FieldKind::Tabulated => None,
    }
}

/// "drops" or "crystals".
fn fields_name(drops: bool) -> &'static str {
    if drops { "drops" } else { "crystals" }
}

/// The knobs every variant moves one of: the standard preset's, the drops at its fixed size
/// count (no size noise target, whose pilot would choose the sizes anew for every variant).
fn standard_knobs(scene: &Scene) -> Knobs {
    Knobs {
        size_noise: 0.0,
        ..Quality::Standard.knobs_for(&scene.spectral)
    }
}

/// Every variant, in the order they are baked: the presets, then one knob moved at a time from
/// `standard`, on the drops and on the crystals (each where the scene has such fields); fewer
/// values with `quick`.
fn variants(scene: &Scene, standard: Knobs, quick: bool) -> Vec<Variant> {
    let has = |drops: bool| scene.fields.iter().any(|f| group(f.kind) == Some(drops));
    let mut variants = Vec::new();
    for drops in [true, false] {
        if !has(drops) {
            continue;
        }
        for q in [Quality::Draft, Quality::Standard] {
            variants.push(Variant {
                knob: "preset",
                value: format!("{q:?}").to_lowercase(),
                drops,
                knobs: q.knobs_for(&scene.spectral),
                wavelengths: None,
            });
        }
    }
    if has(true) {
        variants.extend(drop_variants(scene, standard, quick));
    }
    if has(false) {
        variants.extend(crystal_variants(standard, quick));
    }
    variants
}

/// The values a knob takes: all of `full`, or `few` with `quick`.
fn pick(quick: bool, full: Vec<f64>, few: Vec<f64>) -> Vec<f64> {
    if quick { few } else { full }
}

/// The drop knobs moved one at a time: sizes, Gauss nodes, the blur of the j ≥ 2 terms and
/// (spectral scenes) the wavelength count.
fn drop_variants(scene: &Scene, standard: Knobs, quick: bool) -> Vec<Variant> {
    let mut variants = Vec::new();
    let mut push = |knob, value, knobs, wavelengths| {
        variants.push(Variant {
            knob,
            value,
            drops: true,
            knobs,
            wavelengths,
        })
    };
    for s in pick(quick, vec![32.0, 100.0, 1600.0], vec![100.0]) {
        let knobs = Knobs {
            sizes: s as usize,
            ..standard
        };
        push("sizes per λ", format!("{s}"), knobs, None);
    }
    for n in pick(quick, vec![1.0, 4.0], vec![1.0]) {
        let knobs = Knobs {
            nodes_per_panel: n as usize,
            ..standard
        };
        push("nodes per angular panel", format!("{n}"), knobs, None);
    }
    for b in pick(quick, vec![0.25, 0.5, 1.0], vec![0.5]) {
        let knobs = Knobs {
            reconstruction: tables::ams::Reconstruction::HeatKernel { blur_bins: b },
            ..standard
        };
        push(
            "j ≥ 2 terms: steps blurred by (bins)",
            format!("{b}"),
            knobs,
            None,
        );
    }
    if matches!(scene.spectral, Spectral::Spectral { .. }) {
        for w in pick(quick, vec![8.0, 16.0], vec![16.0]) {
            push("wavelengths", format!("{w}"), standard, Some(w as usize));
        }
    }
    variants
}

/// The crystal knobs moved one at a time: the noise target, the rays without one, the tracer's
/// variance-reduction levers (mie::crystal::trace docs) and the tilt splits.
fn crystal_variants(standard: Knobs, quick: bool) -> Vec<Variant> {
    use mie::crystal::Sampling;
    let mut variants = Vec::new();
    let mut push = |knob, value, knobs| {
        variants.push(Variant {
            knob,
            value,
            drops: false,
            knobs,
            wavelengths: None,
        })
    };
    for n in pick(quick, vec![0.02, 0.0045], vec![0.02]) {
        let knobs = Knobs {
            crystal_noise: n,
            ..standard
        };
        push("crystal noise target", format!("{n}"), knobs);
    }
    for r in pick(quick, vec![1.5e5, 6e5, 2.4e6], vec![1.5e5]) {
        let knobs = Knobs {
            rays: r as u64,
            crystal_noise: 0.0,
            ..standard
        };
        push("rays per λ (no noise target)", format!("{r:e}"), knobs);
    }
    for (value, sampling, symmetric) in [
        ("sobol", Sampling::Sobol, false),
        ("random, fundamental domain", Sampling::Random, true),
        ("sobol, fundamental domain", Sampling::Sobol, true),
    ] {
        if quick && value != "sobol, fundamental domain" {
            continue;
        }
        let knobs = Knobs {
            ray_sampling: sampling,
            ray_symmetric: symmetric,
            rays: 600_000,
            crystal_noise: 0.0,
            ..standard
        };
        push("ray sampling", value.to_string(), knobs);
    }
    for k in pick(quick, vec![1.0, 2.0, 8.0], vec![1.0]) {
        let knobs = Knobs {
            tilt_splits: k as u32,
            rays: 600_000,
            crystal_noise: 0.0,
            ..standard
        };
        push("tilt splits (distorted crystals)", format!("{k}"), knobs);
    }
    variants
}

/// Bakes variant `v` of `scene` (its drop or its crystal fields) from scratch into `dir`, and
/// measures it against the reference bake and its validation checks.
fn measure(
    scene: &Scene,
    v: &Variant,
    dir: &Path,
    reference: &Path,
    reference_checks: &ValidationReport,
) -> Result<Row> {
    let mut s = scene.clone();
    s.fields.retain(|f| group(f.kind) == Some(v.drops));
    if let (Some(w), Spectral::Spectral { min_nm, max_nm, .. }) = (v.wavelengths, s.spectral) {
        s.spectral = Spectral::Spectral {
            count: w,
            min_nm,
            max_nm,
        };
    }
    let seconds = bake_variant(&s, dir, Quality::Standard, v.knobs)?;
    let cmp = compare(dir, reference, 1.0)?;
    let worst = |f: &dyn Fn(&ChannelError) -> f64| cmp.fields.iter().map(f).fold(0.0, f64::max);
    let checks = validate(dir)?;
    let shift = checks
        .checks
        .iter()
        .filter(|c| c.unit == "deg" && c.expected.is_some())
        .filter_map(|c| {
            let r = reference_checks
                .checks
                .iter()
                .find(|r| r.field == c.field && r.channel == c.channel && r.name == c.name)?;
            Some((c.measured? - r.measured?).abs())
        })
        .reduce(f64::max);
    Ok(Row {
        knob: v.knob.into(),
        value: v.value.clone(),
        fields: fields_name(v.drops),
        seconds,
        rms_rel_ams1: worst(&|e| e.rms_rel_ams1),
        max_rel_ams1: worst(&|e| e.max_rel_ams1),
        rms_rel_all: worst(&|e| e.rms_rel_all),
        max_abs_forward_fraction: worst(&|e| e.max_abs_forward_fraction),
        max_peak_shift_deg: shift,
    })
}

/// Writes the rows with the scene, the reference and the standard knobs to
/// `out/tradeoff.json`.
fn write_json(
    out: &Path,
    scene: &Scene,
    reference: &Path,
    standard: Knobs,
    rows: &[Row],
) -> Result<()> {
    let json = serde_json::json!({
        "scene": scene.name,
        "reference": reference.display().to_string(),
        "standard_knobs": standard,
        "rows": rows,
    });
    let path = out.join("tradeoff.json");
    std::fs::write(&path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "tradeoff: wrote {} (plot it with `photometeor plot --tradeoff`)",
        path.display()
    );
    Ok(())
}

fn bake_variant(scene: &Scene, dir: &Path, quality: Quality, knobs: Knobs) -> Result<f64> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).with_context(|| format!("clearing {}", dir.display()))?;
    }
    let plan = BakePlan {
        scene: scene.clone(),
        out_dir: dir.to_path_buf(),
        quality,
        knobs,
        prune: true,
    };
    let start = Instant::now();
    let report = bake::run(&plan, &Silent)?;
    if report.computed.len() != scene.fields.len() {
        bail!("{}: fields were read from a cache", dir.display());
    }
    Ok(start.elapsed().as_secs_f64())
}

/// The table as Markdown (docs/accuracy.md takes it as printed).
pub fn print_table(rows: &[Row]) {
    println!(
        "| fields | knob | value | time (s) | rms Ams_1 | max Ams_1 | rms all n | max ΔF_i | max peak shift (°) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        println!(
            "| {} | {} | {} | {:.1} | {:.2} % | {:.1} % | {:.2} % | {:.1e} | {} |",
            r.fields,
            r.knob,
            r.value,
            r.seconds,
            100.0 * r.rms_rel_ams1,
            100.0 * r.max_rel_ams1,
            100.0 * r.rms_rel_all,
            r.max_abs_forward_fraction,
            r.max_peak_shift_deg
                .map_or("—".to_string(), |s| format!("{s:.3}"))
        );
    }
}
