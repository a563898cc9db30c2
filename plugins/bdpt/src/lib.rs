//! # `bdpt` — bidirectional path tracing
//!
//! Veach's bidirectional path tracer (1997, ch. 10): per pixel sample one camera subpath and
//! one light subpath; every (s, t) strategy — the camera path hitting a light (s = 0), a
//! light sample at each camera vertex (s = 1), each camera vertex connected to each light
//! vertex (s, t ≥ 2) and each light vertex connected to the eye and splatted (t = 1) — is
//! weighed by multiple importance sampling, so the paths through a door gap or a lamp's
//! shade that a camera path finds only by chance are found from the light side. Dirac
//! surfaces, Dirac lights (point, spot, directional) and the pinhole eye take part by the
//! strategies that can sample them; the weights need only two running quantities per
//! subpath (`flowlight_pathtrace::bidir::mis`).
//!
//! Parameters: `heuristic` (`"power"` or `"balance"`), `path_depth` (the deepest lighting
//! layer, as in MCPT), `max_ray_depth`, the roulette (`termination`, `rr_depth`,
//! `rr_max_survival`), `layers` (lighting layers) and `strategies` (one EXR layer per
//! (s, t), Veach's fig. 10.3; they sum to the image). Generated table: docs/bdpt.md
//! ("Parameters").

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_pathtrace::bidir::params::{HEURISTIC, SHARED, STRATEGIES};
use flowlight_pathtrace::bidir::render::{BidirIntegrator, BidirKind};
use flowlight_pathtrace::bidir::Techniques;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::export_integrator;

const PARAMS: [ParamSpec; 8] = [
    SHARED[0],
    SHARED[1],
    SHARED[2],
    SHARED[3],
    SHARED[4],
    SHARED[5],
    HEURISTIC.spec(),
    STRATEGIES.spec(),
];

pub struct Bdpt;

impl BidirKind for Bdpt {
    const NAME: &'static str = "bdpt";
    const DESCRIPTION: &'static str = "Bidirectional path tracing: every (s, t) strategy combined by multiple importance sampling";
    const PARAMS: &'static [ParamSpec] = &PARAMS;
    const TECHNIQUES: Techniques = Techniques::BDPT;
    const STRATEGY_LAYERS: bool = true;
}

export_integrator!(BidirIntegrator<Bdpt>);
