//! Renders through the ordinary host API ([`Renderer`]): one [`RenderRequest`], or every
//! (scene, method, budget, seed) of a suite.

use crate::plot::{plot_layers, plot_scene};
use crate::reference::{read_reference, render_reference, write_reference, Reference};
use crate::report::{summarise, write_tables, BenchReport, SummaryRow};
use crate::suite::{Suite, SuiteScene};
use flowlight_core::Rgb;
use flowlight_host::accumulation::Frame;
use flowlight_host::metrics::{self, Errors};
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_scene::config::{load_config, RenderConfig};
use flowlight_sdk::ParamRole;
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
    /// The integrator's path depth: the resolved value of its parameter with role
    /// [`ParamRole::PathDepth`] (`None` when the plugin has no such parameter).
    pub path_depth: Option<u32>,
    /// The integrator's [`ParamRole::MaxRayDepth`] parameter, likewise.
    pub max_ray_depth: Option<u32>,
    /// The integrator declared its estimator biased ([`Run::biased`]).
    pub biased: bool,
}

/// The resolved value of the render's integer parameter with role `role` (the integrator
/// reports what it read, default included; `None` when it declares no such parameter).
fn resolved_int(renderer: &Renderer, role: ParamRole) -> Option<u32> {
    let name = renderer
        .instance
        .plugin()
        .params()
        .into_iter()
        .find(|p| p.role == role)?
        .name;
    renderer
        .instance
        .resolved_params()
        .into_iter()
        .find(|(k, _)| *k == name)
        .and_then(|(_, v)| v.parse::<u32>().ok())
}

pub(crate) fn resolve_config(req: &RenderRequest) -> Result<RenderConfig, String> {
    let mut cfg = load_config(&req.config).map_err(|e| e.to_string())?;
    if let Some(p) = &req.plugin {
        if *p != cfg.integrator_plugin {
            // Another plugin gets only its own parameters, except the scene's path depth
            // (when the plugin has one): every method of a suite renders the same layers of
            // path space as the scene's reference. Both plugins' parameters are found by
            // their declared role, whatever their names.
            let depth = role_value(&cfg, ParamRole::PathDepth);
            cfg.integrator_plugin = p.clone();
            cfg.integrator_params.clear();
            if let Some(d) = depth {
                if let Some(name) = role_param(&cfg, ParamRole::PathDepth) {
                    cfg.integrator_params.push((name, d));
                }
            }
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

/// The name of the parameter with role `role` of the config's integrator plugin (`None`
/// when it declares none, or cannot be found or loaded: the render itself then reports that).
pub(crate) fn role_param(cfg: &RenderConfig, role: ParamRole) -> Option<String> {
    use flowlight_host::plugin::{find_plugin, search_dirs, PluginLibrary};
    let path = cfg.base_dir.join(&cfg.integrator_plugin);
    let candidate = if cfg.integrator_plugin.contains('/') {
        path.to_string_lossy().into_owned()
    } else {
        cfg.integrator_plugin.clone()
    };
    let lib = find_plugin(&candidate, &search_dirs(&cfg.plugin_search_paths))
        .ok()
        .and_then(|p| PluginLibrary::load(&p).ok())?;
    lib.params()
        .into_iter()
        .find(|p| p.role == role)
        .map(|p| p.name)
}

/// The config's value of its integrator's parameter with role `role`, if the config sets it.
fn role_value(cfg: &RenderConfig, role: ParamRole) -> Option<toml::Value> {
    let name = role_param(cfg, role)?;
    cfg.integrator_params
        .iter()
        .find(|(k, _)| *k == name)
        .map(|(_, v)| v.clone())
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
    let mut renderer = Renderer::from_config(cfg, &ov)?;
    renderer.exr_path = None;
    renderer.png_path = None;
    let stop = AtomicBool::new(false);
    let out = renderer.render(&stop, &|_| {})?;
    if let Some(e) = out.error {
        return Err(e.to_string());
    }
    let frame: &Frame = &out.frame;
    let (w, h) = (frame.width as usize, frame.height as usize);
    let params = renderer
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
        plugin: renderer.instance.plugin().name.clone(),
        params,
        path_depth: resolved_int(&renderer, ParamRole::PathDepth),
        max_ray_depth: resolved_int(&renderer, ParamRole::MaxRayDepth),
        biased: renderer.instance.info.biased != 0,
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
    /// The integrator says its estimator is biased (`flowlight.biased`: VCM's merging,
    /// ERPT's consecutive-sample filter).
    pub biased: bool,
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

/// The file a scene's reference is read from (the committed one when it exists).
fn reference_path(s: &SuiteScene, rebuild: bool) -> PathBuf {
    match &s.committed_reference {
        Some(p) if p.exists() && !rebuild => p.clone(),
        _ => s.reference.clone(),
    }
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

/// Loads the scene's reference: the committed one (`<config folder>/reference/<config
/// stem>.exr`) when it exists, else the suite's (or cached) file, rendering and caching it
/// when missing or when asked to (`rebuild` never overwrites a committed reference: it renders
/// into the cache). A reference of another resolution or path depth than the scene is refused.
pub fn ensure_reference(
    suite: &Suite,
    s: &SuiteScene,
    rebuild: bool,
    log: &dyn Fn(&str),
) -> Result<Reference, String> {
    let committed = s.committed_reference.as_ref().filter(|p| p.exists());
    let path = match committed {
        Some(p) if !rebuild => Some(p.clone()),
        _ if !rebuild && s.reference.exists() => Some(s.reference.clone()),
        _ => None,
    };
    if let Some(path) = path {
        let r = read_reference(&path)?;
        let cfg = resolve_config(&scene_request(s, 0))?;
        check_reference_matches(&r, &path, &s.name, &cfg)?;
        if committed.is_some_and(|c| *c == path) {
            log(&format!(
                "reference for '{}': committed {} ({} spp, floor {})",
                s.name,
                path.display(),
                r.spp,
                r.floor().map_or("unknown".into(), |f| format!("{f:.3e}"))
            ));
        }
        return Ok(r);
    }
    let mut req = scene_request(s, suite.threads);
    req.plugin = suite.reference_plugin.clone();
    req.params = suite.reference_params.clone();
    // The reference writes its lighting layers (the per-layer errors need them) when its
    // plugin declares a parameter for them and the suite does not set it.
    if let Some(name) = role_param(&resolve_config(&req)?, ParamRole::Layers) {
        if !req.params.iter().any(|(k, _)| *k == name) {
            req.params.push((name, toml::Value::Boolean(true)));
        }
    }
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

/// Refuses a reference whose resolution or recorded `path_depth` differs from the scene's
/// (`cfg`: the scene config with the suite's resolution). One line naming the file and both
/// values.
pub fn check_reference_matches(
    r: &Reference,
    path: &Path,
    scene: &str,
    cfg: &RenderConfig,
) -> Result<(), String> {
    if (r.width, r.height) != (cfg.width as usize, cfg.height as usize) {
        return Err(format!(
            "reference {} is {}x{} but scene '{scene}' renders at {}x{}: render a matching one (or delete a cached one, or run with --rebuild-references)",
            path.display(),
            r.width,
            r.height,
            cfg.width,
            cfg.height
        ));
    }
    let depth = role_value(cfg, ParamRole::PathDepth).and_then(|v| v.as_integer());
    if let (Some(want), Some(got)) = (depth, r.path_depth()) {
        if want != i64::from(got) {
            return Err(format!(
                "reference {} was rendered with path_depth {got} but scene '{scene}' has path_depth {want}: render a matching one",
                path.display()
            ));
        }
    }
    Ok(())
}

/// The floor rule: a comparison is meaningful only when the reference's own noise (its floor,
/// the relMSE it adds to every comparison) is at most `ratio` (the suite's `floor_ratio`,
/// 1/10 by default) of the smallest relMSE reported against it — the means over seeds of the
/// summary. `Ok` also when the floor is unknown (a reference without a variance layer cannot
/// be judged, and says so in `results.csv` by an empty `reference_floor`).
///
/// The refusal names the scene, the floor, the smallest relMSE (method, budget) and the samples
/// per pixel a reference would need: floor ∝ 1/spp, and the expected relMSE is the method's own
/// error e = relMSE − floor plus the new floor f', so f' ≤ ratio·(e + f') needs
/// spp' = spp · floor · (1 − ratio) / (ratio · e) (e bounded below by ratio × relMSE when
/// the measured errors are at the floor already).
pub fn check_floor(
    scene: &str,
    reference: &Reference,
    summary: &[SummaryRow],
    ratio: f64,
) -> Result<(), String> {
    let Some(floor) = reference.floor() else {
        return Ok(());
    };
    let Some(best) = summary
        .iter()
        .filter(|r| r.scene == scene && r.relmse.is_finite())
        .min_by(|a, b| a.relmse.total_cmp(&b.relmse))
    else {
        return Ok(());
    };
    if floor <= ratio * best.relmse {
        return Ok(());
    }
    let own = (best.relmse - floor).max(ratio * best.relmse);
    let needed = (reference.spp * floor * (1.0 - ratio) / (ratio * own)).ceil();
    Err(format!(
        "scene '{scene}': reference floor {floor:.3e} is more than {ratio} of the smallest relMSE compared with it ({:.3e}, method '{}' at {} s): comparison refused (results.csv keeps the raw data); a reference of about {needed} spp (now {}) would pass",
        best.relmse, best.method, best.budget, reference.spp
    ))
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
    let mut refused = Vec::new();
    let mut references = Vec::new();
    for s in &suite.scenes {
        let reference = ensure_reference(&suite, s, ov.rebuild_references, log)?;
        'method: for m in suite.methods.iter().filter(|m| m.runs_on(s)) {
            for &budget in &suite.budgets {
                for &seed in &suite.seeds {
                    let mut req = scene_request(s, suite.threads);
                    if let Some(config) = m.config_for(s) {
                        req.config = config;
                    }
                    req.plugin = m.plugin.clone();
                    req.params = m.params.clone();
                    req.budget = Budget::Time(budget);
                    req.seed = seed;
                    let r = render_request(&req)
                        .map_err(|e| format!("scene '{}', method '{}': {e}", s.name, m.label))?;
                    if let (Some(want), Some(got)) = (reference.path_depth(), r.path_depth) {
                        if want != got {
                            let msg = format!(
                                "scene '{}', method '{}': renders path_depth {got} but the reference {} has path_depth {want}: comparison refused (set path_depth = {want} in its params)",
                                s.name,
                                m.label,
                                reference_path(s, ov.rebuild_references).display()
                            );
                            log(&format!("refused: {msg}"));
                            refused.push(msg);
                            continue 'method;
                        }
                    }
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
                        biased: r.biased,
                        layers,
                    });
                }
            }
        }
        references.push(reference);
    }
    let mut summary = summarise(&runs, &suite.baseline);
    // The floor rule (check_floor): a refused scene keeps its rows in results.csv and
    // layers.csv (the raw data) but gets no summary rows and no plots.
    let mut refused_scenes = Vec::new();
    for (s, r) in suite.scenes.iter().zip(&references) {
        if let Err(msg) = check_floor(&s.name, r, &summary, suite.floor_ratio) {
            log(&format!("refused: {msg}"));
            refused.push(msg);
            refused_scenes.push(s.name.clone());
        }
    }
    summary.retain(|r| !refused_scenes.contains(&r.scene));
    let mut files = write_tables(&suite, &runs, &summary)?;
    for s in suite
        .scenes
        .iter()
        .filter(|s| !refused_scenes.contains(&s.name))
    {
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
        refused,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reference of 4 pixels of radiance 1 whose variance layer is `v` everywhere: its floor
    /// is v / (1 + ε) (docs/bench.md).
    fn flat_reference(v: f32, spp: f64) -> Reference {
        Reference {
            width: 2,
            height: 2,
            image: vec![Rgb::splat(1.0); 4],
            variance: Some(vec![Rgb::splat(v); 4]),
            layers: Vec::new(),
            spp,
            meta: Vec::new(),
        }
    }

    fn row(scene: &str, method: &str, budget: f64, relmse: f64) -> SummaryRow {
        SummaryRow {
            scene: scene.into(),
            method: method.into(),
            budget,
            wall: budget,
            spp: 1.0,
            relmse,
            rmse: relmse.sqrt(),
            luminance_ratio: 1.0,
            efficiency: 1.0 / (relmse * budget),
            relative_efficiency: 1.0,
            runs: 2,
            biased: false,
        }
    }

    #[test]
    fn floor_rule_refuses_a_noisy_reference_and_accepts_a_clean_one() {
        let eps = flowlight_host::metrics::REL_EPS;
        let summary = vec![
            row("a", "slow", 2.0, 0.05),
            row("a", "fast", 8.0, 0.012),
            row("b", "other", 8.0, 1e-6),
        ];
        // Floor 1e-3 ≤ 0.1 × 0.012: passes (scene b's smaller errors do not count).
        let ok = flat_reference((1e-3 * (1.0 + eps)) as f32, 1024.0);
        assert!((ok.floor().unwrap() - 1e-3).abs() < 1e-9);
        check_floor("a", &ok, &summary, 0.1).unwrap();
        // Floor 2e-3 > 0.1 × 0.012: refused, naming the scene, floor, smallest relMSE and its
        // method and budget, and the spp that would pass:
        // 1024 · 2e-3 · 0.9 / (0.1 · (0.012 − 0.002)) = 1843.2, so 1844.
        let noisy = flat_reference((2e-3 * (1.0 + eps)) as f32, 1024.0);
        let e = check_floor("a", &noisy, &summary, 0.1).unwrap_err();
        assert!(!e.contains('\n'), "{e}");
        for part in [
            "scene 'a'",
            "2.000e-3",
            "1.200e-2",
            "'fast' at 8 s",
            "about 1844 spp",
            "now 1024",
        ] {
            assert!(e.contains(part), "{part:?} missing in: {e}");
        }
        // A looser bound accepts it; a scene without rows or a reference without variance
        // cannot be judged and passes.
        check_floor("a", &noisy, &summary, 0.2).unwrap();
        check_floor("c", &noisy, &summary, 0.1).unwrap();
        let mut unknown = noisy.clone();
        unknown.variance = None;
        check_floor("a", &unknown, &summary, 0.1).unwrap();
        // Errors at the floor already: the needed spp stays finite (own error bounded below
        // by ratio × relMSE): 1024 · 0.02 · 0.9 / (0.1 · 0.1 · 0.012) = 153600, so 153600 or
        // one more from rounding.
        let at_floor = flat_reference((0.02 * (1.0 + eps)) as f32, 1024.0);
        let e = check_floor("a", &at_floor, &summary, 0.1).unwrap_err();
        assert!(e.contains("about 15360"), "{e}");
    }
}
