//! The `pssmlt` plugin (`flowlight_pathtrace::pss`) on the Cornell box at 32×32:
//!
//! - **No start-up bias.** The mean of many short independent renders (different seeds, a
//!   small bootstrap, chains of 96 mutations that run on across the units of their 64-pixel
//!   tile, one boundary inside a unit, and the large steps combined with the chain) equals
//!   the committed MCPT reference: a z-test
//!   per 8×8 region, and the image mean within 3 standard errors. Each mutation deposits
//!   luminance b̂ in all, so the image mean is the bootstrap's b̂ and checks the
//!   normalisation; the regions check where the chains put it. Chains started from a
//!   bootstrap sample chosen uniformly instead of ∝ f (a start-up bias) failed the region
//!   test at z = 8.3 in region 0.
//! - **Stationarity.** On the box lit by one bounce (`path_depth = 1`), the chain states'
//!   raster positions, histogrammed over 8×8-pixel regions, follow the MCPT image's
//!   luminance shares; with small steps made asymmetric on purpose (a drift) they do not.
//! - **Thread count.** The image is the same with 1 and 2 threads, with chains that cross
//!   units and with one chain per unit (`chain_length = 0`).
//! - **Layers** sum to the image.
//! - **Bad values** get the host's one-line refusal naming the parameter.
//!
//! `PSSMLT_DEBUG=1` prints every region.

use crate::common;

use common::{renderer_with, scene_config, with_seed_sampler};
use flowlight_core::termination::TerminationSchedule;
use flowlight_core::Rgb;
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_pathtrace::pss::{
    run_chain, Bootstrap, ChainBuffers, ChainCounts, McptTarget, Mutation,
};
use flowlight_pathtrace::Variant;

const SIZE: usize = 32;
const BLOCK: usize = 8;
const REGIONS: usize = (SIZE / BLOCK) * (SIZE / BLOCK);

fn debug() -> bool {
    std::env::var("PSSMLT_DEBUG").is_ok()
}

fn region_of(x: usize, y: usize) -> usize {
    (y / BLOCK) * (SIZE / BLOCK) + x / BLOCK
}

/// Mean luminance per region.
fn regions(img: &[Rgb]) -> [f64; REGIONS] {
    let mut r = [0.0; REGIONS];
    for (i, c) in img.iter().enumerate() {
        r[region_of(i % SIZE, i / SIZE)] += c.luminance() as f64 / (BLOCK * BLOCK) as f64;
    }
    r
}

/// The mean of independent values and the variance of that mean.
fn mean_and_var(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count() as f64;
    let m = values.clone().sum::<f64>() / n;
    let var = values.map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, var / n)
}

/// The committed 128×128 MCPT reference of the Cornell box (path depth 8) box-filtered to
/// 32×32: per region, its mean luminance and that mean's variance.
fn cornell_reference() -> ([f64; REGIONS], [f64; REGIONS]) {
    let path = scene_config("cornell-box/reference/cornell-box.exr");
    let meta = flowlight_host::output::read_exr_metadata(&path).unwrap();
    assert_eq!(meta.get("flowlight.path_depth").map(str::trim), Some("8"));
    let (w, h, layers) = flowlight_host::output::read_exr_rgb(&path).unwrap();
    let layer = |name: &str| &layers.iter().find(|(n, _)| n == name).unwrap().1;
    let (image, var) = (layer(""), layer("variance"));
    let f = w / SIZE;
    let (mut mean, mut variance) = ([0.0; REGIONS], [0.0; REGIONS]);
    let pixels = (f * f * BLOCK * BLOCK) as f64;
    for y in 0..h {
        for x in 0..w {
            let (i, k) = (y * w + x, region_of(x / f, y / f));
            mean[k] += image[i].luminance() as f64 / pixels;
            // The channels' errors are correlated: the luminance's standard deviation is at
            // most the weighted sum of theirs.
            let v = var[i];
            let sd = 0.2126 * (v.r as f64).sqrt()
                + 0.7152 * (v.g as f64).sqrt()
                + 0.0722 * (v.b as f64).sqrt();
            variance[k] += sd * sd / (pixels * pixels);
        }
    }
    (mean, variance)
}

fn int(name: &str, v: i64) -> (&str, toml::Value) {
    (name, toml::Value::Integer(v))
}

/// A 32×32 Cornell box renderer of `plugin` with `params`.
fn cornell(plugin: &str, spp: u32, params: &[(&str, toml::Value)]) -> Renderer {
    renderer_with(
        "cornell-box/cornell-box.toml",
        Some(plugin),
        (SIZE as u32, SIZE as u32),
        spp,
        params,
    )
}

/// Renders `s` with `seed` and `tile` and returns its image, checking it for invalid values.
fn image(mut s: Renderer, seed: u64, tile: u32, threads: usize) -> Vec<Rgb> {
    s.options.seed = seed;
    s.options.tile_size = tile;
    s.options.threads = threads;
    let out = common::render(&s);
    assert_eq!(out.stats.invalid_deposits, 0);
    let img = out.frame.image();
    assert!(img.iter().all(|c| c.is_valid_radiance()));
    img
}

/// Short runs: 8 mutations per pixel in chains of 96 (8×8 tiles: a chain runs on across
/// units, and its successor starts inside a unit), a bootstrap of 256. Their mean carries any
/// start-up bias: the chains are short, and each run's bootstrap is small.
#[test]
fn short_runs_match_the_mcpt_reference() {
    const RUNS: u64 = 64;
    let params = [
        int("path_depth", 8),
        int("bootstrap", 256),
        int("chain_length", 96),
    ];
    let images: Vec<Vec<Rgb>> = (0..RUNS)
        .map(|r| image(cornell("pssmlt", 8, &params), 7000 + r, 8, 2))
        .collect();
    let (reference, ref_var) = cornell_reference();
    let per_run: Vec<[f64; REGIONS]> = images.iter().map(|img| regions(img)).collect();
    // The image mean: the regions' mean.
    let run_means = per_run
        .iter()
        .map(|r| r.iter().sum::<f64>() / REGIONS as f64);
    let (m, var) = mean_and_var(run_means);
    let ref_mean = reference.iter().sum::<f64>() / REGIONS as f64;
    let ref_mean_var = ref_var.iter().sum::<f64>() / (REGIONS * REGIONS) as f64;
    let z = (m - ref_mean) / (var + ref_mean_var).sqrt();
    eprintln!("pssmlt: image mean {m:.5} vs MCPT {ref_mean:.5}, z = {z:.2}");
    assert!(
        z.abs() < 3.0,
        "image mean {m:.5} vs MCPT {ref_mean:.5}: z = {z:.2}"
    );
    for k in 0..REGIONS {
        let (m, var) = mean_and_var(per_run.iter().map(|r| r[k]));
        let z = (m - reference[k]) / (var + ref_var[k]).sqrt().max(1e-12);
        if debug() {
            eprintln!("region {k}: {m:.5} vs {:.5}, z = {z:.2}", reference[k]);
        }
        assert!(
            z.abs() < 5.0,
            "region {k}: {m:.5} vs MCPT {:.5}: z = {z:.2}",
            reference[k]
        );
    }
}

/// The image is the same bit for bit with one thread and two: with chains that run on across
/// a tile's units (parked between them) and with one chain per unit.
#[test]
fn the_image_does_not_depend_on_the_thread_count() {
    for length in [96, 0] {
        let params = [
            int("path_depth", 4),
            int("bootstrap", 128),
            int("chain_length", length),
        ];
        let one = image(cornell("pssmlt", 3, &params), 5, 8, 1);
        let two = image(cornell("pssmlt", 3, &params), 5, 8, 2);
        assert!(one.iter().any(|c| !c.is_black()));
        assert_eq!(one, two, "chain_length {length}");
    }
}

/// Chain states over the one-bounce box, with small and large steps of `mutation`: per
/// chain, the share of its states in each 8×8-pixel region.
fn one_bounce_chain_shares(mutation: Mutation) -> Vec<[f64; REGIONS]> {
    const CHAINS: u64 = 200;
    const LENGTH: u64 = 200;
    let s = cornell("mcpt", 1, &[int("path_depth", 1)]);
    with_seed_sampler(&s, |scene, tracer, mut settings| {
        settings.variant = Variant::Entangled;
        settings.path_depth = 1;
        settings.termination = TerminationSchedule::new(settings.termination.kind(), 1)
            .with_roulette(
                settings.termination.rr_depth(),
                settings.termination.max_survival(),
            );
        let mut target = McptTarget::new(scene, tracer, &settings, false);
        let bootstrap = Bootstrap::run(&mut target, 3, 4096, mutation);
        let mut buffers = ChainBuffers::default();
        let mut counts = ChainCounts::default();
        let out = (0..CHAINS)
            .map(|c| {
                let mut h = [0.0; REGIONS];
                run_chain(
                    &mut target,
                    &bootstrap,
                    100 + c,
                    LENGTH,
                    &mut buffers,
                    &mut counts,
                    &mut |_| {},
                    &mut |splats| {
                        let p = splats[0].raster;
                        h[region_of(p.x as usize, p.y as usize)] += 1.0 / LENGTH as f64;
                    },
                )
                .expect("the box is lit");
                h
            })
            .collect();
        assert!(counts.accepted_small > 0 && counts.accepted_large > 0);
        out
    })
}

/// Per 8×8-pixel region, the z-score of the chains' share of states against the share of
/// the MCPT image's luminance (from independent MCPT renders; the ratio's variance by the
/// delta method), with independent chains as batches.
fn one_bounce_z_scores(per_chain: &[[f64; REGIONS]]) -> Vec<f64> {
    let mcpt: Vec<[f64; REGIONS]> = (0..8)
        .map(|r| {
            regions(&image(
                cornell("mcpt", 16, &[int("path_depth", 1)]),
                900 + r,
                16,
                2,
            ))
        })
        .collect();
    (0..REGIONS)
        .map(|k| {
            let share = |r: &[f64; REGIONS]| r[k] / r.iter().sum::<f64>();
            let (expected, expected_var) = mean_and_var(mcpt.iter().map(share));
            let (m, var) = mean_and_var(per_chain.iter().map(|h| h[k]));
            let z = (m - expected) / (var + expected_var).sqrt().max(1e-12);
            if debug() {
                eprintln!("region {k}: states {m:.4} vs MCPT {expected:.4}, z = {z:.2}");
            }
            z
        })
        .collect()
}

#[test]
fn chain_states_follow_the_image_on_a_one_bounce_scene() {
    let z = one_bounce_z_scores(&one_bounce_chain_shares(Mutation::new(0.3, 0.01)));
    for (k, z) in z.iter().enumerate() {
        assert!(z.abs() < 5.0, "region {k}: z = {z:.2}");
    }
}

/// The same check with small steps that drift by 2σ towards +1 each (an asymmetric
/// proposal: f(y)/f(x) is then not the Metropolis–Hastings ratio) must fail.
#[test]
fn drifting_small_steps_fail_the_one_bounce_check() {
    let drifting = Mutation::new(0.3, 0.01).with_drift(2.0);
    let z = one_bounce_z_scores(&one_bounce_chain_shares(drifting));
    let worst = z.iter().fold(0.0f64, |a, z| a.max(z.abs()));
    assert!(
        worst > 2.0 * 5.0,
        "an asymmetric proposal passed: worst |z| = {worst:.2}"
    );
}

#[test]
fn bad_values_are_refused_in_one_line() {
    let refused = |params: &[(&str, toml::Value)]| {
        let e = Renderer::prepare(
            &scene_config("cornell-box/pssmlt.toml"),
            &Overrides {
                params: common::toml_params(params),
                ..Default::default()
            },
        )
        .err()
        .expect("a bad value was accepted");
        let e = common::plugin_refusal(&e, "pssmlt").to_string();
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        e
    };
    let e = refused(&[("large_step", 1.5.into())]);
    assert!(
        e.contains("parameter 'large_step' must be in [0.0, 1.0], got 1.5"),
        "{e}"
    );
    let e = refused(&[("sigma", 0.0.into())]);
    assert!(e.contains("'sigma'"), "{e}");
    let e = refused(&[("bootstrap", 0.into())]);
    assert!(e.contains("'bootstrap'"), "{e}");
    let e = refused(&[("sampler", "metropolis".into())]);
    assert!(e.contains("'sampler'") && e.contains("metropolis"), "{e}");
}

/// With `layers = true` every contribution is splatted in its lighting layer: the layers
/// 0..=N sum to the image, and none is empty on the box.
#[test]
fn lighting_layers_sum_to_the_image() {
    let n = 3;
    let s = cornell(
        "pssmlt",
        2,
        &[
            int("path_depth", n),
            int("bootstrap", 256),
            ("layers", true.into()),
        ],
    );
    let out = common::render(&s);
    let image = out.frame.image();
    let layers: Vec<Vec<Rgb>> = (0..=n as usize).map(|k| out.frame.layer(k)).collect();
    for (i, c) in image.iter().enumerate() {
        let sum = layers.iter().fold(Rgb::ZERO, |a, l| a + l[i]);
        let tol = 1e-4 * c.luminance().max(1e-3);
        assert!(
            (sum.luminance() - c.luminance()).abs() <= tol,
            "pixel {i}: layers sum to {sum:?}, image {c:?}"
        );
    }
    assert!(layers.iter().all(|l| l.iter().any(|c| c.luminance() > 0.0)));
}
