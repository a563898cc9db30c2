//! `flowlight`: the command-line renderer.
//!
//! ```text
//! flowlight render <config.toml> [--spp N | --time SECONDS] [--threads N] [--out FILE]
//! flowlight plugins [--path DIR]...
//! ```

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
        /// Output EXR file (overrides the config).
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
    eprintln!(
        "flowlight: {} ({} triangles, {} lights) with '{}' on {} ({}x{})",
        session.config.scene.display(),
        session.scene.triangles.len(),
        session.scene.emitters.len(),
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
            "  stray deposits  {} outside their tile (plugin bug), discarded",
            s.stray_deposits
        );
    }
    if s.interrupted {
        println!("  interrupted     yes: the image holds the samples finished before the stop");
    }
    for p in &written {
        println!("  wrote           {}", p.display());
    }
    if let Some(e) = outcome.error {
        return Err(anyhow!(e));
    }
    Ok(())
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
