//! # `flowlight-testkit` — conformance checks for plugins
//!
//! One call checks that a mutation plugin is a valid Markov-chain kernel for ERPT:
//!
//! ```no_run
//! # use flowlight_testkit::check_mutation;
//! let report = check_mutation("target/release/libflowlight_my_mutation.so", &[]).unwrap();
//! println!("{report}");
//! ```
//!
//! `plugin` is a plugin name (searched like the host searches: `FLOWLIGHT_PLUGIN_PATH`, then
//! the test executable's folders, i.e. `target/<profile>/`) or a path to the library. The
//! ERPT integrator (`cargo build -p flowlight-erpt`) must be findable the same way.
//!
//! ## What is checked
//!
//! On seed paths x traced by the untangled path tracer (ERPT's own seed sampler) through
//! the scenes of [`DENSITY_SCENES`] — the Cornell box, a chain of mirrors, a glass sphere, a
//! sky-lit model and the same model under point, spot and sun lights, so that a strategy's
//! code for Dirac chains, lights at infinity and Dirac lights is exercised — with the film
//! window K = 8 ERPT gives its chains, every proposal y the strategy reports as a move must
//! satisfy (thesis §5.4, Veach 1997 §11.2):
//!
//! 1. **Types kept**: y has x's number of vertices and every vertex keeps its weak type
//!    (eye, light, smooth, Dirac reflection, Dirac transmission) — the promise of
//!    `Mutation::propose` — except that where every Dirac vertex of both paths is a mirror
//!    (forced), a chain of mirrors may change length, or appear or vanish (the regeneration
//!    engine's free chain lengths, `flowlight_mcmc::regenerate`).
//! 2. **Reachable**: T(x → y) > 0 ([`flowlight_sdk::Mutation::density`]): the strategy
//!    can produce what it produced.
//! 3. **Consistent ratio**: the reported `transition_ratio` equals T(y → x)/T(x → y) from
//!    the densities within a relative 2·10⁻³ (f32 rounding of long products), so that the
//!    acceptance a = min(1, f(y)/f(x) · ratio) an integrator forms with the strategy's own
//!    ratio is the one the mixture density gives; with this, detailed balance holds for the
//!    Metropolis–Hastings acceptance by construction. In particular a proposal the strategy
//!    cannot reverse (T(y → x) = 0, e.g. a cap that does not contain the original vertex
//!    seen from the new one) must report ratio 0, so that it is always rejected: detailed
//!    balance f(x)T(x→y)a(x→y) = f(y)T(y→x)a(y→x) then holds with both sides 0.
//! 4. **Finite**: the ratio and f(y) are finite and non-negative, but for one case: a
//!    ratio of NaN is how a strategy reports a move whose density is degenerate (0/0 or ∞/∞,
//!    e.g. a vertex whose Jacobian vanishes or overflows; `flowlight_sdk::Proposal`), which
//!    the integrator rejects and counts. Such a move passes only where T(y → x)/T(x → y)
//!    from the densities has no value either (0/0, ∞/∞ or a NaN density), and is counted
//!    as degenerate; a NaN where T(x → y) = 0 alone still fails check 2's promise.
//!
//! At least [`MIN_VALID`] proposals (over all scenes) must be valid with a finite ratio above 0 (a strategy that
//! always misses, or only proposes moves it cannot reverse, passes nothing). Then **unbiasedness in the furnace**: ERPT with this strategy alone renders
//! the white furnace (a closed sphere of albedo ½ emitting 1, seen from inside, path-space
//! depth N = 8), whose every pixel is 2·(1 − 0.5⁹) exactly; over eight independent renders
//! the image mean and each 8×8 region's mean must be within 4.5 standard errors of it
//! ([`check_furnace`] says why the regions matter).
//!
//! The kit cannot prove a density correct: a strategy whose `density` and `propose` agree
//! but both differ from the distribution it actually samples passes 1–4; the furnace and a
//! comparison with path tracing on a scene of your own catch that.

use flowlight_core::path::{Path, PathVertex};
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_mcmc::regenerate::all_forced;
use flowlight_mcmc::{measurement, WeakNode};
use flowlight_pathtrace::{untangled, PathSettings, Variant};
use flowlight_sdk::{Scene, Stats, Tracer};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

pub mod caustics;
pub mod gltf;
pub mod research;
pub mod scenes;

/// Fewest valid proposals the kit accepts from the seed paths it tries.
pub const MIN_VALID: usize = 100;
/// Seed paths traced for the density checks.
const SEED_PATHS: usize = 3000;
/// The film window ERPT gives its chains by default.
const FILM_WINDOW: u32 = 8;

/// What [`check_mutation`] measured.
#[derive(Clone, Debug, PartialEq)]
pub struct MutationReport {
    /// The plugin's declared name.
    pub name: String,
    /// Proposals asked for, the valid ones among them, and the valid ones the strategy
    /// cannot reverse (ratio 0: always rejected).
    pub proposals: usize,
    pub valid: usize,
    pub irreversible: usize,
    /// Valid moves whose density is degenerate (ratio NaN): rejected by the integrator.
    pub degenerate: usize,
    /// Largest relative difference between the reported ratio and T(y→x)/T(x→y).
    pub worst_ratio_error: f64,
    /// What was counted on each scene of [`DENSITY_SCENES`], in order.
    pub scenes: Vec<SceneCounts>,
    /// Furnace: mean of ERPT's pixel means over the runs, its standard error, and the exact value.
    pub furnace_mean: f64,
    pub furnace_stderr: f64,
    pub furnace_expected: f64,
}

impl std::fmt::Display for MutationReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} of {} proposals valid ({} irreversible, ratio 0; {} degenerate, ratio NaN), worst ratio error {:.2e}; furnace {:.5} ± {:.5} (exact {:.5})",
            self.name,
            self.valid,
            self.proposals,
            self.irreversible,
            self.degenerate,
            self.worst_ratio_error,
            self.furnace_mean,
            self.furnace_stderr,
            self.furnace_expected
        )?;
        for c in &self.scenes {
            write!(
                f,
                "\n  {:<18} {:>5} of {:>5} valid, {:>5} through mirrors or glass, {:>4} irreversible, {:>3} degenerate, worst ratio error {:.2e}",
                c.scene,
                c.valid,
                c.proposals,
                c.through_dirac,
                c.irreversible,
                c.degenerate,
                c.worst_ratio_error
            )?;
        }
        Ok(())
    }
}

/// The repository's `scenes/` folder.
pub fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// `[[integrator.mutations]]` holding only `plugin` with `params`.
fn mutation_list(plugin: &str, params: &[(&str, toml::Value)]) -> toml::Value {
    let mut t = toml::Table::new();
    t.insert("plugin".into(), toml::Value::String(plugin.into()));
    for (k, v) in params {
        t.insert((*k).into(), v.clone());
    }
    toml::Value::Array(vec![toml::Value::Table(t)])
}

/// An ERPT renderer of `config` (under `scenes/`) at `size`² with `plugin` as its only
/// strategy and no outputs.
fn erpt_renderer(
    config: &str,
    size: u32,
    spp: u32,
    plugin: &str,
    params: &[(&str, toml::Value)],
    extra: &[(&str, toml::Value)],
) -> Result<Renderer, String> {
    let path = scenes_dir().join(config);
    let mut cfg = flowlight_scene::config::load_config(&path).map_err(|e| e.to_string())?;
    cfg.width = size;
    cfg.height = size;
    cfg.integrator_plugin = "erpt".into();
    let mut overrides = vec![("mutations".to_string(), mutation_list(plugin, params))];
    overrides.extend(extra.iter().map(|(k, v)| (k.to_string(), v.clone())));
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        params: overrides,
        ..Default::default()
    };
    let mut s = Renderer::from_config(cfg, &ov)?;
    s.exr_path = None;
    s.png_path = None;
    Ok(s)
}

/// Checks mutation plugin `plugin` (a name or a library path) with its `params`; see the
/// crate docs for what is checked. `Err` says which check failed, on which path types.
pub fn check_mutation(
    plugin: &str,
    params: &[(&str, toml::Value)],
) -> Result<MutationReport, String> {
    let mut report = check_densities(plugin, params)?;
    let (mean, stderr, expected) = check_furnace(plugin, params)?;
    report.furnace_mean = mean;
    report.furnace_stderr = stderr;
    report.furnace_expected = expected;
    Ok(report)
}

/// [`check_mutation`], panicking with the failure: for `#[test]` functions.
pub fn assert_mutation_conforms(plugin: &str, params: &[(&str, toml::Value)]) -> MutationReport {
    check_mutation(plugin, params).unwrap_or_else(|e| panic!("mutation {plugin}: {e}"))
}

/// The scenes whose seed paths the density checks draw from: (label, config under
/// `scenes/`). Between them they hold diffuse interreflection under an area light, chains of
/// mirrors (Dirac reflection, with free chain lengths), a glass sphere (Dirac transmission
/// and reflection, caustics), a sky (environment light, whose vertex is a direction) and
/// point, spot and sun lights (Dirac lights, which no mutation may move).
pub const DENSITY_SCENES: [(&str, &str); 5] = [
    ("Cornell box", "cornell-box/erpt.toml"),
    ("mirror chain", "mirror-chain/erpt.toml"),
    ("glass caustic", "glass-caustic/erpt.toml"),
    ("sky-lit showcase", "blender-showcase/showcase.toml"),
    ("punctual lights", "blender-showcase/lit.toml"),
];

/// What [`check_densities`] counted on one scene of [`DENSITY_SCENES`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneCounts {
    /// The scene's label.
    pub scene: String,
    /// Proposals asked for.
    pub proposals: usize,
    /// Proposals the strategy reported as moves.
    pub valid: usize,
    /// Moves it cannot reverse (ratio 0).
    pub irreversible: usize,
    /// Moves whose density is degenerate (ratio NaN, as the strategy's own densities say):
    /// rejected by the integrator.
    pub degenerate: usize,
    /// Moves from a path with a Dirac (mirror or glass) vertex.
    pub through_dirac: usize,
    /// Largest relative ratio error on the scene.
    pub worst_ratio_error: f64,
}

/// Checks 1–4 of the crate docs on seed paths of every scene of [`DENSITY_SCENES`].
pub fn check_densities(
    plugin: &str,
    params: &[(&str, toml::Value)],
) -> Result<MutationReport, String> {
    let mut report = MutationReport {
        name: String::new(),
        proposals: 0,
        valid: 0,
        irreversible: 0,
        degenerate: 0,
        worst_ratio_error: 0.0,
        scenes: Vec::new(),
        furnace_mean: 0.0,
        furnace_stderr: 0.0,
        furnace_expected: 0.0,
    };
    for (label, config) in DENSITY_SCENES {
        let (name, counts) = check_scene(plugin, params, label, config)?;
        report.name = name;
        report.proposals += counts.proposals;
        report.valid += counts.valid;
        report.irreversible += counts.irreversible;
        report.degenerate += counts.degenerate;
        report.worst_ratio_error = report.worst_ratio_error.max(counts.worst_ratio_error);
        report.scenes.push(counts);
    }
    let judged = report.valid - report.irreversible - report.degenerate;
    if judged < MIN_VALID {
        return Err(format!(
            "{}: only {} of {} proposals were valid and reversible (at least {MIN_VALID} needed to judge it)",
            report.name,
            judged,
            report.proposals
        ));
    }
    Ok(report)
}

/// Check 1: `y` has `x`'s length and weak types, except that where every Dirac vertex of
/// both is forced (mirrors: `flowlight_mcmc::regenerate::all_forced`) a chain of them may
/// have another length, 0 included — the engine's free chain lengths ("Dirac chains of any length" in
/// `flowlight_mcmc::regenerate`), under which paths that differ only by the number of
/// mirror bounces in a chain are points of one space.
fn same_weak_types(scene: &Scene, x: &[PathVertex], y: &[PathVertex]) -> bool {
    let types = |v: &[PathVertex]| v.iter().map(WeakNode::of).collect::<Vec<_>>();
    let (tx, ty) = (types(x), types(y));
    if tx == ty {
        return true;
    }
    if !(all_forced(scene, x) && all_forced(scene, y)) {
        return false;
    }
    // A chain of mirrors is a function of the ray entering it, of any length, none included.
    let free = |mut t: Vec<WeakNode>| {
        t.retain(|w| !w.is_dirac());
        t
    };
    free(tx) == free(ty)
}

/// Checks 1–4 on the seed paths of one scene: the plugin's name and what was counted.
fn check_scene(
    plugin: &str,
    params: &[(&str, toml::Value)],
    label: &str,
    config: &str,
) -> Result<(String, SceneCounts), String> {
    let size = 48;
    let s = erpt_renderer(config, size, 1, plugin, params, &[])
        .map_err(|e| format!("scene {label} ({config}): {e}"))?;
    let set = s.instance.mutation_set();
    let name = set.name(0).to_string();
    // SAFETY: the renderer keeps the view's data alive while `scene` is used.
    let scene = unsafe { Scene::from_view(s.instance.view()) };
    let mut unit_tracer = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let mut settings = PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[]))?;
    settings.variant = Variant::Untangled;
    settings.max_ray_depth = 32;

    let mut rng = Rng::new(0x7e57_c0de, 5);
    let mut x = Box::new(Path::empty());
    let mut y = Box::new(Path::empty());
    let mut counts = SceneCounts {
        scene: label.to_string(),
        ..SceneCounts::default()
    };
    for _ in 0..SEED_PATHS {
        let raster = glam::Vec2::new(rng.uniform(), rng.uniform()) * size as f32;
        let sample = untangled::trace(&scene, &tracer, &settings, &mut rng, raster, Some(&mut x));
        if sample.value.is_black() || x.vertex_count < 2 {
            continue;
        }
        x.film_window = FILM_WINDOW;
        let f_x = measurement(&scene, &x);
        // NaN counts as no energy.
        if f_x.luminance().partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let dirac = x.vertices().iter().any(|v| WeakNode::of(v).is_dirac());
        for _ in 0..2 {
            counts.proposals += 1;
            let Some(ratio) = set
                .propose(0, &tracer, &mut rng, &x, &mut y, &mut Stats::new(&mut []))?
                .transition_ratio()
            else {
                continue;
            };
            counts.valid += 1;
            counts.through_dirac += dirac as usize;
            let what = || format!("{} → {} in the {label}", x.heckbert(), y.heckbert());
            if !same_weak_types(&scene, x.vertices(), y.vertices()) {
                return Err(format!(
                    "{name}: a valid proposal changed the path length or a vertex type ({})",
                    what()
                ));
            }
            let f_y = measurement(&scene, &y);
            let ratio = ratio as f64;
            let forward = set.density(0, &x, &y)?;
            let reverse = set.density(0, &y, &x)?;
            if ratio.is_nan() && f_y.is_valid_radiance() {
                // NaN is the SDK's word for a move whose density is degenerate (`Proposal`):
                // the integrator rejects and counts it. Taken as such only where the
                // densities the strategy evaluates have no ratio either (0/0, ∞/∞ or a NaN
                // density); T(x→y) = 0 against T(y→x) > 0 is check 2's failure, not this.
                let expected = reverse / forward;
                if !expected.is_nan() {
                    return Err(format!(
                        "{name}: reports a degenerate density (ratio NaN) where T(y→x)/T(x→y) = {reverse}/{forward} = {expected} ({})",
                        what()
                    ));
                }
                counts.degenerate += 1;
                continue;
            }
            if !ratio.is_finite() || ratio < 0.0 || !f_y.is_valid_radiance() {
                return Err(format!(
                    "{name}: invalid ratio {ratio} or contribution {f_y:?} ({})",
                    what()
                ));
            }
            if forward.is_nan() || forward <= 0.0 {
                return Err(format!(
                    "{name}: proposed a path its density says it cannot reach: T(x→y) = {forward} ({})",
                    what()
                ));
            }
            let expected = reverse / forward;
            if expected == 0.0 {
                counts.irreversible += 1;
                if ratio != 0.0 {
                    return Err(format!(
                        "{name}: cannot move back (T(y→x) = 0) but reports ratio {ratio}: detailed balance fails ({})",
                        what()
                    ));
                }
                continue;
            }
            // Relative to the larger of the two; f32 ratios below 1e-30 may round to 0.
            let err = (ratio - expected).abs() / expected.max(ratio);
            if (ratio - expected).abs() <= 1e-30 {
                continue;
            }
            counts.worst_ratio_error = counts.worst_ratio_error.max(err);
            if err > 2e-3 {
                return Err(format!(
                    "{name}: ratio {ratio} but T(y→x)/T(x→y) = {reverse}/{forward} = {expected} ({})",
                    what()
                ));
            }
        }
    }
    Ok((name, counts))
}

/// ERPT with `plugin` alone in the white furnace, 32×32 pixels: (image mean, its standard
/// error, exact value), or `Err` when the image mean or a region's mean is off.
///
/// The image mean alone says little about a strategy: ERPT's chains conserve the seeds'
/// energy, so it is fixed by the seeds whatever the mutations do. Where the energy lands is
/// the strategy's doing, so each 8×8 region's mean must match the exact value too. The
/// regions of the furnace are exchangeable, so their noise is estimated from all of them
/// together: the pooled variance over regions and runs (16·(runs − 1) degrees of freedom).
pub fn check_furnace(
    plugin: &str,
    params: &[(&str, toml::Value)],
) -> Result<(f64, f64, f64), String> {
    let depth = 8;
    let expected = 2.0 * (1.0 - 0.5f64.powi(depth + 1));
    // Four runs were too few for the heavy tail of ERPT's region means: after a change of
    // the seeds' random stream, one region of `bxdf-extension` came out at z = 4.7 (2.12
    // against 2.00) from four seeds that were all high, and at z = 2.8 with twelve.
    let runs = 8;
    let mut per_run: Vec<[f64; 16]> = Vec::new();
    for r in 0..runs {
        let mut s = erpt_renderer(
            "furnace/erpt.toml",
            32,
            4,
            plugin,
            params,
            &[("path_depth", toml::Value::Integer(depth as i64))],
        )?;
        s.options.seed = 4000 + r;
        let out = s.render(&AtomicBool::new(false), &|_| {})?;
        if let Some(e) = out.error {
            return Err(format!("furnace render failed: {e}"));
        }
        let img: Vec<Rgb> = out.frame.image();
        if img.iter().any(|c| !c.is_valid_radiance()) {
            return Err("furnace: NaN, infinite or negative pixel".into());
        }
        let mut regions = [0.0f64; 16];
        for (i, c) in img.iter().enumerate() {
            let (x, y) = (i % 32, i / 32);
            regions[(y / 8) * 4 + x / 8] += c.luminance() as f64 / 64.0;
        }
        per_run.push(regions);
    }
    let n = runs as f64;
    let region_means: Vec<f64> = (0..16)
        .map(|k| per_run.iter().map(|r| r[k]).sum::<f64>() / n)
        .collect();
    let pooled = (0..16)
        .map(|k| {
            per_run
                .iter()
                .map(|r| (r[k] - region_means[k]).powi(2))
                .sum::<f64>()
                / (n - 1.0)
        })
        .sum::<f64>()
        / 16.0;
    let region_se = (pooled / n).sqrt().max(1e-4 * expected);
    for (k, m) in region_means.iter().enumerate() {
        let z = (m - expected) / region_se;
        if z.abs() > 4.5 {
            return Err(format!(
                "furnace: region {k} (8×8 block {}, {}) gets {m:.5} ± {region_se:.5}, exact {expected:.5} (z = {z:.1}): the strategy moves energy where it does not belong",
                k % 4,
                k / 4
            ));
        }
    }
    let mean = region_means.iter().sum::<f64>() / 16.0;
    let stderr = region_se / 4.0;
    let z = (mean - expected) / stderr;
    if z.abs() > 4.5 {
        return Err(format!(
            "furnace: ERPT with this strategy alone gives {mean:.5} ± {stderr:.5}, exact {expected:.5} (z = {z:.1})"
        ));
    }
    Ok((mean, stderr, expected))
}
