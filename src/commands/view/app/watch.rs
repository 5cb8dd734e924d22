//! Changes of the scene that need more than a frame: the watched scene file (or a file it
//! reads: a grid, an OpenVDB cloud, a mesh) edited, and a field's microphysics changed in the
//! window, both re-baked in the background.

use std::ops::RangeInclusive;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use bake::{BakePlan, Field, Scene};
use eframe::egui;
use mie::SizeDistribution;
use render::RenderScene;

use super::{App, model_tables, stamps};
use crate::commands::render::at_line;

/// How often the scene file's modification time is looked at.
const WATCH_PERIOD: Duration = Duration::from_millis(500);

impl App {
    /// Applies an edit of the scene file or of a file it reads once it is valid; an invalid one
    /// is shown (in the window and on stderr, with its key and line) and the last good scene
    /// kept.
    pub(super) fn watch_scene(&mut self, ctx: &egui::Context) {
        let Some(path) = self.scene_path.clone() else {
            return;
        };
        if self.checked.elapsed() < WATCH_PERIOD {
            return;
        }
        self.checked = Instant::now();
        let now = stamps(Some(&path), &self.inputs);
        if now == self.modified {
            return;
        }
        self.modified = now;
        match self.reload(&path, ctx) {
            Ok(()) => {
                self.scene_error = None;
                // The edited scene may read other files: watch those from now on.
                self.modified = stamps(Some(&path), &self.inputs);
            }
            Err(e) => {
                let e = format!("{e:#}");
                eprintln!("view: {e} (the window keeps the last good scene)");
                self.scene_error = Some(format!("{e}\n(the window keeps the last good scene)"));
            }
        }
    }

    /// Reads and checks the scene file, then applies it (re-baking first when its fields
    /// changed).
    fn reload(&mut self, path: &Path, ctx: &egui::Context) -> Result<()> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading scene {}", path.display()))?;
        let origin = path.display().to_string();
        let base = path.parent().unwrap_or(Path::new("."));
        let mut fields = Scene::parse_in(&text, &origin, Some(base))?;
        let mut scene = RenderScene::parse(&text, &origin, base)?;
        let inputs = crate::commands::render::scene_inputs(&text, base, &scene);
        scene.width = self.size.0.unwrap_or(scene.width);
        scene.height = self.size.1.unwrap_or(scene.height);
        scene
            .check_for(&self.model)
            .map_err(|e| at_line(&origin, &text, &e.to_string()))?;
        let sweeps: Vec<format::SweepEntry> = fields.sweeps.iter().map(|s| s.entry()).collect();
        scene
            .choose_members(&sweeps)
            .map_err(|e| at_line(&origin, &text, &e))?;
        let used = scene.fields();
        if let Some(missing) = used
            .iter()
            .find(|u| !fields.fields.iter().any(|f| &f.name == *u))
        {
            bail!("{origin}: a [[volume]] uses field {missing:?}, which no [[field]] defines");
        }
        fields.fields.retain(|f| used.contains(&f.name));
        self.models = model_tables(&scene, None);
        self.home = (scene.camera, scene.sun);
        (self.camera, self.sun) = self.home;
        self.exposure = scene.exposure.or(self.exposure);
        if fields.fields != self.plan.scene.fields {
            self.plan.scene.fields = fields.fields;
            self.pending_scene = Some(scene.clone());
            self.start_bake(ctx);
        } else {
            self.worker.set_scene(scene.clone(), None);
        }
        self.scene = scene;
        self.inputs = inputs;
        self.dirty = true;
        Ok(())
    }

    /// Bakes `self.plan` in the background.
    fn start_bake(&mut self, ctx: &egui::Context) {
        let repaint = ctx.clone();
        let plan: BakePlan = self.plan.clone();
        self.rebake.start(plan, move || repaint.request_repaint());
    }

    /// Swaps in the tables of a finished bake.
    pub(super) fn take_bake(&mut self, ctx: &egui::Context) {
        let repaint = ctx.clone();
        let Some(result) = self.rebake.finished(move || repaint.request_repaint()) else {
            return;
        };
        match result {
            Ok(tables) => {
                let scene = self
                    .pending_scene
                    .take()
                    .unwrap_or_else(|| self.scene.clone());
                self.worker.set_scene(scene, Some(tables));
                self.bake_error = None;
                self.dirty = true;
            }
            Err(e) => {
                eprintln!("view: the bake failed: {e}");
                self.pending_scene = None;
                self.bake_error = Some(format!("the bake failed (old tables kept): {e}"));
            }
        }
    }

    /// Each field's size (and a crystal's roughness): a change re-bakes the field in the
    /// background once the drag ends or the value is entered.
    pub(super) fn field_controls(&mut self, ui: &mut egui::Ui, ctx: &egui::Context) {
        ui.label("fields (a change re-bakes in the background)");
        let mut fields = self
            .editing
            .take()
            .unwrap_or_else(|| self.plan.scene.fields.clone());
        let mut commit = false;
        for field in &mut fields {
            let name = field.name.clone();
            if name.contains('@') {
                // A sweep's member: its size is the sweep's value, which the per-voxel mixing
                // relies on; the scene file's sweep and size profile change it.
                if let Some((what, value, _)) = knobs(field).into_iter().next() {
                    ui.label(format!("{name} {what} {value:.3} (sweep member)"));
                }
                continue;
            }
            for (what, value, range) in knobs(field) {
                let speed = (*value * 0.01).max(1e-3);
                let r = ui.add(
                    egui::DragValue::new(value)
                        .range(range)
                        .speed(speed)
                        .prefix(format!("{name} {what} ")),
                );
                commit |= r.drag_stopped() || (r.changed() && !r.dragged());
            }
        }
        if let Some((done, total, message)) = self.rebake.progress() {
            let share = if total > 0 {
                done as f32 / total as f32
            } else {
                0.0
            };
            ui.add(
                egui::ProgressBar::new(share)
                    .text(message)
                    .show_percentage(),
            );
        }
        if commit && fields != self.plan.scene.fields {
            if let Err(e) = self.bake_fields(fields, ctx) {
                self.bake_error = Some(format!("{e:#}"));
            }
        } else if !commit {
            self.editing = Some(fields);
        }
    }
}

impl App {
    /// Checks `fields` and bakes them in the background, to be swapped in when done.
    pub(super) fn bake_fields(&mut self, fields: Vec<Field>, ctx: &egui::Context) -> Result<()> {
        fields.iter().try_for_each(check_field)?;
        self.plan.scene.fields = fields;
        self.start_bake(ctx);
        Ok(())
    }
}

/// The microphysics of `field` the window edits: (what, value, allowed range); the first is
/// its size (a script's `field_size`).
pub(super) fn knobs(field: &mut Field) -> Vec<(&'static str, &mut f64, RangeInclusive<f64>)> {
    let mut out: Vec<(&'static str, &mut f64, RangeInclusive<f64>)> = Vec::new();
    if let Some(d) = &mut field.distribution {
        out.push(match d {
            SizeDistribution::Lognormal {
                median_radius_um, ..
            } => ("median radius µm", median_radius_um, 0.01..=10_000.0),
            SizeDistribution::Gamma { r_eff_um, .. } => ("r_eff µm", r_eff_um, 0.01..=10_000.0),
            SizeDistribution::MarshallPalmer { rain_rate_mm_h } => {
                ("rain rate mm/h", rain_rate_mm_h, 0.1..=500.0)
            }
            SizeDistribution::Monodisperse { radius_um } => {
                ("radius µm", radius_um, 0.01..=10_000.0)
            }
        });
    }
    if let Some(c) = &mut field.crystal {
        out.push(("max dimension µm", &mut c.max_dimension_um, 1.0..=1e5));
        out.push(("roughness δ", &mut c.roughness, 0.0..=1.0));
    }
    out
}

/// The field's microphysics against the ranges the bake allows.
fn check_field(field: &Field) -> Result<()> {
    if let Some(d) = &field.distribution {
        (*d).validated()
            .with_context(|| format!("field {}", field.name))?;
    }
    if let Some(c) = &field.crystal {
        (*c).validated()
            .with_context(|| format!("field {}", field.name))?;
    }
    Ok(())
}
