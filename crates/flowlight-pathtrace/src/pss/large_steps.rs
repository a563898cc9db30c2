//! Kelemen et al.'s combination of the large steps with the chain (2002): the large steps as
//! a second, independent sampling technique, weighed against the chain by the balance
//! heuristic, as their paper and LuxCore's Metropolis sampler do.
//!
//! A chain's mutations are two samplers of the same integral ∫ F:
//!
//! * the **chain**: its states follow the target f / b (b = ∫ f), and with the bootstrap's
//!   b̂, E[b̂ · h(X)] = ∫ f h for every h fixed before the bootstrap ([`super::chain`]);
//! * the **large steps**: with probability p (`large_step`) a mutation's proposal is an
//!   independent uniform vector, whatever the chain's state.
//!
//! With a constant c > 0 (an estimate of b, see below) split F = F·w_c + F·w_l by the weights
//!
//! ```text
//! w_c(u) = f(u) / (f(u) + p·c),     w_l(u) = p·c / (f(u) + p·c)     (sum 1)
//! ```
//!
//! and estimate ∫ F·w_c with the chain's expected-value splatting of h = F / (f + p·c), and
//! ∫ F·w_l with the large steps: a large-step proposal y deposits F(y)·w_l(y) / p, whose
//! expectation per mutation is p · ∫ F·w_l / p. A mutation from x with proposal y and
//! acceptance a then deposits
//!
//! ```text
//! the proposal's splats × (a·b̂ + [large]·c) / (f(y) + p·c),
//! the current state's splats × (1 − a)·b̂ / (f(x) + p·c),
//! ```
//!
//! with expectation ∫ F·w_c + ∫ F·w_l = ∫ F per mutation, for every c: the choice of c moves
//! only the variance. With c = b (Kelemen's choice, LuxCore's running mean of the large steps'
//! luminance) a dark sample (f ≪ p·b) found by a large step weighs F/p, as an independent
//! sample of a path tracer, instead of b̂/f(x) of whatever bright state the chain is in; a
//! bright one (f ≫ p·b) weighs as the chain's. p = 0 gives the plain splatting back.
//!
//! **c must not come from the bootstrap the chain starts from**: the weights would then
//! depend on b̂, E[b̂ · h_b̂(X)] ≠ ∫ f h_b, and the image would be biased by O(1/B). So c is
//! the mean scalar of an independent set of vectors ([`scale_estimate`], seeded apart from
//! the bootstrap's); an estimate from a few thousand vectors is good enough, since c only
//! weighs the two techniques.

use super::bootstrap::{evaluate, ScaleEstimate};
use super::chain::PssTarget;
use super::samples::Mutation;
use flowlight_core::rng::Rng;

/// The balance-heuristic weights of a chain's deposits with its large steps (module
/// documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LargeStepWeights {
    /// p · c: the large steps' density of uniform vectors in units of the target's.
    pc: f64,
    /// c, the estimate of b the weights use.
    scale: f64,
}

impl LargeStepWeights {
    /// The weights for large-step probability `probability` and scale `scale` (an estimate
    /// of b independent of the chain's bootstrap); `None` when either is 0 (the plain
    /// expected-value splatting).
    pub fn new(probability: f32, scale: f64) -> Option<LargeStepWeights> {
        let pc = probability as f64 * scale;
        (pc > 0.0 && pc.is_finite()).then_some(LargeStepWeights { pc, scale })
    }

    /// The weight of the proposal's splats: (a·b̂ + \[large\]·c) / (f(y) + p·c).
    pub fn proposal(&self, a: f64, b: f64, f_y: f64, large: bool) -> f64 {
        let large = if large { self.scale } else { 0.0 };
        (a * b + large) / (f_y + self.pc)
    }

    /// The weight of the current state's splats: (1 − a)·b̂ / (f(x) + p·c).
    pub fn current(&self, a: f64, b: f64, f_x: f64) -> f64 {
        (1.0 - a) * b / (f_x + self.pc)
    }
}

/// The seed of vector `i` of the scale estimate of a render with seed `seed` (apart from the
/// bootstrap's vectors).
pub(super) fn scale_seed(seed: u64, i: u32) -> u64 {
    Rng::hash(&[seed, 0x004b_454c_454d_454e, i as u64])
}

/// c: the mean scalar target of `count` independent vectors of `target` drawn from `seed`,
/// apart from the bootstrap's (module documentation), and how many were invalid (f = 0); on
/// one thread ([`super::bootstrap`] shares the vectors out).
pub fn scale_estimate<T: PssTarget>(
    target: &mut T,
    seed: u64,
    count: u32,
    mutation: Mutation,
) -> ScaleEstimate {
    let evaluated = evaluate(target, seed, true, 0..count, mutation);
    ScaleEstimate::from_pieces([&evaluated])
}
