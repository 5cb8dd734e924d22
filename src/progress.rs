//! Progress of long work on stderr: bars (indicatif) on a terminal; plain lines, a few per
//! field or per render, where stderr is not a terminal or the `CI` environment variable is set
//! (a log or a pipe, where bars would be noise or nothing); nothing with `--quiet`.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How progress is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Nothing (`--quiet`).
    Hidden,
    /// Bars redrawn in place (a terminal).
    Bars,
    /// A line when something starts, changes phase or ends (a log or a pipe).
    Lines,
}

impl Mode {
    fn new(quiet: bool) -> Self {
        if quiet {
            Self::Hidden
        } else if std::io::stderr().is_terminal() && std::env::var_os("CI").is_none() {
            Self::Bars
        } else {
            Self::Lines
        }
    }
}

/// One bar per field, drawn together (fields are computed side by side).
pub struct Bars {
    mode: Mode,
    multi: MultiProgress,
}

impl Bars {
    /// Bars on a terminal, lines elsewhere, nothing if `quiet`.
    pub fn new(quiet: bool) -> Self {
        Self {
            mode: Mode::new(quiet),
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

/// A field's progress as lines: its phases as they start, and its end with the time taken.
struct Lines {
    name: String,
    steps: u64,
    done: Mutex<u64>,
    started: Instant,
}

impl bake::progress::FieldProgress for Lines {
    fn message(&self, text: &str) {
        let done = *self.done.lock().expect("progress lock");
        eprintln!("  {}: {text} ({done}/{} steps)", self.name, self.steps);
    }
    fn advance(&self) {
        *self.done.lock().expect("progress lock") += 1;
    }
    fn finish(&self) {
        eprintln!(
            "  {}: done in {:.1} s",
            self.name,
            self.started.elapsed().as_secs_f64()
        );
    }
}

impl bake::Progress for Bars {
    fn field(&self, name: &str, steps: u64) -> Box<dyn bake::progress::FieldProgress + '_> {
        match self.mode {
            Mode::Hidden => return Box::new(Bar(ProgressBar::hidden())),
            Mode::Lines => {
                eprintln!("  {name}: baking ({steps} steps)");
                return Box::new(Lines {
                    name: name.to_string(),
                    steps,
                    done: Mutex::new(0),
                    started: Instant::now(),
                });
            }
            Mode::Bars => {}
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
/// done, time left, and what the model reports; as lines at most every 10 s where stderr is not
/// a terminal, nothing with `quiet`.
pub struct RenderBar {
    bar: ProgressBar,
    /// In line mode, when the last line was printed.
    lines: Option<Mutex<Option<Instant>>>,
}

impl RenderBar {
    /// A bar that appears on the first update (or lines, or nothing: see [`Bars::new`]).
    pub fn new(quiet: bool) -> Self {
        let mode = Mode::new(quiet);
        if mode != Mode::Bars {
            return Self {
                bar: ProgressBar::hidden(),
                lines: (mode == Mode::Lines).then(|| Mutex::new(None)),
            };
        }
        let p = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        p.set_style(
            ProgressStyle::with_template(
                "  render [{bar:30}] {pos}/{len} {msg} ({elapsed}, {eta} left)",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        Self {
            bar: p,
            lines: None,
        }
    }

    /// Clears the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl render::model::Progress for RenderBar {
    fn update(&self, done: u64, total: u64, message: &str) {
        if let Some(last) = &self.lines {
            let mut last = last.lock().expect("progress lock");
            if done == total || last.is_none_or(|t| t.elapsed().as_secs_f64() >= 10.0) {
                eprintln!("  render: {done}/{total} {message}");
                *last = Some(Instant::now());
            }
            return;
        }
        self.bar.set_length(total);
        self.bar.set_position(done);
        self.bar.set_message(message.to_string());
    }
}
