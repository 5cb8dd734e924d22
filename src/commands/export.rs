//! `photometeor export`: a bake's Ams_n rows in the formats other programs load (Bevy's
//! chromatic phase texture as KTX2 and EXR, Mitsuba 3's `tabphase`, NumPy arrays, CSV), with
//! what the conversion costs in accuracy (`runtime::export`).
//!
//! Everything is computed and checked first; the files are written into a staging directory
//! beside `--out`, which then replaces it in one rename, so a failure leaves nothing
//! half-written.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use format::FieldKind;
use runtime::export::{
    Cost, Lobes, asymmetry, cost, fit_dual_hg, fit_hg, resample, rms_relative, samples_for,
    strip_forward_peak,
};
use runtime::{FieldTable, Tables};
use serde_json::json;

/// Where the files go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// `<field>.ams<n>.ktx2` and `.exr`: Bevy's chromatic phase texture, N × 1 Rgba32Float,
    /// columns linear in cos θ from θ = 180° (first) to 0° (last), A = 1; and
    /// `phase_curve.wgsl`, a WGSL function that samples it.
    Bevy,
    /// `<field>.xml` (one `tabphase` per order and channel, values linear in cos θ from −1 to
    /// 1, and a homogeneous medium) and `mitsuba.json` (the same values, for Python).
    Mitsuba,
    /// `theta_deg.npy` and `<field>.ams.npy` (orders × R, G, B × θ bins, 1/sr) on the bake's
    /// own grid, no resampling.
    Npy,
    /// `<field>.csv`: θ in degrees, then Ams_n per order and channel, on the bake's own grid.
    Csv,
    /// Henyey–Greenstein at the table's own g, and the best-fit lobe and dual lobe
    /// w HG(g1) + (1 − w) HG(g2) per field, order and channel (the phase functions Unreal, Unity HDRP and Godot expose), fitted for
    /// the least light in a wrong θ bin, with what they lose: that light, the rms relative
    /// error for θ ≥ 1°, and the height kept of each optical feature (rainbow, glory, fogbow,
    /// halos, forward peak); `<field>.lobes.png` and `.svg` draw them against Ams_n.
    Hg,
}

/// What to do with the forward peak a grid in cos θ cannot hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ForwardPeak {
    /// Per field, `keep` if some sample count within the format's limit meets --max-loss,
    /// else `strip` if one does, else whichever loses less at the limit, written with its loss
    /// reported; the bake's own θ grid (npy, csv, hg) keeps the row.
    Auto,
    /// Export the row as it is (the peak is spread over the last cell; its cost is reported).
    Keep,
    /// δ-scaling: take the peak's excess f over the next bin out, renormalise, and report the
    /// medium's scaled σ_ext (1 − α f) and albedo α (1 − f)/(1 − α f) to use with it.
    Strip,
}

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// A bake directory (holding manifest.json).
    dir: PathBuf,
    /// Output format.
    #[arg(long, value_enum)]
    format: ExportFormat,
    /// Output directory (created; an earlier export there is replaced, any other non-empty
    /// directory is refused).
    #[arg(long)]
    out: PathBuf,
    /// Fields to export, comma-separated (default: every field of the bake); a swept field's
    /// name takes its members, and npy then also writes the sweep as one axis
    /// (`<sweep>.ams.npy`, values × orders × R, G, B × θ, and `<sweep>.values.npy`).
    #[arg(long, value_delimiter = ',')]
    fields: Vec<String>,
    /// Scattering orders n of Ams_n, comma-separated, each in [1, N] (N: the bake's rows).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    orders: Vec<usize>,
    /// Values per table on the cos θ grid (bevy, mitsuba), in [2, the format's limit: 8192
    /// texels for bevy, wgpu's default texture width; 262145 for mitsuba]. Default: the
    /// smallest 2^k + 1 that keeps the light moved to a wrong bin under --max-loss.
    #[arg(long)]
    samples: Option<usize>,
    /// The most light a resampling may move to a wrong θ bin, as a fraction of the scattered
    /// light (0, 1); chooses --samples when it is not given, and the export is refused when no
    /// sample count within the format's limit meets it.
    #[arg(long, default_value_t = 0.01)]
    max_loss: f64,
    /// What to do with the forward peak a grid in cos θ cannot hold (bevy, mitsuba).
    #[arg(long, value_enum, default_value_t = ForwardPeak::Auto)]
    forward_peak: ForwardPeak,
    /// Print the report as JSON (it is also written to OUT/export.json).
    #[arg(long)]
    json: bool,
}

impl ForwardPeak {
    fn name(self) -> &'static str {
        match self {
            ForwardPeak::Auto => "auto",
            ForwardPeak::Keep => "keep",
            ForwardPeak::Strip => "strip",
        }
    }
}

impl ExportFormat {
    fn name(self) -> &'static str {
        match self {
            ExportFormat::Bevy => "bevy",
            ExportFormat::Mitsuba => "mitsuba",
            ExportFormat::Npy => "npy",
            ExportFormat::Csv => "csv",
            ExportFormat::Hg => "hg",
        }
    }

    /// The most values a table may have on the cos θ grid; `None`: the bake's own grid.
    fn max_samples(self) -> Option<usize> {
        match self {
            ExportFormat::Bevy => Some(8192),
            ExportFormat::Mitsuba => Some((1 << 18) + 1),
            ExportFormat::Npy | ExportFormat::Csv | ExportFormat::Hg => None,
        }
    }
}

const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// One field's rows to export: the forward-peak treatment chosen for it (keep or strip), and
/// per order, per channel, the row after it and the forward peak taken out.
struct FieldRows<'a> {
    field: &'a FieldTable,
    treatment: ForwardPeak,
    rows: Vec<[Vec<f64>; 3]>,
    stripped: Vec<[f64; 3]>,
}

impl FieldRows<'_> {
    /// Every row, each order's channels in turn.
    fn all(&self) -> Vec<&[f64]> {
        self.rows
            .iter()
            .flat_map(|r| r.iter().map(|v| v.as_slice()))
            .collect()
    }

    /// The sample count on the cos θ grid (--samples, or the smallest that meets --max-loss
    /// within `max`) and the worst cost there.
    fn samples(&self, a: &ExportArgs, step: f64, max: usize) -> (usize, Cost) {
        let all = self.all();
        match a.samples {
            Some(n) => (n, worst_cost(&all, step, n)),
            None => samples_for(&all, step, a.max_loss, max),
        }
    }
}

/// The worst cost over `rows` resampled to `n` values.
fn worst_cost(rows: &[&[f64]], step: f64, n: usize) -> Cost {
    rows.iter()
        .map(|r| cost(r, step, &resample(r, step, n)))
        .max_by(|x, y| x.moved.total_cmp(&y.moved))
        .expect("at least one row")
}

/// `field`'s rows under the forward-peak treatment --forward-peak asks for, or for `auto`
/// the one that meets --max-loss (see [`ForwardPeak::Auto`]).
fn choose_rows<'a>(t: &'a Tables, field: &'a FieldTable, a: &ExportArgs) -> FieldRows<'a> {
    let step = t.theta_step_deg;
    match (a.forward_peak, a.format.max_samples()) {
        (ForwardPeak::Auto, None) => rows_of(t, field, a, ForwardPeak::Keep),
        (ForwardPeak::Auto, Some(max)) => {
            let keep = rows_of(t, field, a, ForwardPeak::Keep);
            let (_, kept) = keep.samples(a, step, max);
            if kept.moved <= a.max_loss {
                return keep;
            }
            let strip = rows_of(t, field, a, ForwardPeak::Strip);
            let (_, stripped) = strip.samples(a, step, max);
            if stripped.moved <= a.max_loss || stripped.moved < kept.moved {
                strip
            } else {
                keep
            }
        }
        (treatment, _) => rows_of(t, field, a, treatment),
    }
}

fn rows_of<'a>(
    t: &'a Tables,
    field: &'a FieldTable,
    a: &ExportArgs,
    treatment: ForwardPeak,
) -> FieldRows<'a> {
    let mut rows = Vec::new();
    let mut stripped = Vec::new();
    for &n in &a.orders {
        let mut r: [Vec<f64>; 3] = Default::default();
        let mut s = [0.0; 3];
        for c in 0..3 {
            let row: Vec<f64> = (0..t.angle_count)
                .map(|k| field.image.ams[[c, n - 1, k]])
                .collect();
            (r[c], s[c]) = match treatment {
                ForwardPeak::Strip => strip_forward_peak(&row, t.theta_step_deg),
                ForwardPeak::Keep | ForwardPeak::Auto => (row, 0.0),
            };
        }
        rows.push(r);
        stripped.push(s);
    }
    FieldRows {
        field,
        treatment,
        rows,
        stripped,
    }
}

/// Refuses bad arguments before any work, naming the value and the allowed range.
fn check(a: &ExportArgs, t: &Tables) -> Result<()> {
    if !(a.max_loss > 0.0 && a.max_loss < 1.0) {
        bail!("--max-loss {} is outside (0, 1)", a.max_loss);
    }
    if a.orders.is_empty() {
        bail!("--orders is empty: give at least one order n ≥ 1");
    }
    for name in &a.fields {
        if t.field(name).is_none() && !t.sweeps.iter().any(|s| &s.name == name) {
            let have: Vec<&str> = t
                .fields
                .iter()
                .map(|f| f.name.as_str())
                .chain(t.sweeps.iter().map(|s| s.name.as_str()))
                .collect();
            bail!(
                "--fields: the bake has no field or sweep {name:?} (it has {})",
                have.join(", ")
            );
        }
    }
    for f in selected(t, a) {
        for &n in &a.orders {
            if n < 1 || n > f.n_max() {
                bail!(
                    "--orders: n = {n} is outside [1, {}], the rows of field {:?}",
                    f.n_max(),
                    f.name
                );
            }
        }
    }
    match (a.samples, a.format.max_samples()) {
        (Some(s), Some(max)) if !(2..=max).contains(&s) => bail!(
            "--samples {s} is outside [2, {max}] for --format {}",
            a.format.name()
        ),
        (Some(_), None) => bail!(
            "--samples applies to bevy and mitsuba; --format {} writes the bake's own θ grid",
            a.format.name()
        ),
        _ => {}
    }
    // Not a file, not the bake or inside it, not a directory holding it (an earlier export
    // there is replaced whole).
    format::check_output_dir(&a.out, &[&a.dir]).context("--out")?;
    if a.out.exists() {
        let earlier = a.out.join("export.json").is_file();
        let empty = std::fs::read_dir(&a.out)?.next().is_none();
        if !earlier && !empty {
            bail!(
                "--out {} is a non-empty directory that holds no earlier export (no export.json); \
                 refusing to replace it",
                a.out.display()
            );
        }
    }
    Ok(())
}

/// The fields `--fields` names (a sweep's name stands for its members), in the bake's order;
/// every field by default.
fn selected<'a>(t: &'a Tables, a: &ExportArgs) -> Vec<&'a FieldTable> {
    let named = |f: &FieldTable| {
        a.fields.iter().any(|n| {
            *n == f.name
                || t.sweeps
                    .iter()
                    .any(|s| &s.name == n && s.fields.contains(&f.name))
        })
    };
    t.fields
        .iter()
        .filter(|f| a.fields.is_empty() || named(f))
        .collect()
}

/// One table's values on the cos θ grid and its cost per channel.
struct Resampled {
    values: [Vec<f64>; 3],
    cost: [Cost; 3],
}

pub fn run(a: ExportArgs) -> Result<()> {
    let t = Tables::open(&a.dir)?;
    check(&a, &t)?;
    let step = t.theta_step_deg;
    let fields: Vec<FieldRows> = selected(&t, &a)
        .into_iter()
        .map(|f| choose_rows(&t, f, &a))
        .collect();
    let stage = staging_dir(&a.out)?;
    let result = if a.format == ExportFormat::Hg {
        write_lobes(&a, &t, step, &fields, &stage)
    } else {
        write_all(&a, &t, step, &fields, &stage)
    };
    match result {
        Ok(report) => {
            replace_dir(&stage, &a.out)?;
            if a.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            }
            Ok(())
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(&stage);
            Err(e)
        }
    }
}

/// `--format bevy | mitsuba | npy | csv`: every selected field's tables and the report.
fn write_all(
    a: &ExportArgs,
    t: &Tables,
    step: f64,
    fields: &[FieldRows],
    stage: &Path,
) -> Result<serde_json::Value> {
    let mut report_fields = serde_json::Map::new();
    let mut text = String::new();
    let version = env!("CARGO_PKG_VERSION");
    let writer = format!("photometeor {version}");
    if a.format == ExportFormat::Bevy {
        write_file(
            stage,
            "phase_curve.wgsl",
            runtime::export::PHASE_CURVE_WGSL.as_bytes(),
        )?;
    }
    if a.format == ExportFormat::Npy {
        let k = t.angle_count;
        let theta: Vec<f64> = (0..k).map(|i| i as f64 * step).collect();
        write_file(
            stage,
            "theta_deg.npy",
            &format::export::npy_f64_bytes(&[k], &theta),
        )?;
    }
    let mut mitsuba_json = serde_json::Map::new();
    let mut npy_of: std::collections::HashMap<String, Vec<f64>> = Default::default();
    for fr in fields {
        let f = fr.field;
        let (n, resampled) = field_tables(a, t, step, fr)?;
        let ex = FieldExport {
            a,
            stage,
            fr,
            n,
            resampled,
        };
        let mut parts = FieldParts::default();
        let mut orders_report = serde_json::Map::new();
        for (oi, &order) in a.orders.iter().enumerate() {
            let files = ex.write_order(oi, order, &writer, &mut parts)?;
            let channels = ex.channel_report(oi);
            ex.summary_line(oi, order, &mut text);
            orders_report.insert(
                order.to_string(),
                json!({ "files": files, "channels": channels }),
            );
        }
        if a.format == ExportFormat::Npy && t.sweeps.iter().any(|s| s.fields.contains(&f.name)) {
            npy_of.insert(f.name.clone(), parts.npy.clone());
        }
        ex.write_field(t, step, version, parts, &mut mitsuba_json)?;
        report_fields.insert(
            f.name.clone(),
            json!({
                "kind": f.kind,
                "forward_peak": fr.treatment.name(),
                "samples": n,
                "sigma_ext_m2": f.sigma_ext_m2,
                "albedo": f.albedo,
                "orders": orders_report,
            }),
        );
    }
    if a.format == ExportFormat::Mitsuba {
        write_file(
            stage,
            "mitsuba.json",
            serde_json::to_string(&json!({
                "layout": "values linear in cos θ from -1 (θ = 180°) to 1 (θ = 0°), 1/sr",
                "fields": mitsuba_json,
            }))?
            .as_bytes(),
        )?;
    }
    let mut report = export_report(a, step, version, report_fields);
    let mut sweep_text = String::new();
    report["sweeps"] = export_sweeps(a, t, fields, stage, &npy_of, &mut sweep_text)?;
    write_file(
        stage,
        "export.json",
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    if !a.json {
        if text.is_empty() {
            println!(
                "{}: {} on the bake's own θ grid (Δθ = {step}°), nothing resampled",
                a.out.display(),
                a.format.name()
            );
        } else {
            print!("{text}");
        }
        print!("{sweep_text}");
        println!("wrote {} (report: export.json)", a.out.display());
    }
    Ok(report)
}

/// The sweeps whose members are all exported, as one axis: for npy `<sweep>.ams.npy` (values ×
/// orders × R, G, B × θ bins, the members' arrays stacked in the order of their values) and
/// `<sweep>.values.npy`; for every format the report's entry (key, spacing, values, members in
/// order, and what a shader's `ams_sweep` takes: at_first and at_step).
fn export_sweeps(
    a: &ExportArgs,
    t: &Tables,
    fields: &[FieldRows],
    stage: &Path,
    npy_of: &std::collections::HashMap<String, Vec<f64>>,
    text: &mut String,
) -> Result<serde_json::Value> {
    let mut out = serde_json::Map::new();
    for s in &t.sweeps {
        if !s
            .fields
            .iter()
            .all(|m| fields.iter().any(|fr| &fr.field.name == m))
        {
            continue;
        }
        let at = |v: f64| s.at(v);
        let mut files = Vec::new();
        if a.format == ExportFormat::Npy {
            let k = t.angle_count;
            let stacked: Vec<f64> = s.fields.iter().flat_map(|m| npy_of[m].clone()).collect();
            let shape = [s.values.len(), a.orders.len(), 3, k];
            let (ams, values) = (
                format!("{}.ams.npy", s.name),
                format!("{}.values.npy", s.name),
            );
            write_file(
                stage,
                &ams,
                &format::export::npy_f64_bytes(&shape, &stacked),
            )?;
            write_file(
                stage,
                &values,
                &format::export::npy_f64_bytes(&[s.values.len()], &s.values),
            )?;
            let _ = writeln!(
                text,
                "{}: sweep over {} ({} values) as one axis: {ams} ({}), {values}",
                s.name,
                s.key,
                s.values.len(),
                shape
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(" × ")
            );
            files = vec![ams, values];
        }
        out.insert(
            s.name.clone(),
            json!({
                "key": s.key,
                "spacing": s.spacing,
                "values": s.values,
                "members": s.fields,
                "at_first": at(s.values[0]),
                "at_step": at(s.values[1]) - at(s.values[0]),
                "files": files,
            }),
        );
    }
    Ok(serde_json::Value::Object(out))
}

/// Writes `bytes` to the file `name` in the staging directory.
fn write_file(stage: &Path, name: &str, bytes: &[u8]) -> Result<()> {
    Ok(format::write_output(&stage.join(name), bytes, &[])?)
}

/// A field's values per table (the bake's K angles, or the sample count on the cos θ grid) and
/// on the cos θ grid each order's resampled tables with their cost. Refuses a count chosen
/// for --max-loss that misses it under an explicit --forward-peak.
fn field_tables(
    a: &ExportArgs,
    t: &Tables,
    step: f64,
    fr: &FieldRows,
) -> Result<(usize, Option<Vec<Resampled>>)> {
    let f = fr.field;
    Ok(match a.format.max_samples() {
        None => (t.angle_count, None),
        Some(max) => {
            let n = match a.samples {
                Some(s) => s,
                None => {
                    let (n, worst) = fr.samples(a, step, max);
                    // An explicit treatment that cannot meet the bound is refused; `auto`
                    // writes the least loss it found and reports it.
                    if worst.moved > a.max_loss && a.forward_peak != ForwardPeak::Auto {
                        bail!(
                            "--max-loss {} cannot be met for field {:?} within {max} values, the {} limit: there {:.2} % of the light lands in a wrong θ bin; allow at least --max-loss {:.4}, take the loss with --samples N, or try --forward-peak strip",
                            a.max_loss,
                            f.name,
                            a.format.name(),
                            worst.moved * 100.0,
                            (worst.moved * 1e4).ceil() / 1e4
                        );
                    }
                    n
                }
            };
            let tables: Vec<Resampled> = fr
                .rows
                .iter()
                .map(|r| {
                    let values = std::array::from_fn(|c| resample(&r[c], step, n));
                    let cost = std::array::from_fn(|c| cost(&r[c], step, &values[c]));
                    Resampled { values, cost }
                })
                .collect();
            (n, Some(tables))
        }
    })
}

/// One field's export under way: the arguments, the staging directory, its rows, the values
/// per table and (on the cos θ grid) the resampled tables, one per order.
struct FieldExport<'a> {
    a: &'a ExportArgs,
    stage: &'a Path,
    fr: &'a FieldRows<'a>,
    n: usize,
    resampled: Option<Vec<Resampled>>,
}

/// What a field's orders add to files written once per field: Mitsuba's `tabphase` XML and
/// its JSON values, and the NumPy array's values (orders × R, G, B × θ bins, 1/sr).
#[derive(Default)]
struct FieldParts {
    xml: String,
    mitsuba: serde_json::Map<String, serde_json::Value>,
    npy: Vec<f64>,
}

impl FieldExport<'_> {
    /// Writes order `order`'s own files (bevy) or adds it to `parts`; returns the names of the
    /// files that hold it.
    fn write_order(
        &self,
        oi: usize,
        order: usize,
        writer: &str,
        parts: &mut FieldParts,
    ) -> Result<Vec<String>> {
        let f = self.fr.field;
        let mut files = Vec::new();
        match self.a.format {
            ExportFormat::Bevy => files.extend(self.write_bevy(oi, order, writer)?),
            ExportFormat::Mitsuba => {
                let r = &self.resampled.as_ref().unwrap()[oi];
                let mut per = serde_json::Map::new();
                for (c, ch) in CHANNELS.iter().enumerate() {
                    let values: Vec<String> = r.values[c]
                        .iter()
                        .map(|&v| format!("{}", v as f32))
                        .collect();
                    let _ = writeln!(
                        parts.xml,
                        "    <phase type=\"tabphase\" id=\"{}_ams{order}_{ch}\">\n        \
                         <string name=\"values\" value=\"{}\"/>\n    </phase>",
                        f.name,
                        values.join(", ")
                    );
                    let f32s: Vec<f32> = r.values[c].iter().map(|&v| v as f32).collect();
                    per.insert(ch.to_string(), json!(f32s));
                }
                parts
                    .mitsuba
                    .insert(order.to_string(), serde_json::Value::Object(per));
                files.push(format!("{}.xml", f.name));
            }
            ExportFormat::Npy => {
                for c in 0..3 {
                    parts.npy.extend_from_slice(&self.fr.rows[oi][c]);
                }
                files.push(format!("{}.ams.npy", f.name));
            }
            ExportFormat::Csv => files.push(format!("{}.csv", f.name)),
            ExportFormat::Hg => unreachable!("--format hg is written by write_lobes"),
        }
        Ok(files)
    }

    /// Writes order `order`'s Bevy texture as `<field>.ams<n>.ktx2` and `.exr` (N × 1
    /// Rgba32Float, RGB in 1/sr, A = 1); returns their names.
    fn write_bevy(&self, oi: usize, order: usize, writer: &str) -> Result<[String; 2]> {
        let f = self.fr.field;
        let base = format!("{}.ams{order}", f.name);
        let r = &self.resampled.as_ref().unwrap()[oi];
        let texels: Vec<[f32; 4]> = (0..self.n)
            .map(|i| {
                [
                    r.values[0][i] as f32,
                    r.values[1][i] as f32,
                    r.values[2][i] as f32,
                    1.0,
                ]
            })
            .collect();
        let n_text = order.to_string();
        let meta = [
            ("photometeor/field", f.name.as_str()),
            ("photometeor/order", n_text.as_str()),
            (
                "photometeor/layout",
                "column i: cos θ = -1 + 2i/(width-1), θ = 180° first; RGB 1/sr, A = 1",
            ),
        ];
        write_file(
            self.stage,
            &format!("{base}.ktx2"),
            &format::export::ktx2_rgba32f_bytes(&texels, writer, &meta),
        )?;
        write_file(
            self.stage,
            &format!("{base}.exr"),
            &format::export::curve_exr_bytes(&base, &texels, &meta)?,
        )?;
        Ok([format!("{base}.ktx2"), format!("{base}.exr")])
    }

    /// The report of order `oi` per channel: the resampling's cost, and with the peak
    /// stripped its fraction f and the medium's δ-scaled σ_ext (m²) and albedo.
    fn channel_report(&self, oi: usize) -> serde_json::Map<String, serde_json::Value> {
        let (fr, f) = (self.fr, self.fr.field);
        let mut channels = serde_json::Map::new();
        for (c, ch) in CHANNELS.iter().enumerate() {
            let mut e = serde_json::Map::new();
            if let Some(r) = &self.resampled {
                let k = &r[oi].cost[c];
                e.insert("moved".into(), json!(k.moved));
                e.insert("peak_kept".into(), json!(k.peak_kept));
                e.insert("energy_change".into(), json!(k.energy_change));
            } else {
                e.insert("moved".into(), json!(0.0));
            }
            if fr.treatment == ForwardPeak::Strip {
                let fs = fr.stripped[oi][c];
                let al = f.albedo[c];
                e.insert("forward_peak_stripped".into(), json!(fs));
                e.insert(
                    "scaled_sigma_ext_m2".into(),
                    json!(f.sigma_ext_m2[c] * (1.0 - al * fs)),
                );
                e.insert(
                    "scaled_albedo".into(),
                    json!(al * (1.0 - fs) / (1.0 - al * fs)),
                );
            }
            channels.insert(ch.to_string(), serde_json::Value::Object(e));
        }
        channels
    }

    /// On the cos θ grid, appends order `order`'s line to `text`: values, treatment, the
    /// worst light moved (%) and the least forward peak kept over the channels.
    fn summary_line(&self, oi: usize, order: usize, text: &mut String) {
        let Some(r) = &self.resampled else {
            return;
        };
        let a = self.a;
        let worst = r[oi].cost.iter().map(|c| c.moved).fold(0.0, f64::max);
        let peak = r[oi].cost.iter().map(|c| c.peak_kept).fold(1.0, f64::min);
        let _ = writeln!(
            text,
            "{:<10} Ams_{order:<3} {n:>8} values  forward peak {:<5}  moved {:>7.3} %  forward peak kept {:>9.3e}{}",
            self.fr.field.name,
            self.fr.treatment.name(),
            worst * 100.0,
            peak,
            if worst > a.max_loss {
                format!("  (above --max-loss {} %)", a.max_loss * 100.0)
            } else {
                String::new()
            },
            n = self.n,
        );
    }

    /// Writes the field's files that hold all its orders (mitsuba's XML, npy's array, the
    /// CSV) and adds its values to `mitsuba.json`.
    fn write_field(
        &self,
        t: &Tables,
        step: f64,
        version: &str,
        parts: FieldParts,
        mitsuba_json: &mut serde_json::Map<String, serde_json::Value>,
    ) -> Result<()> {
        let f = self.fr.field;
        match self.a.format {
            ExportFormat::Mitsuba => {
                let scene = self.mitsuba_scene(version, &parts.xml);
                write_file(self.stage, &format!("{}.xml", f.name), scene.as_bytes())?;
                mitsuba_json.insert(f.name.clone(), serde_json::Value::Object(parts.mitsuba));
            }
            ExportFormat::Npy => {
                let k = t.angle_count;
                write_file(
                    self.stage,
                    &format!("{}.ams.npy", f.name),
                    &format::export::npy_f64_bytes(&[self.a.orders.len(), 3, k], &parts.npy),
                )?;
            }
            ExportFormat::Csv => {
                let csv = self.csv(t, step);
                write_file(self.stage, &format!("{}.csv", f.name), csv.as_bytes())?;
            }
            ExportFormat::Bevy | ExportFormat::Hg => {}
        }
        Ok(())
    }

    /// The field's Mitsuba 3 scene: its `tabphase`s (`xml`) and a homogeneous medium with the
    /// albedo and σ_t (m², per particle) of the first order, δ-scaled when the peak is stripped.
    fn mitsuba_scene(&self, version: &str, xml: &str) -> String {
        let (f, a) = (self.fr.field, self.a);
        // With the peak stripped the medium takes the δ-scaled optics of the order it
        // refers to: σ_ext (1 − α f) and α (1 − f)/(1 − α f).
        let f0 = self.fr.stripped[0];
        let al: [f64; 3] =
            std::array::from_fn(|c| f.albedo[c] * (1.0 - f0[c]) / (1.0 - f.albedo[c] * f0[c]));
        let s: [f64; 3] = std::array::from_fn(|c| f.sigma_ext_m2[c] * (1.0 - f.albedo[c] * f0[c]));
        format!(
            "<!-- photometeor {version}: field {name} ({kind}), tabphase per order n and channel.\n     \
             Mitsuba's tabphase is one scalar table: render one channel at a time, or pick G.\n     \
             values: linear in cos θ from -1 (θ = 180°) to 1 (θ = 0°); Mitsuba normalises them,\n     \
             and they already integrate to 1. sigma_t below is for one particle per m³:\n     \
             set 'scale' to the number density (1/m³). -->\n\
             <scene version=\"3.0.0\">\n{xml}    <medium type=\"homogeneous\" id=\"{name}_medium\">\n        \
             <rgb name=\"albedo\" value=\"{:.6}, {:.6}, {:.6}\"/>\n        \
             <rgb name=\"sigma_t\" value=\"{:.6e}, {:.6e}, {:.6e}\"/>\n        \
             <float name=\"scale\" value=\"1\"/>\n        \
             <ref id=\"{name}_ams{first}_G\"/>\n    </medium>\n</scene>\n",
            al[0],
            al[1],
            al[2],
            s[0],
            s[1],
            s[2],
            name = f.name,
            kind = f.kind,
            first = a.orders[0],
        )
    }

    /// The field's CSV: θ in degrees, then Ams_n (1/sr) per order and channel, one row per
    /// bin of the bake's grid.
    fn csv(&self, t: &Tables, step: f64) -> String {
        let mut csv = String::from("theta_deg");
        for &o in &self.a.orders {
            for ch in CHANNELS {
                let _ = write!(csv, ",ams{o}_{ch}");
            }
        }
        csv.push('\n');
        for k in 0..t.angle_count {
            let _ = write!(csv, "{}", k as f64 * step);
            for r in &self.fr.rows {
                for row in r {
                    let _ = write!(csv, ",{:e}", row[k]);
                }
            }
            csv.push('\n');
        }
        csv
    }
}

/// `export.json` of a bevy, mitsuba, npy or csv export: the grid the tables use, the
/// arguments, what the costs mean, and the per-field reports.
fn export_report(
    a: &ExportArgs,
    step: f64,
    version: &str,
    report_fields: serde_json::Map<String, serde_json::Value>,
) -> serde_json::Value {
    let grid = match a.format.max_samples() {
        Some(_) => json!({
            "kind": "cos_theta",
            "layout": "value i at cos θ = -1 + 2i/(n-1): θ = 180° first, θ = 0° last; read back \
                       linear in cos θ between values",
        }),
        None => json!({
            "kind": "theta_bins",
            "theta_step_deg": step,
            "layout": "column k: the average over θ ∈ [kΔθ − Δθ/2, kΔθ + Δθ/2] ∩ [0°, 180°] in solid angle",
        }),
    };
    json!({
        "tool": "photometeor",
        "tool_version": version,
        "source": a.dir.display().to_string(),
        "format": a.format.name(),
        "grid": grid,
        "max_loss": a.max_loss,
        "forward_peak": a.forward_peak.name(),
        "cost": "moved: the share of the scattered light the resampled table puts in a wrong θ bin of the \
                 bake (½ Σ Ω_k |p̂_k − p_k|); peak_kept: its value at θ = 0 over the bake's bin 0",
        "fields": report_fields,
    })
}

/// A fresh staging directory beside `out`.
fn staging_dir(out: &Path) -> Result<PathBuf> {
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).with_context(|| format!("creating {}", parent.display()))?;
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "export".into());
    let stage = parent.join(format!(".{name}.stage-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&stage);
    std::fs::create_dir(&stage).with_context(|| format!("creating {}", stage.display()))?;
    Ok(stage)
}

/// Puts `stage` where `out` was (an earlier export there is removed once the new one is in).
fn replace_dir(stage: &Path, out: &Path) -> Result<()> {
    if out.exists() {
        let old = stage.with_extension("old");
        std::fs::rename(out, &old).with_context(|| format!("moving {} aside", out.display()))?;
        std::fs::rename(stage, out).with_context(|| format!("writing {}", out.display()))?;
        std::fs::remove_dir_all(&old).with_context(|| format!("removing {}", old.display()))?;
    } else {
        std::fs::rename(stage, out).with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}

/// The optical features whose height a lobe should keep, per field kind: name and the θ range
/// (degrees) where the row's largest value is the feature's peak.
fn features(kind: FieldKind) -> Vec<(&'static str, f64, f64)> {
    let mut v = vec![("forward peak", 0.0, 0.0)];
    match kind {
        FieldKind::Rain => v.push(("primary rainbow", 130.0, 145.0)),
        FieldKind::Cloud => {
            v.push(("fogbow", 130.0, 145.0));
            v.push(("glory", 175.0, 180.0));
        }
        FieldKind::Ice | FieldKind::Snow => {
            v.push(("22° halo", 21.0, 24.0));
            v.push(("46° halo", 44.5, 47.5));
        }
        FieldKind::Haze | FieldKind::Hg | FieldKind::Tabulated => {}
    }
    v
}

/// `--format hg`: the fitted lobes and what they lose (see [`ExportFormat::Hg`]).
fn write_lobes(
    a: &ExportArgs,
    t: &Tables,
    step: f64,
    fields: &[FieldRows],
    stage: &Path,
) -> Result<serde_json::Value> {
    let k_len = t.angle_count;
    let mut report_fields = serde_json::Map::new();
    let mut text = String::new();
    for fr in fields {
        let f = fr.field;
        let feats = features(f.kind);
        let mut orders = serde_json::Map::new();
        let mut plot_rows = None;
        for (oi, &order) in a.orders.iter().enumerate() {
            let mut channels = serde_json::Map::new();
            for (c, ch) in CHANNELS.iter().enumerate() {
                let row = &fr.rows[oi][c];
                let fit = ChannelLobes::fit(row, step, k_len, &feats);
                if c == 1 {
                    fit.summary(&mut text, &f.name, order, &feats);
                }
                let ChannelLobes {
                    g,
                    lobes,
                    bins,
                    json: [moment_json, single_json, dual_json],
                    ..
                } = fit;
                if c == 1 && oi == 0 {
                    plot_rows = Some((row.clone(), bins, lobes));
                }
                channels.insert(
                    ch.to_string(),
                    json!({"g": g, "hg_at_g": moment_json, "hg": single_json, "dual_hg": dual_json}),
                );
            }
            orders.insert(order.to_string(), json!({ "channels": channels }));
        }
        if let Some((row, bins, lobes)) = plot_rows {
            plot_lobes(a, step, stage, f, &row, bins, lobes)?;
        }
        report_fields.insert(
            f.name.clone(),
            json!({"kind": f.kind, "sigma_ext_m2": f.sigma_ext_m2, "albedo": f.albedo, "orders": orders}),
        );
    }
    let report = json!({
        "tool": "photometeor",
        "tool_version": env!("CARGO_PKG_VERSION"),
        "source": a.dir.display().to_string(),
        "format": "hg",
        "forward_peak": a.forward_peak.name(),
        "lobes": "HG(g) = (1 - g²)/(4π (1 + g² - 2g cos θ)^1.5), g > 0 forward; dual: w HG(g1) + (1 - w) HG(g2); \
                  fitted per channel for the least light in a wrong θ bin of the bake",
        "cost": "moved: ½ Σ Ω_k |HG_k - p_k| over the bake's θ bins; rms_relative_from_1deg: over the bins θ ≥ 1°; \
                 features: the lobes' value at each feature's peak over the table's (kept)",
        "fields": report_fields,
    });
    format::write_output(
        &stage.join("export.json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
        &[],
    )?;
    if !a.json {
        print!("{text}");
        println!(
            "wrote {} (report: export.json, plots: <field>.lobes.png)",
            a.out.display()
        );
    }
    Ok(report)
}

/// One channel's row against three lobes, in this order: HG at the row's own g, the best-fit
/// HG and the best-fit dual HG; per lobe its bin averages (1/sr), its report and its rms
/// relative error for θ ≥ 1°.
struct ChannelLobes {
    g: f64,
    lobes: [Lobes; 3],
    bins: [Vec<f64>; 3],
    json: [serde_json::Value; 3],
    rms: [f64; 3],
}

impl ChannelLobes {
    /// Fits the lobes to `row` (K bins of `step` degrees) and measures what each keeps of
    /// `feats`.
    fn fit(row: &[f64], step: f64, k_len: usize, feats: &[(&'static str, f64, f64)]) -> Self {
        let (single, dual) = (fit_hg(row, step), fit_dual_hg(row, step));
        // HG at the table's own g: what an engine's `anisotropy` usually gets.
        let g = asymmetry(row, step);
        let moment = Lobes {
            g1: g,
            g2: 0.0,
            w: 1.0,
            moved: runtime::export::moved(row, &runtime::export::hg_bins(g, step, k_len), step),
        };
        let (moment_bins, moment_json, moment_rms) =
            describe_lobes(row, &moment, step, k_len, feats);
        let (single_bins, single_json, single_rms) =
            describe_lobes(row, &single, step, k_len, feats);
        let (dual_bins, dual_json, dual_rms) = describe_lobes(row, &dual, step, k_len, feats);
        ChannelLobes {
            g,
            lobes: [moment, single, dual],
            bins: [moment_bins, single_bins, dual_bins],
            json: [moment_json, single_json, dual_json],
            rms: [moment_rms, single_rms, dual_rms],
        }
    }

    /// Appends the text report's lines for this channel (order `order` of `field`): g, and
    /// per lobe the light moved and rms error (%) and the height kept of each feature.
    fn summary(&self, text: &mut String, field: &str, order: usize, feats: &[(&str, f64, f64)]) {
        let kept = |j: &serde_json::Value| {
            feats
                .iter()
                .map(|(name, _, _)| {
                    format!(
                        "{name} {:.1} %",
                        100.0 * j["features"][*name]["kept"].as_f64().unwrap()
                    )
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        let [moment, single, dual] = &self.lobes;
        let [moment_json, single_json, dual_json] = &self.json;
        let [moment_rms, single_rms, dual_rms] = self.rms;
        let _ = writeln!(
            text,
            "{:<10} Ams_{order:<3} G  g = {:.4}\n    HG at that g: moves {:.1} %, rms {:.0} %; kept: {}\n    best HG g = {:.4}: moves {:.1} %, rms {:.0} %; kept: {}\n    best dual HG {:.4}/{:.4}, w = {:.3}: moves {:.1} %, rms {:.0} %; kept: {}",
            field,
            self.g,
            moment.moved * 100.0,
            moment_rms * 100.0,
            kept(moment_json),
            single.g1,
            single.moved * 100.0,
            single_rms * 100.0,
            kept(single_json),
            dual.g1,
            dual.g2,
            dual.w,
            dual.moved * 100.0,
            dual_rms * 100.0,
            kept(dual_json),
        );
    }
}

/// Lobes `l` against `row`: their bin averages (1/sr), their report (parameters, light
/// moved, rms relative error for θ ≥ 1°, and per feature of `feats` the table's and the
/// lobes' value at the feature's peak, θ in degrees) and that rms error.
fn describe_lobes(
    row: &[f64],
    l: &Lobes,
    step: f64,
    k_len: usize,
    feats: &[(&'static str, f64, f64)],
) -> (Vec<f64>, serde_json::Value, f64) {
    let bins = l.bins(step, k_len);
    let kept: serde_json::Map<String, serde_json::Value> = feats
        .iter()
        .map(|&(name, from, to)| {
            let ks = (from / step).round() as usize..=((to / step).round() as usize).min(k_len - 1);
            let k = ks.max_by(|&x, &y| row[x].total_cmp(&row[y])).unwrap();
            (name.to_string(), json!({"theta_deg": k as f64 * step, "table": row[k], "lobes": bins[k], "kept": bins[k] / row[k]}))
        })
        .collect();
    let rms = rms_relative(row, &bins, step, 1.0);
    (
        bins,
        json!({"g1": l.g1, "g2": l.g2, "w": l.w, "moved": l.moved, "rms_relative_from_1deg": rms, "features": kept}),
        rms,
    )
}

/// Draws `<field>.lobes.png` and `.svg`: the first order's G row against the three lobes'
/// bin averages (1/sr, log scale) over θ in degrees.
fn plot_lobes(
    a: &ExportArgs,
    step: f64,
    stage: &Path,
    f: &FieldTable,
    row: &[f64],
    [moment, single, dual]: [Vec<f64>; 3],
    [m, s, d]: [Lobes; 3],
) -> Result<()> {
    use crate::commands::plot::{CHANNEL_COLOURS, LinePlot, Series, save};
    let pts = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .enumerate()
            .map(|(k, &p)| (k as f64 * step, p))
            .filter(|&(th, p)| th > 0.0 && p > 0.0)
            .collect()
    };
    let order = a.orders[0];
    let plot = LinePlot {
        title: format!(
            "{} ({}): Ams_{order} (G) against Henyey–Greenstein lobes",
            f.name, f.kind
        ),
        x_label: "scattering angle θ (°)".into(),
        y_label: "phase function (1/sr)".into(),
        x_range: (0.0, 180.0),
        log_x: false,
        log_y: true,
        series: vec![
            Series {
                label: format!("Ams_{order}, photometeor"),
                colour: CHANNEL_COLOURS[1],
                width: 2,
                points: pts(row),
            },
            Series {
                label: format!(
                    "HG at the table's g = {:.3}: {:.1} % moved",
                    m.g1,
                    m.moved * 100.0
                ),
                colour: plotters::style::RGBColor(148, 103, 189),
                width: 1,
                points: pts(&moment),
            },
            Series {
                label: format!("best HG g = {:.3}: {:.1} % moved", s.g1, s.moved * 100.0),
                colour: plotters::style::RGBColor(0, 0, 0),
                width: 1,
                points: pts(&single),
            },
            Series {
                label: format!(
                    "best dual HG {:.3}/{:.3}, w {:.2}: {:.1} % moved",
                    d.g1,
                    d.g2,
                    d.w,
                    d.moved * 100.0
                ),
                colour: plotters::style::RGBColor(255, 127, 14),
                width: 1,
                points: pts(&dual),
            },
        ],
    };
    save(&plot, stage, &format!("{}.lobes", f.name), &[])?;
    Ok(())
}
