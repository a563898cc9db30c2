//! ERPT's `preset = "auto"` (plugins/erpt/src/auto.rs): without a mutation list the host
//! hands ERPT every installed strategy and ERPT's pilot picks the split, the chain budget and
//! the weights — no chains where the scene has no Dirac surface, chains for the caustic class
//! through the glass — writes its choices into the EXR metadata and the stats, and the image
//! stays unbiased with the pilot running first (its samples discarded, its time counted).

use crate::common;

use common::{
    assert_image_mean, assert_regions_unbiased, independent_runs, render, renderer_with, MeanRule,
};
use flowlight_core::Rgb;
use flowlight_host::render::RenderOutcome;

fn stat(out: &RenderOutcome, name: &str) -> f64 {
    out.stats
        .integrator
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| *v)
        .unwrap_or_else(|| panic!("no statistic '{name}'"))
}

/// The seeds' depths, the same for ERPT and the MCPT reference: the same path space.
fn depths() -> Vec<(&'static str, toml::Value)> {
    vec![
        ("path_depth", toml::Value::Integer(8)),
        ("max_ray_depth", toml::Value::Integer(32)),
    ]
}

/// `plugin = "erpt"` with only the depths: no mutation list, so `auto`.
fn auto_erpt(config: &str, size: u32, spp: u32) -> flowlight_host::renderer::Renderer {
    renderer_with(config, Some("erpt"), (size, size), spp, &depths())
}

#[test]
fn auto_picks_no_chains_on_a_scene_without_dirac_surfaces() {
    let s = auto_erpt("cornell-box/cornell-box.toml", 16, 2);
    // The host handed ERPT every installed strategy as candidates.
    assert_eq!(s.instance.mutations().len(), 8);
    let out = render(&s);
    assert_eq!(stat(&out, "auto.chains"), 0.0);
    assert!(stat(&out, "auto.pilot.indirect_relative_second_moment") < 20.0);
    assert_eq!(stat(&out, "chains"), 0.0);
    assert_eq!(stat(&out, "units_without_chains"), stat(&out, "units"));
    let meta: Vec<(String, String)> = s.instance.resolved_params();
    let get = |k: &str| meta.iter().find(|(n, _)| n == k).map(|(_, v)| v.as_str());
    assert_eq!(get("chains_for"), Some("\"caustics\""));
    assert_eq!(get("preset"), Some("\"manual\""), "{meta:?}");
}

#[test]
fn auto_picks_the_caustic_classes_through_the_glass() {
    let s = auto_erpt("glass-caustic/glass-caustic.toml", 32, 2);
    let out = render(&s);
    assert_eq!(stat(&out, "auto.chains"), 1.0);
    assert!(stat(&out, "auto.pilot.chained_seeds") >= 8.0);
    assert!(stat(&out, "chains") > 0.0, "no chain ran");
    // Direct light and the non-caustic classes are path traced.
    assert!(stat(&out, "mcpt_part_seeds") > 0.0);
    let meta = s.instance.resolved_params();
    let get = |k: &str| {
        meta.iter()
            .find(|(n, _)| n == k)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| panic!("no {k} in {meta:?}"))
    };
    assert_eq!(get("chains_for"), "\"caustics\"");
    assert_eq!(get("direct"), "\"mcpt\"");
    assert_eq!(get("seeds"), "\"entangled\"");
    // The weights: at least one strategy, each a positive probability, summing to 1.
    let list: toml::Table = format!("m = {}", get("mutations")).parse().unwrap();
    let list = list["m"].as_array().unwrap();
    assert!(!list.is_empty());
    let sum: f64 = list.iter().map(|e| e["weight"].as_float().unwrap()).sum();
    assert!((sum - 1.0).abs() < 1e-3, "{list:?}");
    let weights: f64 = (0..s.instance.mutations().len())
        .map(|i| {
            stat(
                &out,
                &format!("auto.weight.{}", s.instance.mutations()[i].plugin().name),
            )
        })
        .sum();
    assert!((weights - 1.0).abs() < 1e-9, "{weights}");
}

/// `auto` with its pilot is unbiased through the glass caustic: independent runs (each with
/// its own pilot, whose samples are discarded) against entangled MCPT, per 8×8 region and in
/// the image mean.
#[test]
fn auto_is_unbiased_through_the_glass_caustic_with_its_pilot() {
    let config = "glass-caustic/glass-caustic.toml";
    let mut params = depths();
    params.push(("variant", toml::Value::String("entangled".into())));
    let mut reference = renderer_with(config, Some("mcpt"), (32, 32), 4096, &params);
    reference.options.seed = 77;
    let reference: Vec<Rgb> = render(&reference).frame.image();
    let (images, last) = independent_runs("auto glass", 6, 3000, &|| auto_erpt(config, 32, 8));
    assert_eq!(stat(&last, "auto.chains"), 1.0);
    assert!(stat(&last, "chains") > 0.0);
    assert_regions_unbiased("auto glass", &images, &reference);
    assert_image_mean(
        "auto glass",
        &images,
        &reference,
        MeanRule::WithinOrZ(0.03, 4.0),
    );
}

/// Without caustic seeds but with indirect light that a few samples carry (the indirect room,
/// lit through a gap), `auto` chains every path above direct light, and stays unbiased.
#[test]
fn auto_chains_indirect_light_through_a_gap_and_stays_unbiased() {
    let config = "indirect-room/indirect-room.toml";
    let mut params = depths();
    params.push(("variant", toml::Value::String("entangled".into())));
    let mut reference = renderer_with(config, Some("mcpt"), (32, 32), 4096, &params);
    reference.options.seed = 78;
    let reference: Vec<Rgb> = render(&reference).frame.image();
    let (images, last) = independent_runs("auto room", 6, 4000, &|| auto_erpt(config, 32, 8));
    assert_eq!(stat(&last, "auto.chains"), 2.0);
    assert!(stat(&last, "auto.pilot.indirect_relative_second_moment") >= 20.0);
    assert!(stat(&last, "auto.pilot.noise_bound") >= 1.5);
    assert!(stat(&last, "chains") > 0.0);
    assert_regions_unbiased("auto room", &images, &reference);
    assert_image_mean(
        "auto room",
        &images,
        &reference,
        MeanRule::WithinOrZ(0.03, 4.0),
    );
}

/// veach-mis' indirect light is far from its mean (R ≥ 20, which alone would chain it) but a
/// small share of path tracing's noise beside the glossy highlights of its direct light:
/// Amdahl's bound G_max is under 1.5, and `auto` path-traces the scene.
#[test]
fn auto_path_traces_indirect_light_that_carries_little_of_the_noise() {
    let params = vec![
        ("path_depth", toml::Value::Integer(10)),
        ("max_ray_depth", toml::Value::Integer(32)),
    ];
    let s = renderer_with(
        "veach-mis/veach-mis.toml",
        Some("erpt"),
        (32, 32),
        1,
        &params,
    );
    let out = render(&s);
    assert!(stat(&out, "auto.pilot.indirect_relative_second_moment") >= 20.0);
    assert!(stat(&out, "auto.pilot.chained_seeds") >= 8.0);
    assert!(stat(&out, "auto.pilot.noise_bound") < 1.5);
    assert!(stat(&out, "auto.pilot.rest_variance") > stat(&out, "auto.pilot.class_variance"));
    assert_eq!(stat(&out, "auto.chains"), 0.0);
    assert_eq!(stat(&out, "chains"), 0.0);
    // The frozen config path-traces too: no split that chains indirect light (veach-mis has
    // no caustic path by its materials' letters, so `"caustics"` chains nothing).
    let meta = s.instance.resolved_params();
    let split = meta
        .iter()
        .find(|(n, _)| n == "chains_for")
        .map(|(_, v)| v.as_str());
    assert!(
        matches!(split, Some("\"caustics\"") | Some("\"E\"")),
        "{meta:?}"
    );
}

/// `plugin = "erpt"` with no mutation list renders (as `auto`) and its choices are in the
/// EXR header, ready to freeze into a config.
#[test]
fn erpt_without_a_mutation_list_is_auto_and_writes_its_choices() {
    let dir = common::scratch("erpt-auto-metadata");
    let mut s = auto_erpt("glass-caustic/glass-caustic.toml", 32, 1);
    let exr = dir.join("auto.exr");
    s.exr_path = Some(exr.clone());
    let out = render(&s);
    s.write_outputs(out.frame, &out.stats).unwrap();
    let meta = flowlight_host::output::read_exr_metadata(&exr).unwrap();
    let get = |k: &str| {
        meta.get(k)
            .unwrap_or_else(|| panic!("no {k} in {:?}", meta.entries))
    };
    assert_eq!(get("flowlight.param.preset"), "\"manual\"");
    assert_eq!(get("flowlight.param.chains_for"), "\"caustics\"");
    assert_eq!(get("flowlight.param.mixture"), "\"selected\"");
    assert_eq!(get("flowlight.param.termination"), "\"expo\"");
    // e_d once for the image, from the pre-pass `quantum = "image"` runs after the pilot.
    assert_eq!(get("flowlight.param.quantum"), "\"image\"");
    let quantum = out
        .stats
        .integrator
        .iter()
        .find(|(n, _)| n == "auto.quantum")
        .map(|(_, v)| *v);
    assert!(quantum.is_some_and(|q| q > 0.0), "{quantum:?}");
    let m: f64 = get("flowlight.param.mutations_per_sample").parse().unwrap();
    assert!((1.0 / 16.0..=16.0).contains(&m), "{m}");
    let n: u32 = get("flowlight.param.chain_length").parse().unwrap();
    assert!([16, 32, 64].contains(&n), "{n}");
    assert!(get("flowlight.param.mutations").contains("plugin = "));
    // The candidates the host created are in the header too.
    assert_eq!(
        get("flowlight.mutations.0.plugin"),
        "multichain-perturbation"
    );
    // The film window lets the lens jump reach Veach's r₂ = √(0.05·W·H/π): 16 pixels at
    // 64² (the default, 8, at 32²), frozen with the default candidates' own parameters.
    let wide = auto_erpt("glass-caustic/glass-caustic.toml", 64, 1);
    let out = render(&wide);
    assert_eq!(stat(&out, "auto.chains"), 1.0);
    let frozen = wide.instance.resolved_params();
    let get = |k: &str| frozen.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
    assert_eq!(get("film_window").as_deref(), Some("16"), "{frozen:?}");
    assert_eq!(
        get("max_chains_per_seed").as_deref(),
        Some("16"),
        "{frozen:?}"
    );
    let list = get("mutations").unwrap();
    assert!(
        !list.contains("multichain") || list.contains("theta2 = 0.02"),
        "{list}"
    );
    // A list given by the config keeps the manual preset: no pilot, no `auto.*` counters.
    let list = common::mutations(&[("drill", &[])]);
    let mut params = depths();
    params.push(("mutations", list));
    let s = renderer_with(
        "glass-caustic/glass-caustic.toml",
        Some("erpt"),
        (16, 16),
        1,
        &params,
    );
    let out = render(&s);
    assert!(out
        .stats
        .integrator
        .iter()
        .all(|(n, _)| !n.starts_with("auto.")));
    let preset = s.instance.resolved_params();
    assert!(
        preset.contains(&("preset".into(), "\"manual\"".into())),
        "{preset:?}"
    );
}
