//! Stationarity of the chain on a 2-D toy integrand, and the normalisation of its splats.
//!
//! The target reads one pair u = (u₁, u₂) and splats f(u) (a sum of bumps on a floor) at
//! raster position u. Independent chains give independent per-chain histograms (8 × 8 bins)
//! of the states; each bin's mean over chains is z-tested against the bin's share of ∫f, and
//! the z² summed (≈ χ² with 64 degrees of freedom when the chain is right).

use super::chain::{run_chain, Bootstrap, ChainBuffers, ChainCounts, PssTarget, Splat};
use super::samples::{Mutation, PrimarySamples};
use flowlight_core::sampler::SampleStream;
use flowlight_core::Rgb;
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
    let mut target = Bumps;
    let bootstrap = Bootstrap::run(&mut target, 17, 20_000, mutation);
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
