//! `flowlight.load(...)` and the loaded scene: the glTF scene read and its intersector built
//! once ([`LoadedScene`]); every `render` creates only the integrator (with the render's
//! `set={...}` parameters) over it.

use crate::{convert, errors, render_loop, tools};
use flowlight_host::renderer::{LoadedScene, Overrides};
use flowlight_scene::config::{load_config, parse_config, RenderConfig};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A scene loaded for rendering.
#[pyclass(module = "flowlight._native", frozen)]
pub struct Scene {
    loaded: LoadedScene,
    /// Renders made so far over this load.
    renders: AtomicU64,
}

/// The package's plugin folder after the config's own search paths.
fn with_package_plugins(mut config: RenderConfig) -> RenderConfig {
    config
        .plugin_search_paths
        .extend(tools::package_plugin_dirs());
    config
}

fn load(py: Python<'_>, config: RenderConfig) -> PyResult<Scene> {
    let config = with_package_plugins(config);
    let loaded = py
        .detach(|| LoadedScene::load(config))
        .map_err(errors::host_error)?;
    Ok(Scene {
        loaded,
        renders: AtomicU64::new(0),
    })
}

/// Loads the config file at `path` and its scene.
#[pyfunction]
pub fn load_path(py: Python<'_>, path: PathBuf) -> PyResult<Scene> {
    let config = load_config(&path).map_err(|e| errors::host_error(e.into()))?;
    load(py, config)
}

/// Loads a config given as a dict with the TOML file's keys; relative paths in it are
/// relative to `base_dir`, and errors name the config `base_dir/<dict>`.
#[pyfunction]
pub fn load_table(py: Python<'_>, table: &Bound<'_, PyDict>, base_dir: PathBuf) -> PyResult<Scene> {
    let text = toml::to_string(&convert::to_table(table, "")?)
        .map_err(|e| errors::config(format!("the config dict has no TOML form: {e}")))?;
    let base = std::path::absolute(&base_dir).unwrap_or(base_dir);
    let config =
        parse_config(&base.join("<dict>"), &text).map_err(|e| errors::host_error(e.into()))?;
    load(py, config)
}

#[pymethods]
impl Scene {
    /// Renders the loaded scene; `progress` is called on this thread with a dict about every
    /// tenth of a second (its exceptions stop the render; KeyboardInterrupt keeps the partial
    /// image). `denoise` adds the layers `albedo`, `normal` and `denoised` (Open Image
    /// Denoise, as the command line's `--denoise`).
    #[pyo3(signature = (*, spp=None, time=None, threads=None, seed=None, set=None, progress=None, denoise=false))]
    #[allow(clippy::too_many_arguments)]
    fn render(
        &self,
        py: Python<'_>,
        spp: Option<u32>,
        time: Option<f64>,
        threads: Option<usize>,
        seed: Option<u64>,
        set: Option<&Bound<'_, PyDict>>,
        progress: Option<Py<PyAny>>,
        denoise: bool,
    ) -> PyResult<crate::image::Image> {
        if let Some(t) = time {
            if !(t > 0.0 && t.is_finite()) {
                return Err(errors::config(format!(
                    "--time must be a positive number of seconds, got {t}"
                )));
            }
        }
        if spp == Some(0) {
            return Err(errors::config("--spp must be at least 1"));
        }
        let ov = Overrides {
            spp,
            time,
            threads,
            out: None,
            seed,
            params: convert::sets(set)?,
        };
        let index = self.renders.fetch_add(1, Ordering::Relaxed) + 1;
        render_loop::render(py, &self.loaded, &ov, progress, index, denoise)
    }

    /// The config file (or `base_dir/<dict>`).
    #[getter]
    fn config_path(&self) -> PathBuf {
        self.loaded.config.path.clone()
    }
    #[getter]
    fn width(&self) -> u32 {
        self.loaded.camera.width
    }
    #[getter]
    fn height(&self) -> u32 {
        self.loaded.camera.height
    }
    /// Seconds spent reading the scene.
    #[getter]
    fn load_seconds(&self) -> f64 {
        self.loaded.load_time.as_secs_f64()
    }
    /// Seconds spent building the intersector.
    #[getter]
    fn build_seconds(&self) -> f64 {
        self.loaded.build_time.as_secs_f64()
    }
    /// This load's number in the process (`flowlight.loads_so_far()` counts them).
    #[getter]
    fn load_id(&self) -> u64 {
        self.loaded.load_id
    }
    #[getter]
    fn renders(&self) -> u64 {
        self.renders.load(Ordering::Relaxed)
    }
    #[getter]
    fn intersector(&self) -> &'static str {
        self.loaded.intersector.name()
    }
    #[getter]
    fn triangles(&self) -> usize {
        self.loaded.scene.triangles.len()
    }
    /// The integrator plugin the config names.
    #[getter]
    fn integrator(&self) -> String {
        self.loaded.config.integrator_plugin.clone()
    }
    fn __repr__(&self) -> String {
        format!(
            "<flowlight.Scene {} ({}x{}, {} triangles, {} via {}; load {:.3} s, build {:.3} s)>",
            Path::new(&self.loaded.config.path).display(),
            self.width(),
            self.height(),
            self.triangles(),
            self.integrator(),
            self.intersector(),
            self.load_seconds(),
            self.build_seconds()
        )
    }
}
