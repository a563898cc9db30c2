//! Flowlight host: everything a plugin does not own.
//!
//! The host loads plugins ([`plugin`]), owns the one rayon thread pool and schedules work
//! units on it ([`render`](mod@render)), answers ray queries through an intersector ([`intersector`]),
//! owns the accumulators ([`accumulation`]), counts statistics, and writes images atomically
//! ([`output`]); [`parts`] splits a render into sample ranges and merges them back; [`aov`]
//! traces the AOVs (albedo, normal, depth, …) and [`denoise`] runs Open Image Denoise. A
//! [`renderer::Renderer`] fails with a [`HostError`] ([`error`]).

pub mod accumulation;
pub mod aov;
pub mod denoise;
pub mod error;
pub mod intersector;
pub mod metrics;
pub mod output;
pub mod param_docs;
pub mod params;
pub mod parts;
pub mod plugin;
pub mod render;
pub mod renderer;

pub use error::HostError;
pub use plugin::{IntegratorInstance, PluginError, PluginLibrary};
pub use render::{render, RenderOptions, RenderStats};
