//! Flowlight plugin SDK.
//!
//! Plugin authors implement [`Integrator`] or [`Mutation`] as ordinary Rust and call
//! [`export_integrator!`] or [`export_mutation!`] once. The macro emits the single C-ABI
//! symbol `flowlight_plugin_declaration`, which returns a [`abi::PluginDeclaration`]: ABI
//! version, SDK version, rustc version, a layout hash of every crossing type, and
//! `#[repr(C)]` function tables. No Rust trait object, allocation or panic crosses: errors and
//! panics become messages in a host-owned buffer. A plugin writes no `unsafe`: the raw side of
//! the boundary (tables, pointers, the statistics list) lives in this crate's glue.
//!
//! A complete integrator with one parameter and two counters:
//!
//! ```
//! use flowlight_sdk::core::Rgb;
//! use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
//! use flowlight_sdk::{
//!     export_integrator, float_param, Film, FloatParam, Integrator, IntegratorInfo,
//!     MutationSet, ParamSpec, Params, Scene, Tracer, WorkUnit,
//! };
//!
//! /// Declared once: the spec in `PARAMS`, the parsing in `create` and the docs table all
//! /// come from it (see [`declare`]).
//! const VALUE: FloatParam = float_param!("value", 1.0, 0.0 <= x, "radiance of every pixel");
//!
//! pub struct Constant {
//!     value: f32,
//!     samples: Counter,
//!     largest_unit: Counter,
//! }
//!
//! impl Integrator for Constant {
//!     const NAME: &'static str = "constant";
//!     const DESCRIPTION: &'static str = "every pixel gets `value`";
//!     const PARAMS: &'static [ParamSpec] = &[VALUE.spec()];
//!
//!     fn create(
//!         params: &Params,
//!         _mutations: MutationSet<'static>,
//!         _scene: Scene<'static>,
//!         stats: &mut StatsBuilder,
//!     ) -> Result<(Self, IntegratorInfo), String> {
//!         let samples = stats.sum("samples");
//!         let largest_unit = stats.max("largest_unit");
//!         let value = VALUE.get(params)? as f32;
//!         Ok((Constant { value, samples, largest_unit }, IntegratorInfo::simple()))
//!     }
//!
//!     fn render(
//!         &self,
//!         unit: &WorkUnit,
//!         _tracer: &Tracer,
//!         film: &mut Film,
//!         stats: &mut Stats,
//!     ) -> Result<(), String> {
//!         let n = (unit.x1 - unit.x0) * (unit.y1 - unit.y0) * unit.sample_count;
//!         for y in unit.y0..unit.y1 {
//!             for x in unit.x0..unit.x1 {
//!                 for _ in 0..unit.sample_count {
//!                     film.deposit(x as f32 + 0.5, y as f32 + 0.5, 0, Rgb::splat(self.value));
//!                 }
//!             }
//!         }
//!         stats.add(self.samples, n as f64);
//!         stats.add(self.largest_unit, n as f64);
//!         Ok(())
//!     }
//! }
//!
//! export_integrator!(Constant);
//! # fn main() {
//! #     let decl = unsafe { &*flowlight_plugin_declaration() };
//! #     assert_eq!(decl.abi_version, flowlight_sdk::abi::ABI_VERSION);
//! # }
//! ```
//!
//! ## Versions
//!
//! The host loads a plugin only when four things equal its own, checked in this order before
//! anything in the plugin is called ([`abi::PluginDeclaration`]):
//! [`abi::ABI_VERSION`], [`abi::layout_hash`], [`abi::SDK_VERSION`] and
//! [`abi::RUSTC_VERSION`]. The compiler must match because the SDK's generic glue and
//! `flowlight-core`'s types are compiled into each plugin by its own rustc, and Rust promises
//! no layout or calling convention between compiler versions for anything not `#[repr(C)]`.
//! The workspace pins its compiler in `rust-toolchain.toml`; a plugin built outside it must
//! use that same toolchain. A refused plugin gets one line:
//!
//! ```text
//! plugin PATH was refused: WHAT mismatch (plugin has X, host has Y); rebuild the plugin against this host's SDK
//! ```
//!
//! where WHAT is `ABI version`, `type layout`, `SDK version` or `rustc version`.

// Every public item is documented; `cargo clippy -- -D warnings` makes a gap an error.
#![warn(missing_docs)]

pub mod abi;
pub mod declare;
pub mod deposit;
mod guard;
pub mod integrator;
pub mod mutation;
pub mod params;
pub mod scene;
pub mod stats;
pub mod tracer;

pub use abi::{
    AccumulationStyle, Deposit, IntegratorInfo, ParamRole, ParamSpec, PluginDeclaration,
    PluginKind, StatDisplay, StatMerge, WorkUnit,
};
pub use declare::{BoolParam, ChoiceParam, FloatParam, IntParam, StringParam};
pub use deposit::{Accumulator, Film};
pub use flowlight_core as core;
pub use integrator::Integrator;
pub use mutation::{Mutation, MutationSet, Proposal, MAX_MUTATIONS};
pub use params::{param, ParamKind, Params};
pub use scene::Scene;
pub use stats::{Counter, Ratio, Stats, StatsBuilder};
pub use tracer::Tracer;

use abi::{IntegratorTable, MutationTable, StrRef};

/// Builds a declaration for the current SDK; used by the export macros.
pub const fn declaration(
    kind: PluginKind,
    name: &'static str,
    description: &'static str,
    params: &'static [ParamSpec],
    integrator: *const IntegratorTable,
    mutation: *const MutationTable,
) -> PluginDeclaration {
    PluginDeclaration {
        abi_version: abi::ABI_VERSION,
        kind,
        layout_hash: abi::layout_hash(),
        sdk_version: StrRef::new(abi::SDK_VERSION),
        rustc_version: StrRef::new(abi::RUSTC_VERSION),
        name: StrRef::new(name),
        description: StrRef::new(description),
        params: params.as_ptr(),
        param_count: params.len(),
        integrator,
        mutation,
    }
}

/// Exports an [`Integrator`] implementation as this plugin's declaration.
#[macro_export]
macro_rules! export_integrator {
    ($t:ty) => {
        /// The plugin's declaration (Flowlight plugin ABI).
        #[no_mangle]
        pub extern "C" fn flowlight_plugin_declaration() -> *const $crate::abi::PluginDeclaration {
            static TABLE: $crate::abi::IntegratorTable = $crate::integrator::table::<$t>();
            static DECLARATION: $crate::abi::PluginDeclaration = $crate::declaration(
                $crate::abi::PluginKind::Integrator,
                <$t as $crate::Integrator>::NAME,
                <$t as $crate::Integrator>::DESCRIPTION,
                <$t as $crate::Integrator>::PARAMS,
                &TABLE,
                ::std::ptr::null(),
            );
            &DECLARATION
        }
    };
}

/// Exports a [`Mutation`] implementation as this plugin's declaration.
#[macro_export]
macro_rules! export_mutation {
    ($t:ty) => {
        /// The plugin's declaration (Flowlight plugin ABI).
        #[no_mangle]
        pub extern "C" fn flowlight_plugin_declaration() -> *const $crate::abi::PluginDeclaration {
            static TABLE: $crate::abi::MutationTable = $crate::mutation::table::<$t>();
            static DECLARATION: $crate::abi::PluginDeclaration = $crate::declaration(
                $crate::abi::PluginKind::Mutation,
                <$t as $crate::Mutation>::NAME,
                <$t as $crate::Mutation>::DESCRIPTION,
                <$t as $crate::Mutation>::PARAMS,
                ::std::ptr::null(),
                &TABLE,
            );
            &DECLARATION
        }
    };
}
