//! `flowlight render`: one render of a TOML config, with a progress bar and a summary.

use anyhow::{anyhow, Result};
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_sdk::abi::StatSpec;
use flowlight_sdk::StatDisplay;
use indicatif::{ProgressBar, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// `--part K/N` / `--samples A..B` ([`crate::part_args`]).
#[derive(Clone, Copy, Default)]
pub struct PartFlags<'a> {
    pub part: Option<&'a str>,
    pub samples: Option<&'a str>,
}

/// `--tev [HOST:PORT]` / `--preview-every SECONDS` (`flowlight_host::output::live`).
#[derive(Clone, Copy, Default)]
pub struct LiveFlags<'a> {
    pub tev: Option<&'a str>,
    pub preview_every: Option<f64>,
}

pub fn run(
    config: &std::path::Path,
    ov: &Overrides,
    quiet: bool,
    part: PartFlags,
    live: LiveFlags,
    denoise: bool,
) -> Result<()> {
    if let Some(t) = ov.time {
        if !(t > 0.0 && t.is_finite()) {
            return Err(anyhow!(
                "--time must be a positive number of seconds, got {t}"
            ));
        }
    }
    if ov.spp == Some(0) {
        return Err(anyhow!("--spp must be at least 1"));
    }
    if let Some(s) = live.preview_every {
        if !(s > 0.0 && s.is_finite()) {
            return Err(anyhow!(
                "--preview-every must be a positive number of seconds, got {s}"
            ));
        }
    }
    let mut renderer = Renderer::prepare(config, ov).map_err(|e| anyhow!(e))?;
    renderer.options.preview_flush =
        flowlight_host::output::live::preview_flush(live.tev.is_some(), live.preview_every);
    crate::part_args::apply(&mut renderer, part.part, part.samples, ov.out.is_some())?;
    // Before any work: the outputs must be writable and must not overwrite an input, and a
    // denoiser asked for must be there.
    renderer.check_outputs().map_err(|e| anyhow!(e))?;
    let mut denoiser = if denoise {
        Some(
            flowlight_host::denoise::Denoiser::open(renderer.options.threads)
                .map_err(|e| anyhow!(e))?,
        )
    } else {
        None
    };
    if !renderer.config.aovs.is_empty() && renderer.part.is_some() {
        return Err(anyhow!(
            "{}: output.aovs: a part of a distributed render writes no AOVs (flowlight merge joins the beauty only); render them in a whole render",
            renderer.config.path.display()
        ));
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                eprintln!("\nsecond interrupt: exiting without saving");
                std::process::exit(130);
            }
            eprintln!("\ninterrupted: finishing the work units in flight and saving what has accumulated (Ctrl-C again to abort)");
        })
        .map_err(|e| anyhow!("cannot install the Ctrl-C handler: {e}"))?;
    }

    let (w, h) = (renderer.camera.width as u64, renderer.camera.height as u64);
    let bar = if quiet {
        ProgressBar::hidden()
    } else if let Some(t) = renderer.options.time {
        let b = ProgressBar::new(t.as_millis() as u64);
        b.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {msg}").unwrap(),
        );
        b
    } else {
        let b = ProgressBar::new(renderer.options.spp as u64 * w * h);
        b.set_style(
            ProgressStyle::with_template(
                "[{elapsed_precise}] {wide_bar} {percent}% {msg} ETA {eta}",
            )
            .unwrap(),
        );
        b
    };
    let env = if renderer.config.environment.is_some() {
        " + environment"
    } else {
        ""
    };
    let sc = &renderer.scene;
    let triangles = if sc.is_instanced() {
        format!(
            "{} triangles in {} instances, {} stored",
            sc.virtual_triangle_count(),
            sc.instances.len(),
            sc.triangles.len()
        )
    } else {
        format!("{} triangles", sc.triangles.len())
    };
    eprintln!(
        "flowlight: {} ({triangles}, {} emissive triangles, {} punctual lights{env}) with '{}' on {} ({}x{})",
        renderer.config.scene.display(),
        renderer.scene.emitters.len(),
        renderer.scene.punctual_lights.len(),
        renderer.instance.plugin().name,
        renderer.intersector.name(),
        w,
        h
    );
    // How long preparation and the first unit took, and for scripts and tests a sign that the
    // render is under way (FLOWLIGHT_LOG=flowlight_cli=debug).
    let first_unit = std::sync::Once::new();
    let progress = |p: &flowlight_host::render::Progress| {
        first_unit.call_once(|| {
            tracing::debug!(
                "first work unit finished after {:.3} s",
                p.elapsed.as_secs_f64()
            )
        });
        let spp = p.pixel_samples as f64 / (w * h) as f64;
        bar.set_message(format!("{spp:.1} spp"));
        if p.budget.is_some() {
            bar.set_position(p.elapsed.as_millis() as u64);
        } else {
            bar.set_position(p.pixel_samples);
        }
    };
    let preview = crate::live::start(&renderer, live)?;
    let progress = |p: &flowlight_host::render::Progress| {
        progress(p);
        // A unit that finds another thread refreshing the preview goes on.
        if let Some(Ok(mut preview)) = preview.as_ref().map(|m| m.try_lock()) {
            preview.update(p);
        }
    };
    let cpu0 = crate::cpu_time::process_cpu_time();
    let outcome = renderer.render(&stop, &progress).map_err(|e| anyhow!(e))?;
    let cpu = crate::cpu_time::process_cpu_time()
        .zip(cpu0)
        .map(|(b, a)| b.saturating_sub(a));
    bar.finish_and_clear();
    if let Some(e) = outcome.error {
        // A failed render is not a result: keep whatever the outputs held before.
        return Err(anyhow!("{e}; nothing was written"));
    }

    if let Some(preview) = preview {
        let mut preview = preview.into_inner().unwrap_or_else(|e| e.into_inner());
        preview.finish(&outcome.frame.image());
    }
    let s = &outcome.stats;
    let secs = s.wall.as_secs_f64().max(1e-9);
    let peak_render = crate::cpu_time::peak_resident_bytes();
    let extra = crate::extras::compute(&renderer, &outcome.frame, denoiser.as_mut(), &stop)?;
    let written = renderer
        .write_outputs_with(outcome.frame, s, extra.layers)
        .map_err(|e| anyhow!(e))?;
    let peak_written = crate::cpu_time::peak_resident_bytes();
    println!("render summary");
    println!("  integrator      {}", renderer.instance.plugin().name);
    // Embree's mode changes its speed by about 15% (docs/embree.md), so a timing says which.
    let mode = match renderer.intersector.name() {
        "embree" if renderer.config.robust => ", robust mode",
        "embree" => ", fast mode (robust = false)",
        _ => "",
    };
    println!(
        "  intersector     {}{mode} (load {:.3} s, build {:.3} s)",
        renderer.intersector.name(),
        renderer.load_time.as_secs_f64(),
        renderer.build_time.as_secs_f64()
    );
    println!("  threads         {}", s.threads);
    println!("  wall time       {secs:.3} s");
    if let Some(cpu) = cpu {
        println!(
            "  cpu time        {:.3} s (all threads, render only)",
            cpu.as_secs_f64()
        );
    }
    println!(
        "  samples         {} ({:.2} spp), {:.3} M samples/s",
        s.pixel_samples,
        s.pixel_samples as f64 / (w * h) as f64,
        s.pixel_samples as f64 / secs / 1e6
    );
    if let Some((spec, _)) = &renderer.part {
        println!(
            "  part            samples {}..{} of 0..{} (flowlight merge joins the parts)",
            spec.begin, spec.end, spec.total
        );
    }
    println!(
        "  rays            {} ({} closest, {} shadow), {:.3} M rays/s",
        s.rays(),
        s.closest_rays,
        s.shadow_rays,
        s.rays() as f64 / secs / 1e6
    );
    if let Some(a) = &s.accumulation {
        let mib = |b: u64| b as f64 / 1048576.0;
        println!(
            "  accumulation    {}, {} sums: frame {:.1} MiB, private buffers {:.1} MiB; {} flushes, {} framebuffer locks ({} found held)",
            a.style.name(),
            a.precision.name(),
            mib(a.frame_bytes),
            mib(a.private_bytes),
            a.counts.flushes,
            a.counts.locks,
            a.counts.contended
        );
        if let (Some(r), Some(w)) = (peak_render, peak_written) {
            println!(
                "  peak memory     {:.1} MiB resident by the end of the render, {:.1} MiB after writing",
                mib(r),
                mib(w)
            );
        }
    }
    for line in &extra.summary {
        println!("  {line}");
    }
    println!("  NaN/Inf samples {} discarded", s.invalid_deposits);
    if s.stray_deposits > 0 {
        println!(
            "  stray deposits  {} off the film (plugin bug), discarded",
            s.stray_deposits
        );
    }
    print_integrator_stats(&s.integrator, renderer.instance.stat_specs());
    let decided = renderer.instance.decided();
    if !decided.is_empty() {
        println!("  decided         by the integrator while preparing; to freeze into the config:");
        println!("    [integrator]");
        for line in decided.lines() {
            println!("    {line}");
        }
    }
    if s.interrupted {
        println!("  interrupted     yes: the image holds the samples finished before the stop");
    }
    if let Some(p) = s.partial_pass {
        println!(
            "  partial pass    {} of {} tiles (random order): normalised by {} + {:.4} passes",
            p.finished,
            p.tiles,
            s.full_passes,
            p.fraction()
        );
    }
    for p in &written {
        println!("  wrote           {}", p.display());
    }
    Ok(())
}

/// The integrator's counters as their declarations ask ([`StatDisplay`]): plain ones one per
/// line; `group.name` ones (e.g. ERPT's quality norms per strategy) one line per group;
/// [`StatDisplay::Hidden`] ones only in the `.stats.json`. `specs` are the instance's
/// counter specs, in the order of `stats`.
fn print_integrator_stats(stats: &[(String, f64)], specs: &[StatSpec]) {
    if stats.is_empty() {
        return;
    }
    let shown: Vec<(&str, String)> = stats
        .iter()
        .zip(specs)
        .filter_map(|((k, v), spec)| Some((k.as_str(), format_stat(*v, spec.display)?)))
        .collect();
    println!("  integrator statistics (all counters in the .stats.json beside the image)");
    for (k, v) in shown.iter().filter(|(k, _)| !k.contains('.')) {
        println!("    {k:<24}{v}");
    }
    let mut groups: Vec<&str> = Vec::new();
    for (k, _) in &shown {
        if let Some((g, _)) = k.split_once('.') {
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
    }
    for g in groups {
        let line: Vec<String> = shown
            .iter()
            .filter_map(|(k, v)| {
                let name = k.strip_prefix(g)?.strip_prefix('.')?;
                Some(format!("{name} {v}"))
            })
            .collect();
        println!("    {g}: {}", line.join(", "));
    }
}

/// A counter's value as the summary shows it (`None`: not shown).
fn format_stat(v: f64, display: StatDisplay) -> Option<String> {
    Some(match display {
        StatDisplay::Number if v.fract() == 0.0 && v.abs() < 1e15 => format!("{v}"),
        StatDisplay::Number => format!("{v:.4}"),
        StatDisplay::Seconds => format!("{v:.3} s"),
        StatDisplay::Percent => format!("{:.2}%", 100.0 * v),
        StatDisplay::Hidden => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_are_formatted_as_declared() {
        assert_eq!(
            format_stat(12.0, StatDisplay::Number).as_deref(),
            Some("12")
        );
        assert_eq!(
            format_stat(0.5, StatDisplay::Number).as_deref(),
            Some("0.5000")
        );
        assert_eq!(
            format_stat(1.25, StatDisplay::Seconds).as_deref(),
            Some("1.250 s")
        );
        assert_eq!(
            format_stat(0.4567, StatDisplay::Percent).as_deref(),
            Some("45.67%")
        );
        assert_eq!(format_stat(3.0, StatDisplay::Hidden), None);
    }
}
