//! The render thread: it owns the device, the tables and each model's prepared renderer, and
//! renders the newest request it has (module docs of `view`).

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::Instant;

use anyhow::{Context, Result};
use render::camera::{Camera, Sun};
use render::error_map;
use render::model::Progress;
use render::registry::Prepared;
use render::relight::LightingCache;

use render::{Frame, Image, Job, ModelSettings, On, RenderScene, Rendered};
use runtime::Tables;
use runtime::gpu::Gpu;

/// One view to render.
#[derive(Clone)]
pub struct Request {
    /// Increases with every request; the window shows the newest result.
    pub generation: u64,
    /// The model and its settings.
    pub model: ModelSettings,
    /// The camera.
    pub camera: Camera,
    /// The sun.
    pub sun: Sun,
    /// Factor on every volume's number density.
    pub density_scale: f64,
}

/// What the window sends.
enum Message {
    /// Render this view (merged with later ones: the newest wins).
    Render(Box<Request>),
    /// A new scene (edited file) with its tables, or with the ones in use (`None`).
    Scene(Box<RenderScene>, Option<Tables>),
    /// Trace this view (its model: the truth's settings) on a thread of its own.
    Truth(Box<Request>, Sink),
}

/// A finished frame.
pub struct Shown {
    /// The request's generation.
    pub generation: u64,
    /// The frame, or why it could not be rendered.
    pub result: Result<Rendered, String>,
    /// Wall time from the request's start to the image on the host (s).
    pub seconds: f64,
}

/// The window's end of the render thread. Dropping it stops every truth run, closes the render
/// thread's inbox and waits for it (and the truth threads it started) to end, so the device is
/// released before the process exits: a thread still inside the Vulkan driver while the
/// process's exit tears the driver down can crash it (seen on lavapipe).
pub struct Worker {
    /// `None` only while dropping.
    to: Option<Sender<Message>>,
    /// The render thread (`None` only while dropping).
    thread: Option<JoinHandle<()>>,
    /// Every truth run's stop flag.
    stops: Mutex<Vec<Arc<AtomicBool>>>,
    from: Receiver<Shown>,
    /// Told to repaint when a frame is done.
    repaint: Arc<OnceLock<eframe::egui::Context>>,
}

impl Worker {
    /// Starts the thread with `gpu`, `scene` and its `tables`, a relight going in steps of
    /// about `budget` a frame; fails (before any window opens) when the scene's grid cannot be
    /// built.
    pub fn start(
        gpu: Gpu,
        scene: RenderScene,
        tables: Tables,
        budget: std::time::Duration,
    ) -> Result<Self> {
        let base = scene.frame(&tables).context("building the density grid")?;
        let (to, inbox) = channel();
        let (outbox, from) = channel();
        let repaint = Arc::new(OnceLock::<eframe::egui::Context>::new());
        let told = repaint.clone();
        let mut state = State {
            gpu,
            scene,
            tables,
            base: Ok(base),
            scaled: None,
            prepared: HashMap::new(),
            lighting: LightingCache::stepped(budget),
            budget,
            truths: Vec::new(),
        };
        let thread = std::thread::Builder::new()
            .name("render".into())
            .spawn(move || {
                while let Some(request) = next_request(&inbox, &mut state) {
                    let started = Instant::now();
                    let result = state.render(&request).map_err(|e| format!("{e:#}"));
                    let shown = Shown {
                        generation: request.generation,
                        result,
                        seconds: started.elapsed().as_secs_f64(),
                    };
                    if outbox.send(shown).is_err() {
                        return;
                    }
                    if let Some(ctx) = told.get() {
                        ctx.request_repaint();
                    }
                }
                state.end_truths();
            })
            .context("starting the render thread")?;
        Ok(Self {
            to: Some(to),
            thread: Some(thread),
            stops: Mutex::new(Vec::new()),
            from,
            repaint,
        })
    }

    fn send(&self, message: Message) {
        if let Some(to) = &self.to {
            let _ = to.send(message);
        }
    }

    /// The window's context, told to repaint when a frame is done.
    pub fn set_context(&self, ctx: &eframe::egui::Context) {
        let _ = self.repaint.set(ctx.clone());
    }

    /// Asks for a frame.
    pub fn render(&self, request: Request) {
        self.send(Message::Render(Box::new(request)));
    }

    /// Replaces the scene, and the tables when `tables` is given.
    pub fn set_scene(&self, scene: RenderScene, tables: Option<Tables>) {
        self.send(Message::Scene(Box::new(scene), tables));
    }

    /// The frames finished since the last call, oldest first.
    pub fn finished(&self) -> Vec<Shown> {
        self.from.try_iter().collect()
    }

    /// Starts the path-traced truth of `request`'s view (`request.model`: the truth with its
    /// settings) in the background; the frames keep coming meanwhile.
    pub fn trace(&self, request: Request) -> TruthRun {
        let (news, inbox) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let mut stops = self.stops.lock().expect("not poisoned");
        // A flag only this list holds belongs to a run that has ended and been dropped.
        stops.retain(|s| Arc::strong_count(s) > 1);
        stops.push(stop.clone());
        drop(stops);
        let run = TruthRun {
            view: (request.camera, request.sun, request.density_scale),
            news: inbox,
            stop: stop.clone(),
            ended: false,
        };
        let sink = Sink {
            news,
            stop,
            repaint: self.repaint.clone(),
        };
        self.send(Message::Truth(Box::new(request), sink));
        run
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        for stop in self.stops.lock().expect("not poisoned").iter() {
            stop.store(true, Ordering::Relaxed);
        }
        // The inbox closed, the render thread ends after the frame under way.
        self.to = None;
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            eprintln!("view: the render thread panicked (see above)");
        }
    }
}

/// What a truth run tells the window.
pub enum TruthNews {
    /// The frame so far (after each pass of samples).
    Running {
        /// The mean and standard error per pixel.
        frame: error_map::Frame,
        /// Samples per pixel taken.
        spp: usize,
        /// The truth's noise figure (median relative standard error of the volume's pixels).
        noise: f64,
    },
    /// The run has ended: its summary, or why it failed.
    Ended(Result<String, String>),
}

/// A path-traced truth of one view, traced on a thread of its own; dropping it stops it after
/// the pass under way.
pub struct TruthRun {
    /// The view it is of: the camera, the sun and the density scale.
    pub view: (Camera, Sun, f64),
    news: Receiver<TruthNews>,
    stop: Arc<AtomicBool>,
    ended: bool,
}

impl TruthRun {
    /// The news since the last call, oldest first.
    pub fn news(&mut self) -> Vec<TruthNews> {
        let mut news = Vec::new();
        let disconnected = loop {
            match self.news.try_recv() {
                Ok(n) => news.push(n),
                Err(TryRecvError::Empty) => break false,
                Err(TryRecvError::Disconnected) => break true,
            }
        };
        let ended = news.iter().any(|n| matches!(n, TruthNews::Ended(_)));
        // A thread that panicked drops its end without a word: the run has ended all the same.
        if disconnected && !ended && !self.ended {
            news.push(TruthNews::Ended(Err(
                "the truth's thread ended without a frame (it panicked; see stderr)".into(),
            )));
        }
        self.ended |= news.iter().any(|n| matches!(n, TruthNews::Ended(_)));
        news
    }

    /// Whether the run has ended (and its end been taken by [`TruthRun::news`]).
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Ends the run after the pass under way.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

impl Drop for TruthRun {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The truth thread's end of a [`TruthRun`]: the running frames go to the window, which it
/// tells to repaint, and the window's stop comes back.
struct Sink {
    news: Sender<TruthNews>,
    stop: Arc<AtomicBool>,
    repaint: Arc<OnceLock<eframe::egui::Context>>,
}

impl Sink {
    fn send(&self, news: TruthNews) {
        let _ = self.news.send(news);
        if let Some(ctx) = self.repaint.get() {
            ctx.request_repaint();
        }
    }
}

impl Progress for Sink {
    fn update(&self, _: u64, _: u64, _: &str) {}

    fn wants_running(&self) -> bool {
        true
    }

    fn running(&self, image: &Image, std_error: &[[f32; 3]], spp: usize, noise: f64) {
        self.send(TruthNews::Running {
            frame: error_map::Frame {
                image: image.clone(),
                std_error: Some(std_error.to_vec()),
                luma_error: None,
            },
            spp,
            noise,
        });
    }

    fn stop(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Waits for a request, applies every scene change that came with it, and returns the newest
/// request; `None` when the window has closed.
fn next_request(inbox: &Receiver<Message>, state: &mut State) -> Option<Request> {
    let take = |message: Message, state: &mut State, newest: &mut Option<Request>| match message {
        Message::Render(r) => *newest = Some(*r),
        Message::Scene(scene, tables) => state.set_scene(*scene, tables),
        Message::Truth(r, sink) => state.trace(&r, sink),
    };
    let mut newest: Option<Request> = None;
    take(inbox.recv().ok()?, state, &mut newest);
    loop {
        match inbox.try_recv() {
            Ok(message) => take(message, state, &mut newest),
            Err(TryRecvError::Empty) => match newest.take() {
                Some(r) => return Some(r),
                // Only scene changes so far: wait for a view to render with them.
                None => take(inbox.recv().ok()?, state, &mut newest),
            },
            Err(TryRecvError::Disconnected) => return None,
        }
    }
}

/// What the render thread holds.
struct State {
    gpu: Gpu,
    scene: RenderScene,
    tables: Tables,
    /// The scene's frame at density scale 1 (the grid built once per scene and tables).
    base: Result<Frame, String>,
    /// The frame at another density scale, and that scale.
    scaled: Option<(f64, Frame)>,
    /// Each model's renderer and its upload of the tables, made on first use.
    prepared: HashMap<&'static str, Prepared>,
    /// max's and coupled's per-sun lighting, kept while only the camera moves.
    lighting: LightingCache,
    /// Its step budget.
    budget: std::time::Duration,
    /// The truth threads started, joined before the render thread ends.
    truths: Vec<JoinHandle<()>>,
}

impl State {
    fn set_scene(&mut self, scene: RenderScene, tables: Option<Tables>) {
        if let Some(tables) = tables {
            self.tables = tables;
            self.prepared.clear();
            // The lighting was computed from the old tables.
            self.lighting = LightingCache::stepped(self.budget);
        }
        self.base = scene
            .frame(&self.tables)
            .map_err(|e| format!("building the density grid: {e}"));
        self.scene = scene;
        self.scaled = None;
    }

    /// The scene's frame for `r`'s view and density scale.
    fn frame(&mut self, r: &Request) -> Result<&mut Frame> {
        view_frame(&mut self.scene, &mut self.base, &mut self.scaled, r)
    }

    /// Starts the truth of `r`'s view on a thread of its own, with copies of the frame, the
    /// tables and the device (wgpu's handles are shared, not duplicated).
    fn trace(&mut self, r: &Request, sink: Sink) {
        let frame = match self.frame(r) {
            Ok(frame) => frame.clone(),
            Err(e) => return sink.send(TruthNews::Ended(Err(format!("{e:#}")))),
        };
        let (gpu, tables, model) = (self.gpu.clone(), self.tables.clone(), r.model.clone());
        let spawned = std::thread::Builder::new()
            .name("truth".into())
            .spawn(move || {
                let traced = model.prepare(&gpu, &tables).and_then(|prepared| {
                    let job = Job {
                        tables: &tables,
                        frame: &frame,
                        progress: &sink,
                        lighting: None,
                    };
                    model.render(&job, On::Gpu(&gpu, &prepared))
                });
                sink.send(TruthNews::Ended(
                    traced.map(|t| t.summary).map_err(|e| e.to_string()),
                ));
            });
        match spawned {
            Ok(thread) => self.truths.push(thread),
            Err(e) => eprintln!("view: starting the truth's thread: {e}"),
        }
        self.truths.retain(|t| !t.is_finished());
    }

    /// Waits for the truth threads (their runs told to stop) to end.
    fn end_truths(&mut self) {
        for thread in self.truths.drain(..) {
            if thread.join().is_err() {
                eprintln!("view: a truth thread panicked (see above)");
            }
        }
    }

    fn render(&mut self, r: &Request) -> Result<Rendered> {
        let name = r.model.name();
        if !self.prepared.contains_key(name) {
            let prepared = r.model.prepare(&self.gpu, &self.tables)?;
            self.prepared.insert(name, prepared);
        }
        let frame = view_frame(&mut self.scene, &mut self.base, &mut self.scaled, r)?;
        let job = Job {
            tables: &self.tables,
            frame,
            progress: &(),
            lighting: Some(&self.lighting),
        };
        Ok(r.model
            .render(&job, On::Gpu(&self.gpu, &self.prepared[name]))?)
    }
}

/// `scene`'s frame for `r`'s view: the base frame (density scale 1) or the one at `r`'s
/// density scale, made once in `scaled` and kept while the scale stays.
fn view_frame<'a>(
    scene: &mut RenderScene,
    base: &'a mut Result<Frame, String>,
    scaled: &'a mut Option<(f64, Frame)>,
    r: &Request,
) -> Result<&'a mut Frame> {
    scene.camera = r.camera;
    scene.sun = r.sun;
    scene.check(&r.model)?;
    let base = match base {
        Err(e) => anyhow::bail!("{e}"),
        Ok(base) => base,
    };
    let frame = if r.density_scale == 1.0 {
        base
    } else {
        if scaled.as_ref().is_none_or(|(s, _)| *s != r.density_scale) {
            let mut frame = base.clone();
            let s = r.density_scale as f32;
            frame.grid.data.iter_mut().flatten().for_each(|v| *v *= s);
            *scaled = Some((r.density_scale, frame));
        }
        &mut scaled.as_mut().expect("set above").1
    };
    frame.camera = r.camera;
    frame.sun = r.sun;
    Ok(frame)
}
