//! MCPT's two samplers (`sampler = "sobol"`, the default, and `"independent"`): both
//! unbiased region by region, and the stratified one with less error at equal samples.

use crate::common;

use common::{
    assert_image_mean, assert_regions_unbiased, independent_runs, render, renderer_at, MeanRule,
};
use flowlight_core::Rgb;

/// A 32×32 render of `config` with `sampler` at `spp` and the given seed.
fn image(config: &str, sampler: &str, spp: u32, seed: u64) -> Vec<Rgb> {
    let mut s = renderer_at(config, 32, 32, spp, &[("sampler", sampler.into())]);
    s.options.seed = seed;
    let out = render(&s);
    assert_eq!(out.stats.invalid_deposits, 0);
    out.frame.image()
}

/// Independent runs with `sampler` against an independent-sampler reference of many samples:
/// the z-test per region and the image mean.
fn unbiased(config: &str, sampler: &str, spp: u32, reference_spp: u32, rule: MeanRule) {
    let reference = image(config, "independent", reference_spp, 77);
    let label = format!("{config} sampler {sampler}");
    let make = || renderer_at(config, 32, 32, spp, &[("sampler", sampler.into())]);
    let (images, _) = independent_runs(&label, 6, 500, &make);
    assert_regions_unbiased(&label, &images, &reference);
    assert_image_mean(&label, &images, &reference, rule);
}

#[test]
fn sobol_is_unbiased_on_the_cornell_box() {
    unbiased(
        "cornell-box/cornell-box.toml",
        "sobol",
        64,
        2048,
        MeanRule::Within(0.01),
    );
}

#[test]
fn sobol_is_unbiased_through_glass() {
    // Dirac vertices draw no light sample: the later decisions keep their own dimensions
    // (`seek`), and the caustic's heavy tail makes the image mean a z-test.
    unbiased(
        "glass-caustic/glass-caustic.toml",
        "sobol",
        64,
        2048,
        MeanRule::WithinOrZ(0.01, 5.0),
    );
}

/// Paths split into branches (`branches`), with Sobol' numbers (k = 4: the branches of a
/// pixel's samples are stratified together) and with independent ones (k = 3), region by
/// region against an unsplit independent reference: a branch merged into the wrong sample
/// biases regions, which the furnace, being uniform, cannot see. 64 camera samples, as the samplers' own checks above: the
/// image mean's noise is the lamp's edge pixels', which branches do not reduce.
#[test]
fn branches_are_unbiased_on_the_cornell_box_and_through_glass() {
    for (config, rule) in [
        ("cornell-box/cornell-box.toml", MeanRule::Within(0.01)),
        (
            "glass-caustic/glass-caustic.toml",
            MeanRule::WithinOrZ(0.01, 5.0),
        ),
    ] {
        let reference = image(config, "independent", 2048, 80);
        for (sampler, branches) in [("sobol", 4), ("independent", 3)] {
            let label = format!("{config} {sampler}, {branches} branches");
            let make = || {
                renderer_at(
                    config,
                    32,
                    32,
                    64,
                    &[
                        ("sampler", sampler.into()),
                        ("branches", toml::Value::Integer(branches)),
                    ],
                )
            };
            let (images, _) = independent_runs(&label, 6, 700, &make);
            assert_regions_unbiased(&label, &images, &reference);
            assert_image_mean(&label, &images, &reference, rule);
        }
    }
}

#[test]
fn independent_is_unbiased_on_the_cornell_box() {
    // The reference here comes from the default (sobol) sampler, so each sampler is checked
    // against the other.
    let config = "cornell-box/cornell-box.toml";
    let reference = image(config, "sobol", 2048, 78);
    let make = || renderer_at(config, 32, 32, 64, &[("sampler", "independent".into())]);
    let (images, _) = independent_runs("independent", 6, 600, &make);
    assert_regions_unbiased("independent", &images, &reference);
    assert_image_mean("independent", &images, &reference, MeanRule::Within(0.01));
}

#[test]
fn sobol_has_less_error_at_equal_samples() {
    // Mean squared error per pixel against a 4096-spp reference, over four seeds, at 16 spp.
    // Stratifying the pixel area, the first light sample and the first BSDF sample roughly
    // halves it on the Cornell box (0.57x at 256², 64 spp); a sampler whose samples of a
    // pixel were not stratified together (say, seeded per sample) would give about 1.
    let config = "cornell-box/cornell-box.toml";
    let reference = image(config, "independent", 4096, 79);
    let mse = |sampler: &str| {
        (0..4)
            .map(|seed| {
                let img = image(config, sampler, 16, 900 + seed);
                img.iter()
                    .zip(&reference)
                    .map(|(a, b)| (a.luminance() as f64 - b.luminance() as f64).powi(2))
                    .sum::<f64>()
                    / img.len() as f64
            })
            .sum::<f64>()
            / 4.0
    };
    let (sobol, independent) = (mse("sobol"), mse("independent"));
    assert!(
        sobol < 0.8 * independent,
        "sobol MSE {sobol:.3e} is not clearly below independent {independent:.3e}"
    );
}

#[test]
fn untangled_refuses_sobol_and_defaults_to_independent() {
    use flowlight_host::renderer::{Overrides, Renderer};
    let ov = |params: &[(&str, toml::Value)]| Overrides {
        spp: Some(1),
        params: common::toml_params(params),
        ..Default::default()
    };
    // The plugin refuses it, naming the parameter and what it needs.
    let refused = |config: &str, plugin: &str, params: &[(&str, toml::Value)]| {
        let err = Renderer::prepare(&common::scene_config(config), &ov(params))
            .err()
            .unwrap_or_else(|| panic!("{config} {params:?} must be refused"));
        let err = common::plugin_refusal(&err, plugin);
        assert!(
            err.contains("'sampler'") && err.contains("entangled"),
            "unclear error: {err}"
        );
    };
    let sobol = ("sampler", toml::Value::from("sobol"));
    refused(
        "cornell-box/cornell-box.toml",
        "mcpt",
        &[("variant", "untangled".into()), sobol.clone()],
    );
    let config = common::scene_config("cornell-box/cornell-box.toml");
    assert!(Renderer::prepare(&config, &ov(&[("variant", "untangled".into())])).is_ok());
    // ERPT's untangled seeds likewise.
    refused(
        "glass-caustic/erpt.toml",
        "erpt",
        &[("seeds", "untangled".into()), sobol],
    );
}
