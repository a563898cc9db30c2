//! # `lens-perturbation` — Veach's lens perturbation (Veach 1997 §11.4.3)
//!
//! Moves the raster position u by a distance r in a uniformly random direction, r
//! exponentially (log-uniformly) distributed between `r1` and `r2`, follows the new eye ray
//! through the path's Dirac vertices — the same lobe kind (reflection, transmission) at each
//! as the current path, else a domain miss — to the first smooth vertex y_k, and connects
//! y_k to the current path's next vertex x_{k+1} (a shadow ray), keeping x_{k+1} … xₙ. When
//! x_{k+1} is a Dirac vertex no connection is possible (E S D S L: use
//! `multichain-perturbation`); when the eye ray reaches the light through Dirac vertices
//! (E S* L) the last vertex must be an area light.
//!
//! Compared with `hard-reconnection` (the same regeneration after a uniform move in the K×K
//! window), most jumps are a fraction of a pixel, so a path seen through a chain of mirrors
//! or glass keeps its number of specular bounces much more often.
//!
//! **Transition density** (film measure; `flowlight_mcmc::perturbation`):
//!
//! ```text
//! T(x → y) = 1 / (2π r² ln(r₂'/r₁)),   r = |u_y − u_x| ∈ [r₁, r₂'], y_j = x_j for j > k
//! ```
//!
//! with r₂' = min(r₂, K/2) (K the chain's `film_window`: the jump stays inside the window,
//! whose 2K flange ERPT's work units keep for the chains' deposits). The reconnection is a
//! Dirac step both ways and T depends on |u_y − u_x| alone, so T(y→x)/T(x→y) = 1. With
//! K = 0 the raster position never moves; when r₂' ≤ r₁ every proposal is a domain miss.
//!
//! Parameters: declared once (shared ones in `flowlight_mcmc::params`); their table,
//! generated from the declarations, is in docs/erpt.md ("Perturbations"), and
//! `flowlight plugins --markdown` prints it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::params::{FREE_CHAINS, R1, R2};
use flowlight_mcmc::perturbation::LensJump;
use flowlight_mcmc::regenerate::{density_with, propose_with};
use flowlight_mcmc::{FilmMove, Policy};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::path::Path;
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::{
    export_mutation, Mutation, Params, Proposal, Scene, Stats, StatsBuilder, Tracer,
};

/// Strict reconnection at the first smooth vertex: the eye end of the lens perturbation.
fn reconnect(free_chains: bool) -> Policy {
    Policy {
        min_extensions: 0,
        p_reconnect: 1.0,
        extension: None,
        drill_caustics: false,
        free_chains,
    }
}

pub struct LensPerturbation {
    scene: Scene<'static>,
    jump: LensJump,
    policy: Policy,
}

impl Mutation for LensPerturbation {
    const NAME: &'static str = "lens-perturbation";
    const DESCRIPTION: &'static str =
        "Veach's lens perturbation: log-uniform raster jump, Dirac chain followed, reconnect (ratio 1)";
    const PARAMS: &'static [ParamSpec] = &[R1.spec(), R2.spec(), FREE_CHAINS.spec()];

    fn create(
        params: &Params,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<Self, String> {
        let jump = LensJump::from_params(params, scene.camera.width, scene.camera.height)?;
        let policy = reconnect(FREE_CHAINS.get(params)?);
        Ok(LensPerturbation {
            scene,
            jump,
            policy,
        })
    }

    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
        _stats: &mut Stats,
    ) -> Result<Proposal, String> {
        Ok(propose_with(
            &self.scene,
            tracer,
            rng,
            &self.policy,
            FilmMove::Lens(self.jump),
            current,
            proposal,
        ))
    }

    fn density(&self, from: &Path, to: &Path) -> f64 {
        density_with(
            &self.scene,
            &self.policy,
            FilmMove::Lens(self.jump),
            from,
            to,
        )
    }
}

export_mutation!(LensPerturbation);
