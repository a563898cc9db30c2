//! References and the error-against-time benchmark (`flowlight reference`, `flowlight bench`).
//!
//! Everything here goes through the ordinary host API ([`Session`]): a method of the suite is
//! any integrator plugin plus parameters, so a new integrator (ERPT and its mutation mixes)
//! is benchmarked by adding a `[[method]]` entry, without code changes. The suite format is
//! documented in `docs/bench.md`.
//!
//! # References
//!
//! A reference is the mean of **two independent renders** with seeds `s` and `s + 1` (the
//! plugin ABI has no per-pixel second moment, so the variance comes from the host side): with
//! per-pixel means A, B of n_A, n_B samples, the reference is (n_A A + n_B B)/(n_A + n_B) and
//! (A − B)² / ((1/n_A + 1/n_B)(n_A + n_B)) is an unbiased (one degree of freedom, so noisy per
//! pixel, but fine on average) estimate of the variance of that mean. It is stored as the EXR
//! layer `variance`, beside the lighting layers `layer0..layerN` when the integrator wrote them.

use crate::film::Frame;
use crate::metrics::{self, Errors};
use crate::output::{read_exr_metadata, read_exr_rgb, write_exr, ExrMetadata, ImageLayer};
use crate::session::{Overrides, Session};
use flowlight_core::Rgb;
use flowlight_scene::config::{load_config, RenderConfig};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
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

fn resolve_config(req: &RenderRequest) -> Result<RenderConfig, String> {
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

/// A reference image with its sample count and (when known) the variance of its mean.
#[derive(Clone, Debug)]
pub struct Reference {
    pub width: usize,
    pub height: usize,
    pub image: Vec<Rgb>,
    /// Per-pixel, per-channel variance of `image` (the estimate's own noise).
    pub variance: Option<Vec<Rgb>>,
    /// Lighting layers by name (`layer0`, …).
    pub layers: Vec<(String, Vec<Rgb>)>,
    /// Mean samples per pixel in total.
    pub spp: f64,
    /// Extra metadata (integrator, parameters, seeds, wall time).
    pub meta: Vec<(String, String)>,
}

impl Reference {
    /// Layer `k` (`layerK`), if the reference has it.
    pub fn layer(&self, k: usize) -> Option<&[Rgb]> {
        let name = format!("layer{k}");
        self.layers
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, p)| p.as_slice())
    }
}

/// Combines two independent estimates of the same image (means of `na`, `nb` samples per
/// pixel) into their weighted mean and the estimated variance of that mean.
pub fn combine_halves(a: &[Rgb], na: f64, b: &[Rgb], nb: f64) -> (Vec<Rgb>, Vec<Rgb>) {
    let (wa, wb) = (na / (na + nb), nb / (na + nb));
    let k = 1.0 / ((1.0 / na + 1.0 / nb) * (na + nb));
    let mut mean = Vec::with_capacity(a.len());
    let mut var = Vec::with_capacity(a.len());
    for (x, y) in a.iter().zip(b) {
        let m = |p: f32, q: f32| (wa * p as f64 + wb * q as f64) as f32;
        let v = |p: f32, q: f32| (k * (p as f64 - q as f64).powi(2)) as f32;
        mean.push(Rgb::new(m(x.r, y.r), m(x.g, y.g), m(x.b, y.b)));
        var.push(Rgb::new(v(x.r, y.r), v(x.g, y.g), v(x.b, y.b)));
    }
    (mean, var)
}

fn weighted_mean(a: &[Rgb], na: f64, b: &[Rgb], nb: f64) -> Vec<Rgb> {
    combine_halves(a, na, b, nb).0
}

/// Renders a reference: two independent halves of `budget` (seeds `seed`, `seed + 1`).
/// `progress` is told about each half as it starts.
pub fn render_reference(req: &RenderRequest, progress: &dyn Fn(&str)) -> Result<Reference, String> {
    let half = match req.budget {
        Budget::Spp(n) if n >= 2 => Budget::Spp(n / 2),
        Budget::Spp(n) => return Err(format!("a reference needs at least 2 spp, got {n}")),
        Budget::Time(t) => Budget::Time(t / 2.0),
    };
    let mut a_req = req.clone();
    a_req.budget = half;
    let mut b_req = a_req.clone();
    b_req.seed = req.seed.wrapping_add(1);
    progress(&format!("first half (seed {})", a_req.seed));
    let a = render_request(&a_req)?;
    progress(&format!("second half (seed {})", b_req.seed));
    let b = render_request(&b_req)?;
    let (image, variance) = combine_halves(&a.image, a.spp, &b.image, b.spp);
    let layers = a
        .layers
        .iter()
        .zip(&b.layers)
        .enumerate()
        .map(|(k, (la, lb))| (format!("layer{k}"), weighted_mean(la, a.spp, lb, b.spp)))
        .collect();
    Ok(Reference {
        width: a.width,
        height: a.height,
        image,
        variance: Some(variance),
        layers,
        spp: a.spp + b.spp,
        meta: vec![
            ("flowlight.integrator".into(), a.plugin.clone()),
            ("flowlight.params".into(), a.params.clone()),
            (
                "flowlight.seed".into(),
                format!("{} and {}", a_req.seed, b_req.seed),
            ),
            (
                "flowlight.reference.wall".into(),
                format!("{:.3}", a.wall + b.wall),
            ),
            (
                "flowlight.reference.invalid_samples".into(),
                (a.invalid_samples + b.invalid_samples).to_string(),
            ),
        ],
    })
}

fn parse_spp(meta: &ExrMetadata) -> Option<f64> {
    meta.entries
        .iter()
        .find(|(k, _)| k == "flowlight.spp")
        .and_then(|(_, v)| v.split_whitespace().next()?.parse().ok())
}

/// Makes a reference from existing renders: one EXR (its variance is unknown unless it is
/// itself a reference with a `variance` layer), or two independent renders of the same scene
/// (averaged, with the variance estimated from their difference).
pub fn reference_from_exrs(paths: &[PathBuf]) -> Result<Reference, String> {
    type Loaded = (usize, usize, Vec<(String, Vec<Rgb>)>, f64);
    let load = |p: &Path| -> Result<Loaded, String> {
        let (w, h, layers) = read_exr_rgb(p).map_err(|e| e.to_string())?;
        let meta = read_exr_metadata(p).map_err(|e| e.to_string())?;
        if layers.first().is_none_or(|(n, _)| !n.is_empty()) {
            return Err(format!("{}: no main RGB layer", p.display()));
        }
        let spp = parse_spp(&meta).unwrap_or(f64::NAN);
        Ok((w, h, layers, spp))
    };
    match paths {
        [one] => {
            let (w, h, mut layers, spp) = load(one)?;
            let image = layers.remove(0).1;
            let variance = layers
                .iter()
                .position(|(n, _)| n == "variance")
                .map(|i| layers.remove(i).1);
            Ok(Reference {
                width: w,
                height: h,
                image,
                variance,
                layers,
                spp,
                meta: vec![("flowlight.reference.from".into(), one.display().to_string())],
            })
        }
        [p, q] => {
            let (w, h, mut la, na) = load(p)?;
            let (w2, h2, mut lb, nb) = load(q)?;
            if (w, h) != (w2, h2) {
                return Err(format!(
                    "{} is {w}x{h}, {} is {w2}x{h2}",
                    p.display(),
                    q.display()
                ));
            }
            if !(na > 0.0 && nb > 0.0) {
                return Err(format!(
                    "{} or {} has no flowlight.spp metadata: cannot weigh them",
                    p.display(),
                    q.display()
                ));
            }
            let (a, b) = (la.remove(0).1, lb.remove(0).1);
            let (image, variance) = combine_halves(&a, na, &b, nb);
            let layers = la
                .iter()
                .filter(|(n, _)| n.starts_with("layer"))
                .filter_map(|(n, x)| {
                    let (_, y) = lb.iter().find(|(m, _)| m == n)?;
                    Some((n.clone(), weighted_mean(x, na, y, nb)))
                })
                .collect();
            Ok(Reference {
                width: w,
                height: h,
                image,
                variance: Some(variance),
                layers,
                spp: na + nb,
                meta: vec![(
                    "flowlight.reference.from".into(),
                    format!("{} + {}", p.display(), q.display()),
                )],
            })
        }
        _ => Err("--from takes one EXR, or two independent renders of the same scene".into()),
    }
}

/// Writes a reference EXR: main image, `variance` (when known), lighting layers, and metadata
/// (`flowlight.reference`, `flowlight.spp`, …).
pub fn write_reference(path: &Path, r: &Reference) -> Result<(), String> {
    let mut layers = vec![ImageLayer {
        name: String::new(),
        pixels: &r.image,
    }];
    if let Some(v) = &r.variance {
        layers.push(ImageLayer {
            name: "variance".into(),
            pixels: v,
        });
    }
    for (n, p) in &r.layers {
        layers.push(ImageLayer {
            name: n.clone(),
            pixels: p,
        });
    }
    let mut entries = vec![
        (
            "software".to_string(),
            format!("flowlight {}", env!("CARGO_PKG_VERSION")),
        ),
        ("flowlight.reference".into(), "true".into()),
        ("flowlight.spp".into(), format!("{}", r.spp)),
        (
            "flowlight.variance".into(),
            if r.variance.is_some() {
                "layer 'variance': per-pixel variance of the mean, from two independent renders"
                    .into()
            } else {
                "unknown".into()
            },
        ),
    ];
    for (k, v) in &r.meta {
        if !entries.iter().any(|(e, _)| e == k) {
            entries.push((k.clone(), v.clone()));
        }
    }
    write_exr(path, r.width, r.height, &layers, &ExrMetadata { entries }).map_err(|e| e.to_string())
}

/// Reads a reference written by [`write_reference`] (or any EXR: then without variance).
pub fn read_reference(path: &Path) -> Result<Reference, String> {
    reference_from_exrs(&[path.to_path_buf()])
}

// ---------------------------------------------------------------------------------------
// Suites

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSuite {
    bench: RawBench,
    #[serde(default)]
    reference: RawReference,
    #[serde(default)]
    scene: Vec<RawScene>,
    #[serde(default)]
    method: Vec<RawMethod>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBench {
    budgets: Vec<f64>,
    #[serde(default = "default_seeds")]
    seeds: Vec<u64>,
    #[serde(default)]
    threads: usize,
    width: Option<u32>,
    height: Option<u32>,
    #[serde(default = "default_out")]
    out: String,
    baseline: Option<String>,
}

fn default_seeds() -> Vec<u64> {
    vec![1, 2, 3]
}
fn default_out() -> String {
    "bench-results".into()
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawReference {
    spp: Option<u32>,
    time: Option<f64>,
    seed: Option<u64>,
    plugin: Option<String>,
    #[serde(default)]
    params: toml::Table,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: String,
    config: String,
    reference: Option<String>,
    reference_spp: Option<u32>,
    width: Option<u32>,
    height: Option<u32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMethod {
    label: String,
    plugin: Option<String>,
    #[serde(default)]
    params: toml::Table,
    scenes: Option<Vec<String>>,
}

/// A scene of a suite.
#[derive(Clone, Debug)]
pub struct SuiteScene {
    pub name: String,
    pub config: PathBuf,
    pub reference: PathBuf,
    pub reference_budget: Budget,
    pub width: Option<u32>,
    pub height: Option<u32>,
}

/// A method: an integrator plugin with parameters, under a label.
#[derive(Clone, Debug)]
pub struct Method {
    pub label: String,
    pub plugin: Option<String>,
    pub params: Vec<(String, toml::Value)>,
    /// Scene names it runs on (`None`: all).
    pub scenes: Option<Vec<String>>,
}

impl Method {
    pub fn runs_on(&self, scene: &str) -> bool {
        self.scenes
            .as_ref()
            .is_none_or(|s| s.iter().any(|n| n == scene))
    }
}

/// A parsed suite file with absolute paths.
#[derive(Clone, Debug)]
pub struct Suite {
    pub path: PathBuf,
    pub budgets: Vec<f64>,
    pub seeds: Vec<u64>,
    pub threads: usize,
    pub out: PathBuf,
    pub baseline: String,
    pub reference_seed: u64,
    pub reference_plugin: Option<String>,
    pub reference_params: Vec<(String, toml::Value)>,
    pub scenes: Vec<SuiteScene>,
    pub methods: Vec<Method>,
}

fn table_pairs(t: toml::Table) -> Vec<(String, toml::Value)> {
    t.into_iter().collect()
}

/// Parses a suite file (see `docs/bench.md`). Relative paths are relative to its folder.
pub fn load_suite(path: &Path) -> Result<Suite, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    parse_suite(path, &text)
}

/// [`load_suite`] from text.
pub fn parse_suite(path: &Path, text: &str) -> Result<Suite, String> {
    let err = |m: String| format!("{}: {m}", path.display());
    let raw: RawSuite = toml::from_str(text).map_err(|e| err(e.to_string().trim().to_string()))?;
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let base = abs.parent().map(Path::to_path_buf).unwrap_or_default();
    let b = raw.bench;
    if b.budgets.is_empty() || b.budgets.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
        return Err(err(
            "bench.budgets must be a non-empty list of positive seconds".into(),
        ));
    }
    if b.seeds.is_empty() {
        return Err(err("bench.seeds must not be empty".into()));
    }
    if raw.scene.is_empty() || raw.method.is_empty() {
        return Err(err(
            "a suite needs at least one [[scene]] and one [[method]]".into(),
        ));
    }
    let out = base.join(&b.out);
    let ref_budget = match (raw.reference.spp, raw.reference.time) {
        (Some(_), Some(_)) => return Err(err("reference: give spp or time, not both".into())),
        (_, Some(t)) if t > 0.0 && t.is_finite() => Budget::Time(t),
        (_, Some(t)) => return Err(err(format!("reference.time must be positive, got {t}"))),
        (Some(n), None) => Budget::Spp(n),
        (None, None) => Budget::Spp(1024),
    };
    let mut names = std::collections::HashSet::new();
    let mut scenes = Vec::new();
    for s in raw.scene {
        if !names.insert(s.name.clone()) {
            return Err(err(format!("scene '{}' appears twice", s.name)));
        }
        if s.name.is_empty() || s.name.contains(['/', '\\', ',']) {
            return Err(err(format!(
                "scene name '{}' must be non-empty, without '/', '\\' or ','",
                s.name
            )));
        }
        let reference = match &s.reference {
            Some(r) => base.join(r),
            None => out.join("references").join(format!("{}.exr", s.name)),
        };
        scenes.push(SuiteScene {
            reference,
            config: base.join(&s.config),
            reference_budget: s.reference_spp.map(Budget::Spp).unwrap_or(ref_budget),
            width: s.width.or(b.width),
            height: s.height.or(b.height),
            name: s.name,
        });
    }
    let mut labels = std::collections::HashSet::new();
    let mut methods = Vec::new();
    for m in raw.method {
        if !labels.insert(m.label.clone()) || m.label.is_empty() || m.label.contains(',') {
            return Err(err(format!(
                "method label '{}' is empty, has a ',' or appears twice",
                m.label
            )));
        }
        if let Some(list) = &m.scenes {
            if let Some(bad) = list.iter().find(|n| !names.contains(*n)) {
                return Err(err(format!(
                    "method '{}' names unknown scene '{bad}'",
                    m.label
                )));
            }
        }
        methods.push(Method {
            label: m.label,
            plugin: m.plugin,
            params: table_pairs(m.params),
            scenes: m.scenes,
        });
    }
    let baseline = match b.baseline {
        Some(l) if labels.contains(&l) => l,
        Some(l) => return Err(err(format!("bench.baseline '{l}' is not a method label"))),
        None => methods
            .iter()
            .find(|m| m.plugin.as_deref().unwrap_or("mcpt") == "mcpt")
            .unwrap_or(&methods[0])
            .label
            .clone(),
    };
    let mut reference_params = table_pairs(raw.reference.params);
    if !reference_params.iter().any(|(k, _)| k == "layers")
        && raw.reference.plugin.as_deref().unwrap_or("mcpt") == "mcpt"
    {
        reference_params.push(("layers".into(), toml::Value::Boolean(true)));
    }
    Ok(Suite {
        path: abs,
        budgets: b.budgets,
        seeds: b.seeds,
        threads: b.threads,
        out,
        baseline,
        reference_seed: raw.reference.seed.unwrap_or(1_000_000),
        reference_plugin: raw.reference.plugin,
        reference_params,
        scenes,
        methods,
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

/// Mean over seeds of one (scene, method, budget).
#[derive(Clone, Debug)]
pub struct SummaryRow {
    pub scene: String,
    pub method: String,
    pub budget: f64,
    pub wall: f64,
    pub spp: f64,
    pub relmse: f64,
    pub rmse: f64,
    pub luminance_ratio: f64,
    /// 1 / (relMSE × wall time).
    pub efficiency: f64,
    /// Efficiency over the baseline method's at the same scene and budget.
    pub relative_efficiency: f64,
    pub runs: usize,
}

/// Everything a bench produced.
pub struct BenchReport {
    pub runs: Vec<Run>,
    pub summary: Vec<SummaryRow>,
    pub files: Vec<PathBuf>,
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

/// Means over seeds, efficiencies, and efficiencies relative to `baseline`.
pub fn summarise(runs: &[Run], baseline: &str) -> Vec<SummaryRow> {
    // Keep the run order (scenes, then methods as listed) with a BTreeMap on first index.
    let mut groups: BTreeMap<usize, Vec<&Run>> = BTreeMap::new();
    let mut index: Vec<(String, String, u64)> = Vec::new();
    for r in runs {
        let key = (r.scene.clone(), r.method.clone(), r.budget.to_bits());
        let i = match index.iter().position(|k| *k == key) {
            Some(i) => i,
            None => {
                index.push(key);
                index.len() - 1
            }
        };
        groups.entry(i).or_default().push(r);
    }
    let mut rows: Vec<SummaryRow> = groups
        .values()
        .map(|g| {
            let n = g.len() as f64;
            let mean = |f: &dyn Fn(&Run) -> f64| g.iter().map(|r| f(r)).sum::<f64>() / n;
            let wall = mean(&|r| r.wall);
            let relmse = mean(&|r| r.errors.relmse);
            SummaryRow {
                scene: g[0].scene.clone(),
                method: g[0].method.clone(),
                budget: g[0].budget,
                wall,
                spp: mean(&|r| r.spp),
                relmse,
                rmse: mean(&|r| r.errors.rmse),
                luminance_ratio: mean(&|r| r.errors.luminance_ratio),
                efficiency: 1.0 / (relmse * wall),
                relative_efficiency: f64::NAN,
                runs: g.len(),
            }
        })
        .collect();
    let base: Vec<(String, u64, f64)> = rows
        .iter()
        .filter(|r| r.method == baseline)
        .map(|r| (r.scene.clone(), r.budget.to_bits(), r.efficiency))
        .collect();
    for r in &mut rows {
        if let Some((_, _, e)) = base
            .iter()
            .find(|(s, b, _)| *s == r.scene && *b == r.budget.to_bits())
        {
            r.relative_efficiency = r.efficiency / e;
        }
    }
    rows
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn write_text(path: &Path, text: &str) -> Result<(), String> {
    crate::output::write_atomically(path, |tmp| {
        std::fs::write(tmp, text).map_err(|e| crate::output::OutputError::Io {
            path: path.to_owned(),
            source: e,
        })
    })
    .map_err(|e| e.to_string())
}

fn write_tables(
    suite: &Suite,
    runs: &[Run],
    summary: &[SummaryRow],
) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    let mut csv = String::from(
        "scene,method,plugin,params,budget_s,seed,wall_s,spp,relmse,rmse,luminance_ratio,reference_floor,invalid_samples,non_finite_pixels\n",
    );
    for r in runs {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{:.6},{:.3},{:.6e},{:.6e},{:.6},{},{},{}",
            csv_field(&r.scene),
            csv_field(&r.method),
            csv_field(&r.plugin),
            csv_field(&r.params),
            r.budget,
            r.seed,
            r.wall,
            r.spp,
            r.errors.relmse,
            r.errors.rmse,
            r.errors.luminance_ratio,
            r.errors
                .reference_floor
                .map(|f| format!("{f:.6e}"))
                .unwrap_or_default(),
            r.invalid_samples,
            r.errors.non_finite
        );
    }
    let p = suite.out.join("results.csv");
    write_text(&p, &csv)?;
    files.push(p);

    let mut csv = String::from("scene,method,budget_s,seed,layer,relmse,rmse,luminance_ratio\n");
    for r in runs {
        for (k, e) in &r.layers {
            let _ = writeln!(
                csv,
                "{},{},{},{},{k},{:.6e},{:.6e},{:.6}",
                csv_field(&r.scene),
                csv_field(&r.method),
                r.budget,
                r.seed,
                e.relmse,
                e.rmse,
                e.luminance_ratio
            );
        }
    }
    let p = suite.out.join("layers.csv");
    write_text(&p, &csv)?;
    files.push(p);

    let mut csv = String::from(
        "scene,method,budget_s,runs,wall_s,spp,relmse,rmse,luminance_ratio,efficiency,relative_efficiency\n",
    );
    let mut md = format!(
        "Efficiency = 1 / (relMSE × wall time), means over seeds {:?}; relative to `{}` at the same budget.\n\n\
         | scene | method | budget (s) | wall (s) | spp | relMSE | RMSE | lum. ratio | efficiency | vs `{}` |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        suite.seeds, suite.baseline, suite.baseline
    );
    for r in summary {
        let _ = writeln!(
            csv,
            "{},{},{},{},{:.6},{:.3},{:.6e},{:.6e},{:.6},{:.6e},{:.4}",
            csv_field(&r.scene),
            csv_field(&r.method),
            r.budget,
            r.runs,
            r.wall,
            r.spp,
            r.relmse,
            r.rmse,
            r.luminance_ratio,
            r.efficiency,
            r.relative_efficiency
        );
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.2} | {:.1} | {:.3e} | {:.3e} | {:.3} | {:.3e} | {:.2} |",
            r.scene,
            r.method,
            r.budget,
            r.wall,
            r.spp,
            r.relmse,
            r.rmse,
            r.luminance_ratio,
            r.efficiency,
            r.relative_efficiency
        );
    }
    let p = suite.out.join("summary.csv");
    write_text(&p, &csv)?;
    files.push(p);
    let p = suite.out.join("summary.md");
    write_text(&p, &md)?;
    files.push(p);
    Ok(files)
}

fn log_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| *v > 0.0 && v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return None;
    }
    // Pad by a factor so points do not sit on the frame; widen a degenerate range.
    let (lo, hi) = if hi / lo < 1.5 {
        (lo / 1.5, hi * 1.5)
    } else {
        (lo / 1.15, hi * 1.15)
    };
    Some((lo, hi))
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: cannot draw the plot: {e}", path.display())
}

/// Log-log relMSE and RMSE against wall time for one scene, one line per method.
pub fn plot_scene(path: &Path, scene: &str, summary: &[SummaryRow]) -> Result<(), String> {
    use plotters::prelude::*;
    let rows: Vec<&SummaryRow> = summary.iter().filter(|r| r.scene == scene).collect();
    let mut methods: Vec<&str> = Vec::new();
    for r in &rows {
        if !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| plot_err(path, e))?;
    }
    let root = SVGBackend::new(path, (1100, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let (left, right) = root.split_horizontally(550);
    type Metric<'a> = (&'a str, fn(&SummaryRow) -> f64);
    let metrics: [Metric; 2] = [("relMSE", |r| r.relmse), ("RMSE", |r| r.rmse)];
    for (area, (name, f)) in [left, right].iter().zip(metrics) {
        let xr = log_range(rows.iter().map(|r| r.wall));
        let yr = log_range(rows.iter().map(|r| f(r)));
        let (Some((x0, x1)), Some((y0, y1))) = (xr, yr) else {
            area.titled(&format!("{scene}: no finite {name}"), ("sans-serif", 18))
                .map_err(|e| plot_err(path, e))?;
            continue;
        };
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{scene}: {name} vs wall time"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| plot_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc("wall time (s)")
            .y_desc(name)
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .x_label_formatter(&|v| format!("{v:.2}"))
            .draw()
            .map_err(|e| plot_err(path, e))?;
        for (i, m) in methods.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.method == *m)
                .map(|r| (r.wall, f(r)))
                .filter(|(x, y)| *x > 0.0 && *y > 0.0 && y.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| plot_err(path, e))?
                .label(*m)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| plot_err(path, e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| plot_err(path, e))?;
    }
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

/// relMSE per lighting layer at the largest budget, one line per method that wrote layers.
pub fn plot_layers(path: &Path, scene: &str, runs: &[Run]) -> Result<(), String> {
    use plotters::prelude::*;
    let runs: Vec<&Run> = runs
        .iter()
        .filter(|r| r.scene == scene && !r.layers.is_empty())
        .collect();
    let budget = runs.iter().map(|r| r.budget).fold(0.0, f64::max);
    let mut methods: Vec<&str> = Vec::new();
    for r in &runs {
        if !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    // (method, layer) -> mean relMSE over seeds at the largest budget.
    let mut series: Vec<(&str, Vec<(f64, f64)>)> = Vec::new();
    for m in &methods {
        let mut per_layer: BTreeMap<usize, (f64, usize)> = BTreeMap::new();
        for r in runs.iter().filter(|r| r.method == *m && r.budget == budget) {
            for (k, e) in &r.layers {
                let s = per_layer.entry(*k).or_default();
                s.0 += e.relmse;
                s.1 += 1;
            }
        }
        let pts = per_layer
            .into_iter()
            .map(|(k, (s, n))| (k as f64, s / n as f64))
            .filter(|(_, y)| *y > 0.0 && y.is_finite())
            .collect();
        series.push((m, pts));
    }
    let kmax = series
        .iter()
        .flat_map(|(_, p)| p.iter().map(|q| q.0))
        .fold(0.0, f64::max);
    let root = SVGBackend::new(path, (700, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let Some((y0, y1)) = log_range(series.iter().flat_map(|(_, p)| p.iter().map(|q| q.1))) else {
        root.titled(
            &format!("{scene}: no finite layer errors"),
            ("sans-serif", 18),
        )
        .map_err(|e| plot_err(path, e))?;
        root.present().map_err(|e| plot_err(path, e))?;
        return Ok(());
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{scene}: relMSE per lighting layer at {budget} s"),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..kmax + 0.5, (y0..y1).log_scale())
        .map_err(|e| plot_err(path, e))?;
    chart
        .configure_mesh()
        .x_desc("lighting layer k (paths of virtual length k + 1)")
        .y_desc("relMSE")
        .y_label_formatter(&|v| format!("{v:.1e}"))
        .draw()
        .map_err(|e| plot_err(path, e))?;
    for (i, (m, pts)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
            .map_err(|e| plot_err(path, e))?
            .label(*m)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
            .map_err(|e| plot_err(path, e))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| plot_err(path, e))?;
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_combine_into_mean_and_variance_of_the_mean() {
        let a = vec![Rgb::splat(1.0)];
        let b = vec![Rgb::splat(3.0)];
        let (m, v) = combine_halves(&a, 10.0, &b, 10.0);
        assert_eq!(m[0], Rgb::splat(2.0));
        // (A − B)² / 4 for equal halves.
        assert_eq!(v[0], Rgb::splat(1.0));
        let (m, _) = combine_halves(&a, 30.0, &b, 10.0);
        assert_eq!(m[0], Rgb::splat(1.5));
    }

    #[test]
    fn variance_estimate_is_unbiased() {
        // Two independent means of n uniform samples: E[estimate] = Var(U)/(2n).
        let mut rng = flowlight_core::rng::Rng::new(7, 1);
        let n = 8;
        let trials = 20000;
        let mut sum = 0.0;
        for _ in 0..trials {
            let mut half = || (0..n).map(|_| rng.uniform() as f64).sum::<f64>() / n as f64;
            let (x, y) = (half(), half());
            let (_, v) = combine_halves(
                &[Rgb::splat(x as f32)],
                n as f64,
                &[Rgb::splat(y as f32)],
                n as f64,
            );
            sum += v[0].r as f64;
        }
        let expected = 1.0 / 12.0 / (2 * n) as f64;
        let got = sum / trials as f64;
        assert!((got / expected - 1.0).abs() < 0.05, "{got} vs {expected}");
    }

    #[test]
    fn suite_parses_and_validates() {
        let p = Path::new("/tmp/suite.toml");
        let text = r#"
[bench]
budgets = [0.5, 1.0]
seeds = [1, 2]
out = "out"
[reference]
spp = 64
[[scene]]
name = "a"
config = "a/a.toml"
[[scene]]
name = "b"
config = "b/b.toml"
reference = "b/ref.exr"
reference_spp = 16
[[method]]
label = "pt"
params = { variant = "entangled" }
[[method]]
label = "erpt"
plugin = "erpt"
params = { mutations = "lens" }
scenes = ["b"]
"#;
        let s = parse_suite(p, text).unwrap();
        assert_eq!(s.baseline, "pt");
        assert_eq!(
            s.scenes[0].reference,
            Path::new("/tmp/out/references/a.exr")
        );
        assert_eq!(s.scenes[0].reference_budget, Budget::Spp(64));
        assert_eq!(s.scenes[1].reference_budget, Budget::Spp(16));
        assert!(s.reference_params.iter().any(|(k, _)| k == "layers"));
        assert!(!s.methods[1].runs_on("a"));
        assert_eq!(s.methods[1].plugin.as_deref(), Some("erpt"));
        for bad in [
            text.replace("budgets = [0.5, 1.0]", "budgets = []"),
            text.replace("scenes = [\"b\"]", "scenes = [\"c\"]"),
            text.replace("label = \"erpt\"", "label = \"pt\""),
            text.replace("[bench]", "[bench]\nbaseline = \"nope\""),
            text.replace("seeds = [1, 2]", "seedz = [1]"),
        ] {
            assert!(parse_suite(p, &bad).is_err(), "accepted:\n{bad}");
        }
    }

    #[test]
    fn summary_means_and_relative_efficiency() {
        let run = |method: &str, seed: u64, relmse: f64, wall: f64| Run {
            scene: "s".into(),
            method: method.into(),
            plugin: "p".into(),
            params: String::new(),
            budget: 1.0,
            seed,
            wall,
            spp: 1.0,
            errors: Errors {
                relmse,
                ..Default::default()
            },
            invalid_samples: 0,
            layers: vec![],
        };
        let runs = vec![
            run("base", 1, 0.1, 1.0),
            run("base", 2, 0.3, 1.0),
            run("fast", 1, 0.05, 1.0),
            run("fast", 2, 0.05, 1.0),
        ];
        let s = summarise(&runs, "base");
        assert_eq!(s.len(), 2);
        assert!((s[0].relmse - 0.2).abs() < 1e-12);
        assert!((s[0].relative_efficiency - 1.0).abs() < 1e-12);
        assert!((s[1].relative_efficiency - 4.0).abs() < 1e-9);
    }

    #[test]
    fn plots_are_written() {
        let dir = std::env::temp_dir().join(format!("flowlight-plot-{}", std::process::id()));
        let row = |m: &str, wall: f64, e: f64| SummaryRow {
            scene: "s".into(),
            method: m.into(),
            budget: wall,
            wall,
            spp: 1.0,
            relmse: e,
            rmse: e.sqrt(),
            luminance_ratio: 1.0,
            efficiency: 1.0 / (e * wall),
            relative_efficiency: 1.0,
            runs: 1,
        };
        let rows = vec![
            row("a", 0.5, 0.1),
            row("a", 1.0, 0.05),
            row("b", 0.5, 0.2),
            row("b", 1.0, 0.1),
        ];
        let p = dir.join("s.svg");
        plot_scene(&p, "s", &rows).unwrap();
        let svg = std::fs::read_to_string(&p).unwrap();
        assert!(svg.contains("<svg") && svg.contains("relMSE"));
        // Nothing finite to draw must not fail either.
        plot_scene(&dir.join("empty.svg"), "none", &rows).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
