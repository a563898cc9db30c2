//! `flowlight`: the command-line renderer, one module per subcommand.
//!
//! The root package's binary (`crates/cli/main.rs`) only calls [`main`].
//!
//! ```text
//! flowlight render <config.toml> [--spp N | --time SECONDS] [--threads N] [--out FILE] [--part K/N | --samples A..B]
//! flowlight merge <out.exr> <part.exr>... [--allow-missing]
//! flowlight plugins [--path DIR]...
//! flowlight compare <a.exr> <reference.exr> [--out error.png]
//! flowlight seams <image.exr> --tile N [--layer NAME]
//! flowlight reference <config.toml> [--spp N | --time SECONDS] [--out FILE] | --from A.exr [--from B.exr]
//! flowlight bench <suite.toml> [--out DIR] [--budgets 0.5,1] [--seeds 1,2] [--threads N]
//! flowlight new-plugin --kind integrator|mutation|raw-mutation NAME DIR [--sdk-path DIR | --sdk-version V]
//! flowlight conformance <plugin> [--set NAME=VALUE]...
//! ```

mod bench;
mod compare;
mod conformance;
mod cpu_time;
mod extras;
mod live;
mod merge;
mod new_plugin;
mod part_args;
mod plugins;
mod reference;
mod render;
mod seams;

use anyhow::{anyhow, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;

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
        /// Render part K of N (K from 0) of the samples per pixel, for a distributed render
        /// merged with `flowlight merge` (docs/distributed.md).
        #[arg(long, value_name = "K/N", conflicts_with_all = ["time", "samples"])]
        part: Option<String>,
        /// Render samples A..B (B exclusive) of every pixel, for `flowlight merge`.
        #[arg(long, value_name = "A..B", conflicts_with = "time")]
        samples: Option<String>,
        /// Stream the film to a running tev while rendering (default address
        /// 127.0.0.1:14158; put the flag after the config, or write --tev=HOST:PORT).
        #[arg(long, value_name = "HOST:PORT", num_args = 0..=1,
              default_missing_value = flowlight_host::output::tev::DEFAULT_ADDRESS)]
        tev: Option<String>,
        /// Rewrite the PNG preview every SECONDS while rendering (atomically).
        #[arg(long, value_name = "SECONDS")]
        preview_every: Option<f64>,
        /// Denoise with Intel Open Image Denoise: writes a `denoised` EXR layer (the beauty
        /// stays the unbiased estimate) and the PNG preview from it, guided by the albedo and
        /// normal AOVs, which it turns on (docs/denoising.md).
        #[arg(long, conflicts_with_all = ["part", "samples"])]
        denoise: bool,
    },
    /// Merge the parts of a distributed render (`render --part` / `--samples`) into one EXR.
    Merge {
        /// The merged EXR (never one of the parts).
        out: PathBuf,
        /// The parts.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Write the image even when some samples are in no part (marked
        /// `flowlight.partial = true`); without it missing ranges are an error.
        #[arg(long)]
        allow_missing: bool,
    },
    /// List the plugins found on the search path, with versions and parameters.
    Plugins {
        /// Extra directories to search.
        #[arg(long)]
        path: Vec<PathBuf>,
        /// Print each plugin's parameter table in markdown, between the markers the docs
        /// hold it in (`<!-- params:NAME -->` … `<!-- /params -->`).
        #[arg(long)]
        markdown: bool,
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
        /// Compare this layer of the image (e.g. `denoised`) instead of its main image.
        #[arg(long)]
        layer: Option<String>,
    },
    /// Tile-edge artefacts (thesis §5.9): mean luminance gradient across tile borders over
    /// the mean inside tiles; 1.0 means no visible seams, larger means seams.
    Seams {
        /// The image (linear RGB EXR).
        image: PathBuf,
        /// Tile size in pixels (square tiles anchored at the top-left corner).
        #[arg(long)]
        tile: usize,
        /// The RGB layer to measure (e.g. `layer1`); default the main layer.
        #[arg(long)]
        layer: Option<String>,
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
        /// Output EXR (default: `<config stem>.ref.exr` beside the config).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Image width (default: the config's), e.g. a bench suite's 128.
        #[arg(long)]
        width: Option<u32>,
        /// Image height (default: the config's).
        #[arg(long)]
        height: Option<u32>,
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
        #[arg(long, conflicts_with_all = ["spp", "time", "set", "width", "height"])]
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
    /// Check a built mutation plugin with the conformance kit (docs/writing-a-plugin.md).
    Conformance {
        /// Path to the plugin library, or a plugin name.
        plugin: String,
        /// A plugin parameter, NAME=VALUE (TOML value or bare string); repeatable.
        #[arg(long = "set", value_name = "NAME=VALUE")]
        sets: Vec<String>,
    },
}

/// Parses the command line, runs the subcommand, and exits with status 1 on an error.
/// The same file under any spelling: canonical where the file (or its folder) exists.
fn comparable(p: &std::path::Path) -> std::path::PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    match (p.parent(), p.file_name()) {
        (Some(dir), Some(name)) => {
            let dir = if dir.as_os_str().is_empty() {
                std::path::Path::new(".")
            } else {
                dir
            };
            dir.canonicalize()
                .map(|d| d.join(name))
                .unwrap_or_else(|_| p.to_path_buf())
        }
        _ => p.to_path_buf(),
    }
}

/// Refuses an output path that is one of the command's `inputs` (named by what they are).
pub(crate) fn refuse_input_as_output(
    out: &std::path::Path,
    inputs: &[(&str, &std::path::Path)],
) -> anyhow::Result<()> {
    let key = comparable(out);
    match inputs.iter().find(|(_, p)| comparable(p) == key) {
        Some((what, p)) => Err(anyhow::anyhow!(
            "{}: the output is {what} {}; refusing to overwrite an input",
            out.display(),
            p.display()
        )),
        None => Ok(()),
    }
}

pub fn main() {
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
            part,
            samples,
            tev,
            preview_every,
            denoise,
        } => match parse_sets(&set) {
            Ok(params) => {
                let ov = flowlight_host::renderer::Overrides {
                    spp,
                    time,
                    threads,
                    out,
                    seed,
                    params,
                };
                let part = render::PartFlags {
                    part: part.as_deref(),
                    samples: samples.as_deref(),
                };
                let live = render::LiveFlags {
                    tev: tev.as_deref(),
                    preview_every,
                };
                render::run(&config, &ov, quiet, part, live, denoise)
            }
            Err(e) => Err(e),
        },
        Command::Merge {
            out,
            parts,
            allow_missing,
        } => merge::run(&out, &parts, allow_missing),
        Command::Plugins { path, markdown } => plugins::run(&path, markdown),
        Command::Compare {
            a,
            b,
            out,
            epsilon,
            layer,
        } => compare::run(&a, &b, out.as_deref(), epsilon, layer.as_deref()),
        Command::Seams { image, tile, layer } => seams::run(&image, tile, layer.as_deref()),
        Command::Reference {
            config,
            spp,
            time,
            out,
            width,
            height,
            seed,
            threads,
            set,
            from,
        } => reference::run(
            config,
            spp,
            time,
            out,
            (width, height),
            seed,
            threads,
            &set,
            &from,
        ),
        Command::Bench {
            suite,
            out,
            budgets,
            seeds,
            threads,
            reference_spp,
            rebuild_references,
        } => bench::run(
            &suite,
            flowlight_bench::BenchOverrides {
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
        Command::Conformance { plugin, sets } => conformance::run(&plugin, &sets),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// Parses `--set key=value` pairs; the value is TOML, or a bare string.
pub(crate) fn parse_sets(sets: &[String]) -> Result<Vec<(String, toml::Value)>> {
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
