//! Progress bars for long bakes: drawn on stderr with indicatif, hidden with `--quiet` or when
//! the `CI` environment variable is set (logs are not terminals).

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

/// One bar per field, drawn together (fields are computed side by side).
pub struct Bars {
    hidden: bool,
    multi: MultiProgress,
}

impl Bars {
    /// Bars unless `quiet` or in CI.
    pub fn new(quiet: bool) -> Self {
        Self {
            hidden: quiet || std::env::var_os("CI").is_some(),
            multi: MultiProgress::with_draw_target(ProgressDrawTarget::stderr()),
        }
    }
}

struct Bar(ProgressBar);

impl bake::progress::FieldProgress for Bar {
    fn message(&self, text: &str) {
        self.0.set_message(text.to_string());
    }
    fn advance(&self) {
        self.0.inc(1);
    }
    fn finish(&self) {
        self.0.finish_with_message("done");
    }
}

impl bake::Progress for Bars {
    fn field(&self, name: &str, steps: u64) -> Box<dyn bake::progress::FieldProgress + '_> {
        if self.hidden {
            return Box::new(Bar(ProgressBar::hidden()));
        }
        let p = self.multi.add(ProgressBar::new(steps));
        p.set_style(
            ProgressStyle::with_template("{prefix:>8} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
                .expect("valid template")
                .progress_chars("=> "),
        );
        p.set_prefix(name.to_string());
        Box::new(Bar(p))
    }
}

/// The bar of long render work (the path tracer's samples per pixel, with its noise): steps
/// done, time left, and what the model reports; hidden with `quiet` or in CI.
pub struct RenderBar(ProgressBar);

impl RenderBar {
    /// A bar that appears on the first update, unless `quiet` or in CI.
    pub fn new(quiet: bool) -> Self {
        if quiet || std::env::var_os("CI").is_some() {
            return Self(ProgressBar::hidden());
        }
        let p = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        p.set_style(
            ProgressStyle::with_template(
                "  render [{bar:30}] {pos}/{len} {msg} ({elapsed}, {eta} left)",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        Self(p)
    }

    /// Clears the bar.
    pub fn finish(&self) {
        self.0.finish_and_clear();
    }
}

impl render::model::Progress for RenderBar {
    fn update(&self, done: u64, total: u64, message: &str) {
        self.0.set_length(total);
        self.0.set_position(done);
        self.0.set_message(message.to_string());
    }
}
