//! Flowlight plugin SDK.
//!
//! Plugin authors implement [`Integrator`] or [`Mutation`] as ordinary Rust and call
//! [`export_integrator!`] or [`export_mutation!`] once. The macro emits the single C-ABI
//! symbol `flowlight_plugin_declaration`, which returns a [`abi::PluginDeclaration`]: ABI
//! version, SDK version, rustc version, a layout hash of every crossing type, and
//! `#[repr(C)]` function tables. No Rust trait object, allocation or panic crosses: errors and
//! panics become messages in a host-owned buffer.

pub mod abi;
pub mod deposit;
mod guard;
pub mod integrator;
pub mod mutation;
pub mod params;
pub mod scene;
pub mod tracer;

pub use abi::{
    AccumulationStyle, Deposit, IntegratorInfo, PluginDeclaration, PluginKind, Proposal, StatMerge,
    StatSpec, WorkUnit,
};
pub use deposit::{Accumulator, Film};
pub use flowlight_core as core;
pub use integrator::Integrator;
pub use mutation::{Mutation, MutationSet};
pub use params::{param, ParamKind, Params};
pub use scene::Scene;
pub use tracer::Tracer;

use abi::{IntegratorTable, MutationTable, ParamSpec, StrRef};

/// Declares a statistics counter in an integrator's statistics list.
pub const fn stat(name: &'static str, merge: StatMerge) -> StatSpec {
    StatSpec {
        name: StrRef::new(name),
        merge,
        numerator: 0,
        denominator: 0,
    }
}

/// Declares a derived counter: `counter[numerator] / counter[denominator]`.
pub const fn stat_ratio(name: &'static str, numerator: u32, denominator: u32) -> StatSpec {
    StatSpec {
        name: StrRef::new(name),
        merge: StatMerge::Ratio,
        numerator,
        denominator,
    }
}

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
