//! The `Mutation` trait: an ERPT/MCMC perturbation strategy, loadable as its own plugin.

use crate::abi::{
    ErrorBuf, MutationTable, ParamSpec, ParamValue, Proposal, SceneView, Status, TracerTable,
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
/// miss. The returned ratio is T(y→x)/T(x→y); for a mixture of strategies the integrator
/// combines them with the mixture density Σ p(sᵢ)·T^{sᵢ}.
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

/// The function table for `T`; used by [`crate::export_mutation!`].
pub const fn table<T: Mutation>() -> MutationTable {
    MutationTable {
        create: create::<T>,
        destroy: destroy::<T>,
        propose: propose::<T>,
    }
}
