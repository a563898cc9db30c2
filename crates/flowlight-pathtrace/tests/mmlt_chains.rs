//! Multiplexed MLT's chains (`flowlight_pathtrace::pss::mmlt`) on the Cornell box with
//! depths 0 and 1 (the lamp seen directly, and one bounce):
//!
//! - **Stationarity in raster space.** The chains' states of depth 1, after every mutation,
//!   fall into 4×4 film regions with the shares of the depth-1 image's luminance there (the
//!   target f_1 marginalised over everything but the raster position), estimated by
//!   independent full BDPT samples' lighting layer 1. The same histogram is far from the uniform
//!   shares (the check has the power to see a wrong target). Chains whose small steps drift
//!   (an asymmetric proposal, for which f(y)/f(x) is not the Metropolis–Hastings ratio) fail
//!   the same check.
//! - **Stationarity over depths.** The share of mutations of each depth is b̂_d / Σ b̂
//!   within the binomial noise of the chains' depth draws.
//! - **Deposits.** A whole film's worth of work units deposits Σ_d b̂_d per pixel on
//!   average: every mutation deposits Σ b̂ of luminance, whatever its chain's depth.

mod loaded;

use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_pathtrace::bidir::sample::{
    strategy_only_settings, FilmPlan, FilmSampler, SampleScratch,
};
use flowlight_pathtrace::bidir::Heuristic;
use flowlight_pathtrace::pss::mmlt::{
    render_unit, render_unit_in_chains, DepthBootstrap, MmltBuffers, MmltCounts,
};
use flowlight_pathtrace::pss::{Mutation, Splat, TileChains};
use flowlight_sdk::{Scene, Tracer, WorkUnit};
use glam::Vec2;
use loaded::load;

const CORNELL: &str = "scenes/cornell-box/cornell-box.toml";
const DEPTH: u32 = 1;
const BINS: usize = 4;
/// How far a bin's share of the chain states may be from the target's.
const SHARE_TOLERANCE: f64 = 0.02;

/// Runs `f` with a strategy sampler of the Cornell box, its scene and tracer.
fn with_sampler<R>(f: impl FnOnce(&FilmSampler, Vec2, &Scene, &Tracer) -> R) -> R {
    let loaded = load(CORNELL);
    // SAFETY: `loaded` owns what the view points into and outlives `scene`.
    let scene = unsafe { Scene::from_view(&loaded.view) };
    let mut unit_tracer = UnitTracer::new(&loaded.scene, loaded.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let film = Vec2::new(scene.camera.width as f32, scene.camera.height as f32);
    let plan = FilmPlan::new(&scene, strategy_only_settings(Heuristic::Power), DEPTH);
    let sampler = FilmSampler::new(&scene, &tracer, &plan);
    f(&sampler, film, &scene, &tracer)
}

fn bin(film: Vec2, raster: Vec2) -> usize {
    let x = ((raster.x / film.x * BINS as f32) as usize).min(BINS - 1);
    let y = ((raster.y / film.y * BINS as f32) as usize).min(BINS - 1);
    y * BINS + x
}

/// Chains over the whole film split into 16×16 tiles, `samples` sample indices each; returns the counts and the per-bin histogram of depth-1 states and the
/// deposits' mean luminance per pixel (in pixel-value units: ÷ spp = 1).
fn run_chains(
    sampler: &FilmSampler,
    film: Vec2,
    bootstrap: &DepthBootstrap,
    samples: u32,
) -> (MmltCounts, Vec<f64>, f64) {
    let (w, h) = (film.x as u32, film.y as u32);
    let mut buffers = MmltBuffers::default();
    let mut counts = MmltCounts::default();
    let mut histogram = vec![0.0f64; BINS * BINS];
    let mut deposited = 0.0f64;
    let tile = 16;
    for y0 in (0..h).step_by(tile) {
        for x0 in (0..w).step_by(tile) {
            let unit = WorkUnit {
                x0,
                y0,
                x1: (x0 + tile as u32).min(w),
                y1: (y0 + tile as u32).min(h),
                sample_begin: 0,
                sample_count: samples,
                seed: 7,
            };
            render_unit(
                sampler,
                bootstrap,
                &unit,
                &mut buffers,
                &mut counts,
                &mut |s| deposited += f64::from(s.value.luminance()),
                &mut |d, state| {
                    if d == 1 {
                        if let Some(s) = state.first() {
                            histogram[bin(film, s.raster)] += 1.0;
                        }
                    }
                },
            );
        }
    }
    let pixels = f64::from(w) * f64::from(h);
    (counts, histogram, deposited / pixels / f64::from(samples))
}

/// Per bin, the depth-1 image's luminance, and the film's mean pixel per depth, from
/// independent BDPT samples (lighting layers 0 and 1 of `bdpt` at `path_depth` 1: the
/// Cornell box is Lambertian, so a path's lighting layer is its depth).
fn bdpt_estimates(scene: &Scene, tracer: &Tracer, film: Vec2, n: u64) -> (Vec<f64>, [f64; 2]) {
    let mut settings = strategy_only_settings(Heuristic::Power);
    settings.path.path_depth = DEPTH;
    settings.path.max_ray_depth = 64;
    settings.lighting_layers = true;
    let plan = FilmPlan::new(scene, settings, 0);
    let bdpt = FilmSampler::new(scene, tracer, &plan);
    let mut scratch = SampleScratch::default();
    let mut bins = vec![0.0f64; BINS * BINS];
    let mut means = [0.0f64; 2];
    for i in 0..n {
        let (camera, light) = (Rng::new(i ^ 0x77, 0), Rng::new(i ^ 0x77, 2));
        bdpt.bdpt_sample(
            camera,
            light,
            &mut scratch,
            &mut |r: Vec2, layer: u32, v: Rgb| {
                let l = f64::from(v.luminance());
                means[layer as usize] += l;
                if layer == 1 {
                    bins[bin(film, r)] += l;
                }
            },
        );
    }
    // The film's mean pixel value is the mean of a sample's deposits (module docs of
    // `bidir::sample`: I_j = W·H · E[deposits in j]).
    means.iter_mut().for_each(|m| *m /= n as f64);
    (bins, means)
}

/// The largest difference between a bin's share of `reference` and of the chain states'
/// `histogram`, and the largest difference of the states' shares from uniform shares.
fn share_errors(reference: &[f64], histogram: &[f64]) -> (f64, f64) {
    let total_ref: f64 = reference.iter().sum();
    let total_hist: f64 = histogram.iter().sum();
    let mut worst = 0.0f64;
    let mut from_uniform = 0.0f64;
    for k in 0..BINS * BINS {
        let (p, q) = (reference[k] / total_ref, histogram[k] / total_hist);
        println!("bin {k}: target share {p:.4}, chain states {q:.4}");
        worst = worst.max((p - q).abs());
        from_uniform = from_uniform.max((q - 1.0 / (BINS * BINS) as f64).abs());
    }
    (worst, from_uniform)
}

#[test]
fn drifting_small_steps_fail_the_raster_space_check() {
    with_sampler(|sampler, film, scene, tracer| {
        // Two σ of drift per small step (the chains take their mutation from the bootstrap;
        // its own samples are independent). Half a σ, which the chain driver's χ² test on
        // the toy integrand catches, moves a bin here by only 0.0195: chains of one tile's
        // 256 mutations, 30% of them large steps, stay close to where they started.
        let drifting = Mutation::new(0.3, 0.01).with_drift(2.0);
        let bootstrap = DepthBootstrap::run(sampler, DEPTH, 3, 20_000, drifting, false);
        let (_, histogram, _) = run_chains(sampler, film, &bootstrap, 4);
        let (reference, _) = bdpt_estimates(scene, tracer, film, 200_000);
        let (worst, _) = share_errors(&reference, &histogram);
        assert!(
            worst > 1.5 * SHARE_TOLERANCE,
            "an asymmetric proposal passed the check: worst bin off by only {worst:.4}"
        );
    });
}

#[test]
fn mmlt_chains_are_stationary_in_raster_space_and_over_depths() {
    with_sampler(|sampler, film, scene, tracer| {
        let mutation = Mutation::new(0.3, 0.01);
        let bootstrap = DepthBootstrap::run(sampler, DEPTH, 3, 20_000, mutation, false);
        let (b0, b1) = (bootstrap.brightness(0), bootstrap.brightness(1));
        assert!(b0 > 0.0 && b1 > 0.0, "both depths carry light: {b0} {b1}");
        let (counts, histogram, deposited) = run_chains(sampler, film, &bootstrap, 4);
        let (reference, means) = bdpt_estimates(scene, tracer, film, 200_000);
        // Expected-value splatting deposits Σ b̂ of luminance per mutation, whatever the
        // chain's depth (b̂_d, times 1/P_d = Σ b̂ / b̂_d): the film's mean pixel is Σ b̂.
        let total = bootstrap.total();
        println!(
            "deposits: mean pixel {deposited:.5e}, Σ b̂ = {total:.5e}, independent samples {:.5e}",
            means[0] + means[1]
        );
        assert!(
            (deposited / total - 1.0).abs() < 1e-3,
            "the chains' mean pixel {deposited:.5e} against Σ b̂ = {total:.5e}"
        );
        let (worst, from_uniform) = share_errors(&reference, &histogram);
        assert!(
            worst < SHARE_TOLERANCE,
            "a bin's share of states is off by {worst:.4}"
        );
        assert!(
            from_uniform > 5.0 * worst,
            "the target is too close to uniform for the check to see a wrong one ({from_uniform:.4})"
        );
        // Depth shares: each of the chains drew its depth with probability b_d / Σ b.
        let chains = counts.chains.chains as f64;
        let per_chain = counts.chains.mutations as f64 / chains;
        let share1 = counts.mutations_per_depth[1] as f64 / counts.chains.mutations as f64;
        let p1 = b1 / (b0 + b1);
        let sd = (p1 * (1.0 - p1) / chains).sqrt();
        println!("depth 1: share of mutations {share1:.4}, b1 / (b0 + b1) = {p1:.4} ± {sd:.4} ({chains} chains of {per_chain} mutations)");
        assert!(
            ((share1 - p1) / sd).abs() < 5.0,
            "depth 1's share {share1:.4} against {p1:.4}"
        );
    });
}

/// The deposits (raster, value) and counts of `units` in order through one [`TileChains`]
/// of chains of `length` mutations, over the Cornell box's depths 0 and 1 with Kelemen's
/// large-step weights.
fn tile_deposits(units: &[WorkUnit], length: u64) -> (Vec<(Vec2, Rgb)>, MmltCounts) {
    with_sampler(|sampler, _, _, _| {
        let bootstrap =
            DepthBootstrap::run(sampler, DEPTH, 3, 2_000, Mutation::new(0.3, 0.01), true);
        let chains = TileChains::default();
        let mut buffers = MmltBuffers::default();
        let mut counts = MmltCounts::default();
        let mut out = Vec::new();
        for u in units {
            render_unit_in_chains(
                sampler,
                &bootstrap,
                u,
                length,
                &chains,
                &mut buffers,
                &mut counts,
                &mut |s: Splat| out.push((s.raster, s.value)),
            );
        }
        (out, counts)
    })
}

/// Work units of a 4×4 tile (16 mutations per sample index).
fn tile_unit(sample_begin: u32, sample_count: u32) -> WorkUnit {
    WorkUnit {
        x0: 20,
        y0: 24,
        x1: 24,
        y1: 28,
        sample_begin,
        sample_count,
        seed: 11,
    }
}

#[test]
fn an_mmlt_tile_chain_cut_into_units_is_the_whole_chain() {
    // 96 mutations in chains of 40: boundaries at 40 and 80 fall inside units of 16; each
    // chain keeps the depth it drew when it started.
    let (whole, whole_counts) = tile_deposits(&[tile_unit(0, 6)], 40);
    let pieces: Vec<WorkUnit> = (0..6).map(|s| tile_unit(s, 1)).collect();
    let (cut, cut_counts) = tile_deposits(&pieces, 40);
    assert_eq!(whole_counts.chains.mutations, 96);
    assert_eq!(whole_counts.chains.chains, 3);
    assert_eq!(cut_counts.chains, whole_counts.chains);
    assert_eq!(
        cut_counts.mutations_per_depth,
        whole_counts.mutations_per_depth
    );
    assert_eq!(whole_counts.mutations_per_depth.iter().sum::<u64>(), 96);
    assert!(!whole.is_empty());
    assert_eq!(cut, whole);
    // Units run out of order start chains of their own: other deposits, as many mutations.
    let (reordered, counts) = tile_deposits(&[tile_unit(3, 3), tile_unit(0, 3)], 40);
    assert_eq!(counts.chains.mutations, 96);
    assert_ne!(reordered, whole);
}

#[test]
fn a_tiles_chains_share_the_depths_out_in_proportion() {
    // 512 chains of one mutation in one tile: chain k's depth comes from frac(U + k·φ), so
    // the chains per depth are 512·P_d within a few chains, where independent draws would
    // scatter by √(512·P_d·(1 − P_d)), about 11.
    with_sampler(|sampler, _, _, _| {
        let bootstrap =
            DepthBootstrap::run(sampler, DEPTH, 5, 2_000, Mutation::new(0.3, 0.01), false);
        let share = bootstrap.brightness(0) / bootstrap.total();
        assert!((0.2..0.8).contains(&share), "P_0 = {share}");
        let mut worst: f64 = 0.0;
        for seed in 0..4 {
            let unit = WorkUnit {
                seed,
                ..tile_unit(0, 32)
            };
            let chains = TileChains::default();
            let (mut buffers, mut counts) = (MmltBuffers::default(), MmltCounts::default());
            render_unit_in_chains(
                sampler,
                &bootstrap,
                &unit,
                1,
                &chains,
                &mut buffers,
                &mut counts,
                &mut |_| {},
            );
            assert_eq!(counts.chains.chains, 512);
            let off = counts.mutations_per_depth[0] as f64 - 512.0 * share;
            worst = worst.max(off.abs());
        }
        assert!(worst <= 3.0, "depth 0's chains {worst} off 512·P_0");
    })
}
