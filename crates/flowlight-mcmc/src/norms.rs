//! Quality norms of a mutation mix (thesis §5.5).
//!
//! Every mutation step ends in one event of each pair: a **domain hit** (a valid proposal) or
//! a **domain miss**, and for a hit an **acceptance** (the chain moves) or a **rejection**.
//! The *strength* of an event is its count over all steps; a *streak* is a run of consecutive
//! steps with that event within one chain. Good mixes have high acceptance strength, low miss
//! strength, and short rejection and miss streaks (long streaks pile energy into one pixel).

/// The four events.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// The chain moved to the proposal.
    Accept = 0,
    /// The proposal was valid but not taken.
    Reject = 1,
    /// A valid proposal (a domain hit).
    Hit = 2,
    /// No proposal (a domain miss).
    Miss = 3,
}

/// The four events in counter order.
pub const EVENTS: [Event; 4] = [Event::Accept, Event::Reject, Event::Hit, Event::Miss];

impl Event {
    /// The event's name in statistics counters.
    pub fn name(self) -> &'static str {
        match self {
            Event::Accept => "acceptance",
            Event::Reject => "rejection",
            Event::Hit => "domain_hit",
            Event::Miss => "domain_miss",
        }
    }
}

/// Counters of one strategy (or of all together): steps, events, and per event the number of
/// streaks, their total length and the longest.
#[derive(Clone, Copy, Debug, Default)]
pub struct Tally {
    /// Steps recorded.
    pub steps: u64,
    /// Steps with each event.
    pub events: [u64; 4],
    /// Streaks (maximal runs within a chain) of each event.
    pub streaks: [u64; 4],
    /// Total length of each event's streaks.
    pub streak_total: [u64; 4],
    /// Longest streak of each event.
    pub streak_max: [u64; 4],
    /// Length of the run in progress per event (0 when the last step had another event).
    run: [u64; 4],
}

impl Tally {
    /// Records a step: whether the proposal was valid and, if so, whether the chain moved.
    pub fn record(&mut self, valid: bool, accepted: bool) {
        self.steps += 1;
        let happened = [valid && accepted, valid && !accepted, valid, !valid];
        for (e, &on) in happened.iter().enumerate() {
            if on {
                self.events[e] += 1;
                self.run[e] += 1;
            } else {
                self.close(e);
            }
        }
    }

    fn close(&mut self, e: usize) {
        if self.run[e] > 0 {
            self.streaks[e] += 1;
            self.streak_total[e] += self.run[e];
            self.streak_max[e] = self.streak_max[e].max(self.run[e]);
            self.run[e] = 0;
        }
    }

    /// Ends the current chain: runs in progress become streaks.
    pub fn end_chain(&mut self) {
        for e in 0..4 {
            self.close(e);
        }
    }

    /// Share of the steps with event `e` (0 before any step).
    pub fn strength(&self, e: Event) -> f64 {
        if self.steps == 0 {
            0.0
        } else {
            self.events[e as usize] as f64 / self.steps as f64
        }
    }

    /// Mean length of event `e`'s streaks (0 when there is none).
    pub fn mean_streak(&self, e: Event) -> f64 {
        let i = e as usize;
        if self.streaks[i] == 0 {
            0.0
        } else {
            self.streak_total[i] as f64 / self.streaks[i] as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alternating_and_blocked_sequences_differ_in_streaks_not_strength() {
        // The thesis' example: RARA… versus AAA…RRR…, 200 steps each.
        let mut alternating = Tally::default();
        for i in 0..200 {
            alternating.record(true, i % 2 == 1);
        }
        alternating.end_chain();
        let mut blocked = Tally::default();
        for i in 0..200 {
            blocked.record(true, i < 100);
        }
        blocked.end_chain();
        for t in [&alternating, &blocked] {
            assert_eq!(t.strength(Event::Reject), 0.5);
            assert_eq!(t.strength(Event::Hit), 1.0);
            assert_eq!(t.strength(Event::Miss), 0.0);
        }
        assert_eq!(alternating.mean_streak(Event::Reject), 1.0);
        assert_eq!(blocked.mean_streak(Event::Reject), 100.0);
        assert_eq!(blocked.streak_max[Event::Accept as usize], 100);
    }

    #[test]
    fn misses_break_hit_streaks() {
        let mut t = Tally::default();
        for valid in [true, true, false, false, false, true] {
            t.record(valid, false);
        }
        t.end_chain();
        assert_eq!(t.streaks[Event::Hit as usize], 2);
        assert_eq!(t.mean_streak(Event::Miss), 3.0);
        assert_eq!(t.mean_streak(Event::Hit), 1.5);
    }
}
