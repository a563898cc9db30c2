//! Flowlight core: the maths that every plugin compiles in so that it inlines.
//!
//! Everything here is plain data and pure functions. Types that cross the plugin boundary are
//! `#[repr(C)]` and contain no owning pointers (see `docs/architecture.md`).

pub mod bsdf;
pub mod camera;
pub mod denormals;
pub mod geometry;
pub mod light;
pub mod material;
pub mod material_layers;
pub mod mesh;
pub mod path;
pub mod rng;
pub mod sampler;
pub mod sampling;
pub mod sobol;
pub mod spectrum;
pub mod specular_normal;
pub mod termination;
pub mod thin_lens;

pub use glam::{Vec2, Vec3};
pub use spectrum::Rgb;
