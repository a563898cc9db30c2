//! ERPT seeded by BDPT (`seeds = "bdpt"`): every connection strategy (s, t) of a BDPT pixel
//! sample is a seed whose estimate is its MIS weight times f/p with the chains' own target
//! function, the seeds of one sample add up to the `bdpt` plugin's deposits for it, ERPT with
//! them is unbiased against MCPT (a diffuse box and a glass caustic), and every mutation plugin
//! takes them, light-tracing seeds and light-side Dirac chains included.

use crate::common;

use common::{
    assert_image_mean, assert_regions_unbiased, independent_runs, mutations, renderer_at, MeanRule,
};
use flowlight_core::path::Path;
use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_mcmc::measurement;
use flowlight_pathtrace::bidir::strategy_seeds::StrategySeeds;
use flowlight_pathtrace::bidir::{BidirSettings, Heuristic, Techniques};
use flowlight_pathtrace::seeds::{SeedStore, Technique};
use flowlight_pathtrace::PathSettings;
use flowlight_sdk::{Scene, Tracer};

fn s(v: &str) -> toml::Value {
    toml::Value::String(v.into())
}

/// BDPT's settings as ERPT's seeds use them, at `path_depth`.
fn bidir_settings(path_depth: u32) -> BidirSettings {
    let mut path = PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[])).unwrap();
    path.max_ray_depth = 32;
    path.path_depth = path_depth;
    BidirSettings {
        path,
        heuristic: Heuristic::Power,
        techniques: Techniques::BDPT,
        lighting_layers: false,
        strategy_layers: false,
        radius: 0.0,
        radius_alpha: 1.0,
        only_strategy: None,
    }
}

/// Seeds checked per kind of strategy: s = 0, s = 1, s ≥ 2 with t ≥ 2, t = 1; and of those
/// with a Dirac vertex on the light side of their connection.
#[derive(Debug, Default)]
struct Kinds {
    by_kind: [usize; 4],
    light_side_dirac: usize,
}

/// For every pixel sample of a 24² image of `config`: the seeds add up to the `bdpt` plugin's
/// deposits of that sample (camera contributions and light-tracing splats), and every seed with
/// a path is X = w · f(x̄)/p(x̄) with `flowlight-mcmc`'s f.
fn check_bdpt_seeds(config: &str, path_depth: u32) -> Kinds {
    check_bdpt_seeds_of(config, renderer_at(config, 24, 24, 1, &[]), path_depth)
}

/// [`check_bdpt_seeds`] of a prepared renderer (its first 24² pixels).
fn check_bdpt_seeds_of(
    config: &str,
    renderer: flowlight_host::renderer::Renderer,
    path_depth: u32,
) -> Kinds {
    // SAFETY: the renderer keeps the view's data alive.
    let scene = unsafe { Scene::from_view(renderer.instance.view()) };
    let mut unit_tracer = UnitTracer::new(&renderer.scene, renderer.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let settings = bidir_settings(path_depth);
    let mut sampler = StrategySeeds::new(&scene, &tracer, &settings);
    let mut store = SeedStore::default();
    let mut path = Box::new(Path::empty());
    let mut kinds = Kinds::default();
    let (mut zero_f, mut outliers, mut total) = (0usize, 0usize, 0usize);
    for sample in 0..3u32 {
        for y in 0..24 {
            for x in 0..24 {
                let key = (x, y, sample);
                let want = sampler.estimate(31, key);
                store.clear();
                sampler.trace_sample(31, key, &mut store);
                let bdpt =
                    want.contributions.total() + want.splats.iter().fold(Rgb::ZERO, |a, s| a + s.2);
                let seeds = store.seeds.iter().fold(Rgb::ZERO, |a, s| a + s.estimate);
                let (a, b) = (bdpt.luminance(), seeds.luminance());
                assert!(
                    (a - b).abs() <= 1e-5 * a.max(b) + 1e-12,
                    "{config} {key:?}: BDPT {a} vs seeds {b}"
                );
                for k in 0..store.seeds.len() {
                    let sd = store.seeds[k];
                    let Technique::Bidirectional { s, t } = sd.technique else {
                        panic!("{config}: a BDPT seed of technique {:?}", sd.technique);
                    };
                    store.path(k, &mut path);
                    assert_eq!(path.vertex_count, s + t, "{config}: ({s}, {t})");
                    let f = measurement(&scene, &path);
                    total += 1;
                    if f.luminance() == 0.0 {
                        zero_f += 1;
                        continue;
                    }
                    assert!(
                        sd.mis_weight > 0.0 && sd.mis_weight <= 1.0 + 1e-6 && sd.density > 0.0,
                        "{config}: ({s}, {t}) w = {} p = {}",
                        sd.mis_weight,
                        sd.density
                    );
                    for (c, (x, fc)) in [(sd.estimate.r, f.r), (sd.estimate.g, f.g)]
                        .into_iter()
                        .enumerate()
                    {
                        let want = sd.mis_weight as f64 * fc as f64 / sd.density;
                        let error = (x as f64 - want).abs() / (want.abs() + 1e-9);
                        if error > 2e-3 {
                            outliers += 1;
                        }
                        assert!(
                            error < 0.05,
                            "{config}: ({s}, {t}) {} channel {c}: X = {x} but w·f/p = {} · {fc} / {} = {want}",
                            path.heckbert(),
                            sd.mis_weight,
                            sd.density
                        );
                    }
                    let kind = match (s, t) {
                        (0, _) => 0,
                        (1, _) if t > 1 => 1,
                        (_, 1) => 3,
                        _ => 2,
                    };
                    kinds.by_kind[kind] += 1;
                    let n = path.vertex_count as usize;
                    let light_side = &path.vertices()[(t as usize).min(n - 1)..n - 1];
                    if light_side.iter().any(|v| v.node.is_specular()) {
                        kinds.light_side_dirac += 1;
                    }
                }
            }
        }
    }
    assert!(
        outliers * 200 <= total,
        "{config}: {outliers} of {total} seeds differ from w·f/p by over 0.2 %"
    );
    assert!(
        zero_f * 200 <= total,
        "{config}: {zero_f} of {total} seeds have f = 0 in the target function"
    );
    kinds
}

#[test]
fn bdpt_seeds_are_mis_weighted_measurements_that_sum_to_bdpt() {
    let k = check_bdpt_seeds("cornell-box/cornell-box.toml", 8);
    // The lamp is small: few camera paths hit it (s = 0).
    assert!(
        k.by_kind[0] > 10 && k.by_kind[1..].iter().all(|&n| n > 1000),
        "cornell box: {k:?}"
    );
    let k = check_bdpt_seeds("glass-caustic/glass-caustic.toml", 10);
    assert!(
        k.by_kind[0] > 0 && k.by_kind[1..].iter().all(|&n| n > 200),
        "glass caustic: {k:?}"
    );
    assert!(k.light_side_dirac > 20, "glass caustic: {k:?}");
    // Lights at infinity: a sun (a Dirac direction, its disc drawn by the light subpath) and a
    // sky (a direction in solid angle), over a Dirac coat on both sides of the paths.
    let k = check_bdpt_seeds_of(
        "sun and sky",
        varnished_sun("bdpt-seeds-check", "plugin = \"bdpt\"", 1, true),
        3,
    );
    assert!(k.by_kind.iter().all(|&n| n > 40), "sun and sky: {k:?}");
    assert!(k.light_side_dirac > 0, "sun and sky: {k:?}");
}

/// ERPT with BDPT seeds of `config` with `params` (M = 32, N = 32, K = 8 unless given) against
/// `reference` per 8×8 region and in the image mean; returns the last run's stats.
fn check_unbiased(
    config: &str,
    label: &str,
    params: &[(&str, toml::Value)],
    reference: &[Rgb],
) -> flowlight_host::render::RenderOutcome {
    let mut all: Vec<(&str, toml::Value)> = vec![
        ("seeds", s("bdpt")),
        ("mutations_per_sample", 32.0.into()),
        ("chain_length", toml::Value::Integer(32)),
        ("film_window", toml::Value::Integer(8)),
        ("direct", s("erpt")),
        ("chains_for", s("all")),
    ];
    for (k, v) in params {
        all.retain(|(a, _)| a != k);
        all.push((k, v.clone()));
    }
    let (images, last) = independent_runs(label, 6, 3000, &|| renderer_at(config, 32, 32, 4, &all));
    assert_regions_unbiased(label, &images, reference);
    assert_image_mean(label, &images, reference, MeanRule::WithinOrZ(0.03, 4.0));
    last
}

fn stat(out: &flowlight_host::render::RenderOutcome, name: &str) -> f64 {
    out.stats
        .integrator
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| *v)
        .unwrap_or_else(|| panic!("no statistic '{name}'"))
}

#[test]
fn erpt_with_bdpt_seeds_is_unbiased_on_the_cornell_box() {
    let reference = common::mcpt_reference("cornell-box/erpt.toml", 512);
    let mix = mutations(&[
        ("blow", &[("weight", 0.5.into())]),
        ("drill", &[("weight", 0.3.into())]),
        ("hard-reconnection", &[("weight", 0.2.into())]),
    ]);
    // K = 2: a flange of 4 pixels around 16-pixel tiles, so that many light-tracing seeds
    // start outside their unit's flanged tile, and their chains still run.
    let out = check_unbiased(
        "cornell-box/erpt.toml",
        "cornell box, bdpt seeds",
        &[("mutations", mix), ("film_window", toml::Value::Integer(2))],
        &reference,
    );
    let (outside, seeds) = (stat(&out, "seeds_outside_flange"), stat(&out, "seeds"));
    assert!(
        outside > 0.02 * seeds,
        "{outside} of {seeds} seeds outside the flange"
    );
}

#[test]
fn erpt_with_bdpt_seeds_is_unbiased_on_the_glass_caustic() {
    let reference = common::mcpt_reference("glass-caustic/erpt.toml", 1024);
    let mix = mutations(&[
        ("multichain-perturbation", &[("weight", 0.5.into())]),
        ("caustic-perturbation", &[("weight", 0.2.into())]),
        ("blow", &[("weight", 0.3.into())]),
    ]);
    check_unbiased(
        "glass-caustic/erpt.toml",
        "glass caustic, bdpt seeds",
        &[("mutations", mix), ("path_depth", toml::Value::Integer(10))],
        &reference,
    );
}

/// Every mutation plugin, alone, takes BDPT seeds on the glass caustic (light-tracing seeds,
/// light-side chains through the sphere): the render finishes with a finite image, no invalid
/// deposit and no skipped seed, and every chain runs its N steps, each counted as a domain hit
/// or a domain miss (a proposal a strategy cannot make).
#[test]
fn every_mutation_plugin_takes_bdpt_seeds() {
    for plugin in [
        "blow",
        "drill",
        "hard-reconnection",
        "soft-reconnection",
        "lens-perturbation",
        "caustic-perturbation",
        "multichain-perturbation",
        "bxdf-extension",
    ] {
        let params = [
            ("seeds", s("bdpt")),
            ("mutations", mutations(&[(plugin, &[])])),
            ("mutations_per_sample", 4.0.into()),
            ("chain_length", toml::Value::Integer(8)),
            ("direct", s("erpt")),
            ("chains_for", s("all")),
            ("quantum", s("tile")),
        ];
        let label = format!("glass caustic, bdpt seeds, {plugin}");
        let (images, out) = independent_runs(&label, 1, 5, &|| {
            renderer_at("glass-caustic/erpt.toml", 24, 24, 1, &params)
        });
        let mean = images[0].iter().map(|c| c.luminance() as f64).sum::<f64>();
        assert!(mean > 0.0, "{label}: a black image");
        // Every chain ran its N = 8 steps, each counted as a domain hit or miss.
        let (steps, chains) = (stat(&out, "total.mutations"), stat(&out, "chains"));
        let hits = stat(&out, "total.domain_hit") + stat(&out, "total.domain_miss");
        assert!(
            chains > 10.0 && steps == 8.0 * chains && hits == steps,
            "{label}: {chains} chains, {steps} steps, {hits} hits and misses"
        );
        assert_eq!(stat(&out, "seeds_skipped_invalid"), 0.0, "{label}");
    }
}

const SHORT_WALL: [[f32; 3]; 4] = [
    [-10.0, 0.0, -1.0],
    [10.0, 0.0, -1.0],
    [10.0, 1.0, -1.0],
    [-10.0, 1.0, -1.0],
];

/// A dark Lambert base under a Dirac dielectric coat of index 4 (36 % reflected at normal
/// incidence): the sun mirrored by the floor carries a good share of the wall's light.
const VARNISH: &str = r#"{"name": "varnish", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.2, 0.2, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.0}, "extensions": {"KHR_materials_ior": {"ior": 4.0}}}"#;

/// A varnished floor and wall under a sun (in front of the wall, so that the floor mirrors it
/// onto the wall), with a constant sky where `sky`, at 32², rendered by `integrator`
/// (lines of its `[integrator]` table) with `spp` samples per pixel.
fn varnished_sun(
    name: &str,
    integrator: &str,
    spp: u32,
    sky: bool,
) -> flowlight_host::renderer::Renderer {
    let sky = if sky {
        "[environment]\ncolor = [0.6, 0.8, 1.0]\nstrength = 1.5\n"
    } else {
        ""
    };
    let gltf = common::quads_gltf(
        &[common::FLOOR, SHORT_WALL],
        VARNISH,
        &[common::sun_node(-40.0)],
        r#"[{"type": "directional", "intensity": 2000.0, "color": [1.0, 0.8, 0.6]}]"#,
    );
    let body = format!(
        r#"[render]
width = 32
height = 32
seed = 5
intersector = "bvh"
[camera]
position = [0.0, 2.0, 3.0]
look_at = [0.0, 0.5, -1.0]
fov_y = 60.0
{sky}[integrator]
path_depth = 3
{integrator}
"#
    );
    common::renderer_from(name, &gltf, &body, spp)
}

/// The sun reflected by the varnish onto the wall (L S D … E: a directional light after a Dirac
/// vertex) is light BDPT finds and the chains' target function cannot hold: those seeds go to
/// their pixel (`seeds_outside_target`), and the image still agrees with BDPT's.
#[test]
fn bdpt_seeds_the_target_cannot_hold_go_to_their_pixel() {
    let mut reference = varnished_sun("bdpt-seeds-ref", "plugin = \"bdpt\"", 256, false);
    reference.options.seed = 77;
    let reference = common::render(&reference).frame.image();
    let erpt = r#"plugin = "erpt"
seeds = "bdpt"
mutations_per_sample = 16.0
chain_length = 16
film_window = 8
[[integrator.mutations]]
plugin = "blow"
weight = 0.6
[[integrator.mutations]]
plugin = "hard-reconnection"
weight = 0.4"#;
    let label = "varnished floor under a sun, bdpt seeds";
    let (images, out) = independent_runs(label, 6, 4000, &|| {
        varnished_sun("bdpt-seeds-erpt", erpt, 4, false)
    });
    assert!(
        stat(&out, "seeds_outside_target") > 0.0,
        "{label}: no seed outside the target"
    );
    assert_regions_unbiased(label, &images, &reference);
    assert_image_mean(label, &images, &reference, MeanRule::WithinOrZ(0.03, 4.0));
}
