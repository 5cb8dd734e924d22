//! The passes of samples per pixel: how many each pass takes (doubling, bounded by the time a
//! pass takes), the running mean and standard error per pixel, the noise figure that stops a
//! run early, and the frame so far for a viewer.

use super::*;

/// The passes of a traced frame, the CPU's or the GPU's: per pixel Σx and Σx² per channel
/// and ΣY² of the samples' luminance over the samples taken, the pass sizes (1, 1, 2, 4, … samples, at most 64, so that progress
/// and noise come early), the progress, and the stopping rules (`spp`, `noise`, `max_seconds`).
pub(crate) struct Passes<'a> {
    /// Per pixel: Σx and Σx² per channel, and ΣY² of the samples' luminance Y = Σ_c w_c x_c
    /// (Rec. 709; the channels of one path are correlated, so Y's variance is not the
    /// channels' alone: [`TruthImage::luma_error`]).
    pub acc: Vec<([f64; 3], [f64; 3], f64)>,
    /// Samples per pixel taken.
    pub done: usize,
    /// Samples that were not finite, counted as 0 ([`TruthImage::dropped`]).
    pub dropped: u64,
    pub(super) width: usize,
    pub(super) noise: f64,
    pub(super) start: Instant,
    pub(super) settings: &'a Settings,
    pub(super) transparency: Vec<f64>,
    pub(super) progress: &'a dyn Progress,
}

impl<'a> Passes<'a> {
    /// No samples yet, over the pixels (rows of `width`) of volume transparency
    /// `transparency`.
    pub fn new(
        settings: &'a Settings,
        width: usize,
        transparency: Vec<f64>,
        progress: &'a dyn Progress,
    ) -> Self {
        Self {
            acc: vec![([0.0; 3], [0.0; 3], 0.0); transparency.len()],
            done: 0,
            dropped: 0,
            width,
            noise: f64::INFINITY,
            start: Instant::now(),
            settings,
            transparency,
            progress,
        }
    }

    /// The next pass's samples per pixel (at most `cap`, if given), or `None` once all are
    /// taken.
    pub fn next_batch(&self, cap: Option<usize>) -> Option<usize> {
        let left = self
            .settings
            .spp
            .checked_sub(self.done)
            .filter(|&n| n > 0)?;
        Some(
            self.done
                .clamp(1, 64)
                .min(left)
                .min(cap.unwrap_or(usize::MAX))
                .max(1),
        )
    }

    /// A pass of `batch` samples per pixel has been added to `acc`: the noise, the progress
    /// (and the running image, when it is wanted), and whether a stopping rule or the
    /// progress's [`Progress::stop`] ends the frame.
    pub fn end_pass(&mut self, batch: usize) -> bool {
        self.done += batch;
        self.noise = noise_of(&self.acc, self.done, &self.transparency);
        self.progress.update(
            self.done as u64,
            self.settings.spp as u64,
            &format!("noise {:.2} %", self.noise * 100.0),
        );
        if self.progress.wants_running() {
            let now = self.image();
            (self.progress).running(&now.image, &now.std_error, now.spp, now.noise);
        }
        (self.settings.target_noise > 0.0 && self.noise <= self.settings.target_noise)
            || (self.settings.max_seconds > 0.0
                && self.start.elapsed().as_secs_f64() >= self.settings.max_seconds)
            || self.progress.stop()
    }

    /// The frame so far: each pixel's mean and standard error, and the figures.
    pub fn image(&self) -> TruthImage {
        let seconds = self.start.elapsed().as_secs_f64();
        let n = self.done as f64;
        let (width, height) = (self.width, self.acc.len() / self.width.max(1));
        TruthImage {
            image: Image {
                width,
                height,
                rgb: self
                    .acc
                    .iter()
                    .map(|(s, _, _)| s.map(|v| (v / n) as f32))
                    .collect(),
                transparency: self.transparency.iter().map(|&t| t as f32).collect(),
            },
            std_error: self
                .acc
                .iter()
                .map(|(s, q, _)| std::array::from_fn(|c| std_error(s[c], q[c], n) as f32))
                .collect(),
            luma_error: self
                .acc
                .iter()
                .map(|(s, _, y2)| std_error(luminance(*s), *y2, n) as f32)
                .collect(),
            spp: self.done,
            noise: self.noise,
            seconds,
            paths_per_second: (width * height * self.done) as f64 / seconds.max(1e-9),
            dropped: self.dropped,
        }
    }
}

/// Standard error of the mean of n samples with sum `s` and sum of squares `q`.
pub fn std_error(s: f64, q: f64, n: f64) -> f64 {
    if n < 2.0 {
        return f64::INFINITY;
    }
    let mean = s / n;
    ((q / n - mean * mean).max(0.0) / (n - 1.0)).sqrt()
}

/// Rec. 709 luminance Σ_c w_c x_c of an RGB triple (what `compare-render` measures).
pub fn luminance(x: [f64; 3]) -> f64 {
    (0..3).map(|c| crate::error_map::LUMA[c] * x[c]).sum()
}

pub(super) fn noise_of(acc: &[([f64; 3], [f64; 3], f64)], n: usize, transparency: &[f64]) -> f64 {
    let n = n as f64;
    let rel = |pick: &dyn Fn(usize) -> bool| -> Vec<f64> {
        acc.iter()
            .enumerate()
            .filter(|(i, (s, _, _))| pick(*i) && s[1] > 0.0)
            .map(|(_, (s, q, _))| std_error(s[1], q[1], n) / (s[1] / n))
            .collect()
    };
    let mut v = rel(&|i| 1.0 - transparency[i] > 0.01);
    if v.is_empty() {
        v = rel(&|_| true);
    }
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
