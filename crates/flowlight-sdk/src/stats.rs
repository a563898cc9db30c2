//! Typed statistics: counters an integrator declares once, adds to per work unit, and the
//! host merges over units and reports (the render summary and the `.stats.json` beside the
//! image).
//!
//! An integrator declares its counters in [`Integrator::create`](crate::Integrator::create)
//! through the [`StatsBuilder`] it is handed, and a mutation in
//! [`Mutation::create`](crate::Mutation::create) the same way (ABI 6); the builder returns a
//! typed handle per counter:
//!
//! | declaration | per-unit value | merged over units | reported |
//! |---|---|---|---|
//! | [`StatsBuilder::sum`] → [`Counter`] | `Σ x` of [`Stats::add`] | `Σ units` | the sum |
//! | [`StatsBuilder::max`] → [`Counter`] | `max x` of [`Stats::add`] | `max units` | the maximum |
//! | [`StatsBuilder::ratio`] → [`Ratio`] | — | — | `num / den` of two counters (0 when `den = 0`) |
//!
//! The same rule ([`StatMerge::combine`]) adds a value within a unit and merges units, so a
//! counter's total does not depend on how the image was cut into units (sums and maxima are
//! associative and commutative; floating-point sums up to rounding). Ratios are formed only
//! from the merged totals — the mean of per-unit ratios would weight small units like big
//! ones.
//!
//! The SDK keeps the declared names and specs alive with the instance and hands the host the
//! raw [`StatSpec`] list itself; a plugin never sees a pointer or an index. The host reports
//! a mutation's counter `c` as `NAME.c` (NAME the mutation's plugin name, `NAME#2` for its
//! second entry in the list) after the integrator's own, in the group an integrator such as
//! ERPT gives the strategy's own counters; a name the integrator already declared there
//! (ERPT: `NAME.mutations`, `NAME.acceptance`, …) is refused when the render is created, with a
//! one-line error naming the counter.
//!
//! ```
//! use flowlight_sdk::stats::{Stats, StatsBuilder};
//!
//! let mut b = StatsBuilder::new();
//! let chains = b.sum("chains");
//! let seeds = b.sum("seeds");
//! let longest = b.max("longest_chain");
//! b.ratio("chains_per_seed", chains, seeds);
//!
//! // What the host does for one work unit: zeroed slots, one per declared counter.
//! let mut slots = vec![0.0; b.len()];
//! let mut stats = Stats::new(&mut slots);
//! stats.add(seeds, 1.0);
//! stats.add(chains, 3.0);
//! stats.add(longest, 16.0);
//! stats.add(longest, 9.0);
//! assert_eq!(stats.get(chains), 3.0);
//! assert_eq!(stats.get(longest), 16.0);
//! ```

use crate::abi::{StatDisplay, StatList, StatMerge, StatSpec, StrRef};

/// Most counters (sums, maxima and ratios together) one integrator may declare. The host
/// allocates one `f64` per counter per work unit in flight and merges them under a lock, so
/// the list must stay small; ERPT with [`crate::MAX_MUTATIONS`] strategies declares 237.
pub const MAX_COUNTERS: usize = 1024;

/// Handle of a summed or maximised counter, returned by [`StatsBuilder::sum`] and
/// [`StatsBuilder::max`]. Only meaningful with the [`Stats`] of the instance that declared it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Counter {
    index: u32,
    merge: StatMerge,
}

/// Handle of a derived counter `numerator / denominator`, returned by
/// [`StatsBuilder::ratio`]. Nothing is added to it: the host computes it from the totals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ratio {
    index: u32,
}

impl Ratio {
    /// Position of the ratio in the declaration order (as reported by the host).
    pub fn index(self) -> usize {
        self.index as usize
    }
}

impl Counter {
    /// Position of the counter in the declaration order (as reported by the host).
    pub fn index(self) -> usize {
        self.index as usize
    }

    /// How the counter combines values.
    pub fn merge(self) -> StatMerge {
        self.merge
    }
}

impl StatMerge {
    /// Combines `x` into `acc`: `acc + x` for [`StatMerge::Sum`], `max(acc, x)` for
    /// [`StatMerge::Max`], nothing for [`StatMerge::Ratio`] (formed from totals at the end).
    /// [`Stats::add`] uses it within a unit and the host uses it to merge units.
    #[inline]
    pub fn combine(self, acc: &mut f64, x: f64) {
        match self {
            StatMerge::Sum => *acc += x,
            StatMerge::Max => *acc = acc.max(x),
            StatMerge::Ratio => {}
        }
    }
}

/// Declares an integrator's counters; handed to [`Integrator::create`](crate::Integrator::create).
///
/// Names are free text, unique within the integrator; a `group.name` form (e.g.
/// `total.accept_strength`) is shown one line per group by the CLI. A name declared twice, an
/// empty name or more than [`MAX_COUNTERS`] counters make `create` fail with a message
/// naming the counter (reported after `create` returns, so declaring stays infallible).
#[derive(Debug, Default)]
pub struct StatsBuilder {
    names: Vec<Box<str>>,
    specs: Vec<(StatMerge, u32, u32, StatDisplay)>,
    error: Option<String>,
}

impl StatsBuilder {
    /// An empty list.
    pub fn new() -> StatsBuilder {
        StatsBuilder::default()
    }

    /// Number of counters declared so far (ratios included): the slots a unit gets.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// True when nothing is declared.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    fn push(
        &mut self,
        name: String,
        merge: StatMerge,
        (num, den): (u32, u32),
        display: StatDisplay,
    ) -> u32 {
        if self.error.is_none() {
            if name.is_empty() {
                self.error = Some("statistics: a counter has an empty name".into());
            } else if self.names.iter().any(|n| **n == *name) {
                self.error = Some(format!("statistics: counter '{name}' is declared twice"));
            } else if self.names.len() == MAX_COUNTERS {
                self.error = Some(format!(
                    "statistics: counter '{name}' is one more than the {MAX_COUNTERS} an integrator may declare (flowlight_sdk::stats::MAX_COUNTERS)"
                ));
            }
        }
        let index = self.names.len() as u32;
        self.names.push(name.into_boxed_str());
        self.specs.push((merge, num, den, display));
        index
    }

    /// A counter whose per-unit values and units are summed (events, totals), shown as a
    /// number ([`StatDisplay::Number`]).
    pub fn sum(&mut self, name: impl Into<String>) -> Counter {
        self.sum_as(name, StatDisplay::Number)
    }

    /// A summed counter shown as `display` in the render summary.
    pub fn sum_as(&mut self, name: impl Into<String>, display: StatDisplay) -> Counter {
        let index = self.push(name.into(), StatMerge::Sum, (0, 0), display);
        Counter {
            index,
            merge: StatMerge::Sum,
        }
    }

    /// A counter that keeps the largest value added (longest streak, image size), shown as
    /// a number.
    pub fn max(&mut self, name: impl Into<String>) -> Counter {
        self.max_as(name, StatDisplay::Number)
    }

    /// A maximised counter shown as `display` in the render summary.
    pub fn max_as(&mut self, name: impl Into<String>, display: StatDisplay) -> Counter {
        let index = self.push(name.into(), StatMerge::Max, (0, 0), display);
        Counter {
            index,
            merge: StatMerge::Max,
        }
    }

    /// A derived counter: total of `numerator` / total of `denominator` (0 when the
    /// denominator's total is 0), shown as a number.
    pub fn ratio(
        &mut self,
        name: impl Into<String>,
        numerator: Counter,
        denominator: Counter,
    ) -> Ratio {
        self.ratio_as(name, numerator, denominator, StatDisplay::Number)
    }

    /// A derived counter shown as `display` in the render summary (e.g.
    /// [`StatDisplay::Percent`] for a share of events).
    pub fn ratio_as(
        &mut self,
        name: impl Into<String>,
        numerator: Counter,
        denominator: Counter,
        display: StatDisplay,
    ) -> Ratio {
        let index = self.push(
            name.into(),
            StatMerge::Ratio,
            (numerator.index, denominator.index),
            display,
        );
        Ratio { index }
    }

    /// How counter `name` is shown, if it is declared (for tests of a declaration).
    pub fn display_of(&self, name: &str) -> Option<StatDisplay> {
        let i = self.names.iter().position(|n| **n == *name)?;
        Some(self.specs[i].3)
    }

    /// The first declaration error, if any.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// Freezes the list into the table the SDK's glue keeps alive with the instance.
    pub(crate) fn finish(self) -> Result<StatTable, String> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let specs = self
            .names
            .iter()
            .zip(&self.specs)
            .map(
                |(name, &(merge, numerator, denominator, display))| StatSpec {
                    name: StrRef::new(name),
                    merge,
                    numerator,
                    denominator,
                    display,
                },
            )
            .collect();
        Ok(StatTable {
            _names: self.names,
            specs,
        })
    }
}

/// The frozen counter list: the specs point into `_names`, which are boxed and never move
/// or change while the table lives.
#[derive(Debug)]
pub(crate) struct StatTable {
    _names: Vec<Box<str>>,
    specs: Vec<StatSpec>,
}

impl StatTable {
    pub(crate) fn specs(&self) -> &[StatSpec] {
        &self.specs
    }

    /// The list the host reads (null for no counters); valid while the table lives.
    pub(crate) fn list(&self) -> StatList {
        StatList {
            specs: if self.specs.is_empty() {
                std::ptr::null()
            } else {
                self.specs.as_ptr()
            },
            count: self.specs.len(),
        }
    }
}

/// One work unit's counters, zeroed by the host; handed to
/// [`Integrator::render`](crate::Integrator::render) and
/// [`Mutation::propose`](crate::Mutation::propose).
///
/// An integrator's `Stats` also carries, after its own counters, the slots of the counters
/// its mutation strategies declared; [`MutationSet::propose`](crate::MutationSet::propose)
/// hands each strategy its own part.
#[derive(Debug)]
pub struct Stats<'a> {
    slots: &'a mut [f64],
    /// Slots of the owner's own counters; those after it belong to its mutations.
    own: usize,
}

impl<'a> Stats<'a> {
    /// Counters over `slots` (one per declared counter). The host, and tests that drive an
    /// integrator or a mutation directly, build it; a plugin only receives it.
    pub fn new(slots: &'a mut [f64]) -> Stats<'a> {
        let own = slots.len();
        Stats { slots, own }
    }

    /// Counters over `slots` whose first `own` belong to the integrator and the rest to its
    /// mutation strategies (the SDK's glue builds it from what the host passes).
    pub(crate) fn with_mutation_slots(slots: &'a mut [f64], own: usize) -> Stats<'a> {
        let own = own.min(slots.len());
        Stats { slots, own }
    }

    /// The slots of a mutation's counters: `count` from `offset` on among the mutation slots;
    /// `None` when this unit carries none for it (an integrator driven by a test with only
    /// its own slots).
    pub(crate) fn mutation_slots(&mut self, offset: u32, count: u32) -> Option<&mut [f64]> {
        let begin = self.own.checked_add(offset as usize)?;
        let end = begin.checked_add(count as usize)?;
        self.slots.get_mut(begin..end)
    }

    /// Adds `x` to a counter: summed for [`StatsBuilder::sum`], the larger kept for
    /// [`StatsBuilder::max`].
    ///
    /// # Panics
    /// With a handle from another plugin's builder that is out of range (the SDK's glue
    /// turns the panic into an error naming the plugin).
    #[inline]
    pub fn add(&mut self, counter: Counter, x: f64) {
        let slot = self.slots[..self.own]
            .get_mut(counter.index as usize)
            .expect("statistics counter from another integrator's StatsBuilder");
        counter.merge.combine(slot, x);
    }

    /// The counter's value in this unit so far.
    pub fn get(&self, counter: Counter) -> f64 {
        self.slots[..self.own]
            .get(counter.index as usize)
            .copied()
            .unwrap_or(0.0)
    }
}

/// Merges one unit's values into running totals, both indexed like `specs` (host side).
pub fn merge(specs: &[StatSpec], total: &mut [f64], unit: &[f64]) {
    for ((s, t), u) in specs.iter().zip(total.iter_mut()).zip(unit) {
        s.merge.combine(t, *u);
    }
}

/// Names and final values of the counters, ratios formed from the totals (0 where the
/// denominator is 0) (host side).
///
/// # Safety
/// The specs' names must be valid (the loaded plugin's, while its instance lives).
pub unsafe fn resolve(specs: &[StatSpec], total: &[f64]) -> Vec<(String, f64)> {
    specs
        .iter()
        .enumerate()
        .map(|(i, s)| {
            // SAFETY: the caller guarantees the names.
            let name = unsafe { s.name.as_str() }.to_string();
            let value = match s.merge {
                StatMerge::Ratio => {
                    let num = total.get(s.numerator as usize).copied().unwrap_or(0.0);
                    let den = total.get(s.denominator as usize).copied().unwrap_or(0.0);
                    if den != 0.0 {
                        num / den
                    } else {
                        0.0
                    }
                }
                _ => total.get(i).copied().unwrap_or(0.0),
            };
            (name, value)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn handles_index_in_declaration_order_and_carry_their_kind() {
        let mut b = StatsBuilder::new();
        let a = b.sum("a");
        let m = b.max("m");
        let r = b.ratio("a_per_m", a, m);
        assert_eq!((a.index(), m.index(), r.index()), (0, 1, 2));
        assert_eq!((a.merge(), m.merge()), (StatMerge::Sum, StatMerge::Max));
        let table = b.finish().unwrap();
        let specs = table.specs();
        assert_eq!(specs.len(), 3);
        assert_eq!(specs[2].merge, StatMerge::Ratio);
        assert_eq!((specs[2].numerator, specs[2].denominator), (0, 1));
        // SAFETY: the table owns the names.
        assert_eq!(unsafe { specs[1].name.as_str() }, "m");
    }

    #[test]
    fn add_sums_or_keeps_the_maximum() {
        let mut b = StatsBuilder::new();
        let s = b.sum("s");
        let m = b.max("m");
        let mut slots = vec![0.0; b.len()];
        let mut st = Stats::new(&mut slots);
        for x in [3.0, -1.0, 2.5] {
            st.add(s, x);
            st.add(m, x);
        }
        assert_eq!(st.get(s), 4.5);
        assert_eq!(st.get(m), 3.0);
        assert_eq!(slots, [4.5, 3.0]);
    }

    #[test]
    fn merging_units_equals_one_unit_with_every_value_and_ratios_use_totals() {
        let mut b = StatsBuilder::new();
        let hits = b.sum("hits");
        let tries = b.sum("tries");
        b.max("longest");
        b.ratio("hit_rate", hits, tries);
        let table = b.finish().unwrap();
        let specs = table.specs();
        // Unit 1: 1 hit in 4 tries (streak 7); unit 2: 5 hits in 6 tries (streak 2). The mean
        // of the per-unit rates would be (0.25 + 0.8333) / 2 = 0.5417; the total's is 0.6.
        let units = [[1.0, 4.0, 7.0, 0.0], [5.0, 6.0, 2.0, 0.0]];
        let mut total = vec![0.0; specs.len()];
        for u in &units {
            merge(specs, &mut total, u);
        }
        // SAFETY: the table owns the names.
        let r = unsafe { resolve(specs, &total) };
        let names: Vec<&str> = r.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["hits", "tries", "longest", "hit_rate"]);
        assert_eq!(r[0].1, 6.0);
        assert_eq!(r[1].1, 10.0);
        assert_eq!(r[2].1, 7.0);
        assert_eq!(r[3].1, 0.6);
        // A zero denominator reports 0, not NaN.
        let r = unsafe { resolve(specs, &[0.0; 4]) };
        assert_eq!(r[3].1, 0.0);
    }

    #[test]
    fn duplicate_empty_and_too_many_names_are_refused_by_name() {
        let mut b = StatsBuilder::new();
        b.sum("seeds");
        b.max("seeds");
        b.sum("other");
        let e = b.finish().unwrap_err();
        assert_eq!(e, "statistics: counter 'seeds' is declared twice");

        let mut b = StatsBuilder::new();
        b.sum("");
        assert!(b.finish().unwrap_err().contains("empty name"));

        let mut b = StatsBuilder::new();
        for i in 0..MAX_COUNTERS {
            b.sum(format!("c{i}"));
        }
        assert!(b.error().is_none());
        b.sum("one_more");
        let e = b.finish().unwrap_err();
        assert!(e.contains("'one_more'") && e.contains("1024"), "{e}");
    }

    #[test]
    fn a_mutation_gets_the_slots_after_the_integrators_own() {
        // The integrator declared 2 counters; two mutations declared 1 and 2.
        let mut slots = vec![0.0; 5];
        let mut stats = Stats::with_mutation_slots(&mut slots, 2);
        let mut b = StatsBuilder::new();
        let own = b.sum("own");
        stats.add(own, 1.0);
        stats.mutation_slots(1, 2).unwrap()[1] = 9.0;
        stats.mutation_slots(0, 1).unwrap()[0] = 4.0;
        assert!(stats.mutation_slots(2, 2).is_none(), "past the end");
        assert_eq!(slots, [1.0, 0.0, 4.0, 0.0, 9.0]);
        // An integrator's own handle never reaches the mutations' slots.
        let mut slots = vec![0.0; 3];
        let mut stats = Stats::with_mutation_slots(&mut slots, 1);
        let mut b = StatsBuilder::new();
        b.sum("a");
        let second = b.sum("b");
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            stats.add(second, 1.0);
        }));
        assert!(caught.is_err());
    }

    #[test]
    #[should_panic(expected = "another integrator's StatsBuilder")]
    fn a_foreign_handle_panics_instead_of_writing_elsewhere() {
        let mut other = StatsBuilder::new();
        other.sum("a");
        let far = other.sum("b");
        let mut slots = vec![0.0; 1];
        Stats::new(&mut slots).add(far, 1.0);
    }
}
