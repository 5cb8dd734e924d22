//! Shared helpers of the bake tests: a plan at a scene's own preset, and a field's rows as
//! nested vectors.

#![allow(dead_code)]

use bake::{BakeError, BakePlan, Scene};
use format::FieldImage;

/// A bake of the scene `text` into `out` at the scene's own preset, with the preset's knobs as
/// stated for the default scene's 31 wavelengths (`Quality::knobs`), not scaled up for fewer
/// wavelengths per channel, crystals at the first round of rays and drops at the preset's sizes,
/// without their noise targets:
/// these tests check behaviour and stability, and an rgb3 scene at the scaled knobs would cost
/// ten times as much (the presets' accuracy is measured by `photometeor tradeoff` and the
/// table in docs/scenes.md, "Presets, measured").
pub fn plan(text: &str, out: &std::path::Path) -> Result<BakePlan, BakeError> {
    let scene = Scene::parse(text, "test scene")?;
    let quality = scene.quality;
    let mut plan = BakePlan::for_preset(scene, out.to_path_buf(), quality);
    plan.knobs = quality.knobs();
    // Crystals: the preset's first round of rays only, not traced on to its noise target;
    // drops: the preset's sizes, not sized by a pilot for its noise target.
    plan.knobs.crystal_noise = 0.0;
    plan.knobs.size_noise = 0.0;
    Ok(plan)
}

/// Runs a plan silently.
pub fn run(plan: &BakePlan) -> Result<bake::BakeReport, BakeError> {
    bake::run(plan, &bake::Silent)
}

/// `rows[c][r][k]` of a field's tables.
pub fn rows_of(image: &FieldImage) -> [Vec<Vec<f64>>; 3] {
    std::array::from_fn(|c| {
        (0..image.n_max())
            .map(|r| image.row(c, r).to_vec())
            .collect()
    })
}

/// F_1..F_N of channel c.
pub fn forward_fractions(image: &FieldImage, c: usize) -> Vec<f64> {
    image.forward_fractions(c).to_vec()
}
