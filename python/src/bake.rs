//! Bakes: `_bake` runs `photometeor bake`'s plan (scene → BakePlan → `bake::run`) and
//! `_load` reads a bake directory with every check of `photometeor-format` (the manifest, then
//! each field's EXR against its manifest entry: name, Δθ, K, N, F_1..F_N bit for bit, size and
//! CRC-32). The `Bake` class around them is pure Python (photometeor/__init__.py).

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use bake::progress::FieldProgress;
use bake::{BakePlan, Quality, Scene};
use format::BakeDir;
use grid::ThetaGrid;
use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::errors::{out_of_range, to_py};

/// Most worker threads a bake starts (as `photometeor bake --jobs`).
const MAX_JOBS: usize = 256;

/// Bake progress handed to a Python callable `progress(field, done, total, message)`.
/// Steps are reported from worker threads, each call taking the GIL; the first exception the
/// callable raises is kept, no further calls are made, and it is raised when the bake returns.
struct PyProgress {
    callback: Py<PyAny>,
    error: Mutex<Option<PyErr>>,
}

impl PyProgress {
    /// Calls the callable with `field` and what `state` reads (done, total, message). The lock
    /// is taken first, so calls are one at a time and each reads the latest state: `done`
    /// never goes back.
    fn call(&self, field: &str, state: impl FnOnce() -> (u64, u64, String)) {
        let mut error = self.error.lock().unwrap_or_else(|e| e.into_inner());
        if error.is_some() {
            return;
        }
        let (done, total, message) = state();
        Python::attach(|py| {
            if let Err(e) = self.callback.call1(py, (field, done, total, message)) {
                *error = Some(e);
            }
        });
    }
}

struct PyField<'a> {
    owner: &'a PyProgress,
    name: String,
    steps: u64,
    done: AtomicU64,
    message: Mutex<String>,
}

impl PyField<'_> {
    fn report(&self) {
        self.owner.call(&self.name, || {
            let message = self
                .message
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clone();
            let done = self.done.load(Ordering::SeqCst).min(self.steps);
            (done, self.steps, message)
        });
    }
}

impl FieldProgress for PyField<'_> {
    fn message(&self, text: &str) {
        *self.message.lock().unwrap_or_else(|e| e.into_inner()) = text.to_string();
        self.report();
    }
    fn advance(&self) {
        self.done.fetch_add(1, Ordering::SeqCst);
        self.report();
    }
    fn finish(&self) {
        self.done.store(self.steps, Ordering::SeqCst);
        *self.message.lock().unwrap_or_else(|e| e.into_inner()) = "done".into();
        self.report();
    }
}

impl bake::Progress for PyProgress {
    fn field(&self, name: &str, steps: u64) -> Box<dyn FieldProgress + '_> {
        let field = PyField {
            owner: self,
            name: name.to_string(),
            steps,
            done: AtomicU64::new(0),
            message: Mutex::new(String::new()),
        };
        field.report();
        Box::new(field)
    }
}

/// The scene: the embedded default, a TOML file, TOML text or a JSON text of a dict (turned
/// into TOML text first, so every check is the scene parser's).
fn scene_from(
    path: Option<PathBuf>,
    text: Option<String>,
    json: Option<String>,
) -> PyResult<Scene> {
    let parsed = match (path, text, json) {
        (None, None, None) => Scene::from_file_or_default(None),
        (Some(path), None, None) => Scene::from_file(&path),
        (None, Some(text), None) => Scene::parse(&text, "scene text"),
        (None, None, Some(json)) => {
            let value: serde_json::Value = serde_json::from_str(&json)
                .map_err(|e| PyValueError::new_err(format!("scene dict: {e}")))?;
            let text = toml::to_string(&value).map_err(|e| {
                PyValueError::new_err(format!("scene dict cannot be written as TOML: {e}"))
            })?;
            Scene::parse(&text, "scene dict (as TOML)")
        }
        _ => {
            return Err(PyValueError::new_err(
                "give one of scene_path, scene_text, scene_json",
            ));
        }
    };
    parsed.map_err(|e| to_py(&e))
}

/// scene_toml(scene_json)
///
/// The TOML text a scene dict (given as JSON text) is parsed as; error lines refer to it.
#[pyfunction]
pub fn scene_toml(scene_json: &str) -> PyResult<String> {
    let value: serde_json::Value = serde_json::from_str(scene_json)
        .map_err(|e| PyValueError::new_err(format!("scene dict: {e}")))?;
    toml::to_string(&value)
        .map_err(|e| PyValueError::new_err(format!("scene dict cannot be written as TOML: {e}")))
}

/// Bakes a scene into ``out`` as ``photometeor bake SCENE --out OUT [--quality Q] [--jobs J]``
/// does (the same plan, the same bytes); returns the bake report as JSON text. Use
/// ``photometeor.bake``, which wraps this.
#[pyfunction]
#[pyo3(signature = (out, *, scene_path = None, scene_text = None, scene_json = None, quality = None, jobs = None, progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn bake_scene(
    py: Python<'_>,
    out: PathBuf,
    scene_path: Option<PathBuf>,
    scene_text: Option<String>,
    scene_json: Option<String>,
    quality: Option<&str>,
    jobs: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let scene = scene_from(scene_path, scene_text, scene_json)?;
    let quality = match quality {
        Some(q) => Quality::parse(q).ok_or_else(|| {
            PyValueError::new_err(format!(
                "quality = {q:?} is not one of \"draft\", \"standard\", \"reference\""
            ))
        })?,
        None => scene.quality,
    };
    if let Some(jobs) = jobs
        && !(1..=MAX_JOBS).contains(&jobs)
    {
        return Err(out_of_range("jobs", jobs, "[1, 256]"));
    }
    let plan = BakePlan::for_preset(scene, out, quality);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.unwrap_or(0))
        .build()
        .map_err(|e| PyValueError::new_err(format!("building the thread pool: {e}")))?;
    let report = match progress {
        Some(callback) => {
            let progress = PyProgress {
                callback,
                error: Mutex::new(None),
            };
            let report = py.detach(|| pool.install(|| bake::run(&plan, &progress)));
            if let Some(e) = progress
                .error
                .into_inner()
                .unwrap_or_else(|e| e.into_inner())
            {
                return Err(e);
            }
            report
        }
        None => py.detach(|| pool.install(|| bake::run(&plan, &bake::Silent))),
    }
    .map_err(|e| to_py(&e))?;
    serde_json::to_string(&report)
        .map_err(|e| PyValueError::new_err(format!("the bake report as JSON: {e}")))
}

/// Reads and checks the bake in ``dir``; returns ``{"manifest_json", "theta_step_deg",
/// "theta_deg", "fields": [{"name", "ams" (N, K, 3), "forward_fraction" (N, 3),
/// "single": {…} or None}]}``. Use ``photometeor.load``, which wraps this.
#[pyfunction]
pub fn load_bake<'py>(py: Python<'py>, dir: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    type Loaded = (
        BakeDir,
        Vec<(format::FieldImage, Option<format::SingleScatter>)>,
    );
    let (bake, images): Loaded = py
        .detach(
            || -> Result<Loaded, Box<dyn std::error::Error + Send + Sync>> {
                let bake = BakeDir::open(&dir)?;
                let mut images = Vec::new();
                for entry in &bake.manifest.fields {
                    images.push((bake.read_field(entry)?, bake.read_single(entry)?));
                }
                Ok((bake, images))
            },
        )
        .map_err(|e| to_py(e.as_ref()))?;
    let grid = ThetaGrid::new(bake.manifest.theta_step_deg).map_err(|e| to_py(&e))?;
    let out = PyDict::new(py);
    let manifest_json = serde_json::to_string(&bake.manifest)
        .map_err(|e| PyValueError::new_err(format!("the manifest as JSON: {e}")))?;
    out.set_item("manifest_json", manifest_json)?;
    out.set_item("theta_step_deg", bake.manifest.theta_step_deg)?;
    out.set_item("theta_deg", grid.thetas_deg().into_pyarray(py))?;
    let fields = PyList::empty(py);
    for (image, single) in images {
        let field = PyDict::new(py);
        field.set_item("name", &image.field)?;
        // (3, N, K) → (N, K, 3) and (3, N) → (N, 3): new axis order, the same buffer.
        field.set_item("ams", image.ams.permuted_axes([1, 2, 0]).into_pyarray(py))?;
        field.set_item(
            "forward_fraction",
            image.forward_fraction.reversed_axes().into_pyarray(py),
        )?;
        let single = match single {
            None => None,
            Some(s) => {
                let d = PyDict::new(py);
                d.set_item("wavelengths_nm", s.wavelengths_nm.into_pyarray(py))?;
                d.set_item("bins", s.bins.into_pyarray(py))?;
                d.set_item(
                    "forward_delta_fraction",
                    s.forward_delta_fraction.into_pyarray(py),
                )?;
                d.set_item("sigma_ext_m2", s.sigma_ext_m2.into_pyarray(py))?;
                d.set_item("albedo", s.albedo.into_pyarray(py))?;
                Some(d)
            }
        };
        field.set_item("single", single)?;
        fields.append(field)?;
    }
    out.set_item("fields", fields)?;
    Ok(out)
}
