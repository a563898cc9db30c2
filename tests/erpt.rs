//! ERPT and its mutation plugins: detailed balance of every strategy, unbiasedness against a
//! path-traced reference (each strategy alone and a mixture), the colour test that caught
//! Batty's bug, and strategy swapping by config.

mod common;

use common::{mean_and_stderr, render, session_at};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_pathtrace::{untangled, PathSettings, Variant};
use flowlight_sdk::{Scene, Tracer};

fn table(pairs: &[(&str, toml::Value)]) -> toml::Value {
    toml::Value::Table(
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect(),
    )
}

/// `[[integrator.mutations]]` with one entry per (plugin, extra params).
fn mutations(entries: &[(&str, &[(&str, toml::Value)])]) -> toml::Value {
    toml::Value::Array(
        entries
            .iter()
            .map(|(plugin, extra)| {
                let mut pairs = vec![("plugin", toml::Value::String(plugin.to_string()))];
                pairs.extend(extra.iter().cloned());
                table(&pairs)
            })
            .collect(),
    )
}

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
    let s = session_at(
        "cornell-box/erpt.toml",
        48,
        48,
        1,
        &[("mutations", mutations(&list))],
    );
    let set = s.instance.mutation_set();
    assert_eq!(set.len(), all.len());
    // SAFETY: the session keeps the view's data alive.
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
            let p = set.propose(i, &tracer, &mut rng, &x, &mut y).unwrap();
            if p.valid == 0 {
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
            let got = p.transition_ratio as f64;
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

/// Region means of `img` (8×8 blocks of a 32×32 image).
fn regions(img: &[Rgb]) -> Vec<f64> {
    let mut out = vec![0.0; 16];
    for (i, c) in img.iter().enumerate() {
        let (x, y) = (i % 32, i / 32);
        out[(y / 8) * 4 + x / 8] += c.luminance() as f64 / 64.0;
    }
    out
}

/// ERPT with `mutation_list` agrees with a path-traced reference per region (z-test over
/// independent runs) and in the image mean.
fn check_unbiased(config: &str, label: &str, mutation_list: toml::Value, reference: &[Rgb]) {
    let runs = 6;
    let mut per_run: Vec<Vec<f64>> = Vec::new();
    let mut means = Vec::new();
    for r in 0..runs {
        let mut s = session_at(
            config,
            32,
            32,
            4,
            &[
                ("mutations", mutation_list.clone()),
                ("mutations_per_sample", 32.0.into()),
                ("chain_length", toml::Value::Integer(32)),
                ("film_window", toml::Value::Integer(8)),
            ],
        );
        s.options.seed = 1000 + r;
        s.options.tile_size = 16;
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0, "{label}: invalid deposits");
        let img = out.frame.image();
        assert!(
            img.iter().all(|c| c.is_valid_radiance()),
            "{label}: NaN/Inf in the image"
        );
        means.push(img.iter().map(|c| c.luminance() as f64).sum::<f64>() / img.len() as f64);
        per_run.push(regions(&img));
    }
    let refs = regions(reference);
    // Reference noise per region from its pixel variance.
    let ref_se: Vec<f64> = (0..16)
        .map(|k| {
            let px: Vec<Rgb> = reference
                .iter()
                .enumerate()
                .filter(|(i, _)| ((i / 32) / 8) * 4 + (i % 32) / 8 == k)
                .map(|(_, c)| *c)
                .collect();
            mean_and_stderr(&px, |c| c.luminance()).1
        })
        .collect();
    for k in 0..16 {
        let vals: Vec<f64> = per_run.iter().map(|r| r[k]).collect();
        let m = vals.iter().sum::<f64>() / runs as f64;
        let var = vals.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (runs as f64 - 1.0);
        let se = (var / runs as f64 + ref_se[k].powi(2))
            .sqrt()
            .max(1e-4 * refs[k].abs());
        let z = (m - refs[k]) / se;
        assert!(
            z.abs() < 5.0,
            "{label}: region {k}: ERPT {m:.5} vs reference {:.5} (z = {z:.2})",
            refs[k]
        );
    }
    let ref_mean =
        reference.iter().map(|c| c.luminance() as f64).sum::<f64>() / reference.len() as f64;
    let m = means.iter().sum::<f64>() / runs as f64;
    assert!(
        (m / ref_mean - 1.0).abs() < 0.03,
        "{label}: image mean {m:.5} vs reference {ref_mean:.5}"
    );
}

fn reference(config: &str, spp: u32) -> Vec<Rgb> {
    let mut s = session_at(config, 32, 32, spp, &[]);
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

/// Chromaticity (r, b over r + g + b) of an image's mean.
fn chromaticity(img: &[Rgb]) -> (f64, f64) {
    let sum = img.iter().fold([0.0f64; 3], |a, c| {
        [a[0] + c.r as f64, a[1] + c.g as f64, a[2] + c.b as f64]
    });
    let t = sum[0] + sum[1] + sum[2];
    (sum[0] / t, sum[2] / t)
}

#[test]
fn erpt_does_not_shift_hue_between_red_and_blue_walls() {
    let config = "cornell-box/red-blue.toml";
    let mcpt = {
        let mut cfg = flowlight_scene::config::load_config(&common::scene_config(config)).unwrap();
        cfg.integrator_plugin = "mcpt".into();
        cfg.integrator_params.clear();
        let ov = flowlight_host::session::Overrides {
            spp: Some(512),
            threads: Some(2),
            ..Default::default()
        };
        render(&flowlight_host::session::Session::from_config(cfg, &ov).unwrap())
            .frame
            .image()
    };
    let erpt = render(&session_at(config, 64, 64, 8, &[])).frame.image();
    // Left and right thirds: the red and the blue wall with the light they bleed. With the
    // seed's colour in every deposit the blue side's b share drops by ~0.025.
    for (name, range) in [("red side", 0..21usize), ("blue side", 43..64usize)] {
        let pick = |img: &[Rgb]| -> Vec<Rgb> {
            img.iter()
                .enumerate()
                .filter(|(i, _)| range.contains(&(i % 64)))
                .map(|(_, c)| *c)
                .collect()
        };
        let (a, b) = (chromaticity(&pick(&mcpt)), chromaticity(&pick(&erpt)));
        assert!(
            (a.0 - b.0).abs() < 0.008 && (a.1 - b.1).abs() < 0.008,
            "{name}: MCPT chromaticity (r {:.4}, b {:.4}) vs ERPT (r {:.4}, b {:.4})",
            a.0,
            a.1,
            b.0,
            b.1
        );
    }
}

#[test]
fn swapping_strategies_in_the_config_changes_the_loaded_plugins() {
    let names = |list: toml::Value| -> Vec<String> {
        let s = session_at("cornell-box/erpt.toml", 8, 8, 1, &[("mutations", list)]);
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
    let err = flowlight_host::session::Session::prepare(
        &common::scene_config("cornell-box/erpt.toml"),
        &flowlight_host::session::Overrides {
            params: common::toml_params(&[(
                "mutations",
                mutations(&[("drill", &[("width", "medium".into())])]),
            )]),
            ..Default::default()
        },
    )
    .err()
    .expect("bad strategy parameter accepted");
    assert!(err.contains("drill") && err.contains("width"), "{err}");
    let err = flowlight_host::session::Session::prepare(
        &common::scene_config("cornell-box/erpt.toml"),
        &flowlight_host::session::Overrides {
            params: common::toml_params(&[("mutations", mutations(&[("no-such-mutation", &[])]))]),
            ..Default::default()
        },
    )
    .err()
    .expect("missing strategy accepted");
    assert!(err.contains("no-such-mutation"), "{err}");
}

/// A 64×64 ERPT Cornell box in 8×8 tiles (64 units a pass), one sample per pixel, with
/// short chains (8 mutations per sample, chains of 8) to keep it quick.
fn small_erpt(seed: u64) -> flowlight_host::session::Session {
    let mut cfg =
        flowlight_scene::config::load_config(&common::scene_config("cornell-box/erpt.toml"))
            .unwrap();
    cfg.width = 64;
    cfg.height = 64;
    cfg.tile_size = 8;
    let ov = flowlight_host::session::Overrides {
        spp: Some(1),
        threads: Some(2),
        seed: Some(seed),
        params: common::toml_params(&[
            ("mutations_per_sample", 8.into()),
            ("chain_length", 8.into()),
        ]),
        ..Default::default()
    };
    let mut s = flowlight_host::session::Session::from_config(cfg, &ov).unwrap();
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
    let tiles = 64u64;
    let cut = st.partial_pass.map_or(0, |p| {
        assert_eq!(p.tiles as u64, tiles);
        assert!(p.finished < p.tiles);
        p.finished as u64
    });
    // Every started unit finished and belongs to a whole pass or the cut one.
    assert_eq!(st.units, st.full_passes as u64 * tiles + cut);
    assert_eq!(st.pixel_samples, st.full_passes as u64 * 64 * 64 + cut * 64);
    s.write_outputs(&out.frame, st).unwrap();
    let meta = flowlight_host::output::read_exr_metadata(&exr).unwrap();
    let get = |k: &str| {
        meta.entries
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.clone())
            .unwrap()
    };
    let fraction: f64 = get("flowlight.partial_pass").parse().unwrap();
    assert_eq!(fraction, cut as f64 / tiles as f64);
    assert_eq!(get("flowlight.biased"), "false");
    assert_eq!(get("flowlight.interrupted"), "false");
}
