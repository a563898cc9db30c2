//! `flowlight render`'s layers beside the beauty: the AOV pass (`[output] aovs`) and
//! `--denoise`, with their lines of the summary.

use anyhow::{anyhow, Result};
use flowlight_host::accumulation::Frame;
use flowlight_host::denoise::{denoise_image, Denoiser};
use flowlight_host::renderer::{ExtraLayers, Renderer};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// The extra layers and what the summary says of them.
pub struct Extras {
    pub layers: ExtraLayers,
    pub summary: Vec<String>,
}

/// Runs the AOV pass the config (and `--denoise`) asks for, then the denoiser on the
/// beauty of `frame` when one is given.
pub fn compute(
    renderer: &Renderer,
    frame: &Frame,
    denoiser: Option<&mut Denoiser>,
    stop: &AtomicBool,
) -> Result<Extras> {
    let mut out = Extras {
        layers: ExtraLayers::default(),
        summary: Vec::new(),
    };
    let Some(req) = renderer.aov_request(denoiser.is_some()) else {
        return Ok(out);
    };
    // A render stopped by Ctrl-C still gets whole AOVs (the pass is a few percent of a
    // render); a Ctrl-C during the pass stops it.
    let not_yet = AtomicBool::new(false);
    let stop = if stop.load(Ordering::Relaxed) {
        &not_yet
    } else {
        stop
    };
    let cpu0 = crate::cpu_time::process_cpu_time();
    let aovs = renderer.render_aovs(&req, stop).map_err(|e| anyhow!(e))?;
    let cpu = crate::cpu_time::process_cpu_time()
        .zip(cpu0)
        .map_or(String::new(), |(b, a)| {
            format!(", cpu {:.3} s", b.saturating_sub(a).as_secs_f64())
        });
    let names: Vec<&str> = req.aovs.iter().map(|a| a.name()).collect();
    out.summary.push(format!(
        "aovs            {} at {} spp in {:.3} s{cpu}{}",
        names.join(", "),
        req.spp,
        aovs.wall.as_secs_f64(),
        if aovs.interrupted {
            " (interrupted: rows not reached are zero)"
        } else {
            ""
        }
    ));
    if let Some(d) = denoiser {
        let start = Instant::now();
        let denoised = denoise_image(d, &frame.image(), &aovs).map_err(|e| anyhow!(e))?;
        out.summary.push(format!(
            "denoised        {:.3} s with {} (layer \"{}\"; the beauty is not changed)",
            start.elapsed().as_secs_f64(),
            d.source,
            flowlight_host::denoise::LAYER
        ));
        out.layers.denoised = Some(denoised);
        out.layers.denoiser = Some(d.source.clone());
    }
    out.layers.aovs = Some(aovs);
    Ok(out)
}
