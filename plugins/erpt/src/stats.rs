//! The counters ERPT reports to the host: totals, and the quality norms of §5.5 for all
//! strategies together and for each one.

use flowlight_mcmc::norms::{Tally, EVENTS};
use flowlight_sdk::abi::StatSpec;
use flowlight_sdk::{stat, stat_ratio, StatMerge};

pub const SEEDS: usize = 0;
pub const SEEDS_SKIPPED: usize = 1;
pub const SEEDS_CAPPED: usize = 2;
pub const CHAINS: usize = 3;
pub const DEPOSITS: usize = 4;
pub const INVALID_PROPOSALS: usize = 5;
pub const QUANTUM_SUM: usize = 6;
pub const UNITS: usize = 7;
pub const IMAGE_PIXELS: usize = 8;
const GLOBALS: usize = 9;
/// Counters per group: steps, 4 events, and per event streak count, total and max.
const PER_GROUP: usize = 1 + 4 + 4 + 4 + 4;

/// Index of group `g`'s first counter (group 0: all strategies; g ≥ 1: strategy g − 1).
fn base(g: usize) -> usize {
    GLOBALS + g * PER_GROUP
}

/// Builds the counter list for the given strategy names. The specs live as long as the
/// plugin (leaked once per integrator instance: the host reads them through a pointer).
pub fn specs(strategies: &[String]) -> &'static [StatSpec] {
    let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
    let mut out = vec![
        stat("seeds", StatMerge::Sum),
        stat("seeds_skipped_invalid", StatMerge::Sum),
        stat("seeds_capped", StatMerge::Sum),
        stat("chains", StatMerge::Sum),
        stat("deposits", StatMerge::Sum),
        stat("proposals_invalid", StatMerge::Sum),
        stat("quantum_sum", StatMerge::Sum),
        stat("units", StatMerge::Sum),
        stat("image_pixels", StatMerge::Max),
    ];
    let groups: Vec<String> = std::iter::once("total".to_string())
        .chain(strategies.iter().cloned())
        .collect();
    for g in &groups {
        out.push(stat(leak(format!("{g}.mutations")), StatMerge::Sum));
        for e in EVENTS {
            out.push(stat(leak(format!("{g}.{}", e.name())), StatMerge::Sum));
        }
        for e in EVENTS {
            out.push(stat(
                leak(format!("{g}.{}_streaks", e.name())),
                StatMerge::Sum,
            ));
        }
        for e in EVENTS {
            out.push(stat(
                leak(format!("{g}.{}_streak_total", e.name())),
                StatMerge::Sum,
            ));
        }
        for e in EVENTS {
            out.push(stat(
                leak(format!("{g}.{}_streak_max", e.name())),
                StatMerge::Max,
            ));
        }
    }
    out.push(stat_ratio("chains_per_seed", CHAINS as u32, SEEDS as u32));
    out.push(stat_ratio(
        "deposits_per_pixel",
        DEPOSITS as u32,
        IMAGE_PIXELS as u32,
    ));
    out.push(stat_ratio("mean_quantum", QUANTUM_SUM as u32, UNITS as u32));
    for (gi, g) in groups.iter().enumerate() {
        let b = base(gi) as u32;
        for (ei, e) in EVENTS.iter().enumerate() {
            out.push(stat_ratio(
                leak(format!("{g}.{}_strength", e.name())),
                b + 1 + ei as u32,
                b,
            ));
        }
        for (ei, e) in EVENTS.iter().enumerate() {
            let streaks = b + 5 + ei as u32;
            out.push(stat_ratio(
                leak(format!("{g}.{}_mean_streak", e.name())),
                streaks + 4,
                streaks,
            ));
        }
    }
    Box::leak(out.into_boxed_slice())
}

/// Adds a tally into group `g`'s counters.
pub fn add_tally(stats: &mut [f64], g: usize, t: &Tally) {
    let b = base(g);
    stats[b] += t.steps as f64;
    for e in 0..4 {
        stats[b + 1 + e] += t.events[e] as f64;
        stats[b + 5 + e] += t.streaks[e] as f64;
        stats[b + 9 + e] += t.streak_total[e] as f64;
        stats[b + 13 + e] = stats[b + 13 + e].max(t.streak_max[e] as f64);
    }
}

/// Number of counter slots used with `strategies` strategies (must fit the host's slots).
pub fn slot_count(strategies: usize) -> usize {
    base(strategies + 1)
}
