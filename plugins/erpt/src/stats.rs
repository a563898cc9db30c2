//! The counters ERPT reports to the host: totals, and the quality norms of §5.5 for all
//! strategies together (group `total`) and for each one (group named after the strategy).
//!
//! Per group g: `g.mutations` (steps), per event e ∈ {accept, reject, domain hit, domain
//! miss} the count `g.e`, its streaks `g.e_streaks`, their total length `g.e_streak_total`
//! and longest `g.e_streak_max`; derived: the strength `g.e_strength` = `g.e` / `g.mutations`
//! and the mean streak `g.e_mean_streak` = `g.e_streak_total` / `g.e_streaks`. Globals:
//! `chains_per_seed` = chains / seeds, `deposits_per_pixel` = deposits / image pixels,
//! `mean_quantum` = Σ e_d / units.

use flowlight_mcmc::norms::{Tally, EVENTS};
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};

/// The counters of one quality-norm group.
#[derive(Clone, Debug)]
pub struct GroupCounters {
    pub mutations: Counter,
    pub events: [Counter; 4],
    pub streaks: [Counter; 4],
    pub streak_total: [Counter; 4],
    pub streak_max: [Counter; 4],
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
        let names: Vec<&str> = std::iter::once("total")
            .chain(strategies.iter().map(String::as_str))
            .collect();
        let groups: Vec<GroupCounters> = names
            .iter()
            .map(|g| {
                let per_event = |b: &mut StatsBuilder, suffix: &str, max: bool| {
                    EVENTS.map(|e| {
                        let name = format!("{g}.{}{suffix}", e.name());
                        if max {
                            b.max(name)
                        } else {
                            b.sum(name)
                        }
                    })
                };
                GroupCounters {
                    mutations: b.sum(format!("{g}.mutations")),
                    events: per_event(b, "", false),
                    streaks: per_event(b, "_streaks", false),
                    streak_total: per_event(b, "_streak_total", false),
                    streak_max: per_event(b, "_streak_max", true),
                }
            })
            .collect();
        b.ratio("chains_per_seed", chains, seeds);
        b.ratio("deposits_per_pixel", deposits, image_pixels);
        b.ratio("mean_quantum", quantum_sum, units);
        for (g, c) in names.iter().zip(&groups) {
            for (ei, e) in EVENTS.iter().enumerate() {
                b.ratio(
                    format!("{g}.{}_strength", e.name()),
                    c.events[ei],
                    c.mutations,
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
            groups,
        }
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
        // 9 globals + 3 ratios, and per group (total + 8) 17 counters + 8 ratios.
        assert_eq!(b.len(), 9 + 3 + 9 * (17 + 8));
        assert_eq!(c.groups.len(), 9);
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
