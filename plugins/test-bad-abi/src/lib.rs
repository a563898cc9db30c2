//! Test fixture: declares the previous ABI version, `ABI_VERSION - 1` (8, what a plugin built
//! against the SDK before `Emitter` held vertex colours declares). The host must refuse to load
//! it with an error that names this file and both versions, before calling anything in it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![deny(unsafe_code)]

use flowlight_sdk::abi::{IntegratorTable, ParamSpec, PluginDeclaration, ABI_VERSION};
use flowlight_sdk::{
    Film, Integrator, IntegratorInfo, MutationSet, Params, PluginKind, Scene, Stats, StatsBuilder,
    Tracer, WorkUnit,
};

pub struct NeverCalled;

impl Integrator for NeverCalled {
    const NAME: &'static str = "test-bad-abi";
    const DESCRIPTION: &'static str = "test fixture with a wrong ABI version";
    const PARAMS: &'static [ParamSpec] = &[];

    fn create(
        _: &Params,
        _mutations: MutationSet<'static>,
        _: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let info = IntegratorInfo::simple();
        Ok((NeverCalled, info))
    }

    fn render(
        &self,
        _: &WorkUnit,
        _: &Tracer,
        _: &mut Film,
        _stats: &mut Stats,
    ) -> Result<(), String> {
        panic!("a plugin with a mismatched ABI must never be called")
    }
}

static TABLE: IntegratorTable = flowlight_sdk::integrator::table::<NeverCalled>();
static DECLARATION: PluginDeclaration = {
    let mut d = flowlight_sdk::declaration(
        PluginKind::Integrator,
        NeverCalled::NAME,
        NeverCalled::DESCRIPTION,
        NeverCalled::PARAMS,
        &TABLE,
        std::ptr::null(),
    );
    d.abi_version = ABI_VERSION - 1;
    d
};

/// The (deliberately wrong) declaration, written by hand instead of by the export macro
/// (`#[no_mangle]` counts as unsafe code).
#[allow(unsafe_code)]
#[no_mangle]
pub extern "C" fn flowlight_plugin_declaration() -> *const PluginDeclaration {
    &DECLARATION
}
