//! # `caustic-perturbation` — Veach's caustic perturbation (Veach 1997 §11.4.4)
//!
//! For paths whose light side is a specular chain ending at a diffuse vertex: E D S+ L (light
//! through glass or off mirrors onto a floor, seen directly), and the same chain deeper in
//! the path (E D D S+ L, E D S+ D L). With the chain x_d (smooth) … x_m (smooth or a point on
//! an area light), x_{d+1} … x_{m−1} Dirac, and x_{d−1} the eye or smooth:
//!
//! 1. keep x_m … xₙ; perturb the direction at x_m towards the chain by an angle θ
//!    log-uniform in [`theta1`, `theta2`] (Veach's exponential distribution) with a uniform
//!    azimuth;
//! 2. trace it through the Dirac vertices (the same lobe kind at each, else a domain miss)
//!    to a smooth y_d;
//! 3. connect y_d to x_{d−1}: to the eye when d = 1 — the new raster position is y₁'s
//!    projection, which must lie in the chain's K×K film window around the current one —
//!    or to the kept smooth vertex x_{d−1}.
//!
//! **Transition density.** The move keeps x_m, which in the target function's measure μ
//! (film × area of the free vertices) is not a free coordinate: its proposals lie on a leaf
//! of μ-measure zero, and the density is expressed on the leaf with the Jacobian
//! J = dμ/(dA(x_m) dσ(ω_m)) (`flowlight_mcmc::specular_chain` derives it: étendue
//! conservation along the chain, Snell's factor at refractions, the film Jacobian when d = 1):
//!
//! ```text
//! T(x → y) = q(ω → ω') / J(y),   q(ω → ω') = g(θ)/Z,  g = 1/(θ sin θ) on [θ₁, θ₂], 1/(θ₁ sin θ₁) below θ₁,  Z = 2π(ln(θ₂/θ₁) + (1 − cos θ₁)/(θ₁ sin θ₁))
//! T(y → x) / T(x → y) = J(y) / J(x)
//! ```
//!
//! Every other strategy gives such a proposal density 0 (it lands on x_m exactly with
//! probability 0), so the mixture density stays consistent.
//!
//! Parameters: declared once (shared ones in `flowlight_mcmc::params`); their table,
//! generated from the declarations, is in docs/erpt.md ("Perturbations"), and
//! `flowlight plugins --markdown` prints it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::params::{exp_cone, THETA1, THETA2};
use flowlight_mcmc::perturbation::ExpCone;
use flowlight_mcmc::specular_chain;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::path::Path;
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::{
    export_mutation, Mutation, Params, Proposal, Scene, Stats, StatsBuilder, Tracer,
};

pub struct CausticPerturbation {
    scene: Scene<'static>,
    cone: ExpCone,
}

impl Mutation for CausticPerturbation {
    const NAME: &'static str = "caustic-perturbation";
    const DESCRIPTION: &'static str =
        "Veach's caustic perturbation: turn the light-side direction of a specular chain, retrace it, connect to the eye";
    const PARAMS: &'static [ParamSpec] = &[THETA1.spec(), THETA2.spec()];

    fn create(
        params: &Params,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<Self, String> {
        let cone = exp_cone(params)?;
        Ok(CausticPerturbation { scene, cone })
    }

    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
        _stats: &mut Stats,
    ) -> Result<Proposal, String> {
        Ok(specular_chain::propose(
            &self.scene,
            tracer,
            rng,
            &self.cone,
            current,
            proposal,
        ))
    }

    fn density(&self, from: &Path, to: &Path) -> f64 {
        specular_chain::density(&self.scene, &self.cone, from, to)
    }
}

export_mutation!(CausticPerturbation);
