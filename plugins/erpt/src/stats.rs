//! The counters ERPT reports to the host: totals, and the quality norms of §5.5 for all
//! strategies together (group `total`) and for each one (group named after the strategy).
//!
//! Per group g: `g.mutations` (steps), per event e ∈ {accept, reject, domain hit, domain
//! miss} the count `g.e`, its streaks `g.e_streaks`, their total length `g.e_streak_total`
//! and longest `g.e_streak_max`; derived: the strength `g.e_strength` = `g.e` / `g.mutations`
//! and the mean streak `g.e_mean_streak` = `g.e_streak_total` / `g.e_streaks`. Globals:
//! `chains_per_seed` = chains / seeds, `deposits_per_pixel` = deposits / image pixels,
//! `mean_quantum` = Σ e_d / units.
//!
//! The split and the seeds: `camera_samples` (camera paths traced for seeds, once per unit),
//! `seeds` (stored seeds: paths with an estimate), `seeds_per_sample`, `mcpt_part_seeds`
//! (seeds outside the chains' part, deposited directly), `part_misses` (proposals outside it),
//! `units_without_chains` (units path-traced because no path of the scene can be in the part);
//! with BDPT seeds `seeds_outside_target` (seeds whose path the target function gives no
//! energy, deposited at their pixel) and `seeds_outside_flange` (light-tracing seeds that start
//! outside their unit's flanged tile; their chains run all the same).
//!
//! Each counter declares how the render summary shows it ([`StatDisplay`]): per group the
//! steps, the strengths (as percentages), the mean and longest streaks; the event counts,
//! streak totals and costs per group only in the `.stats.json`; seconds as seconds.
//!
//! Costs (§5.5 leaves them out; they decide whether a mixture pays): per group g
//! `g.propose_seconds` (time in the strategy's `propose`), `g.density_calls` and
//! `g.density_seconds` (the mixture density asks every strategy for T(y→z) and T(z→y): 2k calls
//! per step with k strategies, reported under the strategy asked), their ratios per mutation
//! `g.propose_seconds_per_mutation`, `g.density_calls_per_mutation`; globally `measure_calls` and
//! `measure_seconds` (target function at proposals), `seed_seconds` (tracing the unit's seeds)
//! and `flow_seconds` (everything the chains do). Seconds are summed over threads; the
//! per-step ones (propose, density, measure) are estimates from one step in
//! [`crate::flow::STEP_TIMING_STRIDE`], as reading the clock at every step cost 8% of a render.

use flowlight_mcmc::norms::{Tally, EVENTS};
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::StatDisplay;

/// What one strategy's steps cost: time proposing, density calls and their time.
#[derive(Clone, Copy, Debug, Default)]
pub struct Costs {
    pub propose_seconds: f64,
    pub density_calls: u64,
    pub density_seconds: f64,
}

impl Costs {
    pub fn add(&mut self, o: &Costs) {
        self.propose_seconds += o.propose_seconds;
        self.density_calls += o.density_calls;
        self.density_seconds += o.density_seconds;
    }
}

/// The counters of one quality-norm group.
#[derive(Clone, Debug)]
pub struct GroupCounters {
    pub mutations: Counter,
    pub events: [Counter; 4],
    pub streaks: [Counter; 4],
    pub streak_total: [Counter; 4],
    pub streak_max: [Counter; 4],
    pub propose_seconds: Counter,
    pub density_calls: Counter,
    pub density_seconds: Counter,
}

/// Handles of every counter of an ERPT instance, declared on the SDK's builder.
#[derive(Clone, Debug)]
pub struct Counters {
    pub seeds: Counter,
    pub seeds_skipped: Counter,
    pub seeds_capped: Counter,
    pub chains: Counter,
    pub deposits: Counter,
    pub invalid_proposals: Counter,
    pub quantum_sum: Counter,
    pub units: Counter,
    pub image_pixels: Counter,
    pub camera_samples: Counter,
    pub mcpt_part_seeds: Counter,
    pub part_misses: Counter,
    pub units_without_chains: Counter,
    /// BDPT seeds whose path the chains' target function gives no energy, deposited at their
    /// pixel (`lib.rs`, seeds = "bdpt").
    pub seeds_outside_target: Counter,
    /// BDPT seeds (t = 1) that start outside their unit's flanged tile.
    pub seeds_outside_flange: Counter,
    pub measure_calls: Counter,
    pub measure_seconds: Counter,
    pub seed_seconds: Counter,
    pub flow_seconds: Counter,
    /// Group 0: all strategies; group i ≥ 1: strategy i − 1.
    pub groups: Vec<GroupCounters>,
}

impl Counters {
    /// Declares the counters for the given strategy names (unique, e.g. `drill`, `drill#2`).
    pub fn declare(b: &mut StatsBuilder, strategies: &[String]) -> Counters {
        let seeds = b.sum("seeds");
        let seeds_skipped = b.sum("seeds_skipped_invalid");
        let seeds_capped = b.sum("seeds_capped");
        let chains = b.sum("chains");
        let deposits = b.sum("deposits");
        let invalid_proposals = b.sum("proposals_invalid");
        let quantum_sum = b.sum("quantum_sum");
        let units = b.sum("units");
        let image_pixels = b.max("image_pixels");
        let camera_samples = b.sum("camera_samples");
        let mcpt_part_seeds = b.sum("mcpt_part_seeds");
        let part_misses = b.sum("part_misses");
        let units_without_chains = b.sum("units_without_chains");
        let seeds_outside_target = b.sum("seeds_outside_target");
        let seeds_outside_flange = b.sum("seeds_outside_flange");
        let measure_calls = b.sum("measure_calls");
        let measure_seconds = b.sum_as("measure_seconds", StatDisplay::Seconds);
        let seed_seconds = b.sum_as("seed_seconds", StatDisplay::Seconds);
        let flow_seconds = b.sum_as("flow_seconds", StatDisplay::Seconds);
        let names: Vec<&str> = std::iter::once("total")
            .chain(strategies.iter().map(String::as_str))
            .collect();
        let groups: Vec<GroupCounters> = names
            .iter()
            .map(|g| {
                // The summary's line per group: steps, strengths, mean and longest
                // streaks; the rest only in the JSON.
                let per_event = |b: &mut StatsBuilder, suffix: &str, max: bool| {
                    EVENTS.map(|e| {
                        let name = format!("{g}.{}{suffix}", e.name());
                        if max {
                            b.max_as(name, StatDisplay::Number)
                        } else {
                            b.sum_as(name, StatDisplay::Hidden)
                        }
                    })
                };
                let hidden = |b: &mut StatsBuilder, name: &str| {
                    b.sum_as(format!("{g}.{name}"), StatDisplay::Hidden)
                };
                GroupCounters {
                    mutations: b.sum(format!("{g}.mutations")),
                    events: per_event(b, "", false),
                    streaks: per_event(b, "_streaks", false),
                    streak_total: per_event(b, "_streak_total", false),
                    streak_max: per_event(b, "_streak_max", true),
                    propose_seconds: hidden(b, "propose_seconds"),
                    density_calls: hidden(b, "density_calls"),
                    density_seconds: hidden(b, "density_seconds"),
                }
            })
            .collect();
        b.ratio("chains_per_seed", chains, seeds);
        b.ratio("deposits_per_pixel", deposits, image_pixels);
        b.ratio("mean_quantum", quantum_sum, units);
        b.ratio("seeds_per_sample", seeds, camera_samples);
        for (g, c) in names.iter().zip(&groups) {
            b.ratio_as(
                format!("{g}.density_calls_per_mutation"),
                c.density_calls,
                c.mutations,
                StatDisplay::Hidden,
            );
            b.ratio_as(
                format!("{g}.propose_seconds_per_mutation"),
                c.propose_seconds,
                c.mutations,
                StatDisplay::Hidden,
            );
            for (ei, e) in EVENTS.iter().enumerate() {
                b.ratio_as(
                    format!("{g}.{}_strength", e.name()),
                    c.events[ei],
                    c.mutations,
                    StatDisplay::Percent,
                );
            }
            for (ei, e) in EVENTS.iter().enumerate() {
                b.ratio(
                    format!("{g}.{}_mean_streak", e.name()),
                    c.streak_total[ei],
                    c.streaks[ei],
                );
            }
        }
        Counters {
            seeds,
            seeds_skipped,
            seeds_capped,
            chains,
            deposits,
            invalid_proposals,
            quantum_sum,
            units,
            image_pixels,
            camera_samples,
            mcpt_part_seeds,
            part_misses,
            units_without_chains,
            seeds_outside_target,
            seeds_outside_flange,
            measure_calls,
            measure_seconds,
            seed_seconds,
            flow_seconds,
            groups,
        }
    }

    /// Adds costs into group `g`'s counters.
    pub fn add_costs(&self, stats: &mut Stats, g: usize, c: &Costs) {
        let k = &self.groups[g];
        stats.add(k.propose_seconds, c.propose_seconds);
        stats.add(k.density_calls, c.density_calls as f64);
        stats.add(k.density_seconds, c.density_seconds);
    }

    /// Adds a tally into group `g`'s counters.
    pub fn add_tally(&self, stats: &mut Stats, g: usize, t: &Tally) {
        let c = &self.groups[g];
        stats.add(c.mutations, t.steps as f64);
        for e in 0..4 {
            stats.add(c.events[e], t.events[e] as f64);
            stats.add(c.streaks[e], t.streaks[e] as f64);
            stats.add(c.streak_total[e], t.streak_total[e] as f64);
            stats.add(c.streak_max[e], t.streak_max[e] as f64);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eight_strategies_fit_and_names_are_unique() {
        let names: Vec<String> = (0..flowlight_sdk::MAX_MUTATIONS)
            .map(|i| format!("s{i}"))
            .collect();
        let mut b = StatsBuilder::new();
        let c = Counters::declare(&mut b, &names);
        assert!(b.error().is_none(), "{:?}", b.error());
        // 19 globals + 4 ratios, and per group (total + 8) 20 counters + 10 ratios.
        assert_eq!(b.len(), 19 + 4 + 9 * (20 + 10));
        assert_eq!(c.groups.len(), 9);
        // The summary shows what the declarations ask, whatever the names.
        assert_eq!(
            b.display_of("s3.acceptance_strength"),
            Some(StatDisplay::Percent)
        );
        assert_eq!(
            b.display_of("s3.acceptance_streaks"),
            Some(StatDisplay::Hidden)
        );
        assert_eq!(
            b.display_of("total.rejection_streak_max"),
            Some(StatDisplay::Number)
        );
        assert_eq!(b.display_of("flow_seconds"), Some(StatDisplay::Seconds));
        assert_eq!(b.display_of("chains_per_seed"), Some(StatDisplay::Number));
    }

    #[test]
    fn a_tally_lands_in_its_group_only() {
        let mut b = StatsBuilder::new();
        let c = Counters::declare(&mut b, &["drill".into()]);
        let mut slots = vec![0.0; b.len()];
        let mut stats = Stats::new(&mut slots);
        let mut t = Tally::default();
        t.record(true, true);
        t.record(true, true);
        t.record(false, false);
        t.end_chain();
        c.add_tally(&mut stats, 1, &t);
        assert_eq!(stats.get(c.groups[1].mutations), 3.0);
        assert_eq!(stats.get(c.groups[0].mutations), 0.0);
        // Acceptance, rejection, domain hit, domain miss (a miss is neither accepted nor
        // rejected); two acceptances in a row are one streak of 2.
        let events: Vec<f64> = c.groups[1].events.iter().map(|&e| stats.get(e)).collect();
        assert_eq!(events, [2.0, 0.0, 2.0, 1.0]);
        assert_eq!(stats.get(c.groups[1].streak_max[0]), 2.0);
        assert_eq!(stats.get(c.groups[1].streaks[0]), 1.0);
    }
}
