//! The corrected Equal Deposition Flow (thesis §5.3, Algorithm 2, correct version).
//!
//! A seed x with Monte Carlo estimate X_f starts ⌊U + lum(X_f)/(N·e_d)⌋ chains of N steps.
//! Each step proposes z from the current state y with a strategy chosen by weight, accepts
//! it with a = min(1, lum f(z)/lum f(y) · T(z→y)/T(y→z)), and deposits the expected values
//! (§5.5): a·e_d·f(z)/lum f(z) at z and (1 − a)·e_d·f(y)/lum f(y) at y. Each deposit carries the
//! colour of the state it lands on — never the seed's colour, which was Batty's mistake. A
//! domain miss deposits the whole quantum at y.

use crate::settings::{ErptSettings, MixtureRatio};
use crate::stats::{Costs, Counters};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_mcmc::measurement;
use flowlight_mcmc::norms::Tally;
use flowlight_mcmc::regenerate::within_depth;
use flowlight_sdk::{Film, MutationSet, Scene, Stats, Tracer};
use std::time::Instant;

/// The flow times one step in this many (its proposal, target function and density calls)
/// and credits each timed step this many times over. A clock read costs about as much as a
/// small mutation's arithmetic: timing every step took 8% of a glass-caustic render's samples
/// (`perf`: `__vdso_clock_gettime` 7.3%, `Instant::elapsed` 0.7%). The steps timed are every
/// `STEP_TIMING_STRIDE`-th, whatever their strategy or outcome, so the per-strategy seconds
/// are unbiased estimates; call counts stay exact.
pub const STEP_TIMING_STRIDE: u32 = 32;

/// The flow asks the host whether to stop (time budget spent, Ctrl-C) before each seed and
/// once every this many steps of a chain: one 8×8 unit can hold millions of steps (seconds),
/// and a question is a clock read and an indirect call, about one small step's cost, so
/// 1 in 256 costs under 0.5% and answers within about a millisecond.
pub const STOP_CHECK_STRIDE: u32 = 256;

/// Decides which steps [`Flow`] times (see [`STEP_TIMING_STRIDE`]).
#[derive(Default)]
struct StepTimer {
    step: u32,
}

impl StepTimer {
    /// Whether this step is timed; advances to the next step.
    fn next(&mut self) -> bool {
        self.step = self.step.wrapping_add(1);
        self.step.is_multiple_of(STEP_TIMING_STRIDE)
    }

    /// The clock at the start of a timed part of a step, `None` when the step is not timed.
    fn start(timed: bool) -> Option<Instant> {
        timed.then(Instant::now)
    }

    /// Adds the time since `start`, scaled by the stride, to `seconds` (nothing when the
    /// step was not timed).
    fn credit(start: Option<Instant>, seconds: &mut f64) {
        if let Some(t) = start {
            *seconds += STEP_TIMING_STRIDE as f64 * t.elapsed().as_secs_f64();
        }
    }
}

/// Per-unit working state of the chains.
pub struct Flow<'a> {
    pub scene: &'a Scene<'a>,
    pub tracer: &'a Tracer<'a>,
    pub settings: &'a ErptSettings,
    pub mutations: &'a MutationSet<'a>,
    /// Selection probability per strategy: the host's normalised weights, or `auto`'s.
    pub weights: &'a [f64],
    pub counters: &'a Counters,
    pub total: Tally,
    pub per_strategy: Vec<Tally>,
    pub costs: Vec<Costs>,
    pub measure_calls: u64,
    pub measure_seconds: f64,
    pub part_misses: u64,
    /// A seed whose path the target function gives no energy goes to its pixel with its
    /// estimate (counted as `seeds_outside_target`) instead of being skipped: set for BDPT
    /// seeds, some of whose paths (a Dirac light seen through a Dirac chain) no chain can hold.
    pub deposit_unmeasured: bool,
    timer: StepTimer,
    pub proposal: Box<Path>,
    pub state: Box<Path>,
}

/// Deposits into the film, applying the consecutive-sample filter when it is on.
struct Depositor<'f, 'a> {
    film: &'f mut Film<'a>,
    max_consecutive: u32,
    last_pixel: (i64, i64),
    run: u32,
    deposits: u64,
}

impl Depositor<'_, '_> {
    fn deposit(&mut self, path: &Path, value: Rgb) {
        if value.is_black() {
            return;
        }
        let pixel = (path.raster.x.floor() as i64, path.raster.y.floor() as i64);
        if self.max_consecutive > 0 {
            if pixel == self.last_pixel {
                self.run += 1;
            } else {
                self.last_pixel = pixel;
                self.run = 1;
            }
            if self.run > self.max_consecutive {
                return; // the biased filter drops the excess
            }
        }
        self.film.deposit(
            pixel.0 as f32 + 0.5,
            pixel.1 as f32 + 0.5,
            path.layer,
            value,
        );
        self.deposits += 1;
    }
}

/// f / lum(f): the colour a deposit at a state carries.
fn colour(f: Rgb) -> Rgb {
    f / f.luminance()
}

/// How many chains a seed starts and the quantum each of their steps deposits (§5.2,
/// Algorithm 2): ⌊U + lum(X_f)/(N·e_d)⌋ chains of quantum e_d, U uniform in [0, 1), whose
/// expected energy N·e_d·E[chains] is lum(X_f); when that count exceeds `cap`, `cap` chains of
/// quantum lum(X_f)/(N·cap): the same energy, exactly. The flag says the cap applied.
pub fn chain_count(u: f64, lum_seed: f64, n: f64, quantum: f64, cap: f64) -> (u64, f64, bool) {
    let wanted = (u + lum_seed / (n * quantum)).floor();
    if wanted > cap {
        (cap as u64, lum_seed / (n * cap), true)
    } else {
        (wanted as u64, quantum, false)
    }
}

/// Chooses a strategy by `weights` for `u` uniform in [0, 1), as
/// [`MutationSet::choose`] does with the host's weights: the first `i` with
/// `u < Σ_{j ≤ i} wⱼ`, never one of weight 0 (the last of positive weight when rounding leaves
/// `u` past the last sum).
pub fn choose(weights: &[f64], u: f64) -> usize {
    let (mut acc, mut last_positive) = (0.0, 0);
    for (i, &w) in weights.iter().enumerate() {
        if w > 0.0 {
            acc += w;
            last_positive = i;
            if u < acc {
                return i;
            }
        }
    }
    last_positive
}

/// Metropolis–Hastings acceptance of the corrected flow (§5.3, with the mixture or the
/// selected strategy's transition ratio, §5.4):
///
/// ```text
/// a(y → z) = min(1, lum f(z) / lum f(y) · T(z→y) / T(y→z))
/// ```
///
/// `None` when the ratio or f(z) is NaN, infinite or negative: such a proposal is a counted
/// rejection, never a state. 0 when f(z) is black. `f_y` is the current state's, lum f(y) > 0.
pub fn acceptance(f_y: Rgb, f_z: Rgb, ratio: f64) -> Option<f64> {
    let lum_z = f_z.luminance() as f64;
    if !(ratio.is_finite() && ratio >= 0.0 && f_z.is_valid_radiance() && lum_z.is_finite()) {
        return None;
    }
    Some(if lum_z > 0.0 {
        (lum_z / f_y.luminance() as f64 * ratio).min(1.0)
    } else {
        0.0
    })
}

/// The expected-value deposits of one step (§5.5), at the proposal z and at the current state
/// y, each in the colour of the state it lands on:
///
/// ```text
/// at z:  a · e_d · f(z) / lum f(z)        at y:  (1 − a) · e_d · f(y) / lum f(y)
/// ```
///
/// Their luminances sum to e_d whatever a is: every step deposits one quantum.
pub fn expected_deposits(a: f64, e: f32, f_y: Rgb, f_z: Rgb) -> (Rgb, Rgb) {
    let at_z = if a > 0.0 {
        colour(f_z) * (a as f32 * e)
    } else {
        Rgb::ZERO
    };
    let at_y = if a < 1.0 {
        colour(f_y) * ((1.0 - a) as f32 * e)
    } else {
        Rgb::ZERO
    };
    (at_z, at_y)
}

impl<'a> Flow<'a> {
    pub fn new(
        scene: &'a Scene<'a>,
        tracer: &'a Tracer<'a>,
        settings: &'a ErptSettings,
        mutations: &'a MutationSet<'a>,
        weights: &'a [f64],
        counters: &'a Counters,
    ) -> Self {
        Flow {
            scene,
            tracer,
            settings,
            mutations,
            weights,
            counters,
            total: Tally::default(),
            per_strategy: vec![Tally::default(); mutations.len()],
            costs: vec![Costs::default(); mutations.len()],
            measure_calls: 0,
            measure_seconds: 0.0,
            part_misses: 0,
            deposit_unmeasured: false,
            timer: StepTimer::default(),
            proposal: Box::new(Path::empty()),
            state: Box::new(Path::empty()),
        }
    }

    /// T(from → to) of the mixture, Σ p(sᵢ)·T^{sᵢ}(from → to): one density call per strategy,
    /// each counted, and timed when the step is, under its strategy.
    fn mixture_density(
        mutations: &MutationSet,
        weights: &[f64],
        costs: &mut [Costs],
        timed: bool,
        from: &Path,
        to: &Path,
    ) -> Result<f64, String> {
        let mut t = 0.0;
        for (i, c) in costs.iter_mut().enumerate().take(mutations.len()) {
            let start = StepTimer::start(timed);
            let d = mutations.density(i, from, to)?;
            StepTimer::credit(start, &mut c.density_seconds);
            c.density_calls += 1;
            t += weights[i] * d;
        }
        Ok(t)
    }

    /// Runs the chains of one seed. `estimate` is the seed's X_f, `quantum` the unit's e_d.
    pub fn run_seed(
        &mut self,
        seed: &Path,
        estimate: Rgb,
        quantum: f64,
        rng: &mut Rng,
        film: &mut Film,
        stats: &mut Stats,
    ) -> Result<(), String> {
        let c = self.counters;
        if self.tracer.should_stop() {
            // The host discards or keeps what the unit deposited so far (its doc).
            return Ok(());
        }
        stats.add(c.seeds, 1.0);
        let lum_seed = estimate.luminance() as f64;
        if !(estimate.is_valid_radiance() && lum_seed.is_finite()) {
            stats.add(c.seeds_skipped, 1.0);
            return Ok(());
        }
        if lum_seed == 0.0 || quantum.is_nan() || quantum <= 0.0 {
            return Ok(());
        }
        let f_seed = measurement(self.scene, seed);
        let lum_f_seed = f_seed.luminance();
        if !(f_seed.is_valid_radiance() && lum_f_seed > 0.0 && lum_f_seed.is_finite()) {
            if self.deposit_unmeasured && f_seed.is_black() {
                // Outside the chains' target: path tracing's deposit, unbiased as the split's
                // MCPT part is (the set {f = 0} depends on the path alone).
                stats.add(c.seeds_outside_target, 1.0);
                film.deposit(
                    seed.raster.x.floor() + 0.5,
                    seed.raster.y.floor() + 0.5,
                    seed.layer,
                    estimate,
                );
                return Ok(());
            }
            // The sampler found light the target function does not see (or an overflow): a
            // chain could not start here.
            stats.add(c.seeds_skipped, 1.0);
            return Ok(());
        }
        let (chains, quantum, capped) = chain_count(
            rng.uniform() as f64,
            lum_seed,
            self.settings.chain_length as f64,
            quantum,
            self.settings.max_chains_per_seed as f64,
        );
        if capped {
            stats.add(c.seeds_capped, 1.0);
        }
        let e = quantum as f32;
        let mut dep = Depositor {
            film,
            max_consecutive: self.settings.max_consecutive,
            last_pixel: (i64::MIN, 0),
            run: 0,
            deposits: 0,
        };
        let mut steps_to_check = STOP_CHECK_STRIDE;
        for _ in 0..chains {
            stats.add(c.chains, 1.0);
            *self.state = *seed;
            let mut f_y = f_seed;
            dep.run = 0;
            dep.last_pixel = (i64::MIN, 0);
            for _ in 0..self.settings.chain_length {
                steps_to_check -= 1;
                if steps_to_check == 0 {
                    steps_to_check = STOP_CHECK_STRIDE;
                    if self.tracer.should_stop() {
                        stats.add(c.deposits, dep.deposits as f64);
                        return Ok(());
                    }
                }
                let s = if self.mutations.len() > 1 {
                    choose(self.weights, rng.uniform() as f64)
                } else {
                    0
                };
                let timed = self.timer.next();
                let start = StepTimer::start(timed);
                let proposal = self.mutations.propose(
                    s,
                    self.tracer,
                    rng,
                    &self.state,
                    &mut self.proposal,
                    stats,
                )?;
                StepTimer::credit(start, &mut self.costs[s].propose_seconds);
                // A proposal outside the chains' part of path space, or beyond the seeds' depth
                // limits (a mutation with free chain lengths can make a path longer), has
                // f = 0 in their target: a domain miss, counted.
                let outside = proposal.is_move()
                    && !(within_depth(
                        self.proposal.vertex_count,
                        self.proposal.layer,
                        self.settings.seeds.path_depth,
                        self.settings.seeds.max_ray_depth,
                    ) && self.settings.part.contains(&self.proposal));
                if outside {
                    self.part_misses += 1;
                }
                let Some(transition_ratio) = proposal.transition_ratio().filter(|_| !outside)
                else {
                    dep.deposit(&self.state, colour(f_y) * e);
                    self.total.record(false, false);
                    self.per_strategy[s].record(false, false);
                    continue;
                };
                let start = StepTimer::start(timed);
                let f_z = measurement(self.scene, &self.proposal);
                StepTimer::credit(start, &mut self.measure_seconds);
                self.measure_calls += 1;
                let ratio = match self.settings.mixture {
                    MixtureRatio::Mixture if self.mutations.len() > 1 => {
                        let (m, w, costs) = (self.mutations, self.weights, &mut self.costs);
                        let (y, z) = (&self.state, &self.proposal);
                        let forward = Self::mixture_density(m, w, costs, timed, y, z)?;
                        let reverse = Self::mixture_density(m, w, costs, timed, z, y)?;
                        reverse / forward
                    }
                    _ => transition_ratio as f64,
                };
                let a = acceptance(f_y, f_z, ratio).unwrap_or_else(|| {
                    // Never deposit at, or move to, an invalid state: a counted rejection.
                    stats.add(c.invalid_proposals, 1.0);
                    0.0
                });
                let (at_z, at_y) = expected_deposits(a, e, f_y, f_z);
                dep.deposit(&self.proposal, at_z);
                dep.deposit(&self.state, at_y);
                let accepted = (rng.uniform() as f64) < a;
                if accepted {
                    std::mem::swap(&mut self.state, &mut self.proposal);
                    f_y = f_z;
                }
                self.total.record(true, accepted);
                self.per_strategy[s].record(true, accepted);
            }
            self.total.end_chain();
            for t in &mut self.per_strategy {
                t.end_chain();
            }
        }
        stats.add(c.deposits, dep.deposits as f64);
        Ok(())
    }

    /// Adds the norms gathered so far into the unit's counters.
    pub fn report(&self, stats: &mut Stats) {
        let c = self.counters;
        c.add_tally(stats, 0, &self.total);
        for (i, t) in self.per_strategy.iter().enumerate() {
            c.add_tally(stats, i + 1, t);
        }
        let mut all = Costs::default();
        for (i, k) in self.costs.iter().enumerate() {
            c.add_costs(stats, i + 1, k);
            all.add(k);
        }
        c.add_costs(stats, 0, &all);
        stats.add(c.measure_calls, self.measure_calls as f64);
        stats.add(c.measure_seconds, self.measure_seconds);
        stats.add(c.part_misses, self.part_misses as f64);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One step in the stride is timed, whatever the strategies, and its time is credited the
    /// stride's number of times: over many steps of a known duration the estimate is the
    /// total time.
    #[test]
    fn step_timer_times_one_step_in_the_stride_and_scales_it() {
        let mut timer = StepTimer::default();
        let steps = 8 * STEP_TIMING_STRIDE;
        let timed = (0..steps).filter(|_| timer.next()).count();
        assert_eq!(timed as u32, steps / STEP_TIMING_STRIDE);
        assert!(StepTimer::start(false).is_none());
        let mut seconds = 0.0;
        StepTimer::credit(None, &mut seconds);
        assert_eq!(seconds, 0.0);
        let pause = std::time::Duration::from_millis(2);
        let start = StepTimer::start(true);
        std::thread::sleep(pause);
        StepTimer::credit(start, &mut seconds);
        let credited = seconds / STEP_TIMING_STRIDE as f64;
        assert!(credited >= pause.as_secs_f64(), "{credited}");
    }

    #[test]
    fn chain_counts_keep_the_seed_energy_in_expectation_and_under_the_cap() {
        // E[⌊U + a⌋] = a: over a fine grid of U the mean count is lum X/(N e_d).
        let (n, e_d) = (16.0, 0.01);
        for lum in [0.0, 0.05, 0.16, 0.5, 1.234] {
            let steps = 10_000;
            let total: u64 = (0..steps)
                .map(|i| chain_count((i as f64 + 0.5) / steps as f64, lum, n, e_d, 1e9).0)
                .sum();
            let energy = total as f64 / steps as f64 * n * e_d;
            assert!(
                (energy - lum).abs() < 1e-4 * lum.max(1.0),
                "{lum}: {energy}"
            );
        }
        // Over the cap: the cap's count, each step carrying lum/(N·cap), exactly lum in all.
        let (chains, q, capped) = chain_count(0.3, 1000.0, n, e_d, 64.0);
        assert!(capped && chains == 64);
        assert!((chains as f64 * n * q - 1000.0).abs() < 1e-9);
        assert_eq!(chain_count(0.3, 0.05, n, e_d, 64.0), (0, e_d, false));
    }

    #[test]
    fn acceptance_is_the_metropolis_hastings_ratio_and_refuses_invalid_proposals() {
        let (y, z) = (Rgb::splat(2.0), Rgb::splat(1.0));
        assert!((acceptance(y, z, 1.0).unwrap() - 0.5).abs() < 1e-12);
        assert!((acceptance(y, z, 0.5).unwrap() - 0.25).abs() < 1e-12);
        assert_eq!(acceptance(z, y, 1.0), Some(1.0));
        assert_eq!(acceptance(y, z, 4.0), Some(1.0));
        // Detailed balance of the rule: lum f(y)·a(y→z) = lum f(z)·a(z→y)·(T(z→y)/T(y→z)).
        let r = 0.7;
        let lhs = 2.0 * acceptance(y, z, r).unwrap();
        let rhs = 1.0 * acceptance(z, y, 1.0 / r).unwrap() * r;
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} vs {rhs}");
        assert_eq!(acceptance(y, Rgb::ZERO, 1.0), Some(0.0));
        for bad in [f64::NAN, f64::INFINITY, -1.0] {
            assert_eq!(acceptance(y, z, bad), None);
        }
        assert_eq!(acceptance(y, Rgb::splat(f32::NAN), 1.0), None);
        assert_eq!(acceptance(y, Rgb::new(1.0, -1.0, 1.0), 1.0), None);
    }

    #[test]
    fn each_step_deposits_one_quantum_in_the_colours_of_its_states() {
        let (f_y, f_z) = (Rgb::new(3.0, 0.0, 0.0), Rgb::new(0.0, 0.0, 5.0));
        let e = 0.2f32;
        for a in [0.0, 0.3, 1.0] {
            let (at_z, at_y) = expected_deposits(a, e, f_y, f_z);
            let total = at_z.luminance() + at_y.luminance();
            assert!((total - e).abs() < 1e-6, "a = {a}: {total}");
            // Red stays at y, blue at z: no state lends its colour to the other.
            assert!(at_z.r == 0.0 && at_z.g == 0.0 && at_y.b == 0.0 && at_y.g == 0.0);
            assert!((at_z.luminance() - a as f32 * e).abs() < 1e-6);
        }
        // a = 0 with a black proposal: nothing at z (no 0/0).
        let (at_z, at_y) = expected_deposits(0.0, e, f_y, Rgb::ZERO);
        assert!(at_z == Rgb::ZERO && (at_y.luminance() - e).abs() < 1e-6);
    }
}
