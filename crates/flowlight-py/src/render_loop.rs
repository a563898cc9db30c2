//! One render from Python: the renderer made over the loaded scene, the render run on a
//! thread of its own while this (the calling) thread waits without the GIL, waking about
//! ten times a second to run Python's signal handlers (`Python::check_signals`) and the
//! progress callback. Ctrl-C (KeyboardInterrupt), or a callback raising it, sets the host's
//! stop flag, the one the command line's Ctrl-C handler sets: the render finishes the units
//! in flight and the partial image comes back marked `partial`. Any other exception of the
//! callback stops the render too and is raised once it has stopped.

use crate::errors;
use crate::image::Image;
use flowlight_host::render::Progress;
use flowlight_host::renderer::{LoadedScene, Overrides, Renderer};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// How often the waiting thread wakes for signals and progress.
const POLL: Duration = Duration::from_millis(100);

/// The latest progress report, and whether the render has returned.
#[derive(Default)]
struct Shared {
    latest: Option<Counts>,
    done: bool,
}

/// The numbers of a [`Progress`] report, without its borrow of the frame (the live preview's).
#[derive(Clone, Copy)]
struct Counts {
    pixel_samples: u64,
    planned: u64,
    elapsed: Duration,
    budget: Option<Duration>,
}

impl Counts {
    fn of(p: &Progress) -> Counts {
        Counts {
            pixel_samples: p.pixel_samples,
            planned: p.planned,
            elapsed: p.elapsed,
            budget: p.budget,
        }
    }
}

/// Renders `loaded` with `ov` (the `index`-th render of this load).
pub fn render(
    py: Python<'_>,
    loaded: &LoadedScene,
    ov: &Overrides,
    callback: Option<Py<PyAny>>,
    index: u64,
    denoise: bool,
) -> PyResult<Image> {
    // The denoiser asked for must be there before any time is spent rendering.
    let mut denoiser = if denoise {
        Some(
            py.detach(|| {
                flowlight_host::denoise::Denoiser::open(ov.threads.unwrap_or(loaded.config.threads))
            })
            .map_err(errors::RenderError::new_err)?,
        )
    } else {
        None
    };
    let t0 = Instant::now();
    let renderer = py
        .detach(|| Renderer::from_loaded(loaded, ov))
        .map_err(errors::host_error)?;
    let prepare = t0.elapsed();
    let stop = AtomicBool::new(false);
    let shared = Mutex::new(Shared::default());
    let wake = Condvar::new();
    let mut raised: Option<PyErr> = None;
    let outcome = std::thread::scope(|s| {
        let worker = s.spawn(|| {
            let report = |p: &Progress| {
                shared.lock().unwrap().latest = Some(Counts::of(p));
            };
            let outcome = renderer.render(&stop, &report);
            shared.lock().unwrap().done = true;
            wake.notify_all();
            outcome
        });
        let mut shown: Option<u64> = None;
        loop {
            let (done, latest) = py.detach(|| {
                let guard = shared.lock().unwrap();
                let (guard, _) = wake.wait_timeout_while(guard, POLL, |g| !g.done).unwrap();
                (guard.done, guard.latest)
            });
            if done {
                break;
            }
            if let Err(e) = py.check_signals() {
                stop_with(&stop, e, &mut raised, py);
            }
            if let (Some(cb), Some(p)) = (&callback, latest) {
                // Called again only when there is news.
                if stop.load(Ordering::Relaxed) || shown == Some(p.pixel_samples) {
                    continue;
                }
                shown = Some(p.pixel_samples);
                let result = progress_dict(py, &p, &renderer).and_then(|d| cb.call1(py, (d,)));
                if let Err(e) = result {
                    stop_with(&stop, e, &mut raised, py);
                }
            }
        }
        worker.join().expect("the render thread panicked")
    });
    if let Some(e) = raised {
        return Err(e);
    }
    let outcome = outcome.map_err(errors::host_error)?;
    if let Some(e) = outcome.error {
        return Err(errors::RenderError::new_err(format!(
            "{e}; no image was returned"
        )));
    }
    Image::from_outcome(
        py,
        &renderer,
        loaded,
        outcome,
        prepare,
        index,
        denoiser.as_mut(),
    )
}

/// Stops the render for exception `e`: a KeyboardInterrupt keeps the partial image, any
/// other exception is raised after the render has stopped.
fn stop_with(stop: &AtomicBool, e: PyErr, raised: &mut Option<PyErr>, py: Python<'_>) {
    stop.store(true, Ordering::SeqCst);
    if !e.is_instance_of::<PyKeyboardInterrupt>(py) && raised.is_none() {
        *raised = Some(e);
    }
}

/// What the progress callback receives.
fn progress_dict<'py>(
    py: Python<'py>,
    p: &Counts,
    renderer: &Renderer,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let pixels = (renderer.camera.width as f64 * renderer.camera.height as f64).max(1.0);
    let fraction = match p.budget {
        Some(b) => p.elapsed.as_secs_f64() / b.as_secs_f64().max(1e-9),
        None if p.planned > 0 => p.pixel_samples as f64 / p.planned as f64,
        None => 0.0,
    };
    d.set_item("fraction", fraction.clamp(0.0, 1.0))?;
    d.set_item("spp", p.pixel_samples as f64 / pixels)?;
    d.set_item("pixel_samples", p.pixel_samples)?;
    d.set_item("elapsed", p.elapsed.as_secs_f64())?;
    d.set_item("budget_seconds", p.budget.map(|b| b.as_secs_f64()))?;
    Ok(d)
}
