//! Kelemen et al.'s primary sample vector (2002), lazily mutated as pbrt-v4's `MLTSampler`
//! does it (Pharr, Jakob and Humphreys, *Physically Based Rendering*, 4th ed., §13.4.3).
//!
//! A path sampler turns uniform numbers u ∈ [0, 1)^∞ into a path; a Markov chain over u
//! ("primary sample space") mutates the numbers instead of the path. Each iteration is
//!
//! * a **large step** (probability `large_step`): every coordinate a fresh uniform number,
//!   an independent proposal, or
//! * a **small step**: every coordinate u_i moved to u_i + σ·z (z standard normal, the
//!   kernel of pbrt-v4's `MLTSampler`), wrapped into [0, 1). The kernel is symmetric
//!   (z and −z equally likely, and the wrap is a symmetric map on the circle), so the
//!   proposal density cancels from the Metropolis–Hastings ratio.
//!
//! Coordinates are mutated lazily, when the path asks for them: each remembers the iteration
//! it was last brought up to date. A coordinate last touched before the latest accepted
//! large step is first a fresh uniform number as of that step; the n small steps since are
//! then one step of σ·√n (a sum of n independent normals of variance σ² is a normal of
//! variance nσ²), so the result is the same in distribution as mutating every coordinate at
//! every iteration. Each coordinate keeps its value from before the current iteration, so a
//! rejected proposal is undone ([`PrimarySamples::reject`]).
//!
//! One vector holds K independent **streams** interleaved (pbrt-v4's `nSampleStreams`):
//! the i-th number of stream k is coordinate i·K + k, so that a bidirectional sampler's
//! camera, light and connection numbers stay at the same coordinates whatever the others
//! draw. [`PrimarySamples::start_stream`] hands out a cursor ([`PssStream`]) that implements
//! [`SampleStream`] and [`BranchStream`].
//!
//! The first state of a vector ([`PrimarySamples::new`]) is a large step: a fresh uniform
//! vector drawn from its seed, so a state is reproduced exactly by its seed and the sampler
//! that reads it (the chains restart bootstrap states that way, [`super::chain`]).

use crate::sampler::BranchStream;
use flowlight_core::rng::Rng;
use flowlight_core::sampler::SampleStream;
use glam::Vec2;
use std::cell::RefCell;

/// The mutation of a primary sample vector: the large-step probability and the small step's
/// size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mutation {
    /// Probability that an iteration is a large step (a fresh independent vector).
    pub large_step: f32,
    /// Standard deviation σ of a small step, per coordinate, in units of the unit interval.
    pub sigma: f32,
    /// A deliberate drift of every small step (added to the normal offset, times σ): makes
    /// the proposal asymmetric, so that the stationarity tests can check that they fail
    /// without symmetry. Zero in every render.
    pub(crate) drift: f32,
}

impl Mutation {
    /// Large steps with probability `large_step`, small steps of standard deviation `sigma`.
    pub fn new(large_step: f32, sigma: f32) -> Mutation {
        Mutation {
            large_step,
            sigma,
            drift: 0.0,
        }
    }

    /// This mutation with every small step drifted by `drift` σ towards +1: an asymmetric
    /// proposal for the stationarity tests, which must fail with it. Never used to render.
    pub fn with_drift(self, drift: f32) -> Mutation {
        Mutation { drift, ..self }
    }
}

/// One coordinate: its value, the iteration it was last brought up to date, and both as they
/// were before the current iteration.
#[derive(Clone, Copy, Debug, Default)]
struct Coordinate {
    value: f32,
    /// 0: never drawn (older than every large step, the first state included).
    modified: u64,
    backup_value: f32,
    backup_modified: u64,
}

#[derive(Clone, Debug)]
struct State {
    coordinates: Vec<Coordinate>,
    rng: Rng,
    mutation: Mutation,
    streams: u32,
    /// The current iteration, from 1 (the first state).
    iteration: u64,
    large_step: bool,
    /// The latest accepted large step (1: the first state).
    last_large_step: u64,
}

/// A primary sample vector under mutation (module documentation). Interior mutability lets
/// the cursors of [`PrimarySamples::start_stream`] draw through a shared reference, as a
/// path sampler clones its stream; the vector is not `Sync`, one per chain.
#[derive(Clone, Debug)]
pub struct PrimarySamples {
    state: RefCell<State>,
}

impl PrimarySamples {
    /// A fresh vector (a large step from nothing) whose coordinates are drawn, in the order
    /// they are first asked for, from the PCG32 stream of `seed`; `streams` streams
    /// interleaved.
    pub fn new(seed: u64, mutation: Mutation, streams: u32) -> PrimarySamples {
        PrimarySamples {
            state: RefCell::new(State {
                coordinates: Vec::new(),
                rng: Rng::new(seed, 0),
                mutation,
                streams: streams.max(1),
                iteration: 1,
                large_step: true,
                last_large_step: 1,
            }),
        }
    }

    /// Draws the coordinates and mutations from here on from the PCG32 stream of `seed`: a
    /// chain restarted from a reproduced state must not repeat another chain's numbers.
    pub fn reseed(&mut self, seed: u64) {
        self.state.get_mut().rng = Rng::new(seed, 0);
    }

    /// Begins the next proposal: a large step with probability `large_step`, else a small
    /// step. Returns whether it is a large step.
    pub fn start_iteration(&mut self) -> bool {
        let s = self.state.get_mut();
        s.iteration += 1;
        s.large_step = s.rng.uniform() < s.mutation.large_step;
        s.large_step
    }

    /// Whether the current iteration is a large step (the first state is one).
    pub fn is_large_step(&self) -> bool {
        self.state.borrow().large_step
    }

    /// Keeps the current proposal.
    pub fn accept(&mut self) {
        let s = self.state.get_mut();
        if s.large_step {
            s.last_large_step = s.iteration;
        }
    }

    /// Undoes the current proposal: every coordinate it touched gets its value back.
    pub fn reject(&mut self) {
        let s = self.state.get_mut();
        let iteration = s.iteration;
        for c in s.coordinates.iter_mut().filter(|c| c.modified == iteration) {
            c.value = c.backup_value;
            c.modified = c.backup_modified;
        }
        s.iteration -= 1;
    }

    /// A cursor at the first number of stream `k` (< the vector's stream count).
    pub fn start_stream(&self, k: u32) -> PssStream<'_> {
        debug_assert!(k < self.state.borrow().streams);
        PssStream {
            samples: self,
            stream: k,
            base: 0,
            stride: 1,
            next: 0,
        }
    }

    /// Coordinates drawn so far (the vector's length).
    pub fn len(&self) -> usize {
        self.state.borrow().coordinates.len()
    }

    /// Whether no coordinate was drawn yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Coordinate `index`, brought up to date with the current iteration.
    fn get(&self, index: usize) -> f32 {
        let mut guard = self.state.borrow_mut();
        let s = &mut *guard;
        if index >= s.coordinates.len() {
            s.coordinates.resize(index + 1, Coordinate::default());
        }
        let c = &mut s.coordinates[index];
        if c.modified == s.iteration {
            return c.value;
        }
        // Up to date with the latest accepted large step: a fresh number as of then.
        if c.modified < s.last_large_step {
            c.value = s.rng.uniform();
            c.modified = s.last_large_step;
        }
        c.backup_value = c.value;
        c.backup_modified = c.modified;
        if s.large_step {
            c.value = s.rng.uniform();
        } else {
            let steps = (s.iteration - c.modified) as f32;
            let m = s.mutation;
            let offset = (standard_normal(&mut s.rng) + m.drift) * m.sigma * steps.sqrt();
            c.value = wrap(c.value + offset);
        }
        c.modified = s.iteration;
        c.value
    }
}

/// A standard normal number (Box–Muller, one of the pair).
fn standard_normal(rng: &mut Rng) -> f32 {
    let u1 = 1.0 - rng.uniform(); // (0, 1]: ln is finite
    let u2 = rng.uniform();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// `v` wrapped into [0, 1).
fn wrap(v: f32) -> f32 {
    let w = v - v.floor();
    // v slightly below an integer can round to exactly 1.
    if w >= 1.0 {
        0.0
    } else {
        w
    }
}

/// A cursor over one stream of a [`PrimarySamples`]: its numbers in order. Cloning copies the
/// position, not the numbers (both cursors read the same vector).
///
/// A branch ([`BranchStream::branch`]`(j, k)`) reads every k-th number of the stream from
/// here on, starting j numbers in: the k branches of a vertex read disjoint coordinates.
#[derive(Clone, Debug)]
pub struct PssStream<'a> {
    samples: &'a PrimarySamples,
    stream: u32,
    /// The stream's numbers this cursor reads: base + t·stride for t = next, next + 1, …
    base: usize,
    stride: usize,
    next: usize,
}

impl PssStream<'_> {
    /// Which number of its stream the next draw is.
    fn advance(&mut self) -> usize {
        let local = self.base + self.next * self.stride;
        self.next += 1;
        let streams = self.samples.state.borrow().streams as usize;
        local * streams + self.stream as usize
    }
}

impl SampleStream for PssStream<'_> {
    #[inline]
    fn uniform(&mut self) -> f32 {
        let index = self.advance();
        self.samples.get(index)
    }

    #[inline]
    fn uniform2(&mut self) -> Vec2 {
        let x = self.uniform();
        Vec2::new(x, self.uniform())
    }
}

impl BranchStream for PssStream<'_> {
    fn branch(&self, j: u32, k: u32) -> Self {
        PssStream {
            samples: self.samples,
            stream: self.stream,
            base: self.base + (self.next + j as usize) * self.stride,
            stride: self.stride * k.max(1) as usize,
            next: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draw(samples: &PrimarySamples, k: u32, n: usize) -> Vec<f32> {
        let mut s = samples.start_stream(k);
        (0..n).map(|_| s.uniform()).collect()
    }

    #[test]
    fn a_state_is_reproduced_by_its_seed() {
        let m = Mutation::new(0.3, 0.01);
        let a = PrimarySamples::new(7, m, 2);
        let b = PrimarySamples::new(7, m, 2);
        assert_eq!(draw(&a, 0, 5), draw(&b, 0, 5));
        assert_eq!(draw(&a, 1, 5), draw(&b, 1, 5));
        // Reading again in the same iteration gives the same numbers.
        assert_eq!(draw(&a, 0, 5), draw(&b, 0, 5));
        assert_ne!(draw(&a, 0, 5), draw(&PrimarySamples::new(8, m, 2), 0, 5));
    }

    #[test]
    fn streams_interleave_and_do_not_disturb_each_other() {
        let m = Mutation::new(0.3, 0.01);
        let a = PrimarySamples::new(3, m, 3);
        let first = draw(&a, 1, 4);
        draw(&a, 0, 10);
        assert_eq!(draw(&a, 1, 4), first);
        assert_eq!(a.len(), 9 * 3 + 1);
    }

    #[test]
    fn a_rejected_small_step_restores_the_state() {
        let mut a = PrimarySamples::new(11, Mutation::new(0.0, 0.05), 1);
        let before = draw(&a, 0, 6);
        assert!(!a.start_iteration());
        let moved = draw(&a, 0, 6);
        assert_ne!(moved, before);
        for (x, y) in before.iter().zip(&moved) {
            let d = (x - y).abs();
            assert!(d.min(1.0 - d) < 0.5, "{x} → {y}");
        }
        a.reject();
        assert_eq!(draw(&a, 0, 6), before);
        // Accepted, the proposal stays.
        a.start_iteration();
        let kept = draw(&a, 0, 6);
        a.accept();
        assert_eq!(draw(&a, 0, 6), kept);
    }

    #[test]
    fn a_large_step_is_a_fresh_vector_and_a_rejected_one_is_undone() {
        let mut a = PrimarySamples::new(5, Mutation::new(1.0, 0.01), 1);
        let before = draw(&a, 0, 4);
        assert!(a.start_iteration());
        let fresh = draw(&a, 0, 4);
        assert!(before.iter().zip(&fresh).all(|(x, y)| x != y));
        a.reject();
        assert_eq!(draw(&a, 0, 4), before);
    }

    #[test]
    fn branches_read_disjoint_coordinates() {
        let a = PrimarySamples::new(9, Mutation::new(0.3, 0.01), 1);
        let mut s = a.start_stream(0);
        s.uniform2();
        let mut b0 = s.branch(0, 2);
        let mut b1 = s.branch(1, 2);
        let x0: Vec<f32> = (0..3).map(|_| b0.uniform()).collect();
        let x1: Vec<f32> = (0..3).map(|_| b1.uniform()).collect();
        let all = draw(&a, 0, 8);
        assert_eq!(x0, vec![all[2], all[4], all[6]]);
        assert_eq!(x1, vec![all[3], all[5], all[7]]);
    }

    #[test]
    fn numbers_stay_in_the_unit_interval() {
        let mut a = PrimarySamples::new(1, Mutation::new(0.1, 0.3), 1);
        for _ in 0..2000 {
            a.start_iteration();
            for x in draw(&a, 0, 3) {
                assert!((0.0..1.0).contains(&x), "{x}");
            }
            a.accept();
        }
    }
}
