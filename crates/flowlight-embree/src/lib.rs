//! Embree 4 ray queries for the Flowlight host.
//!
//! The library the build provisioned (see `build.rs`) is opened at run time, once per
//! process, and one Embree device is made from it ([`device`]). A scene is built and
//! committed once ([`EmbreeScene::build`]) and then answers closest-hit and any-hit queries
//! from any number of threads. Nothing of Embree crosses the plugin boundary: the host wraps
//! [`EmbreeScene`] in its own intersector trait.
//!
//! Types come from `embree4-sys` (bindgen over the Embree **4.2** headers it ships). Where
//! those differ from the 4.4 library, this crate has its own `#[repr(C)]` definitions: see
//! [`abi`] and docs/embree.md.
// The workspace lint `unsafe_op_in_unsafe_fn` is not yet applied to this FFI crate (owned by
// the instancing work): its two `unsafe fn`s are each one unsafe region.
#![allow(unsafe_op_in_unsafe_fn)]

/// Where the build found Embree: `EMBREE_DIR`, `system` or the pinned wheel.
pub const BUILD_SOURCE: &str = env!("FLOWLIGHT_EMBREE_SOURCE");
/// The library file the build found, opened at run time.
pub const BUILD_LIBRARY: &str = env!("FLOWLIGHT_EMBREE_LIB");

pub mod abi;
mod device;
mod filter;
mod instanced;
mod options;
mod queries;
mod scene;
#[cfg(test)]
mod tests;

pub use device::{device, Device};
pub use instanced::EmbreeInstancedScene;
pub use options::{BuildQuality, Packets, SceneOptions, PACKET_MAX_TRIANGLES};
pub use scene::EmbreeScene;
