//! The window's two panels: the controls on the left, the image (with the mouse and keys that
//! move the camera) in the middle.

use eframe::egui;
use render::error_map::ErrorReport;

use super::{App, Display, dolly, orbit};

/// Degrees of orbit per point of mouse drag.
const ORBIT_PER_POINT: f64 = 0.3;

impl App {
    /// The left panel.
    pub(super) fn controls(&mut self, ui: &mut egui::Ui, ctx: &egui::Context) {
        ui.heading("photometeor view");
        ui.label(format!("adapter: {}", self.adapter));
        ui.label(format!(
            "tables: {} ({}), {}",
            crate::commands::render::shown_path(&self.plan.out_dir),
            format!("{:?}", self.plan.quality).to_lowercase(),
            self.plan
                .scene
                .fields
                .iter()
                .map(|f| f.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ));
        self.frame_figures(ui);
        ui.separator();
        self.model_controls(ui);
        ui.separator();
        self.view_controls(ui, ctx);
        ui.separator();
        self.field_controls(ui, ctx);
        ui.separator();
        self.truth_controls(ui);
        for e in [
            &self.scene_error,
            &self.bake_error,
            &self.settings_error,
            &self.render_error,
        ]
        .into_iter()
        .flatten()
        {
            ui.colored_label(egui::Color32::from_rgb(255, 110, 90), e);
        }
    }

    /// The frame time and its passes (wall times on the host, from submit to the image back).
    fn frame_figures(&self, ui: &mut egui::Ui) {
        let Some(s) = &self.on_screen else {
            ui.label("rendering the first frame…");
            return;
        };
        let image = &s.rendered.image;
        ui.label(format!(
            "{}×{} px, frame {:.1} ms (request to image {:.1} ms)",
            image.width,
            image.height,
            s.rendered.seconds("frame").unwrap_or(s.seconds) * 1e3,
            s.seconds * 1e3
        ));
        let passes: Vec<String> = s
            .rendered
            .passes
            .iter()
            .map(|p| format!("{} {:.1}", p.name, p.seconds * 1e3))
            .collect();
        ui.small(format!(
            "passes (ms, host wall time): {}",
            passes.join(", ")
        ));
        if self.generation != self.answered {
            ui.small("rendering the newest view…");
        }
    }

    /// The model and its settings, each key as the scene file would give it.
    fn model_controls(&mut self, ui: &mut egui::Ui) {
        let before = self.model.clone();
        egui::ComboBox::from_label("model")
            .selected_text(&self.model)
            .show_ui(ui, |ui| {
                for name in self.models.keys().cloned().collect::<Vec<_>>() {
                    ui.selectable_value(&mut self.model, name.clone(), name);
                }
            });
        if let Some(why) = &self.chosen {
            ui.small(format!("auto: {why}"));
        }
        if self.model != before {
            self.settings_error = None;
            self.dirty = true;
        }
        let mut table = self.models[&self.model].0.clone();
        let mut changed = false;
        egui::Grid::new("settings").num_columns(2).show(ui, |ui| {
            for (key, value) in table.iter_mut() {
                ui.label(key);
                changed |= edit_value(ui, key, value);
                ui.end_row();
            }
        });
        if changed {
            self.set_settings(table);
        }
    }

    /// Sun, camera, exposure and density.
    fn view_controls(&mut self, ui: &mut egui::Ui, ctx: &egui::Context) {
        let mut changed = false;
        changed |= ui
            .add(egui::Slider::new(&mut self.sun.elevation_deg, 0.5..=90.0).text("sun elevation °"))
            .changed();
        changed |= ui
            .add(egui::Slider::new(&mut self.sun.azimuth_deg, -180.0..=180.0).text("sun azimuth °"))
            .changed();
        changed |= ui
            .add(egui::Slider::new(&mut self.camera.fov_deg, 5.0..=120.0).text("field of view °"))
            .changed();
        changed |= ui
            .add(
                egui::Slider::new(&mut self.density_scale, 0.05..=20.0)
                    .logarithmic(true)
                    .text("density ×"),
            )
            .changed();
        if changed {
            self.dirty = true;
        }
        let mut exposure = self.exposure.unwrap_or(1.0);
        if ui
            .add(
                egui::Slider::new(&mut exposure, 1e-3..=1e4)
                    .logarithmic(true)
                    .text("exposure"),
            )
            .changed()
        {
            self.exposure = Some(exposure);
            self.retone(ctx);
        }
        ui.add(
            egui::Slider::new(&mut self.fly_speed, 0.05..=20.0)
                .logarithmic(true)
                .text("fly speed ×"),
        );
        if ui.button("reset view").clicked() {
            (self.camera, self.sun) = self.home;
            self.density_scale = 1.0;
            self.dirty = true;
        }
        ui.small("drag: orbit · right drag: pan · wheel: dolly · W A S D, Q E: fly");
    }

    /// The truth of this view, traced in the background; the error figures against it and
    /// the A/B switch.
    fn truth_controls(&mut self, ui: &mut egui::Ui) {
        let (lo, hi) = render::truth::SPP_RANGE;
        ui.horizontal(|ui| {
            ui.add(
                egui::DragValue::new(&mut self.truth_spp)
                    .range(lo..=hi)
                    .suffix(" spp"),
            );
            if ui
                .button("trace this view")
                .on_hover_text(
                    "the path-traced truth of the view as it is now (the GPU's, or the CPU's \
                     on a software adapter), shown as it converges",
                )
                .clicked()
            {
                self.trace(self.truth_spp);
            }
            let running = self.truth_run.as_ref().is_some_and(|r| !r.ended());
            if running && ui.button("stop").clicked() {
                self.truth_run.as_ref().expect("running").stop();
            }
        });
        if let Some(status) = &self.truth_status {
            ui.small(status);
        }
        if self.truth.is_none() {
            return;
        }
        ui.horizontal(|ui| {
            ui.selectable_value(&mut self.display, Display::Model, "model");
            ui.selectable_value(&mut self.display, Display::Truth, "truth");
            ui.selectable_value(&mut self.display, Display::Error, "error map");
        });
        match self.on_screen.as_ref().and_then(|s| s.report.as_ref()) {
            Some(r) => {
                ui.label(report_line(r));
                ui.small(
                    "error map: red too bright, blue too dark (full at ±50 %), grey within 3σ",
                );
            }
            None => {
                ui.label("the truth is of another view");
                if ui.button("go to the truth's view").clicked() {
                    (self.camera, self.sun, self.density_scale) = self.truth_view;
                    self.dirty = true;
                }
            }
        }
    }

    /// The central panel: the image at the largest integer zoom that fits, and the camera's
    /// mouse and key controls over it.
    pub(super) fn image(&mut self, ui: &mut egui::Ui) {
        let Some(s) = &self.on_screen else {
            ui.centered_and_justified(|ui| ui.spinner());
            return;
        };
        let index = match self.display {
            Display::Model => 0,
            Display::Truth => 1,
            Display::Error => 2,
        };
        let texture = s.textures[index].as_ref().or(s.textures[0].as_ref());
        let (w, h) = (s.rendered.image.width, s.rendered.image.height);
        let ppp = ui.ctx().pixels_per_point();
        self.pixels_per_point = ppp;
        let avail = ui.available_size() * ppp;
        let fit = ((avail.x / w as f32).min(avail.y / h as f32)).floor();
        self.zoom = (fit as usize).max(1);
        let size = egui::vec2(w as f32, h as f32) * self.zoom as f32 / ppp;
        // Whole pixels, so that the window's pixels are the image's.
        let min = (ui.min_rect().min * ppp).round() / ppp;
        let rect = egui::Rect::from_min_size(min, size);
        let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
        if let Some(texture) = texture {
            ui.painter().image(
                texture.id(),
                rect,
                egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                egui::Color32::WHITE,
            );
        }
        self.image_rect = rect;
        self.camera_input(ui, &response);
    }

    /// Orbit (drag), pan (right drag), dolly (wheel) and fly (keys).
    fn camera_input(&mut self, ui: &egui::Ui, response: &egui::Response) {
        let drag = response.drag_delta();
        if response.dragged_by(egui::PointerButton::Primary) && drag != egui::Vec2::ZERO {
            orbit(
                &mut self.camera,
                -drag.x as f64 * ORBIT_PER_POINT,
                drag.y as f64 * ORBIT_PER_POINT,
            );
            self.dirty = true;
        }
        if response.dragged_by(egui::PointerButton::Secondary)
            && drag != egui::Vec2::ZERO
            && let Some((_, right, up)) = self.camera.axes()
        {
            let distance = (self.camera.position_m - self.camera.look_at_m).length();
            let per_point =
                2.0 * distance * self.camera.tan_half_fov() / self.image_rect.height() as f64;
            let shift = (-drag.x as f64 * right + drag.y as f64 * up) * per_point;
            self.camera.position_m += shift;
            self.camera.look_at_m += shift;
            self.camera.position_m.y = self.camera.position_m.y.max(0.0);
            self.dirty = true;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                dolly(&mut self.camera, (-scroll as f64 * 0.002).exp());
                self.dirty = true;
            }
        }
        self.fly(ui);
    }

    /// W/S along the view, A/D sideways, Q/E down and up; speed: the distance to the look-at
    /// point per second, times the fly speed.
    fn fly(&mut self, ui: &egui::Ui) {
        if ui.ctx().egui_wants_keyboard_input() {
            return;
        }
        let Some((forward, right, _)) = self.camera.axes() else {
            return;
        };
        let (dt, keys) = ui.input(|i| {
            let key = |k| if i.key_down(k) { 1.0 } else { 0.0 };
            (
                i.stable_dt.min(0.1) as f64,
                [
                    key(egui::Key::W) - key(egui::Key::S),
                    key(egui::Key::D) - key(egui::Key::A),
                    key(egui::Key::E) - key(egui::Key::Q),
                ],
            )
        });
        if keys == [0.0; 3] {
            return;
        }
        let distance = (self.camera.position_m - self.camera.look_at_m).length();
        let step = distance * self.fly_speed * dt;
        let shift = (keys[0] * forward + keys[1] * right + keys[2] * glam::DVec3::Y) * step;
        self.camera.position_m += shift;
        self.camera.look_at_m += shift;
        self.camera.position_m.y = self.camera.position_m.y.max(0.0);
        self.dirty = true;
        ui.ctx().request_repaint();
    }
}

/// One editable setting; true when it changed (numbers on release or Enter, so a drag does
/// not queue a frame per step).
fn edit_value(ui: &mut egui::Ui, key: &str, value: &mut toml::Value) -> bool {
    match value {
        toml::Value::Integer(i) => ui.add(egui::DragValue::new(i)).changed(),
        toml::Value::Float(f) => {
            let speed = (f.abs() * 0.01).max(1e-6);
            // Rust's shortest exact form: a tolerance of 1e-5 reads as such, not as 0.0000.
            ui.add(
                egui::DragValue::new(f)
                    .speed(speed)
                    .custom_formatter(|v, _| format!("{v}")),
            )
            .changed()
        }
        toml::Value::Boolean(b) => ui.checkbox(b, "").changed(),
        toml::Value::String(s) => {
            let id = ui.scope_id().with(key);
            let mut text = ui
                .data(|d| d.get_temp::<String>(id))
                .unwrap_or_else(|| s.clone());
            let response = ui.text_edit_singleline(&mut text);
            let done = response.lost_focus() && text != *s;
            if done {
                *s = text.clone();
            }
            ui.data_mut(|d| d.insert_temp(id, text));
            done
        }
        other => {
            ui.label(other.to_string());
            false
        }
    }
}

/// The error figures in one line.
fn report_line(r: &ErrorReport) -> String {
    format!(
        "against the truth over {} px: bias {:+.1} %, median {:.1} %, p95 {:.1} % (truth noise \
         {:.1} %)",
        r.pixels,
        r.bias * 100.0,
        r.median_rel_error * 100.0,
        r.p95_rel_error * 100.0,
        r.truth_noise * 100.0
    )
}
