//! # `vcm` — vertex connection and merging
//!
//! Georgiev et al.'s vertex connection and merging (2012; Hachisuka et al.'s unified path
//! sampling is the same estimator): every strategy of `bdpt`, plus merging each camera vertex
//! with the light vertices of the iteration within a radius r, all weighed by multiple
//! importance sampling. Merging samples the paths no connection can — a caustic seen
//! through water or glass (L S D S E) — at the price of a bias that vanishes as r shrinks
//! over the iterations: r_i = radius · R · (i + 1)^((radius_alpha − 1)/2) at sample index i,
//! R the scene's bounding-sphere radius. `mode = "ppm"` keeps merging alone (progressive
//! photon mapping). The estimator is biased but consistent, and the EXR says
//! `flowlight.biased = true`.
//!
//! An iteration is one sample index of a work unit: one light subpath per pixel of the
//! unit, merged with by every camera path of the unit (the image depends on the tile size,
//! never on the thread count). Light vertices kept per unit: reported as
//! `max light vertices`.
//!
//! Parameters: those of `bdpt` but `strategies`, plus `radius`, `radius_alpha` and `mode`.
//! Generated table: docs/bdpt.md ("Parameters").

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_pathtrace::bidir::params::{HEURISTIC, MODE, RADIUS, RADIUS_ALPHA, SHARED};
use flowlight_pathtrace::bidir::render::{BidirIntegrator, BidirKind};
use flowlight_pathtrace::bidir::Techniques;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::export_integrator;

const PARAMS: [ParamSpec; 10] = [
    SHARED[0],
    SHARED[1],
    SHARED[2],
    SHARED[3],
    SHARED[4],
    SHARED[5],
    HEURISTIC.spec(),
    RADIUS.spec(),
    RADIUS_ALPHA.spec(),
    MODE.spec(),
];

pub struct Vcm;

impl BidirKind for Vcm {
    const NAME: &'static str = "vcm";
    const DESCRIPTION: &'static str = "Vertex connection and merging (biased, consistent): BDPT's strategies plus merging within a shrinking radius; mode = \"ppm\" for photon mapping";
    const PARAMS: &'static [ParamSpec] = &PARAMS;
    const TECHNIQUES: Techniques = Techniques::VCM;
}

export_integrator!(BidirIntegrator<Vcm>);
