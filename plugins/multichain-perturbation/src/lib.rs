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
//! | parameter | type | default | meaning |
//! |---|---|---|---|
//! | `r1` | float | 0.1 | smallest raster jump, pixels |
//! | `r2` | float | 0 | largest raster jump, pixels; 0: √(0.05·W·H/π); bounded by `film_window`/2 |
//! | `theta1` | float | 0.0001 | smallest direction perturbation, radians |
//! | `theta2` | float | 0.1 | largest direction perturbation, radians |
//! | `free_chains` | bool | true | follow mirror chains to any length (`flowlight_mcmc::regenerate`, "Dirac chains of any length"; docs/erpt.md); `false`: Veach's rule, every chain keeps x's number of vertices |
//! | `axis` | string | `"direction"` | cone centre at a smooth vertex: x's own direction x_j→x_{j+1} (ratio Π J(x)/J(y)); `"next-vertex"`: towards x_{j+1} from y_j (Veach, the ratio above) |

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::perturbation::{ExpCone, LensJump};
use flowlight_mcmc::regenerate::{density_with, propose_with};
use flowlight_mcmc::{Extension, FilmMove, Policy};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::path::Path;
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::{
    export_mutation, param, Mutation, ParamKind, Params, Proposal, Scene, Stats, StatsBuilder,
    Tracer,
};

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
        param(
            "r1",
            ParamKind::Float,
            "0.1",
            "smallest raster jump in pixels",
        ),
        param(
            "r2",
            ParamKind::Float,
            "0",
            "largest raster jump in pixels (0: sqrt(0.05 W H / pi)); bounded by film_window/2",
        ),
        param(
            "theta1",
            ParamKind::Float,
            "0.0001",
            "smallest direction perturbation, radians",
        ),
        param(
            "theta2",
            ParamKind::Float,
            "0.1",
            "largest direction perturbation, radians",
        ),
        param(
            "axis",
            ParamKind::String,
            "\"direction\"",
            "cone axis at a smooth vertex: \"direction\" (the path's own outgoing direction) or \"next-vertex\" (towards its next vertex, Veach's)",
        ),
        param(
            "free_chains",
            ParamKind::Bool,
            "true",
            "follow mirror chains to whatever length they have (false: keep every chain's number of bounces, Veach's rule)",
        ),
    ];

    fn create(
        params: &Params,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<Self, String> {
        let jump = LensJump::from_params(params, scene.camera.width, scene.camera.height)?;
        let cone = ExpCone::new(params.float("theta1", 1e-4)?, params.float("theta2", 0.1)?)?;
        let policy = Policy {
            min_extensions: 0,
            p_reconnect: 1.0,
            extension: Some(
                match params.choice("axis", "direction", &["direction", "next-vertex"])? {
                    "direction" => Extension::ConeAlong(cone),
                    _ => Extension::Cone(cone),
                },
            ),
            drill_caustics: false,
            free_chains: params.boolean("free_chains", true)?,
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
