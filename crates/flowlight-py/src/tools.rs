//! The module's functions beside `load`: the plugins on the search path, image comparison
//! (the metrics of `flowlight compare`), reading an EXR, the benchmark suite runner, and the
//! package's own plugin folder.
//!
//! The wheel carries the plugins in `flowlight/plugins/` beside the extension module; the
//! package names that folder at import ([`set_package_dir`]) and it is searched after a
//! config's own `plugin_search_paths`, before `FLOWLIGHT_PLUGIN_PATH` and the executable's
//! folder (the command line's place, which for Python is the interpreter's).

use crate::errors;
use flowlight_bench as suite;
use flowlight_core::Rgb;
use flowlight_host::metrics;
use flowlight_host::plugin::{list_plugin_files, search_dirs, PluginLibrary};
use numpy::{PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;
use std::sync::OnceLock;

/// An H×W×3 image as numpy.
type Image3<'py> = Bound<'py, PyArray3<f32>>;

static PACKAGE_DIR: OnceLock<PathBuf> = OnceLock::new();

/// Names the package's folder (the one holding `plugins/`); the first call wins.
#[pyfunction]
pub fn set_package_dir(path: PathBuf) {
    let _ = PACKAGE_DIR.set(path);
}

/// The package's plugin folder, when it has one.
pub fn package_plugin_dirs() -> Vec<PathBuf> {
    PACKAGE_DIR
        .get()
        .map(|d| d.join("plugins"))
        .filter(|d| d.is_dir())
        .into_iter()
        .collect()
}

/// The plugin search path without a config: the package's folder, `FLOWLIGHT_PLUGIN_PATH`,
/// the executable's folder.
#[pyfunction]
pub fn search_path() -> Vec<PathBuf> {
    search_dirs(&package_plugin_dirs())
}

/// The plugins on the search path, as `flowlight plugins` lists them.
#[pyfunction]
pub fn plugins<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for f in list_plugin_files(&search_path()) {
        let d = PyDict::new(py);
        d.set_item("file", &f)?;
        match PluginLibrary::load(&f) {
            Ok(p) => {
                d.set_item("name", &p.name)?;
                d.set_item("kind", format!("{:?}", p.kind).to_lowercase())?;
                d.set_item("description", &p.description)?;
                d.set_item("sdk_version", &p.sdk_version)?;
                d.set_item("rustc_version", &p.rustc_version)?;
                let params = PyList::empty(py);
                for q in p.params() {
                    let pd = PyDict::new(py);
                    pd.set_item("name", &q.name)?;
                    pd.set_item("type", q.kind.name())?;
                    pd.set_item("default", &q.default)?;
                    pd.set_item("range", &q.range)?;
                    pd.set_item("doc", &q.doc)?;
                    params.append(pd)?;
                }
                d.set_item("params", params)?;
            }
            Err(e) => d.set_item("refused", e.to_string())?,
        }
        out.append(d)?;
    }
    Ok(out)
}

fn pixels(a: &PyReadonlyArray3<'_, f32>, what: &str) -> PyResult<Vec<Rgb>> {
    let v = a.as_array();
    if v.shape()[2] != 3 {
        return Err(errors::config(format!(
            "{what} must be H×W×3, got {:?}",
            v.shape()
        )));
    }
    let (h, w) = (v.shape()[0], v.shape()[1]);
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            out.push(Rgb::new(v[[y, x, 0]], v[[y, x, 1]], v[[y, x, 2]]));
        }
    }
    Ok(out)
}

fn array<'py>(
    py: Python<'py>,
    w: usize,
    h: usize,
    px: &[Rgb],
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let v: Vec<f32> = px.iter().flat_map(|p| [p.r, p.g, p.b]).collect();
    PyArray1::from_vec(py, v).reshape([h, w, 3])
}

/// The errors of `a` against the reference `b` (`flowlight compare`): RMSE, relMSE with
/// ε = `eps`, the luminance ratio and, given the reference's per-pixel `variance`, its
/// floor (the relMSE its own noise adds) and the relMSE less the floor.
#[pyfunction]
#[pyo3(signature = (a, b, variance=None, eps=metrics::REL_EPS))]
pub fn compare<'py>(
    py: Python<'py>,
    a: PyReadonlyArray3<'py, f32>,
    b: PyReadonlyArray3<'py, f32>,
    variance: Option<PyReadonlyArray3<'py, f32>>,
    eps: f64,
) -> PyResult<Bound<'py, PyDict>> {
    if a.shape() != b.shape() {
        return Err(errors::config(format!(
            "the image is {:?} but the reference is {:?}",
            a.shape(),
            b.shape()
        )));
    }
    let (pa, pb) = (pixels(&a, "the image")?, pixels(&b, "the reference")?);
    let pv = variance.map(|v| pixels(&v, "the variance")).transpose()?;
    let e = py
        .detach(|| metrics::compare_with(&pa, &pb, pv.as_deref(), eps))
        .map_err(errors::config)?;
    let d = PyDict::new(py);
    d.set_item("rmse", e.rmse)?;
    d.set_item("mse", e.mse)?;
    d.set_item("relmse", e.relmse)?;
    d.set_item("luminance_ratio", e.luminance_ratio)?;
    d.set_item("mean_luminance_a", e.mean_luminance_a)?;
    d.set_item("mean_luminance_b", e.mean_luminance_b)?;
    d.set_item("reference_floor", e.reference_floor)?;
    d.set_item("relmse_corrected", e.reference_floor.map(|f| e.relmse - f))?;
    d.set_item("pixels", e.pixels)?;
    d.set_item("non_finite", e.non_finite)?;
    Ok(d)
}

/// Two independent half references (mean images of `na` and `nb` spp) as their mean and
/// the variance of that mean (`flowlight reference`).
#[pyfunction]
pub fn combine_halves<'py>(
    py: Python<'py>,
    a: PyReadonlyArray3<'py, f32>,
    na: f64,
    b: PyReadonlyArray3<'py, f32>,
    nb: f64,
) -> PyResult<(Image3<'py>, Image3<'py>)> {
    if a.shape() != b.shape() {
        return Err(errors::config("the two halves differ in size"));
    }
    if !(na > 0.0 && nb > 0.0) {
        return Err(errors::config("the halves' spp must be positive"));
    }
    let (h, w) = (a.shape()[0], a.shape()[1]);
    let (mean, var) =
        suite::reference::combine_halves(&pixels(&a, "a")?, na, &pixels(&b, "b")?, nb);
    Ok((array(py, w, h, &mean)?, array(py, w, h, &var)?))
}

/// An EXR as `flowlight compare` reads it: `rgb`, `layers`, `variance` (a reference's, or
/// None), mean `spp` and the header entries.
#[pyfunction]
pub fn read_exr<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let r = py
        .detach(|| suite::read_reference(&path))
        .map_err(errors::output)?;
    let d = PyDict::new(py);
    d.set_item("rgb", array(py, r.width, r.height, &r.image)?)?;
    let layers = PyDict::new(py);
    for (name, px) in &r.layers {
        layers.set_item(name, array(py, r.width, r.height, px)?)?;
    }
    d.set_item("layers", layers)?;
    d.set_item(
        "variance",
        r.variance
            .as_ref()
            .map(|v| array(py, r.width, r.height, v))
            .transpose()?,
    )?;
    d.set_item("spp", r.spp)?;
    let meta = PyDict::new(py);
    for (k, v) in &r.meta {
        meta.set_item(k, v)?;
    }
    d.set_item("metadata", meta)?;
    Ok(d)
}

/// Runs a benchmark suite (`flowlight bench`); returns its summary rows and the files
/// written. Comparisons the floor rule refuses raise, as the command line fails.
#[pyfunction]
#[pyo3(signature = (suite_file, out=None, budgets=None, seeds=None, threads=None))]
pub fn bench<'py>(
    py: Python<'py>,
    suite_file: PathBuf,
    out: Option<PathBuf>,
    budgets: Option<Vec<f64>>,
    seeds: Option<Vec<u64>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    if let Some(b) = &budgets {
        if b.is_empty() || b.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(errors::config("--budgets must be positive seconds"));
        }
    }
    if seeds.as_ref().is_some_and(|s| s.is_empty()) {
        return Err(errors::config("--seeds must not be empty"));
    }
    let ov = suite::BenchOverrides {
        out,
        budgets,
        seeds,
        threads,
        ..Default::default()
    };
    let report = py
        .detach(|| {
            let s = suite::load_suite(&suite_file)?;
            suite::run_suite(&s, &ov, &|m| eprintln!("{m}"))
        })
        .map_err(errors::config)?;
    if !report.refused.is_empty() {
        return Err(errors::config(format!(
            "{} comparison(s) refused:\n{}",
            report.refused.len(),
            report.refused.join("\n")
        )));
    }
    let rows = PyList::empty(py);
    for r in &report.summary {
        let d = PyDict::new(py);
        d.set_item("scene", &r.scene)?;
        d.set_item("method", &r.method)?;
        d.set_item("budget", r.budget)?;
        d.set_item("wall", r.wall)?;
        d.set_item("spp", r.spp)?;
        d.set_item("relmse", r.relmse)?;
        d.set_item("rmse", r.rmse)?;
        d.set_item("luminance_ratio", r.luminance_ratio)?;
        d.set_item("efficiency", r.efficiency)?;
        d.set_item("relative_efficiency", r.relative_efficiency)?;
        rows.append(d)?;
    }
    let d = PyDict::new(py);
    d.set_item("summary", rows)?;
    d.set_item("files", report.files.clone())?;
    Ok(d)
}

/// How many scenes this process has loaded (each `flowlight.load` is one).
#[pyfunction]
pub fn loads_so_far() -> u64 {
    flowlight_host::renderer::loads_so_far()
}
