//! The counters ERPT reports to the host: totals, and the quality norms of §5.5 for all
//! strategies together and for each one.

use flowlight_mcmc::norms::{Tally, EVENTS};
use flowlight_sdk::abi::StatSpec;
use flowlight_sdk::abi::StrRef;
use flowlight_sdk::StatMerge;

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

/// The counters of one ERPT instance. The instance owns the names the specs point to, so the
/// host can read them for the instance's whole life.
pub struct StatTable {
    _names: Vec<Box<str>>,
    specs: Vec<StatSpec>,
}

// SAFETY: the specs only point into `_names`, which is immutable and owned alongside.
unsafe impl Send for StatTable {}
unsafe impl Sync for StatTable {}

impl StatTable {
    pub fn specs(&self) -> &[StatSpec] {
        &self.specs
    }

    /// The counter list for the given strategy names.
    pub fn new(strategies: &[String]) -> StatTable {
        // (name, merge, numerator, denominator)
        let mut list: Vec<(String, StatMerge, u32, u32)> = [
            "seeds",
            "seeds_skipped_invalid",
            "seeds_capped",
            "chains",
            "deposits",
            "proposals_invalid",
            "quantum_sum",
            "units",
        ]
        .iter()
        .map(|n| (n.to_string(), StatMerge::Sum, 0, 0))
        .collect();
        list.push(("image_pixels".into(), StatMerge::Max, 0, 0));
        let groups: Vec<String> = std::iter::once("total".to_string())
            .chain(strategies.iter().cloned())
            .collect();
        for g in &groups {
            list.push((format!("{g}.mutations"), StatMerge::Sum, 0, 0));
            for suffix in ["", "_streaks", "_streak_total"] {
                for e in EVENTS {
                    list.push((format!("{g}.{}{suffix}", e.name()), StatMerge::Sum, 0, 0));
                }
            }
            for e in EVENTS {
                list.push((format!("{g}.{}_streak_max", e.name()), StatMerge::Max, 0, 0));
            }
        }
        list.push((
            "chains_per_seed".into(),
            StatMerge::Ratio,
            CHAINS as u32,
            SEEDS as u32,
        ));
        list.push((
            "deposits_per_pixel".into(),
            StatMerge::Ratio,
            DEPOSITS as u32,
            IMAGE_PIXELS as u32,
        ));
        list.push((
            "mean_quantum".into(),
            StatMerge::Ratio,
            QUANTUM_SUM as u32,
            UNITS as u32,
        ));
        for (gi, g) in groups.iter().enumerate() {
            let b = base(gi) as u32;
            for (ei, e) in EVENTS.iter().enumerate() {
                list.push((
                    format!("{g}.{}_strength", e.name()),
                    StatMerge::Ratio,
                    b + 1 + ei as u32,
                    b,
                ));
            }
            for (ei, e) in EVENTS.iter().enumerate() {
                let streaks = b + 5 + ei as u32;
                list.push((
                    format!("{g}.{}_mean_streak", e.name()),
                    StatMerge::Ratio,
                    streaks + 4,
                    streaks,
                ));
            }
        }
        let names: Vec<Box<str>> = list
            .iter()
            .map(|(n, ..)| n.clone().into_boxed_str())
            .collect();
        let specs = names
            .iter()
            .zip(&list)
            .map(|(name, &(_, merge, numerator, denominator))| StatSpec {
                name: StrRef::new(name),
                merge,
                numerator,
                denominator,
            })
            .collect();
        StatTable {
            _names: names,
            specs,
        }
    }
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
