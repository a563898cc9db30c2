//! A render's result: the image as numpy (H×W×3 float32, linear), its lighting layers, its
//! statistics and its EXR header, and the two ways to write it (the EXR the command line
//! writes, and the PNG preview).
//!
//! The pixels are the ones the command line writes: the host resolves each framebuffer into
//! planar channels ([`Frame::take_channels`](flowlight_host::accumulation::Frame::take_channels)),
//! interleaved here once into the array numpy owns (no further copy).

use crate::errors;
use flowlight_host::denoise::{denoise_image, Denoiser, LAYER};
use flowlight_host::output::{write_exr_planar, ExrMetadata, PlanarLayer, PngPreview};
use flowlight_host::render::RenderOutcome;
use flowlight_host::renderer::{stats_json, LoadedScene, Renderer};
use numpy::{PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// A rendered image.
#[pyclass(module = "flowlight._native", frozen)]
pub struct Image {
    rgb: Py<PyArray3<f32>>,
    /// `layer0`, `layer1`, … in order.
    layers: Vec<(String, Py<PyArray3<f32>>)>,
    stats: Py<PyDict>,
    metadata: Vec<(String, String)>,
    /// The `.stats.json` the command line writes beside the EXR (none without counters).
    stats_json: Option<String>,
    partial: bool,
}

/// Planar R, G, B channels as an H×W×3 array.
fn interleaved<'py>(
    py: Python<'py>,
    w: usize,
    h: usize,
    ch: &[Vec<f32>; 3],
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let mut v = Vec::with_capacity(w * h * 3);
    for ((r, g), b) in ch[0].iter().zip(&ch[1]).zip(&ch[2]).take(w * h) {
        v.extend([*r, *g, *b]);
    }
    PyArray1::from_vec(py, v).reshape([h, w, 3])
}

/// An H×W×3 array as planar channels (for the writers).
fn planar(a: &PyReadonlyArray3<'_, f32>) -> PyResult<[Vec<f32>; 3]> {
    let view = a.as_array();
    let (h, w) = (view.shape()[0], view.shape()[1]);
    let mut out: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(w * h));
    for y in 0..h {
        for x in 0..w {
            for (c, ch) in out.iter_mut().enumerate() {
                ch.push(view[[y, x, c]]);
            }
        }
    }
    Ok(out)
}

impl Image {
    /// The Python image of a render's outcome: the beauty, its lighting layers, the AOVs
    /// and (with a denoiser) the denoised beauty.
    #[allow(clippy::too_many_arguments)]
    pub fn from_outcome(
        py: Python<'_>,
        renderer: &Renderer,
        loaded: &LoadedScene,
        outcome: RenderOutcome,
        prepare: Duration,
        index: u64,
        denoiser: Option<&mut Denoiser>,
    ) -> PyResult<Image> {
        let RenderOutcome {
            mut frame, stats, ..
        } = outcome;
        let (w, h) = (frame.width as usize, frame.height as usize);
        // The AOVs the config asks for (`[output] aovs`, and albedo and normal when
        // denoising), as the command line writes them: the host's pass after the beauty,
        // one layer each under its name, then the denoised beauty.
        let mut extra = Vec::new();
        let mut denoised_by = None;
        if let Some(req) = renderer.aov_request(denoiser.is_some()) {
            let aovs = py
                .detach(|| renderer.render_aovs(&req, &AtomicBool::new(false)))
                .map_err(errors::host_error)?;
            let denoised = match denoiser {
                Some(d) => {
                    let image = frame.image();
                    let out = py
                        .detach(|| denoise_image(d, &image, &aovs))
                        .map_err(errors::RenderError::new_err)?;
                    denoised_by = Some(d.source.clone());
                    Some(out)
                }
                None => None,
            };
            for l in aovs.into_planar() {
                extra.push((l.name, interleaved(py, w, h, &l.channels)?.unbind()));
            }
            if let Some(d) = denoised {
                extra.push((LAYER.to_owned(), interleaved(py, w, h, &d)?.unbind()));
            }
        }
        let rgb = interleaved(py, w, h, &frame.take_channels(0))?.unbind();
        let mut layers = Vec::new();
        for k in 1..=frame.layer_count as usize {
            let a = interleaved(py, w, h, &frame.take_channels(k))?.unbind();
            layers.push((format!("layer{}", k - 1), a));
        }
        layers.extend(extra);
        let mut metadata = renderer.metadata(&stats).entries;
        if let Some(source) = denoised_by {
            metadata.push(("flowlight.denoiser".into(), source));
        }
        let name = renderer.instance.plugin().name.clone();
        let s = PyDict::new(py);
        s.set_item("integrator", &name)?;
        s.set_item("intersector", renderer.intersector.name())?;
        s.set_item("width", w)?;
        s.set_item("height", h)?;
        s.set_item("wall_seconds", stats.wall.as_secs_f64())?;
        s.set_item("threads", stats.threads)?;
        s.set_item("pixel_samples", stats.pixel_samples)?;
        s.set_item("spp", stats.pixel_samples as f64 / (w * h).max(1) as f64)?;
        s.set_item("seed", renderer.options.seed)?;
        s.set_item("closest_rays", stats.closest_rays)?;
        s.set_item("shadow_rays", stats.shadow_rays)?;
        s.set_item("invalid_deposits", stats.invalid_deposits)?;
        s.set_item("stray_deposits", stats.stray_deposits)?;
        s.set_item("units", stats.units)?;
        s.set_item("interrupted", stats.interrupted)?;
        s.set_item("full_passes", stats.full_passes)?;
        s.set_item(
            "partial_pass",
            stats.partial_pass.map_or(0.0, |p| p.fraction()),
        )?;
        let counters = PyDict::new(py);
        for (k, v) in &stats.integrator {
            counters.set_item(k, v)?;
        }
        s.set_item("counters", counters)?;
        // What this render cost beyond the shared load: the scene was read and built once
        // (load_id, load_seconds, build_seconds are the load's, the same for every render
        // of it); prepare_seconds is this render's integrator creation.
        s.set_item("load_id", loaded.load_id)?;
        s.set_item("load_seconds", loaded.load_time.as_secs_f64())?;
        s.set_item("build_seconds", loaded.build_time.as_secs_f64())?;
        s.set_item("render_index", index)?;
        s.set_item("prepare_seconds", prepare.as_secs_f64())?;
        let json = (!stats.integrator.is_empty()).then(|| stats_json(&name, &stats));
        Ok(Image {
            rgb,
            layers,
            stats: s.unbind(),
            metadata,
            stats_json: json,
            partial: stats.interrupted,
        })
    }
}

#[pymethods]
impl Image {
    /// The image, H×W×3 float32, linear radiance.
    #[getter]
    fn rgb(&self, py: Python<'_>) -> Py<PyArray3<f32>> {
        self.rgb.clone_ref(py)
    }
    /// The lighting layers by name (`layer0`, …), each like `rgb`.
    #[getter]
    fn layers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.layers {
            d.set_item(k, v.clone_ref(py))?;
        }
        Ok(d)
    }
    /// The render summary and the integrator's counters (`counters`).
    #[getter]
    fn stats(&self, py: Python<'_>) -> Py<PyDict> {
        self.stats.clone_ref(py)
    }
    /// The EXR header entries (`flowlight.integrator`, `flowlight.spp`, …).
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.metadata {
            d.set_item(k, v)?;
        }
        Ok(d)
    }
    /// True when the render was stopped (Ctrl-C) before its budget: the image holds the
    /// samples finished by then.
    #[getter]
    fn partial(&self) -> bool {
        self.partial
    }
    #[getter]
    fn width(&self, py: Python<'_>) -> usize {
        self.rgb.bind(py).shape()[1]
    }
    #[getter]
    fn height(&self, py: Python<'_>) -> usize {
        self.rgb.bind(py).shape()[0]
    }

    /// Writes the EXR the command line writes (main image, lighting layers, header), and
    /// beside it the `.stats.json` when the integrator has counters. Returns the files.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<Vec<PathBuf>> {
        let ext = path.extension().map(|e| e.to_ascii_lowercase());
        if ext.as_deref() != Some(std::ffi::OsStr::new("exr")) {
            return Err(errors::output(format!(
                "{}: save writes OpenEXR; name the file .exr (save_png writes the preview)",
                path.display()
            )));
        }
        let (w, h) = (self.width(py), self.height(py));
        let mut layers = vec![PlanarLayer {
            name: String::new(),
            channels: planar(&self.rgb.bind(py).readonly())?,
        }];
        for (name, a) in &self.layers {
            layers.push(PlanarLayer {
                name: name.clone(),
                channels: planar(&a.bind(py).readonly())?,
            });
        }
        let meta = ExrMetadata {
            entries: self.metadata.clone(),
        };
        py.detach(|| write_exr_planar(&path, w, h, layers, &[], &meta))
            .map_err(errors::output)?;
        let mut written = vec![path.clone()];
        if let Some(json) = &self.stats_json {
            let json_path = path.with_extension("stats.json");
            std::fs::write(&json_path, json)
                .map_err(|e| errors::output(format!("{}: {e}", json_path.display())))?;
            written.push(json_path);
        }
        Ok(written)
    }

    /// Writes the 8-bit sRGB preview the command line writes (`2^exposure` × the linear
    /// image, clamped, sRGB-encoded).
    #[pyo3(signature = (path, exposure=0.0))]
    fn save_png(&self, py: Python<'_>, path: PathBuf, exposure: f32) -> PyResult<()> {
        let (w, h) = (self.width(py), self.height(py));
        let channels = planar(&self.rgb.bind(py).readonly())?;
        PngPreview::from_planar(&path, w, h, &channels, exposure)
            .and_then(|p| p.write(&path))
            .map_err(errors::output)
    }

    /// The preview as PNG bytes, for notebooks (the data stays linear).
    fn _repr_png_<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        static PREVIEWS: AtomicU64 = AtomicU64::new(0);
        let path = std::env::temp_dir().join(format!(
            "flowlight-preview-{}-{}.png",
            std::process::id(),
            PREVIEWS.fetch_add(1, Ordering::Relaxed)
        ));
        self.save_png(py, path.clone(), 0.0)?;
        let bytes =
            std::fs::read(&path).map_err(|e| errors::output(format!("{}: {e}", path.display())));
        let _ = std::fs::remove_file(&path);
        Ok(PyBytes::new(py, &bytes?))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let spp: f64 = self
            .stats
            .bind(py)
            .get_item("spp")?
            .map_or(Ok(0.0), |v| v.extract())?;
        Ok(format!(
            "<flowlight.Image {}x{}, {spp:.2} spp{}>",
            self.width(py),
            self.height(py),
            if self.partial { ", partial" } else { "" }
        ))
    }
}
