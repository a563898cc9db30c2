//! A subpath's vertices: what a light vertex keeps for later connections and merges, the
//! BSDF a light subpath sees (importance transport), and the one scattering step both
//! subpaths take, built on the walker's [`extend`](crate::walk::step::extend).
//!
//! **Adjoint BSDF.** Light carries radiance from the light towards the eye, so at every
//! vertex the BSDF is evaluated with ω_o towards the eye side and ω_i towards the light
//! side, whichever subpath the vertex is on: a light subpath that samples ω_o from ω_i
//! re-evaluates f(ω_o, ω_i) after the sample (the glTF BSDF's energy compensation is not
//! symmetric). Refraction does not scale importance by 1/η² ([`TransportMode::Importance`]).
//! Shading normals make the adjoint differ from the BSDF (Veach 1997 §5.3): a light vertex
//! with ω_i towards the light and ω_o towards the eye multiplies f by
//!
//! ```text
//! |ω_i·n_s| |ω_o·n_g| / |ω_i·n_g|        (instead of the camera side's |ω_o·n_s|)
//! ```
//!
//! ([`adjoint_cos`]); the MIS densities use shading cosines on both sides alike.

use super::mis::{Iteration, Partial};
use crate::shading::Shading;
use crate::walk::{step, Step, WalkState};
use flowlight_core::bsdf::{Bsdf, BsdfAt, TransportMode};
use flowlight_core::geometry::SurfaceHit;
use flowlight_core::sampler::SampleStream;
use flowlight_core::termination::TerminationSchedule;
use flowlight_core::Rgb;
use flowlight_sdk::Scene;
use glam::Vec3;
use std::borrow::Cow;

/// A light subpath's vertex at a surface with a non-Dirac BSDF, kept for connections and
/// merges.
#[derive(Clone, Copy, Debug)]
pub struct LightVertex {
    pub hit: SurfaceHit,
    /// Throughput of the light subpath up to here (the BSDF here not applied): the
    /// emitted radiance over the densities, times f·cos/p of the vertices before.
    pub beta: Rgb,
    /// Unit direction from here back towards the light (ω_i).
    pub towards_light: Vec3,
    pub partial: Partial,
    /// Scattering vertices from the light to here, this one included (y_j has j).
    pub length: u32,
}

/// The BSDF at `hit` for a light subpath: the scene's, with refraction in importance mode.
/// Borrowed where it only reflects (the mode changes nothing there).
pub fn importance_bsdf<'a>(scene: &Scene<'a>, hit: &SurfaceHit) -> Cow<'a, Bsdf> {
    let bsdf = scene.bsdf(hit);
    if bsdf.reflects_only() {
        return bsdf;
    }
    let mut owned = bsdf.into_owned();
    owned.set_transport_mode(TransportMode::Importance);
    Cow::Owned(owned)
}

/// The cosine factor of a light vertex's adjoint BSDF (module docs): `towards_light` = ω_i,
/// `towards_eye` = ω_o, world space.
#[inline]
pub fn adjoint_cos(hit: &SurfaceHit, towards_light: Vec3, towards_eye: Vec3) -> f32 {
    let ig = towards_light.dot(hit.ng).abs();
    if ig == 0.0 {
        return 0.0;
    }
    towards_light.dot(hit.ns).abs() * towards_eye.dot(hit.ng).abs() / ig
}

/// Which end a subpath grows from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Camera,
    Light,
}

/// A vertex's surface as its scattering step needs it: the hit, its BSDF, the shading frame
/// with ω_o (towards where the subpath came from) and the BSDF at ω_o, which the caller has
/// already built for its connections.
pub struct Surface<'a> {
    pub hit: &'a SurfaceHit,
    pub bsdf: &'a Bsdf,
    pub shading: &'a Shading,
    pub at: &'a BsdfAt<'a>,
}

/// One BSDF sample of a subpath at `surface`: the walker's roulette and sample
/// ([`step::extend`] with stop probability `t`), then, on a light subpath, the adjoint value;
/// the partial weights follow. Returns whether the path goes on.
pub fn scatter<S: SampleStream>(
    scene: &Scene,
    it: &Iteration,
    side: Side,
    (state, partial): (&mut WalkState<S>, &mut Partial),
    surface: &Surface,
    t: f32,
) -> bool {
    let Surface {
        hit,
        bsdf,
        shading,
        at,
    } = *surface;
    let towards_back = -state.ray.dir;
    let beta_before = state.beta;
    let (going, extension) = step::extend(scene, state, hit, at, shading, t, None);
    let Some(sample) = extension.sample.filter(|_| going) else {
        return false;
    };
    let survival = extension.survived.map_or(1.0, |t| 1.0 - t);
    let dirac = matches!(state.step, Step::Dirac(_));
    // The reverse density, and on a light subpath the adjoint value f(ω_o = out, ω_i = back).
    let (value, reverse) = if dirac {
        (sample.f, sample.pdf)
    } else {
        bsdf.at(sample.wi).eval_pdf(shading.wo)
    };
    if side == Side::Light {
        let cos = adjoint_cos(hit, towards_back, state.ray.dir);
        state.beta = beta_before * value * (cos / (sample.pdf * survival));
        if state.beta.is_black() {
            return false;
        }
    }
    partial.scatter(it, sample.wi.z.abs(), sample.pdf, reverse, dirac);
    true
}

/// The stop probability of the roulette at a vertex of lighting depth `depth` with BSDF
/// albedo `albedo` and relative throughput `relative` (β over the subpath's first β), and
/// whether the vertex is the subpath's last (its sample is traced for emission only).
#[inline]
pub fn termination(schedule: &TerminationSchedule, depth: u32, albedo: f32, relative: f32) -> f32 {
    if depth == 0 {
        return 0.0;
    }
    schedule.probability_with_throughput(depth, albedo, relative)
}
