//! The `Integrator` trait and the glue that turns an implementation into an
//! [`IntegratorTable`].

use crate::abi::{
    ErrorBuf, FilmTable, IntegratorInfo, IntegratorTable, ParamSpec, ParamValue, SceneView, Status,
    TracerTable, WorkUnit,
};
use crate::film::Film;
use crate::guard::guard;
use crate::params::Params;
use crate::scene::Scene;
use crate::tracer::Tracer;
use std::ffi::c_void;

/// A light-transport algorithm. The host creates one instance per render and calls
/// [`Integrator::render`] for each work unit from its thread pool, concurrently.
pub trait Integrator: Sized + Send + Sync + 'static {
    /// Name the config uses (`plugin = "NAME"`).
    const NAME: &'static str;
    const DESCRIPTION: &'static str;
    /// Parameters the plugin accepts; the host refuses others.
    const PARAMS: &'static [ParamSpec];

    /// Builds an instance. `scene` stays valid for the instance's whole life.
    fn create(params: &Params, scene: Scene<'static>) -> Result<(Self, IntegratorInfo), String>;

    /// Renders one work unit, depositing into `film`. Must not start threads.
    fn render(&self, unit: &WorkUnit, tracer: &Tracer, film: &mut Film) -> Result<(), String>;
}

unsafe extern "C" fn create<T: Integrator>(
    params: *const ParamValue,
    param_count: usize,
    scene: *const SceneView,
    instance: *mut *mut c_void,
    info: *mut IntegratorInfo,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let params = Params::from_raw(params, param_count);
        let scene = Scene::from_view(&*scene);
        let (inst, inf) = T::create(&params, scene)?;
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

unsafe extern "C" fn render<T: Integrator>(
    instance: *const c_void,
    unit: *const WorkUnit,
    tracer: *const TracerTable,
    film: *const FilmTable,
    err: *mut ErrorBuf,
) -> Status {
    guard(err, || {
        let inst = &*(instance as *const T);
        let tracer = Tracer::new(&*tracer);
        let mut film = Film::new(&*film);
        inst.render(&*unit, &tracer, &mut film)
    })
}

/// The function table for `T`; used by [`crate::export_integrator!`].
pub const fn table<T: Integrator>() -> IntegratorTable {
    IntegratorTable {
        create: create::<T>,
        destroy: destroy::<T>,
        render: render::<T>,
    }
}
