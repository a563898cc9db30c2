//! The `Mutation` trait: an ERPT/MCMC perturbation strategy, loadable as its own plugin.
//!
//! A strategy either implements [`Mutation`] by hand (the raw tier: it builds the proposal
//! itself and reports its transition ratio) or, far shorter, describes itself as a policy of
//! the regeneration engine in the `flowlight-mcmc` crate (`flowlight_mcmc::Strategy`, or
//! `flowlight_mcmc::regenerate::propose_with` with a film move of its own), which computes
//! the proposal, its ratio and its density; docs/writing-a-plugin.md shows both.
//!
//! What a strategy returns is a [`Proposal`]: a domain miss, or a move with its transition
//! ratio T(y→x)/T(x→y). It crosses the C ABI as an [`abi::ProposalRecord`](ProposalRecord).

use crate::abi::{
    ErrorBuf, MutationRef, MutationTable, ParamSpec, ParamValue, ProposalRecord, ResolvedList,
    SceneView, StatList, Status, TracerTable,
};
use crate::guard::guard;
use crate::params::{Params, ResolvedTable};
use crate::scene::Scene;
use crate::stats::{StatTable, Stats, StatsBuilder};
use crate::tracer::Tracer;
use flowlight_core::bsdf::Bsdf;
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use std::ffi::c_void;

/// What a mutation proposed from the current path x.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Proposal {
    /// A domain miss: no path of x's length and weak type was found (the chain stays where
    /// it is and deposits there); the proposal path's contents are meaningless.
    Miss,
    /// A proposal y of x's length and weak type was written.
    Move {
        /// Tentative transition density ratio T(y→x) / T(x→y) (thesis §5.4): 0 for a move
        /// the strategy cannot reverse (always rejected), NaN for a degenerate density
        /// (rejected and counted by the integrator).
        transition_ratio: f32,
    },
}

impl Proposal {
    /// A move with ratio 1: a symmetric strategy's.
    pub const SYMMETRIC: Proposal = Proposal::Move {
        transition_ratio: 1.0,
    };

    /// True for [`Proposal::Move`].
    pub fn is_move(self) -> bool {
        matches!(self, Proposal::Move { .. })
    }

    /// The transition ratio of a move; `None` for a miss.
    pub fn transition_ratio(self) -> Option<f32> {
        match self {
            Proposal::Miss => None,
            Proposal::Move { transition_ratio } => Some(transition_ratio),
        }
    }
}

impl From<Proposal> for ProposalRecord {
    fn from(p: Proposal) -> ProposalRecord {
        match p {
            Proposal::Miss => ProposalRecord {
                valid: 0,
                transition_ratio: 0.0,
            },
            Proposal::Move { transition_ratio } => ProposalRecord {
                valid: 1,
                transition_ratio,
            },
        }
    }
}

impl From<ProposalRecord> for Proposal {
    /// `valid = 0` is a miss; any other value a move.
    fn from(r: ProposalRecord) -> Proposal {
        if r.valid == 0 {
            Proposal::Miss
        } else {
            Proposal::Move {
                transition_ratio: r.transition_ratio,
            }
        }
    }
}

/// Proposes a new path from the current state of a Markov chain (thesis §5.4).
///
/// A mutation keeps the path length and the weak path type; otherwise it reports a domain
/// miss. (The regeneration engine of `flowlight-mcmc` may change the length of a chain of
/// mirrors where every Dirac vertex of both paths is one, its "free chain lengths"; the
/// conformance kit accepts that.) A move's ratio is T(y→x)/T(x→y); [`Mutation::density`] gives T itself so that an
/// integrator can form the mixture density Σ p(sᵢ)·T^{sᵢ} of several strategies.
///
/// `propose` and `density` are called from many threads at once with the same instance:
/// keep `self` read-only and draw every random number from the `rng` given (the chain's own
/// stream).
pub trait Mutation: Sized + Send + Sync + 'static {
    /// Name the config uses (`plugin = "NAME"` in `[[integrator.mutations]]`).
    const NAME: &'static str;
    /// One line for `flowlight plugins`.
    const DESCRIPTION: &'static str;
    /// Parameters the plugin accepts; the host refuses others.
    const PARAMS: &'static [ParamSpec];

    /// Builds an instance; `scene` stays valid for its whole life. Counters the strategy
    /// reports are declared on `stats` (reported as `NAME.counter`); keep the handles for
    /// [`Mutation::propose`].
    fn create(
        params: &Params,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<Self, String>;

    /// Fills `proposal` from `current` and says whether it is a move, with its ratio.
    /// `stats` holds the counters declared in `create`, for the integrator's work unit.
    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
        stats: &mut Stats,
    ) -> Result<Proposal, String>;

    /// Transition density T(from → to) of this strategy, in the measure of the integrator's
    /// target function (0 when `to` cannot be proposed from `from`).
    fn density(&self, from: &Path, to: &Path) -> f64;
}

/// A mutation and the per-material BSDFs its scene borrows ([`Scene::material_bsdfs`]).
struct MutationInstance<T> {
    /// Declared first, so dropped first.
    mutation: T,
    /// The parameter values `create` read, for the host's metadata.
    resolved: ResolvedTable,
    /// The counters the mutation declared, read by the host through [`StatList`].
    stats: StatTable,
    _bsdfs: Box<[Option<Bsdf>]>,
}

unsafe extern "C" fn create<T: Mutation>(
    params: *const ParamValue,
    param_count: usize,
    scene: *const SceneView,
    instance: *mut *mut c_void,
    stats: *mut StatList,
    resolved: *mut ResolvedList,
    err: *mut ErrorBuf,
) -> Status {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        guard(err, || {
            let params = Params::from_raw(params, param_count);
            let mut scene = Scene::from_view(&*scene);
            // The instance keeps the table and drops it after the mutation, the scene's only holder.
            let bsdfs = scene.attach_constant_bsdfs();
            let mut builder = StatsBuilder::new();
            let mutation = T::create(&params, scene, &mut builder)?;
            let inst = Box::new(MutationInstance {
                mutation,
                resolved: ResolvedTable::new(params.resolved()),
                stats: builder.finish()?,
                _bsdfs: bsdfs,
            });
            // The entries and specs live in the box, which does not move until `destroy`.
            *resolved = inst.resolved.list();
            *stats = inst.stats.list();
            *instance = Box::into_raw(inst) as *mut c_void;
            Ok(())
        })
    }
}

unsafe extern "C" fn destroy<T: Mutation>(instance: *mut c_void) {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        if !instance.is_null() {
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                drop(Box::from_raw(instance as *mut MutationInstance<T>))
            }));
        }
    }
}

unsafe extern "C" fn propose<T: Mutation>(
    instance: *const c_void,
    tracer: *const TracerTable,
    rng: *mut Rng,
    current: *const Path,
    proposal: *mut Path,
    out: *mut ProposalRecord,
    stats: *mut f64,
    stat_count: usize,
    err: *mut ErrorBuf,
) -> Status {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        guard(err, || {
            let inst = &*(instance as *const MutationInstance<T>);
            let declared = inst.stats.specs().len();
            if stat_count < declared || (declared > 0 && stats.is_null()) {
                return Err(format!(
                    "the integrator passed {stat_count} statistics slots for {declared} declared counters"
                ));
            }
            let slots = if stats.is_null() || declared == 0 {
                &mut [][..]
            } else {
                std::slice::from_raw_parts_mut(stats, declared)
            };
            let tracer = Tracer::new(&*tracer);
            let p = inst.mutation.propose(
                &tracer,
                &mut *rng,
                &*current,
                &mut *proposal,
                &mut Stats::new(slots),
            )?;
            *out = p.into();
            Ok(())
        })
    }
}

unsafe extern "C" fn density<T: Mutation>(
    instance: *const c_void,
    from: *const Path,
    to: *const Path,
    out: *mut f64,
    err: *mut ErrorBuf,
) -> Status {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        guard(err, || {
            let inst = &(*(instance as *const MutationInstance<T>)).mutation;
            *out = inst.density(&*from, &*to);
            Ok(())
        })
    }
}

/// The function table for `T`; used by [`crate::export_mutation!`].
pub const fn table<T: Mutation>() -> MutationTable {
    MutationTable {
        create: create::<T>,
        destroy: destroy::<T>,
        propose: propose::<T>,
        density: density::<T>,
    }
}

/// Most mutation strategies one mutation list may name. The host refuses a longer list with
/// a one-line error before loading any of them; integrators size per-strategy state (ERPT's
/// quality norms: 25 counters per strategy) by it.
pub const MAX_MUTATIONS: usize = 8;

/// The mutation strategies an integrator was given, with their weights as the host
/// normalised them: finite, ≥ 0, summing to 1 (at most [`MAX_MUTATIONS`] of them).
#[derive(Clone, Copy)]
pub struct MutationSet<'a> {
    refs: &'a [MutationRef],
}

// SAFETY: mutation instances are Send + Sync (trait bound) and outlive the integrator.
unsafe impl Send for MutationSet<'_> {}
unsafe impl Sync for MutationSet<'_> {}

impl<'a> MutationSet<'a> {
    /// # Safety
    /// `refs` must point to `count` valid entries whose instances outlive `'a`.
    pub unsafe fn from_raw(refs: *const MutationRef, count: usize) -> Self {
        // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
        // ABI rules in `abi.rs` for the C entry points).
        unsafe {
            let refs = if refs.is_null() || count == 0 {
                &[][..]
            } else {
                std::slice::from_raw_parts(refs, count)
            };
            MutationSet { refs }
        }
    }

    /// No strategies.
    pub fn empty() -> Self {
        MutationSet { refs: &[] }
    }

    /// Number of strategies.
    pub fn len(&self) -> usize {
        self.refs.len()
    }

    /// True when the set holds no strategy.
    pub fn is_empty(&self) -> bool {
        self.refs.is_empty()
    }

    /// Plugin name of strategy `i`.
    pub fn name(&self, i: usize) -> &'a str {
        // SAFETY: the host keeps the names alive with the instances.
        unsafe { self.refs[i].name.as_str() }
    }

    /// Selection probability p(sᵢ) of strategy `i` (normalised by the host).
    pub fn weight(&self, i: usize) -> f64 {
        self.refs[i].weight
    }

    /// Chooses a strategy by weight for `u` uniform in [0, 1): the first `i` with
    /// `u < Σ_{j ≤ i} p(sⱼ)`, so strategy `i` is chosen with probability p(sᵢ). The weights
    /// are `f64`, and so is `u`. A strategy of weight 0 is never chosen, also when rounding
    /// leaves `u` at or above the last partial sum (then the last strategy of positive
    /// weight is). 0 for an empty set.
    ///
    /// ```
    /// # use flowlight_sdk::abi::{MutationRef, StrRef};
    /// # use flowlight_sdk::MutationSet;
    /// # let r = |weight| MutationRef { name: StrRef::EMPTY, weight, table: std::ptr::null(), instance: std::ptr::null(), stat_offset: 0, stat_count: 0 };
    /// let refs = [r(0.25), r(0.0), r(0.75)];
    /// // SAFETY (of this example): `choose` reads only the weights.
    /// let set = unsafe { MutationSet::from_raw(refs.as_ptr(), refs.len()) };
    /// assert_eq!(set.choose(0.1), 0);
    /// assert_eq!(set.choose(0.25), 2);
    /// assert_eq!(set.choose(1.0), 2);
    /// ```
    pub fn choose(&self, u: f64) -> usize {
        let mut acc = 0.0;
        let mut last_positive = 0;
        for (i, r) in self.refs.iter().enumerate() {
            if r.weight > 0.0 {
                acc += r.weight;
                last_positive = i;
                if u < acc {
                    return i;
                }
            }
        }
        last_positive
    }

    fn check(&self, i: usize, status: Status, err: &ErrorBuf) -> Result<(), String> {
        match status {
            Status::Ok => Ok(()),
            _ => Err(format!("mutation '{}': {}", self.name(i), err.message())),
        }
    }

    /// Strategy `i` proposes from `current` into `proposal`, adding to its counters in
    /// `stats` (the integrator's [`Stats`] for the unit, which carries the strategies' slots
    /// after the integrator's own; a [`Stats`] without them, as a test builds, gives the
    /// strategy scratch counters).
    pub fn propose(
        &self,
        i: usize,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
        stats: &mut Stats,
    ) -> Result<Proposal, String> {
        let r = &self.refs[i];
        let mut out = ProposalRecord::from(Proposal::Miss);
        let mut err = ErrorBuf::default();
        let mut scratch = Vec::new();
        let slots = match stats.mutation_slots(r.stat_offset, r.stat_count) {
            Some(s) => s,
            None => {
                scratch.resize(r.stat_count as usize, 0.0);
                &mut scratch[..]
            }
        };
        // SAFETY: the table and instance are alive; all pointers are valid for the call.
        let status = unsafe {
            ((*r.table).propose)(
                r.instance,
                tracer.table(),
                rng,
                current,
                proposal,
                &mut out,
                slots.as_mut_ptr(),
                slots.len(),
                &mut err,
            )
        };
        self.check(i, status, &err).map(|_| out.into())
    }

    /// T^{sᵢ}(from → to) of strategy `i`.
    pub fn density(&self, i: usize, from: &Path, to: &Path) -> Result<f64, String> {
        let r = &self.refs[i];
        let mut out = 0.0;
        let mut err = ErrorBuf::default();
        // SAFETY: as above.
        let status = unsafe { ((*r.table).density)(r.instance, from, to, &mut out, &mut err) };
        self.check(i, status, &err).map(|_| out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abi::StrRef;

    fn refs(weights: &[f64]) -> Vec<MutationRef> {
        weights
            .iter()
            .map(|&weight| MutationRef {
                name: StrRef::new("m"),
                weight,
                table: std::ptr::null(),
                instance: std::ptr::null(),
                stat_offset: 0,
                stat_count: 0,
            })
            .collect()
    }

    #[test]
    fn choose_follows_the_cumulative_weights() {
        let r = refs(&[0.2, 0.3, 0.5]);
        // SAFETY: `choose`, `len` and `weight` read only the weights.
        let set = unsafe { MutationSet::from_raw(r.as_ptr(), r.len()) };
        assert_eq!(set.len(), 3);
        let cases = [
            (0.0, 0),
            (0.199_999, 0),
            (0.2, 1),
            (0.499_999, 1),
            (0.5, 2),
            (0.999_999, 2),
        ];
        for (u, want) in cases {
            assert_eq!(set.choose(u), want, "u = {u}");
        }
        // Over a fine uniform grid, each strategy is chosen in proportion to its weight.
        let n = 100_000;
        let mut counts = [0usize; 3];
        for k in 0..n {
            counts[set.choose((k as f64 + 0.5) / n as f64)] += 1;
        }
        assert_eq!(counts, [20_000, 30_000, 50_000]);
    }

    #[test]
    fn a_proposal_round_trips_through_its_abi_record() {
        for p in [
            Proposal::Miss,
            Proposal::SYMMETRIC,
            Proposal::Move {
                transition_ratio: 0.0,
            },
            Proposal::Move {
                transition_ratio: 2.5,
            },
        ] {
            assert_eq!(Proposal::from(ProposalRecord::from(p)), p);
        }
        let miss = ProposalRecord::from(Proposal::Miss);
        assert_eq!((miss.valid, miss.transition_ratio), (0, 0.0));
        // Any non-zero flag from a foreign plugin is a move; NaN ratios pass through.
        let r = ProposalRecord {
            valid: 7,
            transition_ratio: f32::NAN,
        };
        assert!(Proposal::from(r).transition_ratio().unwrap().is_nan());
        assert_eq!(Proposal::Miss.transition_ratio(), None);
        assert!(!Proposal::Miss.is_move() && Proposal::SYMMETRIC.is_move());
    }

    #[test]
    fn zero_weights_are_never_chosen() {
        let r = refs(&[0.0, 0.6, 0.4, 0.0]);
        // SAFETY: as above.
        let set = unsafe { MutationSet::from_raw(r.as_ptr(), r.len()) };
        assert_eq!(set.choose(0.0), 1);
        assert_eq!(set.choose(0.6), 2);
        // u at or past the total (rounding): the last strategy with positive weight.
        assert_eq!(set.choose(1.0), 2);
        assert_eq!(set.choose(1.5), 2);
        // An f64 weight below f32 resolution still gets its share.
        let r = refs(&[1.0 - 1e-12, 1e-12]);
        let set = unsafe { MutationSet::from_raw(r.as_ptr(), r.len()) };
        assert_eq!(set.choose(1.0 - 5e-13), 1);
        assert_eq!(MutationSet::empty().choose(0.3), 0);
    }
}
