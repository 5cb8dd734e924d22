//! `--script`: camera, sun and model steps run in order, each once the previous one's frame is
//! shown, for docs and tests that drive the window without a person.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use render::RenderScene;
use serde::Deserialize;

/// One step: every key optional; what is given changes, the rest stays.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Step {
    /// The sun's elevation, (0, 90] degrees.
    pub sun_elevation_deg: Option<f64>,
    /// The sun's azimuth, degrees from +z towards +x.
    pub sun_azimuth_deg: Option<f64>,
    /// Orbit about the look-at point: [yaw, pitch] in degrees (yaw about +y, pitch up).
    pub orbit_deg: Option<[f64; 2]>,
    /// Factor on the camera's distance to the look-at point, (0, 100].
    pub dolly: Option<f64>,
    /// The model to switch to.
    pub model: Option<String>,
    /// Settings of the model (after the switch), `key = value`.
    pub set: Option<toml::Table>,
    /// Factor on every volume's number density, (0, 1000].
    pub density_scale: Option<f64>,
    /// The display's exposure, > 0.
    pub exposure: Option<f64>,
    /// What the image shows: "model", "truth" or "error" (the last two with a truth of the
    /// view on record).
    pub display: Option<super::app::Display>,
    /// Start the path-traced truth of the view as this step leaves it, with this many samples
    /// per pixel, [1, 2²⁰]; the step's screenshot waits for it to end.
    pub truth_spp: Option<usize>,
    /// A field's size, by field name: its distribution's size parameter (r_eff_um,
    /// median_radius_um, rain_rate_mm_h or radius_um) or a crystal's max_dimension_um; the
    /// field is re-baked before the step's frame.
    pub field_size: Option<BTreeMap<String, f64>>,
    /// Seconds the window waits, drawing and watching the scene file, before the next step
    /// (after this step's screenshot), (0, 600].
    pub wait_s: Option<f64>,
    /// Write what the window shows once this step's frame is shown (PNG; `.exr` and `.json`
    /// beside it, as `--screenshot`).
    pub screenshot: Option<PathBuf>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Script {
    step: Vec<Step>,
}

/// Reads the steps of `path`; an unknown key or a wrong type is refused with its line.
pub fn read(path: &Path) -> Result<Vec<Step>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let script: Script = toml::from_str(&text).map_err(|e| {
        let line = e
            .span()
            .map(|s| text[..s.start].matches('\n').count() + 1)
            .map_or(String::new(), |l| format!(" line {l}:"));
        anyhow::anyhow!("--script {}:{line} {}", path.display(), e.message())
    })?;
    if script.step.is_empty() {
        bail!("--script {}: no [[step]]", path.display());
    }
    for step in &script.step {
        step.check_ranges()?;
    }
    Ok(script.step)
}

impl Step {
    /// Checks the values against their ranges.
    fn check_ranges(&self) -> Result<()> {
        let range = |name: &str, v: Option<f64>, ok: fn(f64) -> bool, allowed: &str| match v {
            Some(v) if !(v.is_finite() && ok(v)) => {
                bail!("--script step: {name} = {v} is out of range; allowed {allowed}")
            }
            _ => Ok(()),
        };
        range(
            "sun_elevation_deg",
            self.sun_elevation_deg,
            |v| v > 0.0 && v <= 90.0,
            "(0, 90]",
        )?;
        range(
            "sun_azimuth_deg",
            self.sun_azimuth_deg,
            |v| v.abs() <= 3600.0,
            "[−3600, 3600]",
        )?;
        range("dolly", self.dolly, |v| v > 0.0 && v <= 100.0, "(0, 100]")?;
        range(
            "density_scale",
            self.density_scale,
            |v| v > 0.0 && v <= 1000.0,
            "(0, 1000]",
        )?;
        range("exposure", self.exposure, |v| v > 0.0, "> 0")?;
        range("wait_s", self.wait_s, |v| v > 0.0 && v <= 600.0, "(0, 600]")?;
        let (lo, hi) = render::truth::SPP_RANGE;
        if let Some(spp) = self.truth_spp
            && !(lo..=hi).contains(&spp)
        {
            bail!("--script step: truth_spp = {spp} is out of range; allowed [{lo}, {hi}]");
        }
        if let Some([yaw, pitch]) = self.orbit_deg
            && !(yaw.is_finite() && pitch.is_finite() && yaw.abs() <= 3600.0 && pitch.abs() < 180.0)
        {
            bail!(
                "--script step: orbit_deg = [{yaw}, {pitch}]: yaw in [−3600, 3600], pitch in (−180, 180)"
            );
        }
        Ok(())
    }

    /// Checks the model and its keys against `scene`'s models, and the fields a
    /// `field_size` names against its fields, before the window opens.
    pub fn check(&self, scene: &RenderScene) -> Result<()> {
        let fields = scene.fields();
        for (name, size) in self.field_size.iter().flatten() {
            if !fields.contains(name) {
                bail!(
                    "--script step: field_size names {name:?}; the scene's volumes use {fields:?}"
                );
            }
            if name.contains('@') {
                bail!(
                    "--script step: field_size names {name:?}, a member of a swept field: its \
                     size is the sweep's value (change the sweep or the volume's size profile \
                     in the scene file)"
                );
            }
            if !(size.is_finite() && *size > 0.0) {
                bail!("--script step: field_size {name} = {size} must be > 0");
            }
        }
        if let Some(model) = &self.model
            && !super::models().contains(&model.as_str())
        {
            bail!(
                "--script step: model = {model:?}; the window's models are {}",
                super::models().join(", ")
            );
        }
        if let Some(set) = &self.set {
            let Some(model) = &self.model else {
                bail!("--script step: set = {{…}} needs model = \"…\" in the same step");
            };
            let pairs: Vec<(String, toml::Value)> =
                set.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
            scene
                .model(model, &pairs)
                .map_err(|e| anyhow::anyhow!("--script step: {e}"))?;
        }
        Ok(())
    }
}
