//! The path walker: one per-vertex step and one scheduler for every sampler that grows a path
//! from the camera by BSDF sampling with next-event estimation at each smooth vertex (thesis
//! §3.7, the entangled estimator), whatever it does with what the path finds.
//!
//! A path x₀ x₁ … grows one vertex at a time. At a surface hit x_k the step
//!
//! 1. attenuates β by Beer–Lambert transmittance where the segment ran inside an absorbing
//!    volume;
//! 2. reports the emission L_e(x_k → x_{k−1}) found there, weighted against the light sample
//!    of x_{k−1} by the power heuristic (Veach 1997 §9.2):
//!
//!    ```text
//!    w_h = p_σ² / (p_σ² + p_l²)     p_σ: BSDF density at x_{k−1}, p_l: light density (solid angle)
//!    ```
//!
//!    (w_h = 1 after a Dirac step or from the eye);
//! 3. draws the termination probability T_k of the vertex (`termination.rs`) and, from the
//!    vertex's light pair, a light sample y and its connection x_k → y, reported with β before
//!    the roulette and the connection's weight w_c = 1 − w_h on the same step;
//! 4. plays the roulette (survivors divide β by 1 − T_k) and samples the BSDF for the next
//!    ray (β ← β f |cos θ| / p_σ).
//!
//! An escaped ray reports the environment's radiance with the weight of step 2.
//!
//! The step does not decide what a report is for: it hands each to a [`PathSink`]. MCPT's
//! sink (`crate::entangled`) adds the contributions per lighting layer; ERPT's seed sink
//! (`crate::seeds`) stores each as a seed path with its estimate, MIS weight and density. Both
//! therefore see the same numbers, the same decisions and the same float operations: an MCPT
//! contribution and the matching ERPT seed's estimate are equal bit for bit
//! (`tests/integration/erpt_seeds.rs`, `seeds_and_mcpt_contributions_are_equal_path_by_path`).
//!
//! The scheduler ([`wave`]) runs the step for many paths as a wavefront: the camera rays as
//! one coherent batch, then per bounce one batch of extension rays and one of shadow rays, so
//! the host is called twice per bounce instead of twice per vertex; [`wave::run_single`]
//! runs it one path at a time with one host call per ray. Both give the same reports in the
//! same order, bit for bit.
//!
//! Scattering ([`step::extend`]: roulette and BSDF sample) and the arrival bookkeeping
//! (absorption, the sink's densities) do not depend on which end the path started from, so a
//! light-side walker reuses them with the adjoint BSDF; emission and light connections are
//! the camera side's.
//!
//! Depths: `physical` counts scattering events (every bounce, Dirac ones included), capped by
//! `max_ray_depth`; `depth` is the virtual, lighting depth (thesis §2), counted from the first
//! non-Dirac vertex, capped by `path_depth`. A report found at lighting depth k belongs to
//! lighting layer k.

pub mod sink;
pub mod step;
pub mod units;
pub mod wave;

pub use sink::{ConnectionEvent, Extension, PathSink};
pub use wave::{run_single, run_wave, Wave, WaveSinks};

use flowlight_core::geometry::Ray;
use flowlight_core::Rgb;
use glam::Vec3;

/// How a path's last step was drawn: what the vertex it reached was sampled with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// The camera ray (a pinhole or orthographic eye: a Dirac in direction; no MIS).
    Eye,
    /// A Dirac lobe, with its discrete probability.
    Dirac(f32),
    /// A smooth BSDF sample, with its solid-angle density.
    Smooth(f32),
}

impl Step {
    /// The solid-angle density to weigh an emitter hit against a light sample with, `None`
    /// where the hit has a single technique (after the eye or a Dirac lobe: weight 1).
    #[inline(always)]
    pub fn mis_density(self) -> Option<f32> {
        match self {
            Step::Smooth(pdf) => Some(pdf),
            Step::Eye | Step::Dirac(_) => None,
        }
    }
}

/// The walker's own state of one path between two vertices.
#[derive(Clone, Debug)]
pub struct WalkState<S> {
    /// The path's random numbers.
    pub rng: S,
    /// The ray to the next vertex.
    pub ray: Ray,
    /// Throughput β: f |cos| / p over the steps so far, divided by the survival probabilities.
    pub beta: Rgb,
    /// σ_a of the absorbing volume the current ray runs through, if any.
    pub inside: Option<Rgb>,
    /// Lighting (virtual) depth of the last vertex.
    pub depth: u32,
    /// Scattering events so far.
    pub physical: u32,
    /// How the ray to the next vertex was drawn.
    pub step: Step,
    /// The vertex the ray leaves from.
    pub prev_p: Vec3,
    /// Product of η'² over the refractions so far: undoes their 1/η'² radiance scaling in β
    /// for the throughput roulette (termination.rs), so a path inside glass is not cut more
    /// often than one outside.
    pub eta2: f32,
    /// The previous vertex was the path's last: its BSDF sample is traced for emission only.
    pub last: bool,
}

impl<S> WalkState<S> {
    /// A path leaving the eye along `ray`.
    pub fn start(rng: S, ray: Ray) -> Self {
        WalkState {
            rng,
            ray,
            beta: Rgb::ONE,
            inside: None,
            depth: 0,
            physical: 0,
            step: Step::Eye,
            prev_p: ray.origin,
            eta2: 1.0,
            last: false,
        }
    }
}

/// One path of a walk: the walker's state and what its sink keeps beside it
/// ([`PathSink::Trail`]: densities and node types for ERPT's seeds, nothing for MCPT).
#[derive(Clone, Debug)]
pub struct Walker<S, T> {
    pub state: WalkState<S>,
    pub trail: T,
}

#[cfg(test)]
mod tests;
