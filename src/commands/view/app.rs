//! The window: what the user controls, the frame on screen, the A/B with the truth, the
//! watched scene file, and the script and screenshot that drive it without a person.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use anyhow::{Result, anyhow};
use bake::BakePlan;
use eframe::egui;
use render::camera::{Camera, Sun};
use render::error_map::{self, ErrorReport, Pixels};
use render::{ModelSettings, RenderScene, Rendered};

use super::rebake::Rebake;
use super::script::Step;
use super::worker::{Request, TruthNews, TruthRun, Worker};

/// What `run` hands the window.
pub struct Options {
    /// The scene file, watched for edits (none: the embedded scene).
    pub scene_path: Option<PathBuf>,
    /// The first model with its settings (`--set` applied).
    pub first_model: ModelSettings,
    /// `--exposure`.
    pub exposure: Option<f64>,
    /// `--truth`'s frame.
    pub truth: Option<error_map::Frame>,
    /// `--screenshot`.
    pub screenshot: Option<PathBuf>,
    /// `--frames`.
    pub frames: usize,
    /// `--script`'s steps.
    pub steps: Vec<Step>,
    /// The render device, in words.
    pub adapter: String,
    /// What `--model auto` chose and why (shown under the model's menu).
    pub chosen: Option<String>,
    /// `--width`, `--height` (kept over an edited scene file's).
    pub size: (Option<usize>, Option<usize>),
    /// The files the scene reads beside itself, watched with it.
    pub inputs: Vec<PathBuf>,
}

/// The three files a screenshot writes: the window (PNG), the view's radiance (EXR) and what
/// it showed (JSON).
pub fn shot_files(png: &Path) -> [PathBuf; 3] {
    [
        png.to_path_buf(),
        png.with_extension("exr"),
        png.with_extension("json"),
    ]
}

/// Opens the window and runs it until it is closed (or the script's screenshot is written).
pub fn open(options: Options, scene: RenderScene, plan: BakePlan, worker: Worker) -> Result<()> {
    let (w, h) = (scene.width as f32, scene.height as f32);
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("photometeor view")
            // Room for a small image at twice its size.
            .with_inner_size([w.max(640.0) + PANEL_WIDTH + 24.0, h.max(560.0) + 24.0]),
        renderer: eframe::Renderer::Wgpu,
        // The screenshot must hold the tone-mapped pixels exactly as `render` writes them.
        dithering: false,
        ..Default::default()
    };
    let outcome = Arc::new(Mutex::new(Ok(())));
    let told = outcome.clone();
    eframe::run_native(
        "photometeor view",
        native,
        Box::new(move |cc| {
            worker.set_context(&cc.egui_ctx);
            Ok(Box::new(App::new(options, scene, plan, worker, told)))
        }),
    )
    .map_err(|e| {
        anyhow!(
            "photometeor view needs a display (X11 or Wayland: DISPLAY or WAYLAND_DISPLAY) and a \
             GPU surface; the window could not open: {e}"
        )
    })?;
    let result = std::mem::replace(&mut *outcome.lock().expect("not poisoned"), Ok(()));
    result.map_err(|e| anyhow!("{e}"))
}

/// The samples per pixel the window's truth starts with.
const DEFAULT_TRUTH_SPP: usize = 64;

/// Width of the control panel (points).
const PANEL_WIDTH: f32 = 330.0;

/// What the window shows in its image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Display {
    Model,
    Truth,
    Error,
}

/// A frame on screen and what it was rendered from.
struct OnScreen {
    rendered: Rendered,
    request: Request,
    /// Wall time of the request on the render thread (s).
    seconds: f64,
    /// The exposure it is tone-mapped with.
    exposure: f64,
    /// Its error against the truth, when the truth is of this view.
    report: Option<ErrorReport>,
    /// Textures: model, truth, error map (the last two with a truth of this view).
    textures: [Option<egui::TextureHandle>; 3],
}

/// One thing the headless driver does once the window is idle (the newest view on screen).
enum Action {
    Apply(Box<Step>),
    /// Render the same view again (for the mean frame time).
    Repeat,
    Shot(PathBuf),
    /// Wait for the truth run to end.
    AwaitTruth,
    /// Wait this long (s), drawing and watching the scene file.
    Wait(f64),
    Exit,
}

struct App {
    worker: Worker,
    /// The last good scene (the file's, with the view's size).
    scene: RenderScene,
    plan: BakePlan,
    scene_path: Option<PathBuf>,
    /// The files the scene reads beside itself (grids, OpenVDB files, OBJ meshes), watched
    /// with it: a cloud re-exported from Houdini is reloaded as an edit of the scene.
    inputs: Vec<PathBuf>,
    /// When the scene file and each of `inputs` was last modified.
    modified: Vec<Option<SystemTime>>,
    checked: Instant,
    size: (Option<usize>, Option<usize>),
    scene_error: Option<String>,
    /// A scene that waits for its tables.
    pending_scene: Option<RenderScene>,
    rebake: Rebake,
    bake_error: Option<String>,
    // The view.
    model: String,
    models: BTreeMap<String, (toml::Table, ModelSettings)>,
    settings_error: Option<String>,
    camera: Camera,
    sun: Sun,
    density_scale: f64,
    exposure: Option<f64>,
    fly_speed: f64,
    // Frames.
    generation: u64,
    dirty: bool,
    /// Requests sent and not yet answered, oldest first.
    sent: VecDeque<Request>,
    /// The newest generation answered (a frame or an error), and the newest drawn.
    answered: u64,
    drawn: u64,
    on_screen: Option<OnScreen>,
    render_error: Option<String>,
    frame_times: Vec<(f64, f64)>,
    /// How many of them were drawn from a relight that had not converged.
    converging_frames: usize,
    adapter: String,
    /// What `--model auto` chose and why.
    chosen: Option<String>,
    image_rect: egui::Rect,
    zoom: usize,
    /// Physical pixels per point, as of the last pass.
    pixels_per_point: f32,
    /// The scene's own view: what "reset view" returns to.
    home: (Camera, Sun),
    /// The fields as being edited (a drag not yet released).
    editing: Option<Vec<bake::Field>>,
    // The truth.
    truth: Option<error_map::Frame>,
    truth_view: (Camera, Sun, f64),
    display: Display,
    /// The truth traced in the background, its samples per pixel, and where it stands.
    truth_run: Option<TruthRun>,
    truth_spp: usize,
    truth_status: Option<String>,
    // Headless.
    actions: VecDeque<Action>,
    shot: Arc<Mutex<Option<Arc<egui::ColorImage>>>>,
    shooting: Option<PathBuf>,
    waiting: Option<Instant>,
    outcome: Arc<Mutex<Result<(), String>>>,
}

impl App {
    fn new(
        options: Options,
        scene: RenderScene,
        plan: BakePlan,
        worker: Worker,
        outcome: Arc<Mutex<Result<(), String>>>,
    ) -> Self {
        let model = options.first_model.name().to_string();
        let models = model_tables(&scene, Some(&options.first_model));
        let mut actions: VecDeque<Action> = VecDeque::new();
        for step in options.steps {
            let shot = step.screenshot.clone();
            let wait = step.wait_s;
            let traces = step.truth_spp.is_some();
            actions.push_back(Action::Apply(Box::new(step)));
            actions.extend(traces.then_some(Action::AwaitTruth));
            actions.extend(shot.map(Action::Shot));
            actions.extend(wait.map(Action::Wait));
        }
        if let Some(path) = options.screenshot {
            actions.extend((1..options.frames).map(|_| Action::Repeat));
            actions.push_back(Action::Shot(path));
            actions.push_back(Action::Exit);
        }
        let modified = stamps(options.scene_path.as_deref(), &options.inputs);
        Self {
            worker,
            camera: scene.camera,
            sun: scene.sun,
            exposure: options.exposure.or(scene.exposure),
            truth_view: (scene.camera, scene.sun, 1.0),
            home: (scene.camera, scene.sun),
            editing: None,
            scene,
            plan,
            scene_path: options.scene_path,
            inputs: options.inputs,
            modified,
            checked: Instant::now(),
            size: options.size,
            scene_error: None,
            pending_scene: None,
            rebake: Rebake::default(),
            bake_error: None,
            model,
            models,
            settings_error: None,
            density_scale: 1.0,
            fly_speed: 1.0,
            generation: 0,
            dirty: true,
            sent: VecDeque::new(),
            answered: 0,
            drawn: 0,
            on_screen: None,
            render_error: None,
            frame_times: Vec::new(),
            converging_frames: 0,
            adapter: options.adapter,
            chosen: options.chosen,
            image_rect: egui::Rect::NOTHING,
            zoom: 1,
            pixels_per_point: 1.0,
            truth: options.truth,
            display: Display::Model,
            truth_run: None,
            truth_spp: DEFAULT_TRUTH_SPP,
            truth_status: None,
            actions,
            shot: Arc::new(Mutex::new(None)),
            shooting: None,
            waiting: None,
            outcome,
        }
    }

    /// The view as a request to the render thread.
    fn request(&mut self) -> Option<Request> {
        let (_, model) = self.models.get(&self.model)?;
        self.generation += 1;
        Some(Request {
            generation: self.generation,
            model: model.clone(),
            camera: self.camera,
            sun: self.sun,
            density_scale: self.density_scale,
        })
    }

    /// Takes the render thread's finished frames; the newest becomes the one on screen. A
    /// frame that fails is shown as an error, and ends a headless run.
    fn receive(&mut self, ctx: &egui::Context) {
        for shown in self.worker.finished() {
            self.answered = shown.generation;
            while self
                .sent
                .front()
                .is_some_and(|r| r.generation < shown.generation)
            {
                self.sent.pop_front();
            }
            let Some(request) = self.sent.pop_front() else {
                continue;
            };
            match shown.result {
                Err(e) => {
                    eprintln!("view: {e}");
                    if !self.actions.is_empty() {
                        self.fail(ctx, format!("the frame failed: {e}"));
                    }
                    self.render_error = Some(e);
                }
                Ok(rendered) => {
                    self.render_error = None;
                    let frame = rendered.seconds("frame").unwrap_or(shown.seconds);
                    self.frame_times.push((frame, shown.seconds));
                    // A relight in steps that has not converged: the next frame of this view
                    // takes it further (and a screenshot waits for the converged one).
                    if rendered.is_converging() {
                        self.dirty = true;
                        self.converging_frames += 1;
                    }
                    self.show(ctx, rendered, request, shown.seconds);
                }
            }
        }
    }

    /// Starts the path-traced truth of the view as it is now, `spp` samples per pixel (the
    /// scene's `[render.truth]` settings otherwise), replacing a run under way; its running
    /// image becomes the A/B's truth pass by pass.
    fn trace(&mut self, spp: usize) {
        let settings = self
            .scene
            .model("truth", &[("spp".into(), toml::Value::Integer(spp as i64))]);
        match settings {
            Ok(model) => {
                self.truth_run = Some(self.worker.trace(Request {
                    generation: 0,
                    model,
                    camera: self.camera,
                    sun: self.sun,
                    density_scale: self.density_scale,
                }));
                self.truth_spp = spp;
                self.truth_status = Some(format!("tracing this view, {spp} spp…"));
            }
            Err(e) => self.truth_status = Some(format!("truth: {}", e.0)),
        }
    }

    /// Takes the truth run's news: each running frame becomes the truth of its view and the
    /// frame on screen is compared with it again.
    fn receive_truth(&mut self, ctx: &egui::Context) {
        let Some(run) = self.truth_run.as_mut() else {
            return;
        };
        let view = run.view;
        let mut compare = false;
        for news in run.news() {
            match news {
                TruthNews::Running { frame, spp, noise } => {
                    self.truth = Some(frame);
                    self.truth_view = view;
                    self.truth_status = Some(format!(
                        "tracing: {spp} of {} spp, noise {:.2} %",
                        self.truth_spp,
                        noise * 100.0
                    ));
                    compare = true;
                }
                TruthNews::Ended(Ok(summary)) => self.truth_status = Some(summary),
                TruthNews::Ended(Err(e)) => {
                    eprintln!("view: truth: {e}");
                    if !self.actions.is_empty() {
                        self.fail(ctx, format!("the truth failed: {e}"));
                    }
                    self.truth_status = Some(format!("truth: {e}"));
                }
            }
        }
        if compare {
            self.retone(ctx);
        }
    }

    /// Puts a frame on screen: tone-mapped as `render`'s PNG, with the truth's A/B when the
    /// truth is of this view.
    fn show(&mut self, ctx: &egui::Context, rendered: Rendered, request: Request, seconds: f64) {
        let image = &rendered.image;
        let exposure = *self.exposure.get_or_insert_with(|| image.auto_exposure());
        let texture = |name: &str, rgb: &[u8]| {
            ctx.load_texture(
                name,
                egui::ColorImage::from_rgb([image.width, image.height], rgb),
                egui::TextureOptions::NEAREST,
            )
        };
        let mut textures = [
            Some(texture("model", &image.to_srgb8(exposure))),
            None,
            None,
        ];
        let mut report = None;
        let same_view = (request.camera, request.sun, request.density_scale) == self.truth_view;
        if let Some(truth) = self.truth.as_ref().filter(|_| same_view) {
            let model = error_map::Frame {
                image: image.clone(),
                std_error: None,
                luma_error: None,
            };
            match error_map::compare(truth, &model, Pixels::Volume) {
                Ok((r, map)) => {
                    textures[1] = Some(texture("truth", &truth.image.to_srgb8(exposure)));
                    textures[2] = Some(texture("error", &error_map::error_map_rgb8(&map)));
                    report = Some(r);
                }
                Err(e) => self.render_error = Some(format!("--truth: {e}")),
            }
        }
        self.on_screen = Some(OnScreen {
            rendered,
            request,
            seconds,
            exposure,
            report,
            textures,
        });
    }

    /// Tone-maps the frame on screen again (the exposure changed).
    fn retone(&mut self, ctx: &egui::Context) {
        if let Some(s) = self.on_screen.take() {
            self.show(ctx, s.rendered, s.request, s.seconds);
        }
    }

    /// Whether the newest view is on screen and has been drawn, with nothing baking.
    fn idle(&self) -> bool {
        !self.dirty
            && self.answered == self.generation
            && self.drawn == self.generation
            && self.rebake.progress().is_none()
            && self.pending_scene.is_none()
    }

    /// The headless driver: one action per idle pass; a screenshot waits for its pixels.
    fn drive(&mut self, ctx: &egui::Context) {
        if let Some(path) = self.shooting.clone() {
            let Some(pixels) = self.shot.lock().expect("not poisoned").take() else {
                ctx.request_repaint_after(Duration::from_millis(20));
                return;
            };
            self.shooting = None;
            if let Err(e) = self.write_shot(&path, &pixels) {
                self.fail(ctx, format!("--screenshot {}: {e:#}", path.display()));
            }
            ctx.request_repaint();
            return;
        }
        if let Some(until) = self.waiting {
            if Instant::now() < until {
                ctx.request_repaint_after(Duration::from_millis(50));
                return;
            }
            self.waiting = None;
        }
        if self.actions.is_empty() || !self.idle() {
            return;
        }
        match self.actions.pop_front().expect("not empty") {
            Action::Apply(step) => self.apply(&step, ctx),
            Action::Repeat => self.dirty = true,
            Action::Shot(path) => {
                let slot = self.shot.clone();
                let repaint = ctx.clone();
                ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(
                    egui::ScreenshotCallback::new(move |image| {
                        *slot.lock().expect("not poisoned") = Some(image);
                        repaint.request_repaint();
                    }),
                ));
                self.shooting = Some(path);
            }
            Action::AwaitTruth => {
                if self.truth_run.as_ref().is_some_and(|r| !r.ended()) {
                    self.actions.push_front(Action::AwaitTruth);
                    ctx.request_repaint_after(Duration::from_millis(50));
                    return;
                }
            }
            Action::Wait(s) => {
                self.waiting = Some(Instant::now() + Duration::from_secs_f64(s));
            }
            Action::Exit => ctx.send_viewport_cmd(egui::ViewportCommand::Close),
        }
        ctx.request_repaint();
    }

    /// Ends the session with an error (exit 2, on stderr).
    fn fail(&mut self, ctx: &egui::Context, message: String) {
        *self.outcome.lock().expect("not poisoned") = Err(message);
        self.actions.clear();
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// A script step: what it gives changes.
    fn apply(&mut self, step: &Step, ctx: &egui::Context) {
        if let Some(e) = step.sun_elevation_deg {
            self.sun.elevation_deg = e;
        }
        if let Some(a) = step.sun_azimuth_deg {
            self.sun.azimuth_deg = a;
        }
        if let Some([yaw, pitch]) = step.orbit_deg {
            orbit(&mut self.camera, yaw, pitch);
        }
        if let Some(f) = step.dolly {
            dolly(&mut self.camera, f);
        }
        if let Some(model) = &step.model {
            self.model = model.clone();
        }
        if let Some(set) = &step.set {
            let mut table = self.models[&self.model].0.clone();
            table.extend(set.clone());
            self.set_settings(table);
        }
        if let Some(d) = step.density_scale {
            self.density_scale = d;
        }
        if let Some(e) = step.exposure {
            self.exposure = Some(e);
        }
        if let Some(d) = step.display {
            self.display = d;
        }
        if let Some(sizes) = &step.field_size {
            let mut fields = self.plan.scene.fields.clone();
            for (name, value) in sizes {
                if let Some(f) = fields.iter_mut().find(|f| &f.name == name)
                    && let Some((_, size, _)) = watch::knobs(f).into_iter().next()
                {
                    *size = *value;
                }
            }
            if let Err(e) = self.bake_fields(fields, ctx) {
                self.fail(ctx, format!("--script step: field_size: {e:#}"));
            }
        }
        if let Some(spp) = step.truth_spp {
            self.trace(spp);
        }
        self.frame_times.clear();
        self.converging_frames = 0;
        self.dirty = true;
    }

    /// Replaces the current model's settings when they parse; shows why not otherwise.
    fn set_settings(&mut self, table: toml::Table) {
        match ModelSettings::parse(&self.model, &table) {
            Ok(settings) => {
                self.models.insert(self.model.clone(), (table, settings));
                self.settings_error = None;
                self.dirty = true;
            }
            Err(e) => self.settings_error = Some(e.0),
        }
    }

    /// Writes the window's pixels (PNG), the view's radiance (EXR) and what it showed (JSON).
    fn write_shot(&self, path: &Path, pixels: &egui::ColorImage) -> Result<()> {
        let s = self
            .on_screen
            .as_ref()
            .ok_or_else(|| anyhow!("no frame on screen"))?;
        let [png, exr, json] = shot_files(path);
        let [w, h] = pixels.size;
        let rgb: Vec<u8> = pixels
            .pixels
            .iter()
            .flat_map(|c| [c.r(), c.g(), c.b()])
            .collect();
        let bytes = crate::commands::plot::png_rgb8(w as u32, h as u32, &rgb)?;
        format::write_output(&png, &bytes, &[])?;
        s.rendered.image.write_exr(&exr)?;
        // The truth the frame is compared with, beside it (with its standard error).
        let truth = self.truth.as_ref().filter(|_| s.report.is_some());
        if let Some(t) = truth {
            let extra = t.std_error.as_ref().map_or_else(Vec::new, |e| {
                (0..3)
                    .map(|c| {
                        let name = format!("stderr.{}", ["R", "G", "B"][c]);
                        (name, e.iter().map(|v| v[c]).collect())
                    })
                    .collect()
            });
            t.image
                .write_exr_with(&path.with_extension("truth.exr"), extra)?;
        }
        // The frames of this view: those since the last step (the `--frames` repeats).
        let n = self.frame_times.len();
        let mean = |f: fn(&(f64, f64)) -> f64| {
            self.frame_times.iter().map(f).sum::<f64>() / n.max(1) as f64
        };
        let r = self.image_rect;
        let ppp = self.pixels_per_point;
        let report = serde_json::json!({
            "image_rect_px": [r.min.x * ppp, r.min.y * ppp, r.width() * ppp, r.height() * ppp],
            "zoom": self.zoom,
            "image_size": [s.rendered.image.width, s.rendered.image.height],
            "window_size_px": [w, h],
            "model": s.request.model.name(),
            "settings": s.request.model.to_table(),
            "sun": { "elevation_deg": s.request.sun.elevation_deg, "azimuth_deg": s.request.sun.azimuth_deg },
            "camera": {
                "position_m": s.request.camera.position_m.to_array(),
                "look_at_m": s.request.camera.look_at_m.to_array(),
                "fov_deg": s.request.camera.fov_deg,
            },
            "density_scale": s.request.density_scale,
            "exposure": s.exposure,
            "display": format!("{:?}", self.display).to_lowercase(),
            "frames": n,
            "converging_frames": self.converging_frames,
            "frame_seconds": self.frame_times.iter().map(|t| t.0).collect::<Vec<_>>(),
            "frame_seconds_mean": mean(|t| t.0),
            "wall_seconds_mean": mean(|t| t.1),
            "passes": s.rendered.passes.iter().map(|p| (p.name, p.seconds)).collect::<Vec<_>>(),
            "figures": s.rendered.figures,
            "adapter": self.adapter,
            "error_against_truth": s.report,
            "truth": self.truth_status,
        });
        format::write_output(
            &json,
            serde_json::to_string_pretty(&report)?.as_bytes(),
            &[],
        )?;
        Ok(())
    }
}

/// Each GPU model's settings as a table (the scene's, defaults filled in) and parsed; `first`
/// replaces its model's (the command line's `--set`).
fn model_tables(
    scene: &RenderScene,
    first: Option<&ModelSettings>,
) -> BTreeMap<String, (toml::Table, ModelSettings)> {
    super::models()
        .into_iter()
        .filter_map(|name| {
            let settings = match first {
                Some(f) if f.name() == name => f.clone(),
                _ => scene.model(name, &[]).ok()?,
            };
            Some((name.to_string(), (settings.to_table(), settings)))
        })
        .collect()
}

/// The file's modification time.
fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// When the scene file `scene` and each of `inputs` was last modified.
fn stamps(scene: Option<&Path>, inputs: &[PathBuf]) -> Vec<Option<SystemTime>> {
    scene
        .into_iter()
        .chain(inputs.iter().map(PathBuf::as_path))
        .map(modified)
        .collect()
}

/// Rotates the camera about its look-at point: `yaw` degrees about +y, `pitch` degrees up,
/// the elevation kept within ±89° and the camera at or above the ground.
pub fn orbit(camera: &mut Camera, yaw_deg: f64, pitch_deg: f64) {
    let offset = camera.position_m - camera.look_at_m;
    let r = offset.length();
    if r <= 0.0 {
        return;
    }
    let yaw = offset.x.atan2(offset.z) + yaw_deg.to_radians();
    let pitch = ((offset.y / r).clamp(-1.0, 1.0).asin() + pitch_deg.to_radians())
        .clamp(-89f64.to_radians(), 89f64.to_radians());
    let moved = camera.look_at_m
        + r * glam::DVec3::new(
            pitch.cos() * yaw.sin(),
            pitch.sin(),
            pitch.cos() * yaw.cos(),
        );
    camera.position_m = glam::DVec3::new(moved.x, moved.y.max(0.0), moved.z);
}

/// Scales the camera's distance to its look-at point by `factor`, keeping it above the ground.
pub fn dolly(camera: &mut Camera, factor: f64) {
    let moved = camera.look_at_m + (camera.position_m - camera.look_at_m) * factor;
    camera.position_m = glam::DVec3::new(moved.x, moved.y.max(0.0), moved.z);
}

impl eframe::App for App {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.receive(&ctx);
        self.receive_truth(&ctx);
        self.watch_scene(&ctx);
        self.take_bake(&ctx);
        egui::Panel::left("controls")
            .exact_size(PANEL_WIDTH)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui, &ctx));
            });
        egui::CentralPanel::default().show(ui, |ui| self.image(ui));
        if self.dirty
            && let Some(request) = self.request()
        {
            self.sent.push_back(request.clone());
            self.worker.render(request);
            self.dirty = false;
        }
        self.drawn = self.answered;
        self.drive(&ctx);
        if self.rebake.progress().is_some() || self.scene_path.is_some() {
            ctx.request_repaint_after(Duration::from_millis(250));
        }
    }
}

mod panel;
mod watch;
