//! # `lighttrace` — light tracing
//!
//! Particle tracing (Veach 1997 §10.2; pbrt-v4's light path integrator): light subpaths
//! leave the lights by their emission densities and every vertex with a non-Dirac BSDF is
//! connected to the eye and splatted onto the film at its raster position (t = 1). A lamp
//! is seen through its own vertex's connection. Paths whose first vertex from the eye is a
//! Dirac surface (a mirror or smooth glass seen directly) and the environment seen directly
//! have no t = 1 strategy: they are black in this integrator (use `bdpt`).
//!
//! One light subpath is traced per pixel sample, so `spp` means what it means for MCPT:
//! W·H light paths per sample index. The light paths of a work unit splat anywhere on the
//! film; the host keeps every deposit. The library: `flowlight_pathtrace::bidir`
//! (docs/bdpt.md).
//!
//! Parameters: `path_depth` (the deepest lighting layer: light vertices y₁ … y_N),
//! `max_ray_depth`, `termination`/`rr_depth`/`rr_max_survival` (the roulette, as in MCPT, on
//! the throughput relative to the emitted one), `layers` (no `heuristic`: every path has one
//! strategy). Generated table: docs/bdpt.md ("Parameters").

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_pathtrace::bidir::params::SHARED;
use flowlight_pathtrace::bidir::render::{BidirIntegrator, BidirKind};
use flowlight_pathtrace::bidir::Techniques;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::export_integrator;

pub struct LightTrace;

impl BidirKind for LightTrace {
    const NAME: &'static str = "lighttrace";
    const DESCRIPTION: &'static str =
        "Light tracing: light subpaths connected to the eye at every vertex (t = 1)";
    const PARAMS: &'static [ParamSpec] = &SHARED;
    const TECHNIQUES: Techniques = Techniques::LIGHT_TRACE;
}

export_integrator!(BidirIntegrator<LightTrace>);
