//! `flowlight`: the command-line renderer.
//!
//! ```text
//! flowlight render <config.toml> [--spp N | --time SECONDS] [--threads N] [--out FILE]
//! flowlight plugins [--path DIR]...
//! flowlight compare <a.exr> <reference.exr> [--out error.png]
//! flowlight reference <config.toml> [--spp N | --time SECONDS] [--out FILE] | --from A.exr [--from B.exr]
//! flowlight bench <suite.toml> [--out DIR] [--budgets 0.5,1] [--seeds 1,2] [--threads N]
//! flowlight new-plugin --kind integrator|mutation NAME DIR [--sdk-path DIR | --sdk-version V]
//! ```

mod new_plugin;

use anyhow::{anyhow, Result};
use clap::{Parser, Subcommand};
use flowlight_host::plugin::{list_plugin_files, search_dirs, PluginLibrary};
use flowlight_host::session::{Overrides, Session};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "flowlight",
    version,
    about = "Physically based renderer for Markov-chain light transport research"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render the scene a TOML config describes.
    Render {
        config: PathBuf,
        /// Samples per pixel (overrides the config).
        #[arg(long, conflicts_with = "time")]
        spp: Option<u32>,
        /// Time budget in seconds (overrides the config).
        #[arg(long)]
        time: Option<f64>,
        /// Worker threads (0 = one per core).
        #[arg(long)]
        threads: Option<usize>,
        /// Output EXR file (overrides the config); the config's PNG preview, if it has one,
        /// is written beside it with the extension .png.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Render seed (overrides the config).
        #[arg(long)]
        seed: Option<u64>,
        /// Set an integrator parameter, TOML syntax: `--set layers=true --set variant='"untangled"'`
        /// (bare words are taken as strings: `--set variant=untangled`).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// No progress bar.
        #[arg(long, short)]
        quiet: bool,
    },
    /// List the plugins found on the search path, with versions and parameters.
    Plugins {
        /// Extra directories to search.
        #[arg(long)]
        path: Vec<PathBuf>,
    },
    /// Compare an image with a reference: RMSE, relMSE, mean luminance ratio, error image.
    Compare {
        /// The image to judge.
        a: PathBuf,
        /// The reference (a `variance` layer, as `flowlight reference` writes, adds the
        /// reference's own noise floor to the report).
        b: PathBuf,
        /// Write a false-colour PNG of the per-pixel relative squared error.
        #[arg(long)]
        out: Option<PathBuf>,
        /// The ε of relMSE = mean (a−b)²/(b²+ε).
        #[arg(long, default_value_t = flowlight_host::metrics::REL_EPS)]
        epsilon: f64,
    },
    /// Render a long reference (two independent halves, for a per-pixel variance estimate),
    /// or make one from existing EXRs.
    Reference {
        /// The scene's render config (not needed with --from).
        #[arg(required_unless_present = "from")]
        config: Option<PathBuf>,
        /// Total samples per pixel (default: the config's budget).
        #[arg(long, conflicts_with = "time")]
        spp: Option<u32>,
        /// Total time budget in seconds.
        #[arg(long)]
        time: Option<f64>,
        /// Output EXR (default: <config stem>.ref.exr beside the config).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed of the first half; the second uses seed + 1.
        #[arg(long, default_value_t = 1_000_000)]
        seed: u64,
        /// Worker threads (0 = one per core).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Set an integrator parameter, as for `render`.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Use existing renders instead: one EXR, or two independent renders of the same
        /// scene (then the variance is estimated from their difference).
        #[arg(long, conflicts_with_all = ["spp", "time", "set"])]
        from: Vec<PathBuf>,
    },
    /// Run a benchmark suite: error against wall time per scene and method (docs/bench.md).
    Bench {
        suite: PathBuf,
        /// Output folder (default: the suite's `bench.out`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Time budgets in seconds, comma separated (replace the suite's).
        #[arg(long, value_delimiter = ',')]
        budgets: Option<Vec<f64>>,
        /// Seeds, comma separated (replace the suite's).
        #[arg(long, value_delimiter = ',')]
        seeds: Option<Vec<u64>>,
        /// Worker threads (0 = one per core).
        #[arg(long)]
        threads: Option<usize>,
        /// Samples per pixel of references that have to be rendered.
        #[arg(long)]
        reference_spp: Option<u32>,
        /// Render the references again even when their files exist.
        #[arg(long)]
        rebuild_references: bool,
    },
    /// Write a new plugin crate that builds outside this workspace (docs/writing-a-plugin.md).
    NewPlugin {
        /// What the plugin implements.
        #[arg(long, value_enum)]
        kind: new_plugin::Kind,
        /// Plugin name as configs write it: lowercase letters, digits and '-'.
        name: String,
        /// Folder to create (must not exist, or be empty).
        dir: PathBuf,
        /// Depend on the SDK at this path (default: this checkout's crates/flowlight-sdk).
        #[arg(long, conflicts_with = "sdk_version")]
        sdk_path: Option<PathBuf>,
        /// Depend on this registry version of flowlight-sdk instead of a path.
        #[arg(long)]
        sdk_version: Option<String>,
    },
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FLOWLIGHT_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .without_time()
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render {
            config,
            spp,
            time,
            threads,
            out,
            seed,
            set,
            quiet,
        } => match parse_sets(&set) {
            Ok(params) => {
                let ov = Overrides {
                    spp,
                    time,
                    threads,
                    out,
                    seed,
                    params,
                };
                render(&config, &ov, quiet)
            }
            Err(e) => Err(e),
        },
        Command::Plugins { path } => plugins(&path),
        Command::Compare { a, b, out, epsilon } => compare(&a, &b, out.as_deref(), epsilon),
        Command::Reference {
            config,
            spp,
            time,
            out,
            seed,
            threads,
            set,
            from,
        } => reference(config, spp, time, out, seed, threads, &set, &from),
        Command::Bench {
            suite,
            out,
            budgets,
            seeds,
            threads,
            reference_spp,
            rebuild_references,
        } => bench(
            &suite,
            flowlight_host::bench::BenchOverrides {
                out,
                budgets,
                seeds,
                threads,
                reference_spp,
                rebuild_references,
            },
        ),
        Command::NewPlugin {
            kind,
            name,
            dir,
            sdk_path,
            sdk_version,
        } => {
            let sdk = match (sdk_path, sdk_version) {
                (_, Some(v)) => new_plugin::SdkSource::Version(v),
                (Some(p), None) => new_plugin::SdkSource::Path(p),
                (None, None) => new_plugin::SdkSource::Path(new_plugin::default_sdk_path()),
            };
            new_plugin::run(kind, &name, &dir, sdk)
        }
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// Parses `--set key=value` pairs; the value is TOML, or a bare string.
fn parse_sets(sets: &[String]) -> Result<Vec<(String, toml::Value)>> {
    sets.iter()
        .map(|s| {
            let (k, v) = s
                .split_once('=')
                .ok_or_else(|| anyhow!("--set {s}: expected KEY=VALUE"))?;
            let value = toml::from_str::<toml::Table>(&format!("v = {v}"))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .unwrap_or_else(|| toml::Value::String(v.to_string()));
            Ok((k.trim().to_string(), value))
        })
        .collect()
}

fn render(config: &std::path::Path, ov: &Overrides, quiet: bool) -> Result<()> {
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
    let session = Session::prepare(config, ov).map_err(|e| anyhow!(e))?;
    // Before any work: the outputs must be writable and must not overwrite an input.
    session.check_outputs().map_err(|e| anyhow!(e))?;
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

    let (w, h) = (session.camera.width as u64, session.camera.height as u64);
    let bar = if quiet {
        ProgressBar::hidden()
    } else if let Some(t) = session.options.time {
        let b = ProgressBar::new(t.as_millis() as u64);
        b.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {msg}").unwrap(),
        );
        b
    } else {
        let b = ProgressBar::new(session.options.spp as u64 * w * h);
        b.set_style(
            ProgressStyle::with_template(
                "[{elapsed_precise}] {wide_bar} {percent}% {msg} ETA {eta}",
            )
            .unwrap(),
        );
        b
    };
    let env = if session.config.environment.is_some() {
        " + environment"
    } else {
        ""
    };
    eprintln!(
        "flowlight: {} ({} triangles, {} emissive triangles, {} punctual lights{env}) with '{}' on {} ({}x{})",
        session.config.scene.display(),
        session.scene.triangles.len(),
        session.scene.emitters.len(),
        session.scene.punctual_lights.len(),
        session.instance.plugin().name,
        session.intersector.name(),
        w,
        h
    );
    let progress = |p: &flowlight_host::render::Progress| {
        let spp = p.pixel_samples as f64 / (w * h) as f64;
        bar.set_message(format!("{spp:.1} spp"));
        if p.budget.is_some() {
            bar.set_position(p.elapsed.as_millis() as u64);
        } else {
            bar.set_position(p.pixel_samples);
        }
    };
    let outcome = session.render(&stop, &progress).map_err(|e| anyhow!(e))?;
    bar.finish_and_clear();
    if let Some(e) = outcome.error {
        // A failed render is not a result: keep whatever the outputs held before.
        return Err(anyhow!("{e}; nothing was written"));
    }

    let s = &outcome.stats;
    let secs = s.wall.as_secs_f64().max(1e-9);
    let written = session
        .write_outputs(&outcome.frame, s)
        .map_err(|e| anyhow!(e))?;
    println!("render summary");
    println!("  integrator      {}", session.instance.plugin().name);
    println!(
        "  intersector     {} (load {:.3} s, build {:.3} s)",
        session.intersector.name(),
        session.load_time.as_secs_f64(),
        session.build_time.as_secs_f64()
    );
    println!("  threads         {}", s.threads);
    println!("  wall time       {secs:.3} s");
    println!(
        "  samples         {} ({:.2} spp), {:.3} M samples/s",
        s.pixel_samples,
        s.pixel_samples as f64 / (w * h) as f64,
        s.pixel_samples as f64 / secs / 1e6
    );
    println!(
        "  rays            {} ({} closest, {} shadow), {:.3} M rays/s",
        s.rays(),
        s.closest_rays,
        s.shadow_rays,
        s.rays() as f64 / secs / 1e6
    );
    println!("  NaN/Inf samples {} discarded", s.invalid_deposits);
    if s.stray_deposits > 0 {
        println!(
            "  stray deposits  {} off the film (plugin bug), discarded",
            s.stray_deposits
        );
    }
    print_integrator_stats(&s.integrator);
    if s.interrupted {
        println!("  interrupted     yes: the image holds the samples finished before the stop");
    }
    if s.discarded_samples > 0 {
        println!(
            "  dropped         {} samples of a pass cut short (a partial pass would bias the image)",
            s.discarded_samples
        );
    }
    for p in &written {
        println!("  wrote           {}", p.display());
    }
    Ok(())
}

/// The integrator's counters: plain ones one per line; `group.name` ones (e.g. ERPT's quality
/// norms per strategy) one line per group with strengths, mean and longest streaks.
fn print_integrator_stats(stats: &[(String, f64)]) {
    if stats.is_empty() {
        return;
    }
    let fmt = |v: f64| {
        if v.fract() == 0.0 && v.abs() < 1e15 {
            format!("{v}")
        } else {
            format!("{v:.4}")
        }
    };
    println!("  integrator statistics (all counters in the .stats.json beside the image)");
    for (k, v) in stats.iter().filter(|(k, _)| !k.contains('.')) {
        println!("    {k:<24}{}", fmt(*v));
    }
    let mut groups: Vec<&str> = Vec::new();
    for (k, _) in stats {
        if let Some((g, _)) = k.split_once('.') {
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
    }
    for g in groups {
        let shown: Vec<String> = stats
            .iter()
            .filter_map(|(k, v)| {
                let name = k.strip_prefix(g)?.strip_prefix('.')?;
                let keep = name == "mutations"
                    || name.ends_with("_strength")
                    || name.ends_with("_mean_streak")
                    || name.ends_with("_streak_max");
                keep.then(|| format!("{name} {}", fmt(*v)))
            })
            .collect();
        println!("    {g}: {}", shown.join(", "));
    }
}

fn plugins(extra: &[PathBuf]) -> Result<()> {
    let dirs = search_dirs(extra);
    let files = list_plugin_files(&dirs);
    println!(
        "search path: {}",
        dirs.iter()
            .map(|d| d.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    if files.is_empty() {
        println!("no plugins found (build them with `cargo build --release --workspace`)");
        return Ok(());
    }
    for f in files {
        match PluginLibrary::load(&f) {
            Ok(p) => {
                println!("\n{} ({:?}) — {}", p.name, p.kind, p.description);
                println!("  file   {}", p.path.display());
                println!("  sdk    {}, {}", p.sdk_version, p.rustc_version);
                for param in p.params() {
                    println!(
                        "  {:<14} {:<8} default {:<12} {}",
                        param.name,
                        param.kind.name(),
                        param.default,
                        param.doc
                    );
                }
            }
            Err(e) => println!("\n{}: refused: {e}", f.display()),
        }
    }
    Ok(())
}

fn compare(
    a: &std::path::Path,
    b: &std::path::Path,
    out: Option<&std::path::Path>,
    eps: f64,
) -> Result<()> {
    use flowlight_host::{bench, metrics};
    let ra = bench::read_reference(a).map_err(|e| anyhow!(e))?;
    let rb = bench::read_reference(b).map_err(|e| anyhow!(e))?;
    if (ra.width, ra.height) != (rb.width, rb.height) {
        return Err(anyhow!(
            "{} is {}x{} but {} is {}x{}",
            a.display(),
            ra.width,
            ra.height,
            b.display(),
            rb.width,
            rb.height
        ));
    }
    let e = metrics::compare_with(&ra.image, &rb.image, rb.variance.as_deref(), eps)
        .map_err(|e| anyhow!("{} vs {}: {e}", a.display(), b.display()))?;
    println!("compare {} against {}", a.display(), b.display());
    println!(
        "  pixels          {} ({}x{})",
        e.pixels, ra.width, ra.height
    );
    if e.non_finite > 0 {
        println!("  non-finite      {} pixels skipped", e.non_finite);
    }
    println!("  RMSE            {:.6e}", e.rmse);
    println!(
        "  relMSE          {:.6e}  (mean (a-b)^2/(b^2+eps), eps = {eps})",
        e.relmse
    );
    if let Some(f) = e.reference_floor {
        println!(
            "  reference floor {f:.6e}  (the reference's own variance in relMSE units; {} spp)",
            rb.spp
        );
    }
    println!(
        "  luminance ratio {:.6}  (mean {:.6} / {:.6})",
        e.luminance_ratio, e.mean_luminance_a, e.mean_luminance_b
    );
    for k in 0.. {
        match (ra.layer(k), rb.layer(k)) {
            (Some(la), Some(lb)) => {
                let le = metrics::compare_with(la, lb, None, eps).map_err(|e| anyhow!(e))?;
                println!(
                    "  layer{k:<9} relMSE {:.4e}  RMSE {:.4e}  luminance ratio {:.4}",
                    le.relmse, le.rmse, le.luminance_ratio
                );
            }
            _ => break,
        }
    }
    if let Some(out) = out {
        let map = metrics::relative_error_map(&ra.image, &rb.image, eps);
        let (lo, hi) = metrics::FALSE_COLOUR_LOG10_RANGE;
        metrics::write_rgb8_png(out, ra.width, ra.height, &metrics::false_colour(&map))
            .map_err(|e| anyhow!(e))?;
        println!(
            "  wrote           {} (relative squared error, log scale 1e{lo}..1e{hi}: black..yellow-white; magenta = not finite)",
            out.display()
        );
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn reference(
    config: Option<PathBuf>,
    spp: Option<u32>,
    time: Option<f64>,
    out: Option<PathBuf>,
    seed: u64,
    threads: usize,
    set: &[String],
    from: &[PathBuf],
) -> Result<()> {
    use flowlight_host::bench::{self, Budget, RenderRequest};
    let t0 = std::time::Instant::now();
    let (r, out) = if !from.is_empty() {
        let out = out.ok_or_else(|| anyhow!("--from needs --out"))?;
        (
            bench::reference_from_exrs(from).map_err(|e| anyhow!(e))?,
            out,
        )
    } else {
        let config = config.ok_or_else(|| anyhow!("a config is required"))?;
        let cfg = flowlight_scene::config::load_config(&config).map_err(|e| anyhow!("{e}"))?;
        let budget = match (spp, time, cfg.budget) {
            (_, Some(t), _) if t > 0.0 && t.is_finite() => Budget::Time(t),
            (_, Some(t), _) => {
                return Err(anyhow!(
                    "--time must be a positive number of seconds, got {t}"
                ))
            }
            (Some(n), None, _) => Budget::Spp(n),
            (None, None, flowlight_scene::config::SampleBudget::Spp(n)) => Budget::Spp(n),
            (None, None, flowlight_scene::config::SampleBudget::Time(t)) => Budget::Time(t),
        };
        let out = out.unwrap_or_else(|| {
            let stem = config
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "reference".into());
            cfg.base_dir.join(format!("{stem}.ref.exr"))
        });
        let req = RenderRequest {
            config,
            plugin: None,
            params: parse_sets(set)?,
            width: None,
            height: None,
            budget,
            seed,
            threads,
        };
        let r = bench::render_reference(&req, &|m| eprintln!("flowlight reference: {m}"))
            .map_err(|e| anyhow!(e))?;
        (r, out)
    };
    bench::write_reference(&out, &r).map_err(|e| anyhow!(e))?;
    println!("reference summary");
    println!("  size            {}x{}", r.width, r.height);
    println!("  samples         {} spp", r.spp);
    if let Some(v) = &r.variance {
        let n = v.len().max(1) as f64;
        let mean_var = v.iter().map(|c| c.luminance() as f64).sum::<f64>() / n;
        println!(
            "  variance        mean per-pixel variance of the mean (luminance) {mean_var:.4e}"
        );
    } else {
        println!("  variance        unknown (one image without a variance layer)");
    }
    if !r.layers.is_empty() {
        println!("  layers          {}", r.layers.len());
    }
    println!("  wall time       {:.3} s", t0.elapsed().as_secs_f64());
    println!("  wrote           {}", out.display());
    Ok(())
}

fn bench(suite: &std::path::Path, ov: flowlight_host::bench::BenchOverrides) -> Result<()> {
    use flowlight_host::bench;
    let s = bench::load_suite(suite).map_err(|e| anyhow!(e))?;
    if let Some(b) = &ov.budgets {
        if b.is_empty() || b.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(anyhow!("--budgets must be positive seconds"));
        }
    }
    if ov.seeds.as_ref().is_some_and(|s| s.is_empty()) {
        return Err(anyhow!("--seeds must not be empty"));
    }
    let report = bench::run_suite(&s, &ov, &|m| eprintln!("{m}")).map_err(|e| anyhow!(e))?;
    println!(
        "bench summary (efficiency = 1/(relMSE x wall time), relative to '{}')",
        s.baseline
    );
    println!(
        "  {:<16} {:<28} {:>8} {:>8} {:>11} {:>11} {:>8}",
        "scene", "method", "budget", "wall", "relMSE", "RMSE", "vs base"
    );
    for r in &report.summary {
        println!(
            "  {:<16} {:<28} {:>8.2} {:>8.3} {:>11.4e} {:>11.4e} {:>8.2}",
            r.scene, r.method, r.budget, r.wall, r.relmse, r.rmse, r.relative_efficiency
        );
    }
    for f in &report.files {
        println!("  wrote           {}", f.display());
    }
    Ok(())
}
