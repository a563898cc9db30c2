//! Stationarity of the chain on a 2-D toy integrand, and the normalisation of its splats.
//!
//! The target reads one pair u = (u₁, u₂) and splats f(u) (a sum of bumps on a floor) at
//! raster position u. Independent chains give independent per-chain histograms (8 × 8 bins)
//! of the states; each bin's mean over chains is z-tested against the bin's share of ∫f, and
//! the z² summed (≈ χ² with 64 degrees of freedom when the chain is right).

use super::bootstrap::ScaleEstimate;
use super::chain::{run_chain, Bootstrap, ChainBuffers, ChainCounts, PssTarget, Splat};
use super::large_steps::scale_estimate;
use super::samples::{Mutation, PrimarySamples};
use super::units::{render_unit_in_chains, TileChains};
use flowlight_core::sampler::SampleStream;
use flowlight_core::Rgb;
use flowlight_sdk::WorkUnit;
use glam::Vec2;

const BINS: usize = 8;

struct Bumps;

fn bumps(u: Vec2) -> f32 {
    let bump = |c: Vec2, r: f32| (-(u - c).length_squared() / (2.0 * r * r)).exp();
    0.05 + bump(Vec2::new(0.3, 0.35), 0.08) + 0.6 * bump(Vec2::new(0.7, 0.7), 0.12)
}

impl PssTarget for Bumps {
    fn streams(&self) -> u32 {
        1
    }
    fn evaluate(&mut self, samples: &PrimarySamples, splats: &mut Vec<Splat>) {
        splats.clear();
        let u = samples.start_stream(0).uniform2();
        splats.push(Splat {
            raster: u,
            layer: 0,
            value: Rgb::splat(bumps(u)),
        });
    }
}

fn bin(p: Vec2) -> usize {
    let i = ((p.x * BINS as f32) as usize).min(BINS - 1);
    let j = ((p.y * BINS as f32) as usize).min(BINS - 1);
    j * BINS + i
}

/// ∫ f over each bin (midpoint rule, 32² points per bin).
fn bin_integrals() -> Vec<f64> {
    let n = 32 * BINS;
    let mut out = vec![0.0; BINS * BINS];
    for j in 0..n {
        for i in 0..n {
            let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
            out[bin(u)] += bumps(u) as f64 / (n * n) as f64;
        }
    }
    out
}

/// Per chain, the share of its states in each bin and its deposits per mutation per bin.
struct PerChain {
    states: Vec<Vec<f64>>,
    deposits: Vec<Vec<f64>>,
    counts: ChainCounts,
}

fn run_chains(mutation: Mutation, chains: u64, length: u64) -> PerChain {
    run_chains_with(mutation, chains, length, |_| {})
}

/// As [`run_chains`], with `setup` applied to the bootstrap first (the large-step weights).
fn run_chains_with(
    mutation: Mutation,
    chains: u64,
    length: u64,
    setup: impl FnOnce(&mut Bootstrap),
) -> PerChain {
    let mut target = Bumps;
    let mut bootstrap = Bootstrap::run(&mut target, 17, 20_000, mutation);
    setup(&mut bootstrap);
    let mut buffers = ChainBuffers::default();
    let mut out = PerChain {
        states: Vec::new(),
        deposits: Vec::new(),
        counts: ChainCounts::default(),
    };
    for c in 0..chains {
        let mut states = vec![0.0; BINS * BINS];
        let mut deposits = vec![0.0; BINS * BINS];
        run_chain(
            &mut target,
            &bootstrap,
            1000 + c,
            length,
            &mut buffers,
            &mut out.counts,
            &mut |s: Splat| deposits[bin(s.raster)] += s.value.luminance() as f64 / length as f64,
            &mut |s: &[Splat]| states[bin(s[0].raster)] += 1.0 / length as f64,
        )
        .expect("the bootstrap finds the integrand");
        out.states.push(states);
        out.deposits.push(deposits);
    }
    out
}

/// Σ z² of the per-bin means over chains against `expected`.
fn chi_square(per_chain: &[Vec<f64>], expected: &[f64]) -> f64 {
    let n = per_chain.len() as f64;
    (0..expected.len())
        .map(|k| {
            let mean = per_chain.iter().map(|h| h[k]).sum::<f64>() / n;
            let var = per_chain.iter().map(|h| (h[k] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean - expected[k]).powi(2) / (var / n).max(1e-30)
        })
        .sum()
}

/// Independent chains per check (of 500 mutations each). With 400 the symmetric chain's χ²
/// came out at 88.7 and 93.5 (+2.5σ of the χ² of 64 degrees of freedom), with 1600 and
/// 6400 at 56–64: chance, not a bias, so this many.
const CHAINS: u64 = 1600;

/// χ² of 64 degrees of freedom stays below 64 + 6·√128 ≈ 132 but in 1 of ~10⁷ runs.
const CHI_SQUARE_LIMIT: f64 = 132.0;

#[test]
fn chain_states_are_distributed_as_the_target() {
    let integrals = bin_integrals();
    let total: f64 = integrals.iter().sum();
    let shares: Vec<f64> = integrals.iter().map(|v| v / total).collect();
    let run = run_chains(Mutation::new(0.3, 0.05), CHAINS, 500);
    let chi2 = chi_square(&run.states, &shares);
    eprintln!("symmetric: state χ² = {chi2:.1}");
    assert!(chi2 < CHI_SQUARE_LIMIT, "state histogram χ² = {chi2:.1}");
    assert!(run.counts.accepted_small > 0 && run.counts.accepted_large > 0);
    // Expected-value splatting: the deposits per mutation estimate ∫ f over each bin.
    let chi2 = chi_square(&run.deposits, &integrals);
    eprintln!("symmetric: deposit χ² = {chi2:.1}");
    assert!(chi2 < CHI_SQUARE_LIMIT, "deposit χ² = {chi2:.1}");
}

#[test]
fn an_asymmetric_small_step_fails_the_same_check() {
    let integrals = bin_integrals();
    let total: f64 = integrals.iter().sum();
    let shares: Vec<f64> = integrals.iter().map(|v| v / total).collect();
    let mut mutation = Mutation::new(0.3, 0.05);
    // Every small step drifts by half its size towards +u: the proposal is no longer
    // symmetric, and the ratio f(y)/f(x) no longer the Metropolis–Hastings ratio.
    mutation.drift = 0.5;
    let run = run_chains(mutation, CHAINS, 500);
    let chi2 = chi_square(&run.states, &shares);
    eprintln!("asymmetric: state χ² = {chi2:.1}");
    assert!(
        chi2 > 4.0 * CHI_SQUARE_LIMIT,
        "state histogram χ² = {chi2:.1}"
    );
}

#[test]
fn the_bootstrap_normalisation_is_the_integral() {
    let mut target = Bumps;
    let b = Bootstrap::run(&mut target, 3, 50_000, Mutation::new(0.3, 0.05));
    let exact: f64 = bin_integrals().iter().sum();
    let n = b.len() as f64;
    let var = (0..b.len())
        .map(|i| (b.scalar(i) - b.normalisation()).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    let z = (b.normalisation() - exact) / (var / n).sqrt();
    assert!(
        z.abs() < 4.0,
        "b = {} against {exact}: z = {z:.2}",
        b.normalisation()
    );
    // Resampling picks ∝ scalar: a uniform u lands on a sample with weight.
    for k in 0..100 {
        let i = b.pick(k as f32 / 100.0).unwrap();
        assert!(b.scalar(i) > 0.0);
    }
}

/// ∫ f of the toy integrand over the unit square.
fn total() -> f64 {
    bin_integrals().iter().sum()
}

#[test]
fn deposits_combined_with_the_large_steps_are_the_bin_integrals() {
    let integrals = bin_integrals();
    // c need not be b (nor anything of the bootstrap's): any scale keeps the expectation.
    for scale in [total(), 4.0 * total(), 0.25 * total()] {
        let run = run_chains_with(Mutation::new(0.3, 0.05), CHAINS, 500, |b| {
            b.combine_large_steps(ScaleEstimate {
                c: scale,
                vectors: 0,
                invalid: 0,
            })
        });
        let chi2 = chi_square(&run.deposits, &integrals);
        eprintln!("large steps combined, c = {scale:.3}: deposit χ² = {chi2:.1}");
        assert!(
            chi2 < CHI_SQUARE_LIMIT,
            "c = {scale}: deposit χ² = {chi2:.1}"
        );
    }
}

#[test]
fn large_step_weights_of_the_wrong_probability_fail_the_same_check() {
    let integrals = bin_integrals();
    // Weights for large steps twice as frequent as the chains draw: the large steps'
    // share is deposited at half its weight, the floor between the bumps too dark.
    let run = run_chains_with(Mutation::new(0.3, 0.05), CHAINS, 500, |b| {
        b.combine_large_steps_as(0.6, total())
    });
    let chi2 = chi_square(&run.deposits, &integrals);
    eprintln!("large steps combined with p = 0.6 for 0.3: deposit χ² = {chi2:.1}");
    assert!(chi2 > 4.0 * CHI_SQUARE_LIMIT, "deposit χ² = {chi2:.1}");
}

#[test]
fn the_scale_estimate_is_the_integral_from_its_own_vectors() {
    let mutation = Mutation::new(0.3, 0.05);
    let ScaleEstimate {
        c,
        vectors,
        invalid,
    } = scale_estimate(&mut Bumps, 3, 50_000, mutation);
    let b = Bootstrap::run(&mut Bumps, 3, 50_000, mutation);
    assert_eq!((vectors, invalid), (50_000, 0));
    // Within 4σ of ∫ f (σ of f's spread over 50,000 vectors is below 0.5% of it here) ...
    assert!(
        (c / total() - 1.0).abs() < 0.02,
        "c = {c} against {}",
        total()
    );
    // ... and drawn apart from the bootstrap of the same seed.
    assert_ne!(c, b.normalisation());
}

/// Work units of a 4×4 tile (16 mutations per sample index) of `seed`.
fn unit(seed: u64, sample_begin: u32, sample_count: u32) -> WorkUnit {
    WorkUnit {
        x0: 4,
        y0: 0,
        x1: 8,
        y1: 4,
        sample_begin,
        sample_count,
        seed,
    }
}

/// The deposits (raster, value) and counts of `units`, in order, through one [`TileChains`]
/// with chains of `length`.
fn tile_deposits(units: &[WorkUnit], length: u64) -> (Vec<(Vec2, Rgb)>, ChainCounts) {
    let mut target = Bumps;
    let bootstrap = Bootstrap::run(&mut target, 5, 4096, Mutation::new(0.3, 0.05));
    let chains = TileChains::default();
    let mut buffers = ChainBuffers::default();
    let mut counts = ChainCounts::default();
    let mut out = Vec::new();
    for u in units {
        render_unit_in_chains(
            &mut target,
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
}

#[test]
fn a_tile_chain_cut_into_units_is_the_whole_chain() {
    // 96 mutations in chains of 40: boundaries at 40 and 80 fall inside units of 16.
    let (whole, whole_counts) = tile_deposits(&[unit(1, 0, 6)], 40);
    let pieces: Vec<WorkUnit> = (0..6).map(|s| unit(1, s, 1)).collect();
    let (cut, cut_counts) = tile_deposits(&pieces, 40);
    assert_eq!(whole_counts.mutations, 96);
    assert_eq!(whole_counts.chains, 3);
    assert_eq!(cut_counts, whole_counts);
    assert_eq!(cut, whole);
}

#[test]
fn a_unit_without_its_parked_chain_starts_its_own() {
    // Units 3..6 alone (the first unit of a distributed part): a chain of their own from
    // m = 48, then the chain of m = 80; the same mutations, other numbers.
    let (whole, _) = tile_deposits(&[unit(1, 0, 6)], 40);
    let (part, counts) = tile_deposits(&[unit(1, 3, 3)], 40);
    assert_eq!(counts.mutations, 48);
    assert_eq!(counts.chains, 2);
    assert_ne!(part, whole[whole.len() - part.len()..]);
    // A chain parked by another render seed is not continued: seed 2's unit 1 after seed
    // 1's unit 0 is seed 2's unit 1 alone.
    let (after_other, _) = tile_deposits(&[unit(1, 0, 1), unit(2, 1, 1)], 40);
    let (alone, _) = tile_deposits(&[unit(2, 1, 1)], 40);
    assert_eq!(after_other[after_other.len() - alone.len()..], alone[..]);
}

#[test]
fn chain_length_zero_runs_one_chain_per_sample_index() {
    // The plugins' `chain_length = 0`: render_unit's chains, a tile's pixels long each.
    let (chained, counts) = tile_deposits(&[unit(1, 0, 6)], 0);
    assert_eq!(counts.chains, 6);
    let mut target = Bumps;
    let bootstrap = Bootstrap::run(&mut target, 5, 4096, Mutation::new(0.3, 0.05));
    let (mut buffers, mut direct_counts, mut direct) =
        (ChainBuffers::default(), ChainCounts::default(), Vec::new());
    super::units::render_unit(
        &mut target,
        &bootstrap,
        &unit(1, 0, 6),
        &mut buffers,
        &mut direct_counts,
        &mut |s: Splat| direct.push((s.raster, s.value)),
    );
    assert_eq!(direct_counts, counts);
    assert_eq!(direct, chained);
}
