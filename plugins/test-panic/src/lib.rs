//! Test fixture: an integrator that fails on purpose. `fail_create = true` makes `create`
//! return an error; otherwise `render` panics on the unit that contains pixel (0, 0). The
//! host must report both as errors naming the plugin, and keep the units finished before.
//! It also declares a mutation list named `strategies`, which it ignores.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::Rgb;
use flowlight_sdk::{
    export_integrator, param, Film, Integrator, IntegratorInfo, MutationSet, ParamKind, Params,
    Scene, Stats, StatsBuilder, Tracer, WorkUnit,
};

pub struct Faulty;

impl Integrator for Faulty {
    const NAME: &'static str = "test-panic";
    const DESCRIPTION: &'static str = "test fixture that fails on purpose";
    const PARAMS: &'static [ParamSpec] = &[
        param("fail_create", ParamKind::Bool, "false", "fail in create"),
        // A mutation list under another name than ERPT's `mutations`: the host must read the
        // list under the name the integrator declares.
        param(
            "strategies",
            ParamKind::MutationList,
            "(none)",
            "[[integrator.strategies]]: mutation plugins (accepted and ignored)",
        ),
    ];

    fn create(
        params: &Params,
        _mutations: MutationSet<'static>,
        _: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        if params.boolean("fail_create", false)? {
            return Err("asked to fail in create".into());
        }
        let info = IntegratorInfo::simple();
        Ok((Faulty, info))
    }

    fn render(
        &self,
        unit: &WorkUnit,
        _: &Tracer,
        film: &mut Film,
        _stats: &mut Stats,
    ) -> Result<(), String> {
        if unit.x0 == 0 && unit.y0 == 0 {
            panic!("deliberate panic in render");
        }
        film.deposit(unit.x0 as f32 + 0.5, unit.y0 as f32 + 0.5, 0, Rgb::ONE);
        Ok(())
    }
}

export_integrator!(Faulty);
