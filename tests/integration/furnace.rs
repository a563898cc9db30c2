//! White furnace: a closed sphere of albedo a = 0.5 emitting Le = 1 everywhere, seen from
//! inside, has radiance Le/(1−a) = 2 in every direction (up to the tail beyond the path-space
//! depth N: Le·(1 − a^{N+1})/(1 − a)). Both MCPT variants with all three termination
//! distributions of the thesis and the throughput roulette must get it within 1%. The expodistribution starves shallow layers (thesis
//! §3.8: "too aggressive"): layer 1 gets a share of 2^-(N-1), so the untangled estimator's
//! variance grows like 2^N; that case runs at N = 6 with more samples.

use crate::common;

use common::{mean_and_stderr, render, renderer};

/// `depth` N leaves a tail of 0.5^(N+1)·2 beyond the path-space depth; the check uses the
/// exact truncated value Le(1 − a^{N+1})/(1 − a).
fn check(variant: &str, termination: &str, depth: i64, spp: u32) {
    check_with(variant, termination, depth, spp, &[]);
}

fn check_with(
    variant: &str,
    termination: &str,
    depth: i64,
    spp: u32,
    extra: &[(&str, toml::Value)],
) {
    let mut params = vec![
        ("variant", variant.into()),
        ("termination", termination.into()),
        ("path_depth", toml::Value::Integer(depth)),
    ];
    params.extend_from_slice(extra);
    let s = renderer("furnace/furnace.toml", spp, &params);
    let out = render(&s);
    assert_eq!(out.stats.invalid_deposits, 0, "no NaN/Inf samples expected");
    let img = out.frame.image();
    let expected = (1.0 - 0.5f64.powi(depth as i32 + 1)) / (1.0 - 0.5);
    for c in [
        |c: flowlight_core::Rgb| c.r,
        |c: flowlight_core::Rgb| c.g,
        |c: flowlight_core::Rgb| c.b,
    ] {
        let (mean, stderr) = mean_and_stderr(&img, c);
        let rel = (mean / expected - 1.0).abs();
        assert!(
            rel < 0.01,
            "{variant}/{termination}: mean {mean:.5}, expected {expected:.5} (relative error {rel:.4}, stderr {stderr:.5})"
        );
        // The test must be able to tell a 1% error apart from noise (3 standard errors).
        assert!(
            stderr / expected < 0.0033,
            "{variant}/{termination}: too noisy to judge (stderr {stderr})"
        );
    }
}

#[test]
fn entangled_bxdf() {
    check("entangled", "bxdf", 8, 256);
}
#[test]
fn entangled_equi() {
    check("entangled", "equi", 8, 256);
}
#[test]
fn entangled_expo() {
    check("entangled", "expo", 8, 256);
}
#[test]
fn untangled_bxdf() {
    check("untangled", "bxdf", 8, 256);
}
#[test]
fn untangled_equi() {
    check("untangled", "equi", 8, 256);
}
#[test]
fn untangled_expo() {
    check("untangled", "expo", 6, 3072);
}

// Shallow path-space depths: the deepest layer is a large share of the image there
// (a^N / (1 − a^{N+1}) = 33%, 14%, 7% at N = 1, 2, 3), so an estimator that loses part of it
// fails by far more than the 1% tolerance — entangled MCPT once stopped after the last light
// sample without tracing the BSDF sample it was MIS-weighted against (1.245 instead of 1.5 at
// N = 1, 1.622 instead of 1.75 at N = 2).
macro_rules! shallow {
    ($($name:ident: $variant:literal, $termination:literal, $depth:literal;)*) => {
        $(#[test]
        fn $name() {
            check($variant, $termination, $depth, 128);
        })*
    };
}

shallow! {
    entangled_bxdf_depth1: "entangled", "bxdf", 1;
    entangled_bxdf_depth2: "entangled", "bxdf", 2;
    entangled_bxdf_depth3: "entangled", "bxdf", 3;
    entangled_equi_depth1: "entangled", "equi", 1;
    entangled_equi_depth2: "entangled", "equi", 2;
    entangled_equi_depth3: "entangled", "equi", 3;
    entangled_expo_depth1: "entangled", "expo", 1;
    entangled_expo_depth2: "entangled", "expo", 2;
    entangled_expo_depth3: "entangled", "expo", 3;
    untangled_bxdf_depth1: "untangled", "bxdf", 1;
    untangled_bxdf_depth2: "untangled", "bxdf", 2;
    untangled_bxdf_depth3: "untangled", "bxdf", 3;
    untangled_equi_depth1: "untangled", "equi", 1;
    untangled_equi_depth2: "untangled", "equi", 2;
    untangled_equi_depth3: "untangled", "equi", 3;
    untangled_expo_depth1: "untangled", "expo", 1;
    untangled_expo_depth2: "untangled", "expo", 2;
    untangled_expo_depth3: "untangled", "expo", 3;
}

// The throughput roulette (default start depth 5) at every path-space depth 1..=8: below 5
// the entangled sampler never stops early, at 6..=8 the roulette acts on layers 5..N−1.
shallow! {
    entangled_throughput_depth1: "entangled", "throughput", 1;
    entangled_throughput_depth2: "entangled", "throughput", 2;
    entangled_throughput_depth3: "entangled", "throughput", 3;
    entangled_throughput_depth4: "entangled", "throughput", 4;
    entangled_throughput_depth5: "entangled", "throughput", 5;
    entangled_throughput_depth6: "entangled", "throughput", 6;
    entangled_throughput_depth7: "entangled", "throughput", 7;
    untangled_throughput_depth1: "untangled", "throughput", 1;
    untangled_throughput_depth2: "untangled", "throughput", 2;
    untangled_throughput_depth3: "untangled", "throughput", 3;
    untangled_throughput_depth4: "untangled", "throughput", 4;
    untangled_throughput_depth5: "untangled", "throughput", 5;
    untangled_throughput_depth6: "untangled", "throughput", 6;
    untangled_throughput_depth7: "untangled", "throughput", 7;
}

#[test]
fn entangled_throughput() {
    check("entangled", "throughput", 8, 256);
}
#[test]
fn untangled_throughput() {
    check("untangled", "throughput", 8, 256);
}

/// Roulette from the first vertex, with a low survival cap: most of the image then comes from
/// survivors, so a sampler that forgot to divide them by q would lose far more than 1%.
#[test]
fn entangled_throughput_from_first_vertex() {
    let extra = [
        ("rr_depth", toml::Value::Integer(1)),
        ("rr_max_survival", toml::Value::Float(0.6)),
    ];
    check_with("entangled", "throughput", 8, 256, &extra);
}

/// Each lighting layer k of the furnace holds exactly Le·a^k (layer 0: the emitter seen
/// directly). Under the throughput roulette the layers' sample shares depend on the paths'
/// history, so this checks every layer on its own against its analytic value, with the
/// roulette from vertex 2 (rr_depth = 2): in the entangled variant layers 2..N are estimated
/// by survivors only, each divided by its survival probability (the untangled one ignores
/// rr_depth and connects by the albedo rule). Both variants.
#[test]
fn throughput_layers_match_the_analytic_furnace_layers() {
    // Untangled paths carry one connection each, so deep layers get few samples: N = 4 there.
    for (variant, n) in [("entangled", 6i64), ("untangled", 4)] {
        let s = renderer(
            "furnace/furnace.toml",
            512,
            &[
                ("variant", variant.into()),
                ("termination", "throughput".into()),
                ("path_depth", toml::Value::Integer(n)),
                ("rr_depth", toml::Value::Integer(2)),
                ("layers", true.into()),
            ],
        );
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0);
        assert_eq!(out.frame.layer_count as i64, n + 1, "layers 0..=N");
        for k in 0..=n as usize {
            let layer = out.frame.layer(k);
            let (mean, stderr) = mean_and_stderr(&layer, |c| c.g);
            let expected = 0.5f64.powi(k as i32);
            let rel = (mean / expected - 1.0).abs();
            assert!(
                rel < 0.03 && (mean - expected).abs() < 5.0 * stderr + 1e-3 * expected,
                "{variant}: layer {k}: mean {mean:.5} ± {stderr:.5}, expected {expected:.5}"
            );
            // Tight enough that a 3% error is 3 standard errors.
            assert!(
                stderr / expected < 0.01,
                "{variant}: layer {k} too noisy ({stderr})"
            );
        }
    }
}

// Paths split into branches at their first lighting vertex (`branches`): each branch carries
// 1/k of the weight into its own light connection there and its own BSDF sample, so a
// connection or branch with the wrong weight, or a lost branch, shows at every depth (all
// five fail when the split vertex's connections carry 2/k), most at N = 1, where the split
// vertex's connections and emission-only BSDF samples are the image but for the emitter
// seen directly. With the roulette from the first vertex both the split vertex's roulette
// and the branches' (whose β holds the 1/k the roulette multiplies back out) are exercised.
macro_rules! branched {
    ($($name:ident: $termination:literal, $depth:literal, $branches:literal, $rr_depth:literal;)*) => {
        $(#[test]
        fn $name() {
            let extra = [
                ("branches", toml::Value::Integer($branches)),
                ("rr_depth", toml::Value::Integer($rr_depth)),
            ];
            check_with("entangled", $termination, $depth, 64, &extra);
        })*
    };
}

branched! {
    entangled_branches_depth1: "throughput", 1, 3, 5;
    entangled_branches_depth2: "throughput", 2, 2, 5;
    entangled_branches_depth8: "throughput", 8, 4, 5;
    entangled_branches_roulette_from_first_vertex: "throughput", 8, 3, 1;
    entangled_branches_bxdf: "bxdf", 8, 2, 5;
}

/// `branches` out of range, or with the untangled variant (one light connection per path,
/// nothing to split), is refused with the parameter's name.
#[test]
fn bad_branches_are_named() {
    use flowlight_host::renderer::{Overrides, Renderer};
    for (params, shown) in [
        (vec![("branches", toml::Value::Integer(0))], "got 0"),
        (vec![("branches", toml::Value::Integer(65))], "got 65"),
        (
            vec![
                ("branches", toml::Value::Integer(2)),
                ("variant", "untangled".into()),
            ],
            "entangled",
        ),
    ] {
        let ov = Overrides {
            params: common::toml_params(&params),
            ..Default::default()
        };
        let err = Renderer::prepare(&common::scene_config("furnace/furnace.toml"), &ov)
            .err()
            .unwrap_or_else(|| panic!("{params:?} accepted"));
        let err = common::plugin_refusal(&err, "mcpt");
        assert!(err.contains("branches") && err.contains(shown), "{err}");
    }
}

/// Out-of-range roulette settings are refused with the parameter's name and value.
#[test]
fn bad_roulette_settings_are_named() {
    use flowlight_host::renderer::{Overrides, Renderer};
    for (key, value, shown) in [
        ("rr_depth", toml::Value::Integer(0), "got 0"),
        ("rr_max_survival", toml::Value::Float(1.0), "got 1"),
        ("termination", "roulette".into(), "\"roulette\""),
    ] {
        let ov = Overrides {
            params: common::toml_params(&[("termination", "throughput".into()), (key, value)]),
            ..Default::default()
        };
        let err = Renderer::prepare(&common::scene_config("furnace/furnace.toml"), &ov)
            .err()
            .unwrap_or_else(|| panic!("{key} accepted"));
        let err = common::plugin_refusal(&err, "mcpt");
        assert!(err.contains(key) && err.contains(shown), "{err}");
    }
}

/// ERPT's untangled seeds under `throughput`, with a survival cap below the furnace's albedo
/// (so T = 0.6, not the 0.5 of `bxdf`): the image mean stays 2·(1 − 0.5^9).
#[test]
fn erpt_seeds_with_throughput_termination_keep_the_furnace() {
    let s = renderer(
        "furnace/erpt.toml",
        16,
        &[
            ("termination", "throughput".into()),
            ("rr_max_survival", toml::Value::Float(0.4)),
        ],
    );
    let out = render(&s);
    assert_eq!(out.stats.invalid_deposits, 0);
    let img = out.frame.image();
    let (mean, stderr) = mean_and_stderr(&img, |c| c.luminance());
    let expected = 2.0 * (1.0 - 0.5f64.powi(9));
    assert!(
        (mean / expected - 1.0).abs() < 0.02,
        "ERPT furnace: mean {mean:.5} ± {stderr:.5}, expected {expected:.5}"
    );
}
