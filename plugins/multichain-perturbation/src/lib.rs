//! # `multichain-perturbation` — Veach's multi-chain perturbation (Veach 1997 §11.4.5)
//!
//! For paths with several specular chains, e.g. E S D S L in a mirror corridor. Moves the
//! raster position as `lens-perturbation` does (log-uniform jump between `r1` and `r2`,
//! bounded by half the film window), follows the eye ray through the Dirac vertices (same lobe
//! kinds, else a domain miss) to the first smooth vertex y_j, and then, at each smooth vertex:
//!
//! * if the current path's next vertex x_{j+1} is connectable (smooth or a light), connects
//!   y_j to it and keeps x_{j+1} … xₙ (the last chain is done);
//! * otherwise (x_{j+1} is a Dirac vertex) perturbs the outgoing direction: a direction in
//!   Veach's exponential cone (angle log-uniform in [`theta1`, `theta2`], uniform azimuth)
//!   around the direction from y_j to x_{j+1}, and follows the next specular chain through its
//!   Dirac vertices to the next smooth vertex — or to the light, which it must hit (an area
//!   light, or the environment).
//!
//! **Transition density** (film measure for the eye ray, area measure for every free vertex;
//! `flowlight_mcmc::perturbation`, `flowlight_mcmc::regenerate`):
//!
//! ```text
//! T(x → y) = T₀(u_x → u_y) · Π_{perturbed j} q(ω_{y_j→y_{j+1}} | axis y_j→x_{j+1}) · J(y_j → y_{j+1})
//! T₀ = 1 / (2π r² ln(r₂'/r₁)),   q(ω | a) = g(θ)/Z,  θ = ∠(ω, a) ≤ θ₂,  g and Z as in flowlight_mcmc::perturbation
//! ```
//!
//! with J(a→b) = |n_b·ω|/|b − a|² (1 for a direction at infinity). The reverse move is
//! centred on x_j → y_{j+1}; T₀ is symmetric, so
//!
//! ```text
//! T(y→x)/T(x→y) = Π_j q(ω_{x_j→x_{j+1}} | x_j→y_{j+1}) J(x_j→x_{j+1}) / (q(ω_{y_j→y_{j+1}} | y_j→x_{j+1}) J(y_j→y_{j+1}))
//! ```
//!
//! On paths whose first smooth vertex connects (E D …, E S D D …) it is the lens perturbation.
//!
//! Parameters: declared once (shared ones in `flowlight_mcmc::params`); their table,
//! generated from the declarations, is in docs/erpt.md ("Perturbations"), and
//! `flowlight plugins --markdown` prints it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::params::{exp_cone, FREE_CHAINS, R1, R2, THETA1, THETA2};
use flowlight_mcmc::perturbation::LensJump;
use flowlight_mcmc::regenerate::{density_with, propose_with};
use flowlight_mcmc::{Extension, FilmMove, Policy};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::path::Path;
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::declare::ChoiceParam;
use flowlight_sdk::{
    choice_param, export_mutation, Mutation, Params, Proposal, Scene, Stats, StatsBuilder, Tracer,
};

/// `axis`: the exponential cone's centre at a smooth vertex.
const AXIS: ChoiceParam = choice_param!(
    "axis",
    "direction",
    ["direction", "next-vertex"],
    "cone centre at a smooth vertex: \"direction\", x's own outgoing direction x_j -> x_{j+1}; \"next-vertex\", towards x_{j+1} from y_j (Veach)"
);

pub struct MultichainPerturbation {
    scene: Scene<'static>,
    policy: Policy,
    film: FilmMove,
}

impl Mutation for MultichainPerturbation {
    const NAME: &'static str = "multichain-perturbation";
    const DESCRIPTION: &'static str =
        "Veach's multi-chain perturbation: lens jump, exponential-cone steps through each specular chain, reconnect";
    const PARAMS: &'static [ParamSpec] = &[
        R1.spec(),
        R2.spec(),
        THETA1.spec(),
        THETA2.spec(),
        AXIS.spec(),
        FREE_CHAINS.spec(),
    ];

    fn create(
        params: &Params,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<Self, String> {
        let jump = LensJump::from_params(params, scene.camera.width, scene.camera.height)?;
        let cone = exp_cone(params)?;
        let policy = Policy {
            min_extensions: 0,
            p_reconnect: 1.0,
            extension: Some(match AXIS.get(params)? {
                "direction" => Extension::ConeAlong(cone),
                _ => Extension::Cone(cone),
            }),
            drill_caustics: false,
            free_chains: FREE_CHAINS.get(params)?,
        };
        Ok(MultichainPerturbation {
            scene,
            policy,
            film: FilmMove::Lens(jump),
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
            self.film,
            current,
            proposal,
        ))
    }

    fn density(&self, from: &Path, to: &Path) -> f64 {
        density_with(&self.scene, &self.policy, self.film, from, to)
    }
}

export_mutation!(MultichainPerturbation);
