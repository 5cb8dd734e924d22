//! A field's microphysics changed in the window (or in the watched scene file): bake the
//! scene's fields in the background, with a progress bar, while the window keeps drawing with
//! the old tables. The bake's cache makes a return to an earlier value immediate.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use bake::BakePlan;
use runtime::Tables;

use crate::commands::render::bake_waiting;

/// The state of the background bake, shared with its thread.
#[derive(Default)]
struct Shared {
    done: AtomicU64,
    total: AtomicU64,
    message: Mutex<String>,
    result: Mutex<Option<Result<Tables, String>>>,
}

/// At most one bake runs; a change made while it runs waits for it, the newest kept.
#[derive(Default)]
pub struct Rebake {
    running: Option<Arc<Shared>>,
    queued: Option<BakePlan>,
}

/// Counts the bake's steps for the bar.
struct Counter(Arc<Shared>);

struct FieldCounter(Arc<Shared>);

impl bake::progress::Progress for Counter {
    fn field(&self, name: &str, steps: u64) -> Box<dyn bake::progress::FieldProgress + '_> {
        self.0.total.fetch_add(steps, Ordering::Relaxed);
        *self.0.message.lock().expect("not poisoned") = format!("baking {name}");
        Box::new(FieldCounter(self.0.clone()))
    }
}

impl bake::progress::FieldProgress for FieldCounter {
    fn message(&self, text: &str) {
        *self.0.message.lock().expect("not poisoned") = text.to_string();
    }
    fn advance(&self) {
        self.0.done.fetch_add(1, Ordering::Relaxed);
    }
    fn finish(&self) {}
}

impl Rebake {
    /// Bakes `plan` (now, or after the bake that runs); `repaint` is called when it ends.
    pub fn start(&mut self, plan: BakePlan, repaint: impl Fn() + Send + 'static) {
        if self.running.is_some() {
            self.queued = Some(plan);
            return;
        }
        let shared = Arc::new(Shared::default());
        self.running = Some(shared.clone());
        std::thread::spawn(move || {
            let names: Vec<String> = plan.scene.fields.iter().map(|f| f.name.clone()).collect();
            let result = bake_waiting(&plan, &Counter(shared.clone()), true)
                .and_then(|()| {
                    let names: Vec<&str> = names.iter().map(String::as_str).collect();
                    Ok(Tables::open_fields(&plan.out_dir, Some(&names))?)
                })
                .map_err(|e| format!("{e:#}"));
            *shared.result.lock().expect("not poisoned") = Some(result);
            repaint();
        });
    }

    /// The bake's progress: (done, total, message), while one runs.
    pub fn progress(&self) -> Option<(u64, u64, String)> {
        self.running.as_ref().map(|s| {
            (
                s.done.load(Ordering::Relaxed),
                s.total.load(Ordering::Relaxed),
                s.message.lock().expect("not poisoned").clone(),
            )
        })
    }

    /// The finished bake's tables (or its error), once; starts the queued bake then.
    pub fn finished(
        &mut self,
        repaint: impl Fn() + Send + 'static,
    ) -> Option<Result<Tables, String>> {
        let result = self
            .running
            .as_ref()?
            .result
            .lock()
            .expect("not poisoned")
            .take()?;
        self.running = None;
        if let Some(plan) = self.queued.take() {
            self.start(plan, repaint);
        }
        Some(result)
    }
}
