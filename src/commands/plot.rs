//! `photometeor plot`: pictures of a bake, each as PNG and SVG (plotters): the single-scattering
//! phase function Ams_1 per channel on a log scale (with a reference bake overlaid), the Ams_n
//! family, F_i against n, zooms on each field's optical features, sRGB colour strips of what an
//! observer sees across 0–180° after n scatterings, and the Pareto front of a tradeoff run.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow};
use clap::Args as ClapArgs;
use format::{BakeDir, FieldEntry, FieldImage};
use plotters::coord::Shift;
use plotters::prelude::*;

#[derive(Debug, ClapArgs)]
pub struct PlotArgs {
    /// Bake directory (holding manifest.json); optional with --tradeoff.
    dir: Option<PathBuf>,
    /// Folder for the pictures (created if missing).
    #[arg(long, default_value = "photometeor-plots")]
    out: PathBuf,
    /// A reference bake of the same scene, overlaid in black on the phase-function plots.
    #[arg(long)]
    reference: Option<PathBuf>,
    /// tradeoff.json from `photometeor tradeoff`: plot its Pareto front (time against error).
    #[arg(long)]
    tradeoff: Option<PathBuf>,
}

pub(crate) const CHANNEL_COLOURS: [RGBColor; 3] =
    [RGBColor(214, 39, 40), RGBColor(44, 160, 44), BLUE_1];
const BLUE_1: RGBColor = RGBColor(31, 119, 180);
const FAMILY_COLOURS: [RGBColor; 6] = [
    RGBColor(0, 0, 0),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(214, 39, 40),
];

/// One curve of a plot: a line, or dots where `width` is 0.
pub(crate) struct Series {
    pub(crate) label: String,
    pub(crate) colour: RGBColor,
    pub(crate) width: u32,
    pub(crate) points: Vec<(f64, f64)>,
}

/// A plot whose axes are each linear or logarithmic.
pub(crate) struct LinePlot {
    pub(crate) title: String,
    pub(crate) x_label: String,
    pub(crate) y_label: String,
    pub(crate) x_range: (f64, f64),
    pub(crate) log_x: bool,
    pub(crate) log_y: bool,
    pub(crate) series: Vec<Series>,
}

/// Runs `photometeor plot`.
pub fn run(a: PlotArgs) -> Result<()> {
    // What the command reads is never written over: the bakes and the trade-off file.
    let protected: Vec<&Path> = [&a.dir, &a.reference, &a.tradeoff]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    format::check_output_dir(&a.out, &protected)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut written = Vec::new();
    if let Some(dir) = &a.dir {
        written.extend(plot_bake(dir, a.reference.as_deref(), &a.out, &protected)?);
    }
    if let Some(t) = &a.tradeoff {
        written.extend(plot_tradeoff(t, &a.out, &protected)?);
    }
    if a.dir.is_none() && a.tradeoff.is_none() {
        anyhow::bail!("nothing to plot: give a bake directory, --tradeoff FILE, or both");
    }
    for w in &written {
        println!("{}", w.display());
    }
    Ok(())
}

/// Every picture of the bake in `dir` (the reference bake overlaid where given), written to
/// `out` (never over a path in `protected`); their paths.
fn plot_bake(
    dir: &Path,
    reference: Option<&Path>,
    out: &Path,
    protected: &[&Path],
) -> Result<Vec<PathBuf>> {
    let bake = BakeDir::open(dir)?;
    let manifest = &bake.manifest;
    let reference = reference.map(BakeDir::open).transpose()?;
    let step = manifest.theta_step_deg;
    let mut written = Vec::new();
    let mut forward = Vec::new();
    for (i, f) in manifest.fields.iter().enumerate() {
        let image = bake.read_field(f).with_context(|| f.file.clone())?;
        let reference_image = reference_image(reference.as_ref(), f)?;
        let curves = FieldCurves {
            entry: f,
            image: &image,
            reference: reference_image.as_ref(),
            step,
        };
        written.extend(save(
            &curves.phase(0.0, 180.0, "single scattering, per channel"),
            out,
            &format!("{}_phase", f.name),
            protected,
        )?);
        for (slug, title, a, b) in zooms(f.kind.name()) {
            written.extend(save(
                &curves.phase(*a, *b, title),
                out,
                &format!("{}_zoom_{slug}", f.name),
                protected,
            )?);
        }
        written.extend(save(
            &curves.ams_family(),
            out,
            &format!("{}_ams_family", f.name),
            protected,
        )?);
        forward.extend(forward_series(i, f, &image));
        written.push(colour_strips(&image, step, out, &f.name, protected)?);
    }
    for sweep in &manifest.sweeps {
        written.extend(plot_sweep(&bake, sweep, out, protected)?);
    }
    let n_max = manifest.fields.iter().map(|f| f.n_max).max().unwrap_or(1);
    written.extend(save(
        &LinePlot {
            title: "forward fraction F_n (R, G thick, B)".into(),
            x_label: "scattering order n".into(),
            y_label: "F_n".into(),
            x_range: (1.0, n_max as f64),
            log_x: false,
            log_y: false,
            series: forward,
        },
        out,
        "forward_fraction",
        protected,
    )?);
    Ok(written)
}

/// A swept field's members over each of its kind's zooms, one curve of Ams_1 (G) per value
/// coloured from blue (the first) to red (the last): the rings moving with the size.
fn plot_sweep(
    bake: &BakeDir,
    sweep: &format::SweepEntry,
    out: &Path,
    protected: &[&Path],
) -> Result<Vec<PathBuf>> {
    let step = bake.manifest.theta_step_deg;
    let mut members = Vec::new();
    for name in &sweep.fields {
        let entry = bake
            .entry(name)
            .with_context(|| format!("sweep {}: member {name}", sweep.name))?;
        members.push((entry.kind.name(), bake.read_field(entry)?));
    }
    let count = members.len();
    let label_every = count.div_ceil(6).max(1);
    let mut written = Vec::new();
    for (slug, title, a, b) in zooms(members[0].0) {
        let series = members
            .iter()
            .zip(&sweep.values)
            .enumerate()
            .map(|(k, ((_, image), value))| {
                let t = k as f64 / (count - 1).max(1) as f64;
                let mixed = |from: u8, to: u8| (from as f64 + t * (to as f64 - from as f64)) as u8;
                Series {
                    label: if k % label_every == 0 || k + 1 == count {
                        format!("{} = {value:.3}", sweep.key)
                    } else {
                        String::new()
                    },
                    colour: RGBColor(mixed(31, 214), mixed(119, 39), mixed(180, 40)),
                    width: 2,
                    points: image
                        .row(1, 0)
                        .iter()
                        .enumerate()
                        .map(|(i, &v)| (i as f64 * step, v))
                        .filter(|&(t, v)| t >= *a && t <= *b && v > 0.0)
                        .collect(),
                }
            })
            .collect();
        let plot = LinePlot {
            title: format!(
                "{} swept over {} ({} values): {title}, G",
                sweep.name, sweep.key, count
            ),
            x_label: "scattering angle θ (°)".into(),
            y_label: "Ams₁ = phase function (1/sr)".into(),
            x_range: (*a, *b),
            log_x: false,
            log_y: true,
            series,
        };
        written.extend(save(
            &plot,
            out,
            &format!("{}_sweep_{slug}", sweep.name),
            protected,
        )?);
    }
    Ok(written)
}

/// The field `f`'s tables in the reference bake, where one is given.
fn reference_image(reference: Option<&BakeDir>, f: &FieldEntry) -> Result<Option<FieldImage>> {
    let Some(r) = reference else {
        return Ok(None);
    };
    let entry = r.entry(&f.name).with_context(|| {
        format!(
            "field {:?} is not in the reference bake {}",
            f.name,
            r.dir.display()
        )
    })?;
    Ok(Some(r.read_field(entry).with_context(|| {
        format!("reference {}", r.dir.join(&entry.file).display())
    })?))
}

/// The angle ranges worth a closer look in a field of this kind: (file slug, title, from, to in
/// degrees).
fn zooms(kind: &str) -> &'static [(&'static str, &'static str, f64, f64)] {
    match kind {
        "rain" => &[("rainbows", "primary and secondary rainbows", 120.0, 145.0)],
        "cloud" => &[
            ("corona", "corona", 0.0, 10.0),
            ("glory", "glory", 165.0, 180.0),
            ("fogbow", "fogbow", 120.0, 160.0),
        ],
        "ice" => &[("halos", "22° and 46° halos", 15.0, 50.0)],
        _ => &[("no_halos", "10–60° (no halos expected)", 10.0, 60.0)],
    }
}

/// One field's tables, and the reference bake's, as curves against θ.
struct FieldCurves<'a> {
    entry: &'a FieldEntry,
    image: &'a FieldImage,
    reference: Option<&'a FieldImage>,
    /// Δθ, degrees.
    step: f64,
}

impl FieldCurves<'_> {
    /// Row `r` of channel `c` of `img` as (θ, value) points in [a, b]° where the value is > 0
    /// (a log axis shows no zeros).
    fn row(&self, img: &FieldImage, c: usize, r: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
        img.row(c, r)
            .iter()
            .enumerate()
            .map(|(k, &v)| (k as f64 * self.step, v))
            .filter(|&(t, v)| t >= a && t <= b && v > 0.0)
            .collect()
    }

    /// Ams_1 per channel over [a, b]°, the reference bake's in black.
    fn phase(&self, a: f64, b: f64, title: &str) -> LinePlot {
        let f = self.entry;
        let mut series: Vec<Series> = (0..3)
            .map(|c| Series {
                label: ["R", "G", "B"][c].to_string(),
                colour: CHANNEL_COLOURS[c],
                width: 2,
                points: self.row(self.image, c, 0, a, b),
            })
            .collect();
        if let Some(ri) = self.reference {
            for c in 0..3 {
                series.push(Series {
                    label: if c == 0 {
                        "reference bake".into()
                    } else {
                        String::new()
                    },
                    colour: RGBColor(0, 0, 0),
                    width: 1,
                    points: self.row(ri, c, 0, a, b),
                });
            }
        }
        LinePlot {
            title: format!("{} ({}): {title}", f.name, f.kind),
            x_label: "scattering angle θ (°)".into(),
            y_label: "Ams₁ = phase function (1/sr)".into(),
            x_range: (a, b),
            log_x: false,
            log_y: true,
            series,
        }
    }

    /// The Ams_n family in the G channel: n = 1, 2, 4, 8, 16 below N, and N.
    fn ams_family(&self) -> LinePlot {
        let n_max = self.image.n_max();
        let mut orders: Vec<usize> = [1, 2, 4, 8, 16]
            .into_iter()
            .filter(|&n| n < n_max)
            .collect();
        orders.push(n_max);
        LinePlot {
            title: format!("{}: Ams_n, channel G", self.entry.name),
            x_label: "scattering angle θ (°)".into(),
            y_label: "Ams_n (1/sr)".into(),
            x_range: (0.0, 180.0),
            log_x: false,
            log_y: true,
            series: orders
                .iter()
                .enumerate()
                .map(|(j, &n)| Series {
                    label: format!("n = {n}"),
                    colour: FAMILY_COLOURS[j % FAMILY_COLOURS.len()],
                    width: 2,
                    points: self.row(self.image, 1, n - 1, 0.0, 180.0),
                })
                .collect(),
        }
    }
}

/// F_n against n of the `i`-th field, one curve per channel (G thick, named after the field).
fn forward_series(i: usize, f: &FieldEntry, image: &FieldImage) -> Vec<Series> {
    (0..3)
        .map(|c| Series {
            label: if c == 1 {
                f.name.clone()
            } else {
                String::new()
            },
            colour: FAMILY_COLOURS[(i + 1) % FAMILY_COLOURS.len()],
            width: if c == 1 { 2 } else { 1 },
            points: image
                .forward_fractions(c)
                .iter()
                .enumerate()
                .map(|(n, &v)| ((n + 1) as f64, v))
                .collect(),
        })
        .collect()
}

/// sRGB strips, one per order n ∈ {1, 2, 4, 8}: column k is Ams_n(θ_k) as linear sRGB, exposed
/// so the 98th percentile of the largest channel over θ ≥ 30° maps to 1 (the
/// forward lobe saturates; features at larger angles keep their contrast), tone-mapped by
/// x/(1 + x)·2 (1 ↦ 1) and encoded with the sRGB transfer function.
fn colour_strips(
    image: &FieldImage,
    step: f64,
    out: &Path,
    name: &str,
    protected: &[&Path],
) -> Result<PathBuf> {
    let k_len = image.angle_count();
    let orders: Vec<usize> = [1, 2, 4, 8]
        .into_iter()
        .filter(|&n| n <= image.n_max())
        .collect();
    let strip_h = 40u32;
    let gap = 6u32;
    let path = out.join(format!("{name}_colours.png"));
    let height = orders.len() as u32 * (strip_h + gap);
    let mut pixels = vec![0u8; 3 * k_len * height as usize];
    {
        let root =
            BitMapBackend::with_buffer(&mut pixels, (k_len as u32, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
        let k2 = ((30.0 / step).ceil() as usize).min(k_len - 1);
        for (s, &n) in orders.iter().enumerate() {
            let rows = [
                image.row(0, n - 1),
                image.row(1, n - 1),
                image.row(2, n - 1),
            ];
            let mut peaks: Vec<f64> = (k2..k_len)
                .map(|k| rows.iter().map(|r| r[k]).fold(0.0, f64::max))
                .collect();
            peaks.sort_by(f64::total_cmp);
            let scale = peaks[(0.98 * (peaks.len() - 1) as f64) as usize].max(1e-30);
            let y0 = s as u32 * (strip_h + gap);
            for k in 0..k_len {
                let rgb: Vec<u8> = rows
                    .iter()
                    .map(|r| {
                        let x = (r[k] / scale).max(0.0);
                        let t = (2.0 * x / (1.0 + x)).min(1.0);
                        (255.0 * render::image::srgb_encode(t)).round() as u8
                    })
                    .collect();
                let colour = RGBColor(rgb[0], rgb[1], rgb[2]);
                for y in y0..y0 + strip_h {
                    root.draw_pixel((k as i32, y as i32), &colour)
                        .map_err(|e| anyhow!("{e:?}"))?;
                }
            }
        }
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e:?}", path.display()))?;
    }
    format::write_output(&path, &png_rgb8(k_len as u32, height, &pixels)?, protected)?;
    Ok(path)
}

fn plot_tradeoff(path: &Path, out: &Path, protected: &[&Path]) -> Result<Vec<PathBuf>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let rows = v["rows"]
        .as_array()
        .ok_or_else(|| anyhow!("{}: no rows", path.display()))?;
    let mut series = Vec::new();
    let (mut x_min, mut x_max) = (f64::INFINITY, 1.0f64);
    for (g, group) in ["drops", "crystals"].into_iter().enumerate() {
        let mut pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r["fields"] == group)
            .filter_map(|r| Some((r["seconds"].as_f64()?, 100.0 * r["rms_rel_ams1"].as_f64()?)))
            .collect();
        if pts.is_empty() {
            continue;
        }
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        x_min = x_min.min(pts[0].0 / 1.5);
        x_max = x_max.max(pts.last().unwrap().0 * 1.2);
        // Pareto front: points no faster-or-equal point beats in error.
        let mut front = Vec::new();
        let mut best = f64::INFINITY;
        for &(t, e) in &pts {
            if e < best {
                front.push((t, e));
                best = e;
            }
        }
        series.push(Series {
            label: format!("{group}: variants"),
            colour: FAMILY_COLOURS[2 * g + 1],
            width: 0,
            points: pts,
        });
        series.push(Series {
            label: format!("{group}: Pareto front"),
            colour: FAMILY_COLOURS[2 * g + 1],
            width: 2,
            points: front,
        });
    }
    save(
        &LinePlot {
            title: "speed/accuracy: bake time against rms error of Ams₁".into(),
            x_label: "bake time on this machine (s)".into(),
            y_label: "rms relative error of Ams₁, θ ≥ 1° (%)".into(),
            x_range: (x_min.min(x_max / 10.0), x_max),
            log_x: true,
            log_y: true,
            series,
        },
        out,
        "tradeoff_pareto",
        protected,
    )
}

/// Writes `plot` as `<name>.png` and `<name>.svg` under `out`, each drawn in memory and
/// written through `format::write_output` (never over the files in `protected`).
pub(crate) fn save(
    plot: &LinePlot,
    out: &Path,
    name: &str,
    protected: &[&Path],
) -> Result<Vec<PathBuf>> {
    let png = out.join(format!("{name}.png"));
    let svg = out.join(format!("{name}.svg"));
    let (width, height) = (960, 540);
    let mut rgb = vec![0u8; 3 * width as usize * height as usize];
    draw(
        BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area(),
        plot,
    )
    .with_context(|| format!("drawing {}", png.display()))?;
    format::write_output(&png, &png_rgb8(width, height, &rgb)?, protected)?;
    let mut text = String::new();
    draw(
        SVGBackend::with_string(&mut text, (width, height)).into_drawing_area(),
        plot,
    )
    .with_context(|| format!("drawing {}", svg.display()))?;
    format::write_output(&svg, text.as_bytes(), protected)?;
    Ok(vec![png, svg])
}

/// 8-bit RGB pixels (rows top to bottom) as the bytes of a PNG.
pub(crate) fn png_rgb8(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header()?;
        writer.write_image_data(rgb)?;
    }
    Ok(bytes)
}

fn y_bounds(plot: &LinePlot) -> (f64, f64) {
    let ys = plot
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1));
    let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
        (a.min(y), b.max(y))
    });
    if !(lo.is_finite() && hi.is_finite()) {
        return (1e-3, 1.0);
    }
    if plot.log_y {
        (lo / 1.5, hi * 1.5)
    } else {
        let pad = 0.05 * (hi - lo).max(1e-9);
        (lo - pad, hi + pad)
    }
}

/// A coordinate on a log axis is drawn as its log10 on a linear one.
fn axis(v: f64, log: bool) -> f64 {
    if log { v.log10() } else { v }
}

/// The plots' one font, carried in the binary: the same pictures on every machine, whatever
/// fonts it has (or none).
fn register_font() -> Result<()> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            epaint_default_fonts::UBUNTU_LIGHT,
        )
        .is_ok()
    });
    ok.then_some(())
        .ok_or_else(|| anyhow!("the plots' font (Ubuntu Light) did not load"))
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, plot: &LinePlot) -> Result<()>
where
    DB::ErrorType: 'static,
{
    register_font()?;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("{e:?}");
    root.fill(&WHITE).map_err(err)?;
    let (lx, ly) = (plot.log_x, plot.log_y);
    let (y0, y1) = y_bounds(plot);
    let (x0, x1) = plot.x_range;
    let mut chart = ChartBuilder::on(&root)
        .caption(&plot.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(axis(x0, lx)..axis(x1, lx), axis(y0, ly)..axis(y1, ly))
        .map_err(err)?;
    let decade = |v: &f64| format!("{:.1e}", 10f64.powf(*v));
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(&plot.x_label).y_desc(&plot.y_label);
    if lx {
        mesh.x_label_formatter(&decade);
    }
    if ly {
        mesh.y_label_formatter(&decade);
    }
    mesh.draw().map_err(err)?;
    for s in &plot.series {
        let points = s.points.iter().map(|&(x, y)| (axis(x, lx), axis(y, ly)));
        let colour = s.colour;
        let style = ShapeStyle::from(&colour).stroke_width(s.width.max(1));
        let drawn = if s.width == 0 {
            chart.draw_series(points.map(|p| Circle::new(p, 5, colour.filled())))
        } else {
            chart.draw_series(LineSeries::new(points, style))
        }
        .map_err(err)?;
        if !s.label.is_empty() {
            drawn
                .label(&s.label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
