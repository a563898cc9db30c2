//! The `Integrator` trait and the glue that turns an implementation into an
//! [`IntegratorTable`].

use crate::abi::{
    ErrorBuf, FilmTable, IntegratorInfo, IntegratorTable, MutationRef, ParamSpec, ParamValue,
    SceneView, Status, TracerTable, WorkUnit,
};
use crate::deposit::Film;
use crate::guard::guard;
use crate::mutation::MutationSet;
use crate::params::Params;
use crate::scene::Scene;
use crate::tracer::Tracer;
use std::ffi::c_void;

/// The host always hands a unit this many counter slots (only the declared ones are read).
pub const STAT_SLOTS: usize = 256;

/// A light-transport algorithm. The host creates one instance per render and calls
/// [`Integrator::render`] for each work unit from its thread pool, concurrently.
pub trait Integrator: Sized + Send + Sync + 'static {
    /// Name the config uses (`plugin = "NAME"`).
    const NAME: &'static str;
    const DESCRIPTION: &'static str;
    /// Parameters the plugin accepts; the host refuses others.
    const PARAMS: &'static [ParamSpec];

    /// Builds an instance. `scene` and `mutations` (the strategies the config lists under
    /// `[[integrator.mutations]]`, empty for most integrators) stay valid for the instance's
    /// whole life.
    fn create(
        params: &Params,
        mutations: MutationSet<'static>,
        scene: Scene<'static>,
    ) -> Result<(Self, IntegratorInfo), String>;

    /// Runs once before the first work unit, on one thread, with ray queries.
    fn prepare(&mut self, _tracer: &Tracer) -> Result<(), String> {
        Ok(())
    }

    /// Renders one work unit, depositing into `film` and adding to `stats` (one slot per
    /// declared counter, zeroed for the unit). Must not start threads.
    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut [f64],
    ) -> Result<(), String>;
}

#[allow(clippy::too_many_arguments)]
unsafe extern "C" fn create<T: Integrator>(
    params: *const ParamValue,
    param_count: usize,
    mutations: *const MutationRef,
    mutation_count: usize,
    scene: *const SceneView,
    instance: *mut *mut c_void,
    info: *mut IntegratorInfo,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let params = Params::from_raw(params, param_count);
        let scene = Scene::from_view(&*scene);
        let mutations = MutationSet::from_raw(mutations, mutation_count);
        let (inst, inf) = T::create(&params, mutations, scene)?;
        *instance = Box::into_raw(Box::new(inst)) as *mut c_void;
        *info = inf;
        Ok(())
    })
}

unsafe extern "C" fn destroy<T: Integrator>(instance: *mut c_void) {
    if !instance.is_null() {
        // Dropping must not unwind into the host.
        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            drop(Box::from_raw(instance as *mut T))
        }));
    }
}

unsafe extern "C" fn prepare<T: Integrator>(
    instance: *mut c_void,
    tracer: *const TracerTable,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let inst = &mut *(instance as *mut T);
        inst.prepare(&Tracer::new(&*tracer))
    })
}

unsafe extern "C" fn render<T: Integrator>(
    instance: *const c_void,
    unit: *const WorkUnit,
    tracer: *const TracerTable,
    film: *const FilmTable,
    stats: *mut f64,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let inst = &*(instance as *const T);
        let tracer = Tracer::new(&*tracer);
        let mut film = Film::new(&*film);
        let stats = if stats.is_null() {
            &mut [][..]
        } else {
            std::slice::from_raw_parts_mut(stats, STAT_SLOTS)
        };
        inst.render(&*unit, &tracer, &mut film, stats)
    })
}

/// The function table for `T`; used by [`crate::export_integrator!`].
pub const fn table<T: Integrator>() -> IntegratorTable {
    IntegratorTable {
        create: create::<T>,
        destroy: destroy::<T>,
        prepare: prepare::<T>,
        render: render::<T>,
    }
}
