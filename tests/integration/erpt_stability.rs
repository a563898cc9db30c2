//! ERPT on hard cases (the MCMC part of the stability suite): chains that meet zero densities,
//! corner traps (y₁ and x₂ on the same surface), and seeds of 1e30 and of overflowing energy.
//! No NaN or infinity may reach the image, no invalid state may be deposited, and what was
//! thrown away is counted.

use crate::common;

use common::{render, renderer_at};
use flowlight_host::render::RenderOutcome;
use flowlight_host::renderer::{Overrides, Renderer};

fn counter(out: &RenderOutcome, name: &str) -> f64 {
    out.stats
        .integrator
        .iter()
        .find(|(k, _)| k == name)
        .map(|(_, v)| *v)
        .unwrap_or_else(|| panic!("no counter {name}"))
}

fn erpt_params() -> Vec<(&'static str, toml::Value)> {
    let m = |plugin: &str| {
        let mut t = toml::Table::new();
        t.insert("plugin".into(), plugin.into());
        toml::Value::Table(t)
    };
    vec![
        (
            "mutations",
            toml::Value::Array(vec![
                m("blow"),
                m("drill"),
                m("hard-reconnection"),
                m("bxdf-extension"),
            ]),
        ),
        ("mutations_per_sample", 16.0.into()),
        ("chain_length", toml::Value::Integer(16)),
    ]
}

/// Renders `config` (made ERPT with the mixture above) and checks the invariants.
fn check_clean(s: &Renderer, label: &str) -> RenderOutcome {
    let out = render(s);
    assert_eq!(
        out.stats.invalid_deposits, 0,
        "{label}: an invalid deposit reached the host"
    );
    let img = out.frame.image();
    assert!(
        img.iter().all(|c| c.is_valid_radiance()),
        "{label}: NaN/Inf/negative pixel"
    );
    assert!(
        counter(&out, "total.mutations") > 0.0,
        "{label}: no chain ran"
    );
    out
}

fn erpt_renderer(config: &str, width: u32, extra: &[(&str, toml::Value)]) -> Renderer {
    erpt_renderer_with(config, width, extra, |_| {})
}

fn erpt_renderer_with(
    config: &str,
    width: u32,
    extra: &[(&str, toml::Value)],
    edit: impl FnOnce(&mut flowlight_scene::config::RenderConfig),
) -> Renderer {
    let mut cfg = flowlight_scene::config::load_config(&common::scene_config(config)).unwrap();
    edit(&mut cfg);
    cfg.width = width;
    cfg.height = width;
    cfg.integrator_plugin = "erpt".into();
    cfg.integrator_params.retain(|(k, _)| k == "path_depth");
    let mut params = common::toml_params(&erpt_params());
    params.extend(common::toml_params(extra));
    let ov = Overrides {
        spp: Some(2),
        threads: Some(2),
        params,
        ..Default::default()
    };
    let mut s = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

#[test]
fn corner_traps_are_survived_and_show_in_the_norms() {
    let out = check_clean(
        &erpt_renderer("narrow-gap/narrow-gap.toml", 48, &[]),
        "narrow gap",
    );
    // Corner traps surface as domain misses and rejections; they are counted, per strategy.
    let misses = counter(&out, "total.domain_miss");
    let hits = counter(&out, "total.domain_hit");
    assert!(misses > 0.0 && hits > 0.0);
    assert_eq!(counter(&out, "total.mutations"), misses + hits);
    for s in ["blow", "drill", "hard-reconnection", "bxdf-extension"] {
        let m = counter(&out, &format!("{s}.mutations"));
        let e = counter(&out, &format!("{s}.acceptance"))
            + counter(&out, &format!("{s}.rejection"))
            + counter(&out, &format!("{s}.domain_miss"));
        assert_eq!(m, e, "{s}: events do not add up");
    }
}

#[test]
fn chains_meeting_zero_densities_never_deposit_there() {
    // Black ceiling, floor, back wall and boxes: a mutation that moves a path onto them has
    // f = 0 (a zero density for the chain) and must be rejected, never deposited.
    let blacken = |cfg: &mut flowlight_scene::config::RenderConfig| {
        cfg.material_overrides.insert(
            "white".into(),
            flowlight_scene::MaterialOverride {
                diffuse: None,
                sigma_degrees: None,
                two_sided_emission: None,
                base_color: Some([0.0, 0.0, 0.0]),
            },
        );
    };
    let s = erpt_renderer_with("cornell-box/cornell-box.toml", 32, &[], blacken);
    let out = check_clean(&s, "black surfaces");
    assert!(
        counter(&out, "total.rejection") > 0.0,
        "no proposal met a zero density"
    );
    // With a zero-width film window the raster never moves: still clean.
    let s = erpt_renderer_with(
        "cornell-box/cornell-box.toml",
        32,
        &[("film_window", toml::Value::Integer(0))],
        blacken,
    );
    check_clean(&s, "fixed raster");
}

/// A furnace whose emission strength is `strength`, written next to a copy of the config.
fn furnace_with_strength(strength: &str) -> common::InTempDir<std::path::PathBuf> {
    let dir = common::scratch(&format!("strong-{strength}"));
    let gltf = std::fs::read_to_string(common::scene_config("furnace/furnace.gltf")).unwrap();
    let patched = gltf.replace(
        "\"emissiveStrength\": 1.0",
        &format!("\"emissiveStrength\": {strength}"),
    );
    assert_ne!(gltf, patched, "emission strength not found in furnace.gltf");
    std::fs::write(dir.join("furnace.gltf"), patched).unwrap();
    std::fs::copy(
        common::scene_config("furnace/erpt.toml"),
        dir.join("erpt.toml"),
    )
    .unwrap();
    let value = dir.join("erpt.toml");
    common::InTempDir { dir, value }
}

#[test]
fn enormous_seeds_are_capped_or_counted_never_written_as_nan() {
    // 1e30 everywhere: quanta, chain counts and deposits stay finite and keep the energy.
    let cfg = furnace_with_strength("1e30");
    let mut c = flowlight_scene::config::load_config(&cfg).unwrap();
    c.width = 16;
    c.height = 16;
    let ov = Overrides {
        spp: Some(16),
        threads: Some(2),
        ..Default::default()
    };
    let mut s = Renderer::from_config(c, &ov).unwrap();
    s.exr_path = None;
    let out = check_clean(&s, "1e30 furnace");
    let mean = out
        .frame
        .image()
        .iter()
        .map(|c| c.luminance() as f64)
        .sum::<f64>()
        / 256.0;
    // Radiance 1e30·(1 − 0.5⁹)/(1 − 0.5): the energy is kept, not lost to the cap.
    assert!((mean / 1.996e30 - 1.0).abs() < 0.08, "mean {mean:e}");

    // 3e38: the emitters' power overflows f32. The scene is refused when it loads, with a
    // line naming the cause, instead of failing at write time after the whole render.
    let cfg = furnace_with_strength("3e38");
    let c = flowlight_scene::config::load_config(&cfg).unwrap();
    let err = Renderer::from_config(c, &ov)
        .err()
        .expect("3e38 emission must be refused");
    // The loader refuses the scene, before anything is rendered.
    let flowlight_host::error::HostError::Scene(err) = err else {
        panic!("not the scene's error: {err:?}")
    };
    let err = err.to_string();
    assert!(
        err.contains("not finite") && !err.contains('\n'),
        "unclear error: {err}"
    );
}

#[test]
fn the_biased_filter_is_marked_in_the_output() {
    let dir = common::scratch("biased-filter");
    let mut s = renderer_at(
        "furnace/erpt.toml",
        16,
        16,
        2,
        &[("max_consecutive", toml::Value::Integer(2))],
    );
    assert_eq!(s.instance.info.biased, 1);
    s.exr_path = Some(dir.join("f.exr"));
    let out = render(&s);
    s.write_outputs(out.frame, &out.stats).unwrap();
    let meta = flowlight_host::output::read_exr_metadata(&dir.join("f.exr")).unwrap();
    assert!(
        meta.entries
            .iter()
            .any(|(k, v)| k == "flowlight.biased" && v == "true"),
        "metadata: {:?}",
        meta.entries
    );
    assert!(
        dir.join("f.stats.json").is_file(),
        "norms not written beside the image"
    );
}

#[test]
fn image_quantum_and_selected_ratio_modes_render_clean() {
    for extra in [
        vec![("quantum", toml::Value::from("image"))],
        vec![("mixture", toml::Value::from("selected"))],
        vec![("layers", toml::Value::Boolean(true))],
    ] {
        let label = format!("{extra:?}");
        let out = check_clean(
            &erpt_renderer("cornell-box/cornell-box.toml", 24, &extra),
            &label,
        );
        assert!(counter(&out, "mean_quantum") > 0.0, "{label}");
        if extra[0].0 == "layers" {
            // ERPT's layers sum to its image, like MCPT's.
            let img = out.frame.image();
            let n = out.frame.layer_count as usize;
            assert_eq!(n, 9);
            let layers: Vec<_> = (0..n).map(|k| out.frame.layer(k)).collect();
            for (i, px) in img.iter().enumerate() {
                let sum: f32 = layers.iter().map(|l| l[i].luminance()).sum();
                assert!(
                    (sum - px.luminance()).abs() <= 1e-4 * px.luminance().max(1.0),
                    "pixel {i}"
                );
            }
        }
    }
}
