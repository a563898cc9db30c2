//! ERPT and its mutation plugins: detailed balance of every strategy, unbiasedness against a
//! path-traced reference (each strategy alone and a mixture), the colour test that caught
//! Batty's bug, and strategy swapping by config.

use crate::common;

use common::{
    assert_image_mean, assert_regions_unbiased, assert_same_wall_hues, independent_runs, mutations,
    render, renderer_at, sun_node, MeanRule, FLOOR, LAMBERT,
};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_pathtrace::{untangled, PathSettings, Variant};
use flowlight_sdk::{Scene, Stats, Tracer};

/// Every strategy, as the tests use them.
fn strategies() -> Vec<(&'static str, Vec<(&'static str, toml::Value)>)> {
    vec![
        ("hard-reconnection", vec![]),
        ("soft-reconnection", vec![("cap_degrees", 8.0.into())]),
        ("bxdf-extension", vec![]),
        ("blow", vec![("width", "wide".into())]),
        ("blow", vec![("width", "narrow".into())]),
        ("drill", vec![("width", "narrow".into())]),
        ("drill", vec![("width", "wide".into())]),
    ]
}

#[test]
fn every_strategy_satisfies_detailed_balance() {
    let all = strategies();
    let list: Vec<(&str, &[(&str, toml::Value)])> =
        all.iter().map(|(p, e)| (*p, e.as_slice())).collect();
    let s = renderer_at(
        "cornell-box/erpt.toml",
        48,
        48,
        1,
        &[("mutations", mutations(&list))],
    );
    let set = s.instance.mutation_set();
    assert_eq!(set.len(), all.len());
    // SAFETY: the renderer keeps the view's data alive.
    let scene = unsafe { Scene::from_view(s.instance.view()) };
    let mut unit_tracer = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let mut settings = PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[])).unwrap();
    settings.variant = Variant::Untangled;
    settings.max_ray_depth = 32;

    let mut rng = Rng::new(11, 3);
    let mut x = Box::new(Path::empty());
    let mut y = Box::new(Path::empty());
    let mut checked = vec![0usize; set.len()];
    for _ in 0..4000 {
        let raster = glam::Vec2::new(rng.uniform() * 48.0, rng.uniform() * 48.0);
        let sample = untangled::trace(&scene, &tracer, &settings, &mut rng, raster, Some(&mut x));
        if sample.value.is_black() || x.vertex_count < 3 {
            continue;
        }
        x.film_window = 8;
        for (i, count) in checked.iter_mut().enumerate() {
            let p = set
                .propose(i, &tracer, &mut rng, &x, &mut y, &mut Stats::new(&mut []))
                .unwrap();
            // A degenerate density (a NaN ratio) is a rejection (`finish` in the engine): a
            // direction drawn in a cap whose rounded end point lies just outside it (one seed
            // drew 1.99999° in a 2° cap) has T = 0 both ways.
            if !p.is_move() || p.transition_ratio().unwrap().is_nan() {
                continue;
            }
            let forward = set.density(i, &x, &y).unwrap();
            let reverse = set.density(i, &y, &x).unwrap();
            assert!(
                forward > 0.0,
                "{}: proposed a path its density says it cannot reach",
                set.name(i)
            );
            assert_eq!(y.vertex_count, x.vertex_count, "path length changed");
            let expected = reverse / forward;
            let got = p.transition_ratio().unwrap() as f64;
            assert!(
                (got - expected).abs() <= 2e-3 * expected.max(got) + 1e-30,
                "{}: ratio {got} but T(y→x)/T(x→y) = {reverse}/{forward} = {expected} ({} → {})",
                set.name(i),
                x.heckbert(),
                y.heckbert()
            );
            *count += 1;
        }
    }
    for (i, c) in checked.iter().enumerate() {
        assert!(
            *c > 100,
            "strategy {} made only {c} valid proposals",
            set.name(i)
        );
    }
}

/// ERPT with `mutation_list` agrees with a path-traced reference per region (z-test over
/// independent runs) and in the image mean.
fn check_unbiased(config: &str, label: &str, mutation_list: toml::Value, reference: &[Rgb]) {
    check_unbiased_window(config, label, mutation_list, reference, 8)
}

/// [`check_unbiased`] with film window `film_window`: a window as wide as the image lets the
/// chains carry energy across regions, so that a wrong target function or transition ratio
/// shows in the region means, not only inside them.
fn check_unbiased_window(
    config: &str,
    label: &str,
    mutation_list: toml::Value,
    reference: &[Rgb],
    film_window: i64,
) {
    // Wider windows spread each run's noise over the image: more runs keep the test sharp.
    let runs = if film_window > 8 { 10 } else { 6 };
    let make = || {
        renderer_at(
            config,
            32,
            32,
            4,
            &[
                ("mutations", mutation_list.clone()),
                ("mutations_per_sample", 32.0.into()),
                ("chain_length", toml::Value::Integer(32)),
                ("film_window", toml::Value::Integer(film_window)),
            ],
        )
    };
    let (images, _) = independent_runs(label, runs, 1000, &make);
    assert_regions_unbiased(label, &images, reference);
    assert_image_mean(label, &images, reference, MeanRule::Within(0.03));
}

fn reference(config: &str, spp: u32) -> Vec<Rgb> {
    let mut s = renderer_at(config, 32, 32, spp, &[]);
    s.options.seed = 77;
    render(&s).frame.image()
}

#[test]
fn erpt_is_unbiased_on_the_cornell_box_for_each_strategy_and_a_mixture() {
    let reference = reference("cornell-box/cornell-box.toml", 2048);
    for (plugin, extra) in strategies() {
        let label = format!("{plugin} {extra:?}");
        check_unbiased(
            "cornell-box/erpt.toml",
            &label,
            mutations(&[(plugin, &extra)]),
            &reference,
        );
    }
    let mix = mutations(&[
        ("blow", &[("weight", 0.5.into())]),
        ("drill", &[("weight", 0.3.into())]),
        ("hard-reconnection", &[("weight", 0.2.into())]),
    ]);
    check_unbiased("cornell-box/erpt.toml", "mixture", mix, &reference);
}

#[test]
fn erpt_is_unbiased_in_the_white_furnace() {
    // Every pixel of the furnace is 2·(1 − 0.5^(N+1)) with N = 8.
    let exact = vec![Rgb::splat((2.0 * (1.0 - 0.5f64.powi(9))) as f32); 32 * 32];
    let mix = mutations(&[("blow", &[]), ("drill", &[("width", "wide".into())])]);
    check_unbiased("furnace/erpt.toml", "furnace mixture", mix, &exact);
    check_unbiased(
        "furnace/erpt.toml",
        "furnace hard",
        mutations(&[("hard-reconnection", &[])]),
        &exact,
    );
}

#[test]
fn erpt_does_not_shift_hue_between_red_and_blue_walls() {
    let config = "cornell-box/red-blue.toml";
    let mcpt = {
        let mut cfg = flowlight_scene::config::load_config(&common::scene_config(config)).unwrap();
        cfg.integrator_plugin = "mcpt".into();
        cfg.integrator_params.clear();
        let ov = flowlight_host::renderer::Overrides {
            spp: Some(512),
            threads: Some(2),
            ..Default::default()
        };
        render(&flowlight_host::renderer::Renderer::from_config(cfg, &ov).unwrap())
            .frame
            .image()
    };
    let erpt = render(&renderer_at(config, 64, 64, 8, &[])).frame.image();
    assert_same_wall_hues(&mcpt, &erpt);
}

#[test]
fn swapping_strategies_in_the_config_changes_the_loaded_plugins() {
    let names = |list: toml::Value| -> Vec<String> {
        let s = renderer_at("cornell-box/erpt.toml", 8, 8, 1, &[("mutations", list)]);
        s.instance
            .mutations()
            .iter()
            .map(|m| m.plugin().name.clone())
            .collect()
    };
    assert_eq!(names(mutations(&[("drill", &[])])), ["drill"]);
    assert_eq!(
        names(mutations(&[("blow", &[]), ("hard-reconnection", &[])])),
        ["blow", "hard-reconnection"]
    );
    // A strategy's own parameters are checked by its plugin.
    let err = flowlight_host::renderer::Renderer::prepare(
        &common::scene_config("cornell-box/erpt.toml"),
        &flowlight_host::renderer::Overrides {
            params: common::toml_params(&[(
                "mutations",
                mutations(&[("drill", &[("width", "medium".into())])]),
            )]),
            ..Default::default()
        },
    )
    .err()
    .expect("bad strategy parameter accepted");
    let err = common::plugin_refusal(&err, "drill");
    assert!(err.contains("width"), "{err}");
    let err = flowlight_host::renderer::Renderer::prepare(
        &common::scene_config("cornell-box/erpt.toml"),
        &flowlight_host::renderer::Overrides {
            params: common::toml_params(&[("mutations", mutations(&[("no-such-mutation", &[])]))]),
            ..Default::default()
        },
    )
    .err()
    .expect("missing strategy accepted");
    let flowlight_host::error::HostError::Plugin {
        field: Some(field),
        error,
        ..
    } = &err
    else {
        panic!("not a plugin's error: {err:?}")
    };
    let flowlight_host::PluginError::NotFound { name, .. } = error.as_ref() else {
        panic!("not a missing mutation plugin: {err:?}")
    };
    assert_eq!(
        (field.as_str(), name.as_str()),
        ("integrator.mutations", "no-such-mutation")
    );
}

// ---------------------------------------------------------------------------------------------
// Lights at infinity: a directional light (a fixed direction) and the environment (a direction
// the mutations perturb). Synthetic scenes: a Lambert floor (albedo ½) and a short wall.

/// A wall one unit high at z = −1 facing +Z: it shadows the floor in front of it from a sun
/// behind it, hides part of the sky from the floor and bounces light onto it.
const SHORT_WALL: [[f32; 3]; 4] = [
    [-10.0, 0.0, -1.0],
    [10.0, 0.0, -1.0],
    [10.0, 1.0, -1.0],
    [-10.0, 1.0, -1.0],
];

/// The Lambert base under a Dirac dielectric coat (roughness 0, ior 1.5): every vertex has a
/// Dirac reflection and a smooth component, so paths mix them (E S L, E D S L, E S D L).
const VARNISH: &str = r#"{"name": "varnish", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.0}}"#;

/// Writes the floor-and-wall scene lit by a sun (or none) and `tail` (e.g. an
/// `[environment]`) with `integrator` into a scratch folder; returns the config's path.
fn distant_scene(name: &str, sun: bool, integrator: &str, tail: &str) -> common::InTempDir<String> {
    distant_scene_of(name, LAMBERT, sun, integrator, tail)
}

/// [`distant_scene`] with the floor and wall of `material`.
fn distant_scene_of(
    name: &str,
    material: &str,
    sun: bool,
    integrator: &str,
    tail: &str,
) -> common::InTempDir<String> {
    let gltf = if sun {
        common::quads_gltf(
            &[FLOOR, SHORT_WALL],
            material,
            &[sun_node(40.0)],
            r#"[{"type": "directional", "intensity": 2000.0, "color": [1.0, 0.8, 0.6]}]"#,
        )
    } else {
        common::quads_gltf(&[FLOOR, SHORT_WALL], material, &[], "")
    };
    let dir = common::scratch(name);
    std::fs::write(dir.join("scene.gltf"), gltf).unwrap();
    let cfg = dir.join("scene.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"scene = "scene.gltf"
[render]
width = 32
height = 32
seed = 5
intersector = "bvh"
[camera]
position = [0.0, 2.0, 3.0]
look_at = [0.0, 0.5, -1.0]
fov_y = 60.0
[integrator]
{integrator}
path_depth = 3
{tail}"#
        ),
    )
    .unwrap();
    let value = cfg.display().to_string();
    common::InTempDir { dir, value }
}

const SKY: &str = "[environment]\ncolor = [0.6, 0.8, 1.0]\nstrength = 1.5\n";

#[test]
fn mutations_keep_detailed_balance_with_lights_at_infinity() {
    let all = strategies();
    let list: Vec<(&str, &[(&str, toml::Value)])> =
        all.iter().map(|(p, e)| (*p, e.as_slice())).collect();
    for (label, material, sun, tail) in [
        ("sun", LAMBERT, true, ""),
        ("sky", LAMBERT, false, SKY),
        ("varnished sun", VARNISH, true, ""),
        ("varnished sky", VARNISH, false, SKY),
    ] {
        let cfg = distant_scene_of(
            &format!("balance-{label}"),
            material,
            sun,
            "plugin = \"erpt\"",
            tail,
        );
        let s = renderer_at(&cfg, 32, 32, 1, &[("mutations", mutations(&list))]);
        let set = s.instance.mutation_set();
        // SAFETY: the renderer keeps the view's data alive.
        let scene = unsafe { Scene::from_view(s.instance.view()) };
        let mut unit_tracer = UnitTracer::new(&s.scene, s.intersector.as_ref());
        let table = unit_tracer.table();
        let tracer = Tracer::new(&table);
        let mut settings =
            PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[])).unwrap();
        settings.variant = Variant::Untangled;
        settings.path_depth = 3;
        let mut rng = Rng::new(17, 2);
        let mut x = Box::new(Path::empty());
        let mut y = Box::new(Path::empty());
        let (mut valid, mut moved) = (vec![0usize; set.len()], vec![0usize; set.len()]);
        let (mut seen_sky, mut seen_dirac) = (0, 0);
        // The coat reflects a few per cent: more seeds to meet enough Dirac vertices.
        let seeds = if material == VARNISH { 5000 } else { 1500 };
        for _ in 0..seeds {
            let raster = glam::Vec2::new(rng.uniform() * 32.0, rng.uniform() * 32.0);
            let sample =
                untangled::trace(&scene, &tracer, &settings, &mut rng, raster, Some(&mut x));
            if sample.value.is_black() {
                continue;
            }
            let n = x.vertex_count as usize - 1;
            let light = x.vertices[n];
            assert!(
                flowlight_mcmc::measure::is_distant(&scene, &light),
                "{label}: a seed ended on {light:?}"
            );
            // The target function sees what the seed sampler found.
            assert!(
                !flowlight_mcmc::measurement(&scene, &x).is_black(),
                "{label}: f = 0 for a seed {}",
                x.heckbert()
            );
            seen_sky += usize::from(n == 1);
            seen_dirac += usize::from(x.heckbert().contains('S'));
            let smooth_before_light = x.vertices[n - 1].node.heckbert() == 'D';
            x.film_window = 8;
            for i in 0..set.len() {
                let p = set
                    .propose(i, &tracer, &mut rng, &x, &mut y, &mut Stats::new(&mut []))
                    .unwrap();
                if !p.is_move() {
                    continue;
                }
                let ly = y.vertices[n];
                if sun {
                    assert_eq!(ly.ng, light.ng, "{} moved the sun's direction", set.name(i));
                } else if smooth_before_light && ly.ng != light.ng {
                    // (After the eye or a Dirac vertex, the film move alone turns ω.)
                    moved[i] += 1;
                }
                let forward = set.density(i, &x, &y).unwrap();
                let reverse = set.density(i, &y, &x).unwrap();
                assert!(
                    forward > 0.0,
                    "{label} {}: unreachable proposal",
                    set.name(i)
                );
                let expected = reverse / forward;
                let got = p.transition_ratio().unwrap() as f64;
                assert!(
                    (got - expected).abs() <= 2e-3 * expected.max(got) + 1e-30,
                    "{label} {}: ratio {got} vs T(y→x)/T(x→y) {expected} ({} → {})",
                    set.name(i),
                    x.heckbert(),
                    y.heckbert()
                );
                valid[i] += 1;
            }
        }
        for (i, v) in valid.iter().enumerate() {
            assert!(
                *v > 100,
                "{label}: {} made {v} valid proposals",
                set.name(i)
            );
        }
        if material == VARNISH {
            assert!(
                seen_dirac > 30,
                "{label}: {seen_dirac} seeds with a Dirac vertex"
            );
        }
        if !sun {
            // The camera sees the sky (E L paths), and every extending strategy perturbs the
            // sky direction (hard reconnection keeps it).
            assert!(seen_sky > 50, "{seen_sky} seeds saw the sky");
            assert_eq!(moved[0], 0, "hard reconnection moved the sky direction");
            for (i, m) in moved.iter().enumerate().skip(1) {
                assert!(
                    *m > 20,
                    "{} perturbed the sky direction {m} times",
                    set.name(i)
                );
            }
        }
    }
}

#[test]
fn erpt_agrees_with_mcpt_under_a_directional_light() {
    let mcpt = distant_scene(
        "sun-mcpt",
        true,
        "plugin = \"mcpt\"\nvariant = \"entangled\"",
        "",
    );
    let reference = reference(&mcpt, 1024);
    let cfg = distant_scene("sun-erpt", true, "plugin = \"erpt\"", "");
    for (plugin, extra) in [
        ("hard-reconnection", vec![]),
        ("blow", vec![("width", "wide".into())]),
    ] {
        let label = format!("sun: {plugin} {extra:?}");
        check_unbiased_window(&cfg, &label, mutations(&[(plugin, &extra)]), &reference, 32);
    }
}

#[test]
fn erpt_agrees_with_mcpt_under_a_constant_environment() {
    let mcpt = distant_scene(
        "sky-mcpt",
        false,
        "plugin = \"mcpt\"\nvariant = \"entangled\"",
        SKY,
    );
    let reference = reference(&mcpt, 1024);
    let cfg = distant_scene("sky-erpt", false, "plugin = \"erpt\"", SKY);
    for (plugin, extra) in [
        ("bxdf-extension", vec![]),
        ("drill", vec![("width", "narrow".into())]),
    ] {
        let label = format!("sky: {plugin} {extra:?}");
        check_unbiased_window(&cfg, &label, mutations(&[(plugin, &extra)]), &reference, 32);
    }
}

#[test]
fn erpt_under_a_constant_sky_gives_albedo_times_sky_on_an_open_plane() {
    // An unoccluded Lambert plane under a constant sky of radiance L has irradiance E = πL and
    // radiance ρ·E/π = ρL at every point; the camera looks straight down and sees only the
    // plane, so every pixel is ρL.
    let gltf = common::quads_gltf(&[FLOOR], LAMBERT, &[], "");
    let dir = common::scratch("sky-plane");
    std::fs::write(dir.join("scene.gltf"), gltf).unwrap();
    let cfg = dir.join("scene.toml");
    std::fs::write(
        &cfg,
        format!(
            "scene = \"scene.gltf\"\n[render]\nseed = 9\nintersector = \"bvh\"\n[camera]\n\
             position = [0.3, 4.0, 0.2]\nlook_at = [0.3, 0.0, 0.2]\nup = [0.0, 0.0, -1.0]\n\
             fov_y = 50.0\n[integrator]\nplugin = \"erpt\"\npath_depth = 2\n\
             {SKY}"
        ),
    )
    .unwrap();
    let mix = mutations(&[
        ("hard-reconnection", &[]),
        ("blow", &[("width", "narrow".into())]),
        ("soft-reconnection", &[]),
    ]);
    // ρ·L per channel: 0.5 · 1.5 · (0.6, 0.8, 1.0).
    let exact = vec![Rgb::new(0.45, 0.6, 0.75); 32 * 32];
    check_unbiased(
        cfg.to_str().unwrap(),
        "open plane under the sky",
        mix,
        &exact,
    );
}

#[test]
fn erpt_agrees_with_mcpt_on_a_varnished_floor_under_sun_and_sky() {
    // Both lights at infinity at once, and Dirac coat reflections of the sky and of the lit
    // floor (E S L, E S D L, E D S L): a mixture of strategies.
    let mcpt = distant_scene_of(
        "both-mcpt",
        VARNISH,
        true,
        "plugin = \"mcpt\"\nvariant = \"entangled\"",
        SKY,
    );
    let reference = reference(&mcpt, 1024);
    let cfg = distant_scene_of("both-erpt", VARNISH, true, "plugin = \"erpt\"", SKY);
    let mix = mutations(&[
        ("blow", &[("weight", 0.4.into())]),
        ("drill", &[("width", "wide".into()), ("weight", 0.3.into())]),
        ("hard-reconnection", &[("weight", 0.3.into())]),
    ]);
    check_unbiased_window(&cfg, "varnish under sun and sky", mix, &reference, 32);
}

/// A 64×64 ERPT Cornell box in 8×8 tiles (64 units a pass), one sample per pixel, with
/// short chains (8 mutations per sample, chains of 8) to keep it quick.
fn small_erpt(seed: u64) -> flowlight_host::renderer::Renderer {
    let mut cfg =
        flowlight_scene::config::load_config(&common::scene_config("cornell-box/erpt.toml"))
            .unwrap();
    cfg.width = 64;
    cfg.height = 64;
    cfg.tile_size = 8;
    let ov = flowlight_host::renderer::Overrides {
        spp: Some(1),
        threads: Some(2),
        seed: Some(seed),
        params: common::toml_params(&[
            ("mutations_per_sample", 8.into()),
            ("chain_length", 8.into()),
        ]),
        ..Default::default()
    };
    let mut s = flowlight_host::renderer::Renderer::from_config(cfg, &ov).unwrap();
    s.exr_path = None;
    s.png_path = None;
    s
}

/// Mean luminance of rows 16..64 of a 64-pixel-wide image: the walls, floor and boxes
/// below the lamp, whose tiles differ far less in brightness than the lamp's (the
/// estimator is unbiased per pixel, so any fixed set of pixels may be compared).
fn mean_luminance_below_lamp(img: &[Rgb]) -> f64 {
    let rows = &img[16 * 64..];
    rows.iter().map(|c| c.luminance() as f64).sum::<f64>() / rows.len() as f64
}

/// A pass cut after m of its n tiles keeps a uniformly random subset of them and is
/// normalised by m/n of a pass (render.rs): over several seeds, the cut images' mean
/// brightness matches the full passes'. Normalised by each pixel's own samples instead
/// (unfinished tiles black, flange deposits of finished tiles into them lost) it would be
/// about m/n = 1/2 of it; a scan-order cut would be the top half of the box (lamp included).
/// The cut is made by the stop flag after 32 finished units, the same path a deadline takes.
#[test]
fn erpt_pass_cut_inside_the_first_pass_keeps_the_mean_brightness() {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    let seeds = 1..=12u64;
    let mut diffs = Vec::new();
    let mut full_means = Vec::new();
    for seed in seeds {
        let s = small_erpt(seed);
        let full = render(&s);
        assert!(full.stats.partial_pass.is_none());
        assert_eq!(full.stats.full_passes, 1);
        let stop = AtomicBool::new(false);
        let finished = AtomicUsize::new(0);
        let cut = s
            .render(&stop, &|_| {
                if finished.fetch_add(1, Ordering::SeqCst) + 1 >= 32 {
                    stop.store(true, Ordering::SeqCst);
                }
            })
            .unwrap();
        assert!(cut.error.is_none());
        let p = cut.stats.partial_pass.expect("the pass was cut");
        assert_eq!(cut.stats.full_passes, 0);
        assert_eq!(p.tiles, 64);
        // The units in flight when the flag is set (one per other thread) still finish.
        assert!((32..=33).contains(&p.finished), "{p:?}");
        assert_eq!(cut.stats.units, p.finished as u64);
        let (mf, mc) = (
            mean_luminance_below_lamp(&full.frame.image()),
            mean_luminance_below_lamp(&cut.frame.image()),
        );
        full_means.push(mf);
        diffs.push(mc - mf);
    }
    let n = diffs.len() as f64;
    let mean_full = full_means.iter().sum::<f64>() / n;
    let d = diffs.iter().sum::<f64>() / n;
    let sd = (diffs.iter().map(|x| (x - d).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    eprintln!(
        "full-pass mean {mean_full:.5}; cut minus full {d:+.5} ± {:.5} (sd {sd:.5})",
        sd / n.sqrt()
    );
    // The seeds are independent: the mean difference is within 4 standard errors of 0 (and,
    // as a sanity bound on that error, within 15 % of the mean).
    assert!(
        d.abs() < 4.0 * sd / n.sqrt() && d.abs() < 0.15 * mean_full,
        "cut passes average {d:+.5} (± {:.5}) away from the full passes' mean {mean_full:.5} (per-seed differences {diffs:?})",
        sd / n.sqrt()
    );
}

/// Under a time budget no work unit starts after the deadline (the stop rule, read from the
/// render's own report rather than a clock), the cut pass joins the image with its fraction,
/// and the EXR says so without calling the image biased.
#[test]
fn erpt_time_budget_starts_no_unit_after_the_deadline_and_marks_the_fraction() {
    let mut s = small_erpt(3);
    let budget = std::time::Duration::from_millis(300);
    s.options.time = Some(budget);
    let dir = common::scratch("erpt-time-budget");
    let exr = dir.join("t.exr");
    s.exr_path = Some(exr.clone());
    let out = render(&s);
    let st = &out.stats;
    let last = st.last_unit_start.expect("some unit started");
    assert!(
        last <= budget,
        "a unit started at {last:?}, after the {budget:?} budget"
    );
    assert!(!st.interrupted);
    // Under a time budget flanged units are FLANGED_TIME_TILE² pixels.
    let side = flowlight_host::render::FLANGED_TIME_TILE.min(8) as u64;
    let tiles = (64 / side) * (64 / side);
    let cut = st.partial_pass.map_or(0, |p| {
        assert_eq!(p.tiles as u64, tiles);
        assert!(p.finished < p.tiles);
        p.finished as u64
    });
    // Every started unit finished and belongs to a whole pass or the cut one.
    assert_eq!(st.units, st.full_passes as u64 * tiles + cut);
    assert_eq!(
        st.pixel_samples,
        st.full_passes as u64 * 64 * 64 + cut * side * side
    );
    s.write_outputs(out.frame, st).unwrap();
    let meta = flowlight_host::output::read_exr_metadata(&exr).unwrap();
    let get = |k: &str| meta.get(k).unwrap().to_string();
    let fraction: f64 = get("flowlight.partial_pass").parse().unwrap();
    assert_eq!(fraction, cut as f64 / tiles as f64);
    assert_eq!(get("flowlight.biased"), "false");
    assert_eq!(get("flowlight.interrupted"), "false");
}
