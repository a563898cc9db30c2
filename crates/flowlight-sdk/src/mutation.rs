//! The `Mutation` trait: an ERPT/MCMC perturbation strategy, loadable as its own plugin.

use crate::abi::{
    ErrorBuf, MutationRef, MutationTable, ParamSpec, ParamValue, Proposal, SceneView, Status,
    TracerTable,
};
use crate::guard::guard;
use crate::params::Params;
use crate::scene::Scene;
use crate::tracer::Tracer;
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use std::ffi::c_void;

/// Proposes a new path from the current state of a Markov chain (thesis §5.4).
///
/// A mutation keeps the path length and the weak path type; otherwise it reports a domain
/// miss. The returned ratio is T(y→x)/T(x→y); [`Mutation::density`] gives T itself so that
/// an integrator can form the mixture density Σ p(sᵢ)·T^{sᵢ} of several strategies.
pub trait Mutation: Sized + Send + Sync + 'static {
    const NAME: &'static str;
    const DESCRIPTION: &'static str;
    const PARAMS: &'static [ParamSpec];

    fn create(params: &Params, scene: Scene<'static>) -> Result<Self, String>;

    /// Fills `proposal` from `current`. Returns the proposal's validity and transition ratio.
    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
    ) -> Result<Proposal, String>;

    /// Transition density T(from → to) of this strategy, in the measure of the integrator's
    /// target function (0 when `to` cannot be proposed from `from`).
    fn density(&self, from: &Path, to: &Path) -> f64;
}

unsafe extern "C" fn create<T: Mutation>(
    params: *const ParamValue,
    param_count: usize,
    scene: *const SceneView,
    instance: *mut *mut c_void,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let params = Params::from_raw(params, param_count);
        let inst = T::create(&params, Scene::from_view(&*scene))?;
        *instance = Box::into_raw(Box::new(inst)) as *mut c_void;
        Ok(())
    })
}

unsafe extern "C" fn destroy<T: Mutation>(instance: *mut c_void) {
    if !instance.is_null() {
        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            drop(Box::from_raw(instance as *mut T))
        }));
    }
}

unsafe extern "C" fn propose<T: Mutation>(
    instance: *const c_void,
    tracer: *const TracerTable,
    rng: *mut Rng,
    current: *const Path,
    proposal: *mut Path,
    out: *mut Proposal,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let inst = &*(instance as *const T);
        *out = inst.propose(&Tracer::new(&*tracer), &mut *rng, &*current, &mut *proposal)?;
        Ok(())
    })
}

unsafe extern "C" fn density<T: Mutation>(
    instance: *const c_void,
    from: *const Path,
    to: *const Path,
    out: *mut f64,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let inst = &*(instance as *const T);
        *out = inst.density(&*from, &*to);
        Ok(())
    })
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

/// The mutation strategies an integrator was given, with their normalised weights.
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
        let refs = if refs.is_null() || count == 0 {
            &[][..]
        } else {
            std::slice::from_raw_parts(refs, count)
        };
        MutationSet { refs }
    }

    pub fn empty() -> Self {
        MutationSet { refs: &[] }
    }

    pub fn len(&self) -> usize {
        self.refs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.refs.is_empty()
    }

    pub fn name(&self, i: usize) -> &'a str {
        // SAFETY: the host keeps the names alive with the instances.
        unsafe { self.refs[i].name.as_str() }
    }

    pub fn weight(&self, i: usize) -> f64 {
        self.refs[i].weight
    }

    /// Chooses a strategy by weight: its index.
    pub fn choose(&self, u: f32) -> usize {
        let mut acc = 0.0;
        for (i, r) in self.refs.iter().enumerate() {
            acc += r.weight;
            if (u as f64) < acc {
                return i;
            }
        }
        self.refs.len() - 1
    }

    fn check(&self, i: usize, status: Status, err: &ErrorBuf) -> Result<(), String> {
        match status {
            Status::Ok => Ok(()),
            _ => Err(format!("mutation '{}': {}", self.name(i), err.message())),
        }
    }

    /// Strategy `i` proposes from `current` into `proposal`.
    pub fn propose(
        &self,
        i: usize,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
    ) -> Result<Proposal, String> {
        let r = &self.refs[i];
        let mut out = Proposal {
            valid: 0,
            transition_ratio: 0.0,
        };
        let mut err = ErrorBuf::default();
        // SAFETY: the table and instance are alive; all pointers are valid for the call.
        let status = unsafe {
            ((*r.table).propose)(
                r.instance,
                tracer.table(),
                rng,
                current,
                proposal,
                &mut out,
                &mut err,
            )
        };
        self.check(i, status, &err).map(|_| out)
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
