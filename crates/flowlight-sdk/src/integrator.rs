//! The `Integrator` trait and the glue that turns an implementation into an
//! [`IntegratorTable`].

use crate::abi::{
    ErrorBuf, FilmTable, IntegratorInfo, IntegratorTable, MutationRef, ParamSpec, ParamValue,
    ResolvedList, SceneView, StatList, Status, TracerTable, WorkUnit,
};
use crate::deposit::Film;
use crate::guard::guard;
use crate::mutation::MutationSet;
use crate::params::{Params, ResolvedTable};
use crate::scene::Scene;
use crate::stats::{StatTable, Stats, StatsBuilder};
use crate::tracer::Tracer;
use flowlight_core::bsdf::Bsdf;
use std::ffi::c_void;

/// A light-transport algorithm. The host creates one instance per render and calls
/// [`Integrator::render`] for each work unit from its thread pool, concurrently.
pub trait Integrator: Sized + Send + Sync + 'static {
    /// Name the config uses (`plugin = "NAME"`).
    const NAME: &'static str;
    /// One line for `flowlight plugins`.
    const DESCRIPTION: &'static str;
    /// Parameters the plugin accepts; the host refuses others. Built from the parameters'
    /// declarations ([`crate::declare`]): `&[PATH_DEPTH.spec(), …]`.
    const PARAMS: &'static [ParamSpec];

    /// Builds an instance. Read each parameter through its declaration
    /// (`PATH_DEPTH.get(params)?`): the values read are reported to the host as the
    /// instance's resolved parameters. `scene` and `mutations` (the strategies the config lists under the
    /// integrator's [`ParamKind::MutationList`](crate::ParamKind::MutationList) parameter,
    /// empty for most integrators) stay valid for the instance's whole life. Counters the
    /// integrator reports are declared on `stats`; keep the handles for
    /// [`Integrator::render`].
    fn create(
        params: &Params,
        mutations: MutationSet<'static>,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String>;

    /// Runs once before the first work unit, on one thread, with ray queries.
    fn prepare(&mut self, _tracer: &Tracer) -> Result<(), String> {
        Ok(())
    }

    /// Parameter values the instance decided in [`Integrator::prepare`] (e.g. from a pilot),
    /// `(name, TOML text)`: after `prepare` they replace the values of the same names that
    /// `create` resolved, or join them, in the output's metadata (ABI 7).
    fn decided_params(&self) -> Vec<(String, String)> {
        Vec::new()
    }

    /// Renders one work unit, depositing into `film` and adding to the counters declared in
    /// `create` through `stats` (zeroed for the unit). Must not start threads.
    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut Stats,
    ) -> Result<(), String>;
}

/// What the glue boxes behind the instance pointer: the integrator and the counter list the
/// host reads through [`StatList`] until `destroy`.
struct Instance<T> {
    /// Declared first, so dropped first: its scene borrows `bsdfs`.
    integrator: T,
    stats: StatTable,
    /// The parameter values `create` read, for the host's metadata.
    resolved: ResolvedTable,
    /// The per-material BSDFs the integrator's scene borrows ([`Scene::material_bsdfs`]).
    _bsdfs: Box<[Option<Bsdf>]>,
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
            // The instance keeps the table and drops it after the integrator, the scene's only holder.
            let bsdfs = scene.attach_constant_bsdfs();
            let mutations = MutationSet::from_raw(mutations, mutation_count);
            let mut builder = StatsBuilder::new();
            let (integrator, inf) = T::create(&params, mutations, scene, &mut builder)?;
            let table = builder.finish()?;
            let boxed = Box::new(Instance {
                integrator,
                stats: table,
                resolved: ResolvedTable::new(params.resolved()),
                _bsdfs: bsdfs,
            });
            *resolved = boxed.resolved.list();
            // The specs live in the box, which does not move until `destroy`.
            let specs = boxed.stats.specs();
            *stats = StatList {
                specs: if specs.is_empty() {
                    std::ptr::null()
                } else {
                    specs.as_ptr()
                },
                count: specs.len(),
            };
            *instance = Box::into_raw(boxed) as *mut c_void;
            *info = inf;
            Ok(())
        })
    }
}

unsafe extern "C" fn destroy<T: Integrator>(instance: *mut c_void) {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        if !instance.is_null() {
            // Dropping must not unwind into the host.
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                drop(Box::from_raw(instance as *mut Instance<T>))
            }));
        }
    }
}

unsafe extern "C" fn prepare<T: Integrator>(
    instance: *mut c_void,
    tracer: *const TracerTable,
    resolved: *mut ResolvedList,
    err: *mut ErrorBuf,
) -> Status {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        guard(err, || {
            let inst = &mut *(instance as *mut Instance<T>);
            inst.integrator.prepare(&Tracer::new(&*tracer))?;
            let decided = inst.integrator.decided_params();
            if !decided.is_empty() {
                inst.resolved = inst.resolved.with(decided);
            }
            *resolved = inst.resolved.list();
            Ok(())
        })
    }
}

unsafe extern "C" fn render<T: Integrator>(
    instance: *const c_void,
    unit: *const WorkUnit,
    tracer: *const TracerTable,
    film: *const FilmTable,
    stats: *mut f64,
    stat_count: usize,
    err: *mut ErrorBuf,
) -> Status {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        guard(err, || {
            let inst = &*(instance as *const Instance<T>);
            let tracer = Tracer::new(&*tracer);
            let mut film = Film::new(&*film);
            let declared = inst.stats.specs().len();
            if stat_count < declared || (declared > 0 && stats.is_null()) {
                return Err(format!(
                "the host passed {stat_count} statistics slots for {declared} declared counters"
            ));
            }
            // The integrator's own counters, then the mutations' (ABI 6), which it hands
            // on through `MutationSet::propose`.
            let slots = if stats.is_null() || stat_count == 0 {
                &mut [][..]
            } else {
                std::slice::from_raw_parts_mut(stats, stat_count)
            };
            let mut stats = Stats::with_mutation_slots(slots, declared);
            inst.integrator
                .render(&*unit, &tracer, &mut film, &mut stats)
        })
    }
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
