//! Renders through the ordinary host API ([`Session`]): one [`RenderRequest`], or every
//! (scene, method, budget, seed) of a suite.

use crate::plot::{plot_layers, plot_scene};
use crate::reference::{read_reference, render_reference, write_reference, Reference};
use crate::report::{summarise, write_tables, BenchReport};
use crate::suite::{Suite, SuiteScene};
use flowlight_core::Rgb;
use flowlight_host::accumulation::Frame;
use flowlight_host::metrics::{self, Errors};
use flowlight_host::session::{Overrides, Session};
use flowlight_scene::config::{load_config, RenderConfig};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// How long one render runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    Spp(u32),
    /// Seconds of wall time.
    Time(f64),
}

/// One render through the host, described without a config file of its own.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    /// The scene's render config.
    pub config: PathBuf,
    /// Integrator plugin; `None` keeps the config's.
    pub plugin: Option<String>,
    /// Integrator parameters. With the config's plugin they replace or extend the config's
    /// `[integrator]` keys; with another plugin they are its only parameters.
    pub params: Vec<(String, toml::Value)>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub budget: Budget,
    pub seed: u64,
    /// Worker threads, 0 = one per core.
    pub threads: usize,
}

/// A finished render's image and counters.
#[derive(Clone, Debug)]
pub struct RenderResult {
    pub width: usize,
    pub height: usize,
    pub image: Vec<Rgb>,
    /// Lighting layers (`layer0..`), empty when the integrator writes none.
    pub layers: Vec<Vec<Rgb>>,
    /// Render wall time in seconds (scene loading and BVH build excluded).
    pub wall: f64,
    /// Mean samples per pixel.
    pub spp: f64,
    pub invalid_samples: u64,
    pub plugin: String,
    /// The integrator parameters used, `key=value` separated by spaces.
    pub params: String,
}

pub(crate) fn resolve_config(req: &RenderRequest) -> Result<RenderConfig, String> {
    let mut cfg = load_config(&req.config).map_err(|e| e.to_string())?;
    if let Some(p) = &req.plugin {
        if *p != cfg.integrator_plugin {
            cfg.integrator_plugin = p.clone();
            cfg.integrator_params.clear();
        }
    }
    if let Some(w) = req.width {
        cfg.width = w;
    }
    if let Some(h) = req.height {
        cfg.height = h;
    }
    Ok(cfg)
}

/// Renders `req` and returns the normalised image, without writing any file.
pub fn render_request(req: &RenderRequest) -> Result<RenderResult, String> {
    let cfg = resolve_config(req)?;
    let (spp, time) = match req.budget {
        Budget::Spp(n) if n > 0 => (Some(n), None),
        Budget::Time(t) if t > 0.0 && t.is_finite() => (None, Some(t)),
        b => return Err(format!("invalid render budget {b:?}")),
    };
    let ov = Overrides {
        spp,
        time,
        threads: Some(req.threads),
        out: None,
        seed: Some(req.seed),
        params: req.params.clone(),
    };
    let mut session = Session::from_config(cfg, &ov)?;
    session.exr_path = None;
    session.png_path = None;
    let stop = AtomicBool::new(false);
    let out = session.render(&stop, &|_| {})?;
    if let Some(e) = out.error {
        return Err(e.to_string());
    }
    let frame: &Frame = &out.frame;
    let (w, h) = (frame.width as usize, frame.height as usize);
    let params = session
        .config
        .integrator_params
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(" ");
    Ok(RenderResult {
        width: w,
        height: h,
        image: frame.image(),
        layers: (0..frame.layer_count as usize)
            .map(|k| frame.layer(k))
            .collect(),
        wall: out.stats.wall.as_secs_f64(),
        spp: out.stats.pixel_samples as f64 / (w * h).max(1) as f64,
        invalid_samples: out.stats.invalid_deposits,
        plugin: session.instance.plugin().name.clone(),
        params,
    })
}

/// One render of the bench and its errors.
#[derive(Clone, Debug)]
pub struct Run {
    pub scene: String,
    pub method: String,
    pub plugin: String,
    pub params: String,
    pub budget: f64,
    pub seed: u64,
    pub wall: f64,
    pub spp: f64,
    pub errors: Errors,
    pub invalid_samples: u64,
    /// (layer index, errors) for each lighting layer both the render and the reference have.
    pub layers: Vec<(usize, Errors)>,
}

/// Options that the command line lays over a suite.
#[derive(Clone, Debug, Default)]
pub struct BenchOverrides {
    pub out: Option<PathBuf>,
    pub budgets: Option<Vec<f64>>,
    pub seeds: Option<Vec<u64>>,
    pub threads: Option<usize>,
    pub reference_spp: Option<u32>,
    /// Render references again even when their files exist.
    pub rebuild_references: bool,
}

fn scene_request(s: &SuiteScene, threads: usize) -> RenderRequest {
    RenderRequest {
        config: s.config.clone(),
        plugin: None,
        params: Vec::new(),
        width: s.width,
        height: s.height,
        budget: Budget::Spp(1),
        seed: 0,
        threads,
    }
}

/// Loads the scene's reference, rendering (and caching) it when missing or when asked to.
pub fn ensure_reference(
    suite: &Suite,
    s: &SuiteScene,
    rebuild: bool,
    log: &dyn Fn(&str),
) -> Result<Reference, String> {
    if !rebuild && s.reference.exists() {
        let r = read_reference(&s.reference)?;
        let cfg = resolve_config(&scene_request(s, 0))?;
        if (r.width, r.height) != (cfg.width as usize, cfg.height as usize) {
            return Err(format!(
                "reference {} is {}x{} but scene '{}' renders at {}x{}: delete it or run with --rebuild-references",
                s.reference.display(),
                r.width,
                r.height,
                s.name,
                cfg.width,
                cfg.height
            ));
        }
        return Ok(r);
    }
    let mut req = scene_request(s, suite.threads);
    req.plugin = suite.reference_plugin.clone();
    req.params = suite.reference_params.clone();
    req.budget = s.reference_budget;
    req.seed = suite.reference_seed;
    log(&format!(
        "reference for '{}': rendering {:?} into {}",
        s.name,
        s.reference_budget,
        s.reference.display()
    ));
    let r = render_reference(&req, &|m| log(&format!("  {m}")))?;
    write_reference(&s.reference, &r)?;
    Ok(r)
}

/// Runs a suite: every (scene, method, budget, seed), then writes `results.csv`,
/// `layers.csv`, `summary.csv`, `summary.md` and one SVG plot per scene (plus
/// `<scene>-layers.svg` where layer errors exist) into the output folder.
pub fn run_suite(
    suite: &Suite,
    ov: &BenchOverrides,
    log: &dyn Fn(&str),
) -> Result<BenchReport, String> {
    let mut suite = suite.clone();
    if let Some(o) = &ov.out {
        // References that default into the output folder move with it.
        for s in &mut suite.scenes {
            if let Ok(rel) = s.reference.strip_prefix(&suite.out) {
                s.reference = o.join(rel);
            }
        }
        suite.out = o.clone();
    }
    if let Some(b) = &ov.budgets {
        suite.budgets = b.clone();
    }
    if let Some(s) = &ov.seeds {
        suite.seeds = s.clone();
    }
    if let Some(t) = ov.threads {
        suite.threads = t;
    }
    if let Some(n) = ov.reference_spp {
        for s in &mut suite.scenes {
            s.reference_budget = Budget::Spp(n);
        }
    }
    std::fs::create_dir_all(&suite.out)
        .map_err(|e| format!("cannot create {}: {e}", suite.out.display()))?;

    let mut runs = Vec::new();
    for s in &suite.scenes {
        let reference = ensure_reference(&suite, s, ov.rebuild_references, log)?;
        for m in suite.methods.iter().filter(|m| m.runs_on(&s.name)) {
            for &budget in &suite.budgets {
                for &seed in &suite.seeds {
                    let mut req = scene_request(s, suite.threads);
                    req.plugin = m.plugin.clone();
                    req.params = m.params.clone();
                    req.budget = Budget::Time(budget);
                    req.seed = seed;
                    let r = render_request(&req)
                        .map_err(|e| format!("scene '{}', method '{}': {e}", s.name, m.label))?;
                    let errors =
                        metrics::compare(&r.image, &reference.image, reference.variance.as_deref())
                            .map_err(|e| {
                                format!("scene '{}', method '{}': {e}", s.name, m.label)
                            })?;
                    let layers = r
                        .layers
                        .iter()
                        .enumerate()
                        .filter_map(|(k, l)| {
                            let refl = reference.layer(k)?;
                            Some((k, metrics::compare(l, refl, None).ok()?))
                        })
                        .collect();
                    log(&format!(
                        "{:<16} {:<28} {:>6.2} s  seed {:<4} wall {:>7.3} s  {:>8.1} spp  relMSE {:.4e}  RMSE {:.4e}",
                        s.name, m.label, budget, seed, r.wall, r.spp, errors.relmse, errors.rmse
                    ));
                    runs.push(Run {
                        scene: s.name.clone(),
                        method: m.label.clone(),
                        plugin: r.plugin,
                        params: r.params,
                        budget,
                        seed,
                        wall: r.wall,
                        spp: r.spp,
                        errors,
                        invalid_samples: r.invalid_samples,
                        layers,
                    });
                }
            }
        }
    }
    let summary = summarise(&runs, &suite.baseline);
    let mut files = write_tables(&suite, &runs, &summary)?;
    for s in &suite.scenes {
        let p = suite.out.join(format!("{}.svg", s.name));
        plot_scene(&p, &s.name, &summary)?;
        files.push(p);
        if runs
            .iter()
            .any(|r| r.scene == s.name && !r.layers.is_empty())
        {
            let p = suite.out.join(format!("{}-layers.svg", s.name));
            plot_layers(&p, &s.name, &runs)?;
            files.push(p);
        }
    }
    Ok(BenchReport {
        runs,
        summary,
        files,
    })
}
