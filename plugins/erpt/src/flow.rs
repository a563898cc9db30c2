//! The corrected Equal Deposition Flow (thesis §5.3, Algorithm 2, correct version).
//!
//! A seed x with Monte Carlo estimate X_f starts ⌊U + lum(X_f)/(N·e_d)⌋ chains of N steps.
//! Each step proposes z from the current state y with a strategy chosen by weight, accepts
//! it with a = min(1, lum f(z)/lum f(y) · T(z→y)/T(y→z)), and deposits the expected values
//! (§5.5): a·e_d·f(z)/lum f(z) at z and (1 − a)·e_d·f(y)/lum f(y) at y. Each deposit carries the
//! colour of the state it lands on — never the seed's colour, which was Batty's mistake. A
//! domain miss deposits the whole quantum at y.

use crate::settings::{ErptSettings, MixtureRatio};
use crate::stats::Counters;
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_mcmc::measurement;
use flowlight_mcmc::norms::Tally;
use flowlight_sdk::{Film, MutationSet, Scene, Stats, Tracer};

/// Per-unit working state of the chains.
pub struct Flow<'a> {
    pub scene: &'a Scene<'a>,
    pub tracer: &'a Tracer<'a>,
    pub settings: &'a ErptSettings,
    pub mutations: &'a MutationSet<'a>,
    pub counters: &'a Counters,
    pub total: Tally,
    pub per_strategy: Vec<Tally>,
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

impl<'a> Flow<'a> {
    pub fn new(
        scene: &'a Scene<'a>,
        tracer: &'a Tracer<'a>,
        settings: &'a ErptSettings,
        mutations: &'a MutationSet<'a>,
        counters: &'a Counters,
    ) -> Self {
        Flow {
            scene,
            tracer,
            settings,
            mutations,
            counters,
            total: Tally::default(),
            per_strategy: vec![Tally::default(); mutations.len()],
            proposal: Box::new(Path::empty()),
            state: Box::new(Path::empty()),
        }
    }

    /// T(from → to) of the mixture, Σ p(sᵢ)·T^{sᵢ}(from → to).
    fn mixture_density(&self, from: &Path, to: &Path) -> Result<f64, String> {
        let mut t = 0.0;
        for i in 0..self.mutations.len() {
            t += self.mutations.weight(i) * self.mutations.density(i, from, to)?;
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
            // The sampler found light the target function does not see (or an overflow): a
            // chain could not start here.
            stats.add(c.seeds_skipped, 1.0);
            return Ok(());
        }
        let n = self.settings.chain_length as f64;
        let wanted = (rng.uniform() as f64 + lum_seed / (n * quantum)).floor();
        let cap = self.settings.max_chains_per_seed as f64;
        // A seed that would need more chains than the cap spreads the same energy over the
        // capped number: each deposit carries lum(X_f)/(N·chains) instead of e_d.
        let (chains, quantum) = if wanted > cap {
            stats.add(c.seeds_capped, 1.0);
            (cap as u64, lum_seed / (n * cap))
        } else {
            (wanted as u64, quantum)
        };
        let e = quantum as f32;
        let mut dep = Depositor {
            film,
            max_consecutive: self.settings.max_consecutive,
            last_pixel: (i64::MIN, 0),
            run: 0,
            deposits: 0,
        };
        for _ in 0..chains {
            stats.add(c.chains, 1.0);
            *self.state = *seed;
            let mut f_y = f_seed;
            dep.run = 0;
            dep.last_pixel = (i64::MIN, 0);
            for _ in 0..self.settings.chain_length {
                let s = if self.mutations.len() > 1 {
                    self.mutations.choose(rng.uniform() as f64)
                } else {
                    0
                };
                let proposal =
                    self.mutations
                        .propose(s, self.tracer, rng, &self.state, &mut self.proposal)?;
                if proposal.valid == 0 {
                    dep.deposit(&self.state, colour(f_y) * e);
                    self.total.record(false, false);
                    self.per_strategy[s].record(false, false);
                    continue;
                }
                let f_z = measurement(self.scene, &self.proposal);
                let ratio = match self.settings.mixture {
                    MixtureRatio::Mixture if self.mutations.len() > 1 => {
                        let forward = self.mixture_density(&self.state, &self.proposal)?;
                        let reverse = self.mixture_density(&self.proposal, &self.state)?;
                        reverse / forward
                    }
                    _ => proposal.transition_ratio as f64,
                };
                let lum_z = f_z.luminance() as f64;
                let a = if !(ratio.is_finite()
                    && ratio >= 0.0
                    && f_z.is_valid_radiance()
                    && lum_z.is_finite())
                {
                    // Never deposit at, or move to, an invalid state: a counted rejection.
                    stats.add(c.invalid_proposals, 1.0);
                    0.0
                } else if lum_z > 0.0 {
                    (lum_z / f_y.luminance() as f64 * ratio).min(1.0)
                } else {
                    0.0
                };
                if a > 0.0 {
                    dep.deposit(&self.proposal, colour(f_z) * (a as f32 * e));
                }
                if a < 1.0 {
                    dep.deposit(&self.state, colour(f_y) * ((1.0 - a) as f32 * e));
                }
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
        self.counters.add_tally(stats, 0, &self.total);
        for (i, t) in self.per_strategy.iter().enumerate() {
            self.counters.add_tally(stats, i + 1, t);
        }
    }
}
