//! Light subpaths: a ray emitted by a light
//! ([`flowlight_core::light::Lights::sample_emission`]), continued by BSDF
//! sampling with the adjoint BSDF ([`super::vertex`]); each vertex with a non-Dirac BSDF is
//! kept for connections and merges and, where light tracing is on, connected to the eye and
//! splatted onto the film at its raster position (t = 1; Veach 1997 §10.2).
//!
//! **The splat.** A pixel's value is the mean radiance over its raster area; a camera ray
//! starts at a raster position uniform over the W·H film. The camera's importance times the
//! geometry term of the eye connection is then the area density with which the camera reaches
//! the vertex, `Camera::hit_density`, times W·H; with one light path traced per pixel sample
//! (W·H per sample index, N_LT), a light vertex y with throughput β deposits
//!
//! ```text
//! β · f(y → eye, y → light) · adjoint cos · hit_density(…, cos = 1) · w
//! ```
//!
//! at its raster position, and the host's division by the samples per pixel finishes the
//! estimate. `w` weighs it against the camera-side strategies (`mis::eye_connection`; 1 for
//! light tracing alone).
//!
//! With a thin lens the eye is a lens point drawn with the camera's own density, and
//! `hit_density` is taken from it (`flowlight_core::thin_lens`, "Importance and densities").
//!
//! The vertex on the light itself (s = 1, t = 1) is connected to the eye only by light
//! tracing alone (for area lights), where it is the only way to see a lamp; with camera
//! subpaths the lamp is seen by hitting it.
//!
//! **Bound.** A subpath keeps at most `path_depth` vertices: at most one per surface it
//! reaches (the vertex on the light is never kept), and it stops at its `path_depth`-th
//! surface, so an iteration of a unit keeps at most (unit pixels) × `path_depth`
//! ([`super::render`]).

use super::mis::{self, Iteration, Partial};
use super::strategy_seeds::{StrategyEnd, StrategyEvent, StrategyRecorder};
use super::vertex::{self, adjoint_cos, importance_bsdf, LightVertex, Side, Surface};
use super::BidirSettings;
use crate::shading::{side_consistent, Shading};
use crate::walk::WalkState;
use flowlight_core::bsdf::volume;
use flowlight_core::geometry::{offset_ray_origin, Frame, Ray};
use flowlight_core::light::{EmissionSample, LightKind};
use flowlight_core::sampler::SampleStream;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};
use std::cell::RefCell;

/// Where a light subpath's deposits go: raster position, layer and value.
pub trait Splat {
    fn splat(&mut self, raster: Vec2, layer: u32, value: Rgb);
}

impl<F: FnMut(Vec2, u32, Rgb)> Splat for F {
    fn splat(&mut self, raster: Vec2, layer: u32, value: Rgb) {
        self(raster, layer, value)
    }
}

/// What every light subpath of an iteration shares.
pub struct LightPaths<'a, 'b> {
    pub scene: &'a Scene<'b>,
    pub tracer: &'a Tracer<'a>,
    pub settings: &'a BidirSettings,
    pub it: &'a Iteration,
    /// Centre and radius of a sphere holding the scene (distant lights emit from its disc).
    pub sphere: (Vec3, f32),
    /// Where ERPT's BDPT seeds record the subpath and its splats ([`StrategyRecorder`]).
    pub recorder: Option<&'a RefCell<StrategyRecorder>>,
}

/// The layer a deposit goes to: the lighting layer `lighting`, or the strategy (s, t)'s
/// index where the render writes per-strategy layers ([`super::strategy_layer`]).
#[inline]
pub fn layer_of(settings: &BidirSettings, lighting: u32, s: u32, t: u32) -> u32 {
    if settings.strategy_layers {
        super::strategy_layer(s, t)
    } else {
        lighting
    }
}

impl LightPaths<'_, '_> {
    /// Traces one light subpath with the numbers of `rng` (any [`SampleStream`]: PCG for the
    /// plugins, primary samples for the Metropolis samplers), pushing its kept vertices onto
    /// `vertices` (where anything connects or merges to them) and splatting its eye
    /// connections to `out`.
    pub fn trace<S: SampleStream>(
        &self,
        rng: S,
        vertices: &mut Vec<LightVertex>,
        out: &mut impl Splat,
    ) {
        let mut rng = rng;
        let (u_light, u_pos, u_dir) = (rng.uniform(), rng.uniform2(), rng.uniform2());
        let lights = &self.scene.lights;
        let Some(e) = lights.sample_emission(u_light, u_pos, u_dir, self.sphere) else {
            return;
        };
        let emission = e.pdf_choose * e.pdf_pos * e.pdf_dir;
        if !(emission > 0.0 && emission.is_finite()) {
            return;
        }
        let distant = e.kind.is_distant();
        // The density of the light sample that picks the same light point or direction:
        // solid angle for the environment, the choice alone for a directional light (its
        // disc position is not sampled by a light sample), area otherwise (1 for a point).
        let direct = match e.kind {
            LightKind::Environment => e.pdf_choose * e.pdf_dir,
            LightKind::Directional => e.pdf_choose,
            _ => e.pdf_choose * e.pdf_pos,
        };
        let beta = e.radiance * (e.cos / emission);
        let mut partial = Partial::light_start(self.it, direct, emission, e.cos, e.kind.is_delta());
        if let Some(r) = self.recorder {
            r.borrow_mut().light_start(&e);
        }
        if self.it.techniques == mis::Techniques::LIGHT_TRACE && e.kind == LightKind::Area {
            self.connect_light_to_eye(&e, &mut rng, out);
        }
        let origin = if e.kind == LightKind::Area {
            offset_ray_origin(e.p, e.p_error, e.n, e.dir)
        } else {
            e.p
        };
        let mut state = WalkState::start(rng, Ray::new(origin, e.dir, f32::INFINITY));
        state.beta = beta;
        let keep = self.it.techniques.connect || self.it.techniques.merge;
        let mut length = 0u32;
        while let Some(hit) = self.tracer.intersect(&state.ray) {
            if let Some(sigma) = state.inside.take() {
                state.beta *= volume::transmittance(sigma, hit.t);
            }
            let cos_in = hit.ns.dot(state.ray.dir).abs();
            if cos_in == 0.0 || state.beta.is_black() {
                return;
            }
            partial.arrive(self.it, hit.t * hit.t, cos_in, length > 0 || !distant);
            if let Some(r) = self.recorder {
                r.borrow_mut()
                    .light_hit(&hit, (state.step, state.eta2), state.prev_p);
            }
            length += 1;
            state.physical += 1;
            let bsdf = importance_bsdf(self.scene, &hit);
            if bsdf.has_non_delta() {
                let v = LightVertex {
                    hit,
                    beta: state.beta,
                    towards_light: -state.ray.dir,
                    partial,
                    length,
                };
                if self.it.techniques.light_trace && self.settings.wants(v.length + 1, 1) {
                    self.connect_to_eye(&v, &bsdf, &mut state.rng, out);
                }
                if keep {
                    vertices.push(v);
                }
            }
            // A vertex of depth `path_depth` ends every path it is on.
            if length >= self.settings.path.path_depth
                || state.physical >= self.settings.path.max_ray_depth
            {
                return;
            }
            let relative = state.beta.max_component() / beta.max_component().max(f32::MIN_POSITIVE);
            let t = vertex::termination(
                &self.settings.path.termination,
                length,
                bsdf.albedo(),
                relative,
            );
            if let Some(r) = self.recorder {
                r.borrow_mut()
                    .light_scatter(if t > 0.0 { 1.0 - t } else { 1.0 });
            }
            let shading = Shading::new(&hit, -state.ray.dir);
            let surface = Surface {
                hit: &hit,
                bsdf: &bsdf,
                shading: &shading,
                at: &bsdf.at(shading.wo),
            };
            let going = vertex::scatter(
                self.scene,
                self.it,
                Side::Light,
                (&mut state, &mut partial),
                &surface,
                t,
            );
            if !going {
                return;
            }
        }
    }

    /// The eye connection of light vertex `v` (t = 1), splatted where visible. With a thin
    /// lens the eye is a lens point drawn from the next pair of `rng` with the camera's own
    /// density (`flowlight_core::thin_lens`, "Importance and densities").
    fn connect_to_eye<S: SampleStream>(
        &self,
        v: &LightVertex,
        bsdf: &flowlight_core::bsdf::Bsdf,
        rng: &mut S,
        out: &mut impl Splat,
    ) {
        let camera = &self.scene.camera;
        let Some(eye) = camera.sample_eye_connection(v.hit.p, rng) else {
            return;
        };
        let frame = Frame::from_z(v.hit.ns);
        let (wo, wi) = (frame.to_local(eye.to_eye), frame.to_local(v.towards_light));
        if !side_consistent(&v.hit, eye.to_eye, wo) {
            return;
        }
        let (f, reverse) = bsdf.at(wo).eval_pdf(wi);
        if f.is_black() {
            return;
        }
        let cos_eye = wo.z.abs();
        let factor = camera.hit_density(-eye.to_eye, eye.distance, 1.0);
        let value = v.beta * f * (adjoint_cos(&v.hit, v.towards_light, eye.to_eye) * factor);
        let weight = if self.it.techniques.weighs() {
            mis::eye_connection(
                self.it,
                &v.partial,
                factor * cos_eye * self.it.film_pixels,
                reverse,
            )
        } else {
            1.0
        };
        let Some(value) = mis::weighted(value, weight) else {
            return;
        };
        if self.visible_from_eye(v.hit.p, v.hit.p_error, v.hit.ng, eye.eye) {
            let layer = layer_of(self.settings, v.length, v.length + 1, 1);
            out.splat(eye.raster, layer, value);
            if let Some(r) = self.recorder {
                let cos = v.hit.ng.dot(eye.to_eye).abs();
                r.borrow_mut().event(StrategyEvent {
                    s: v.length + 1,
                    t: 1,
                    weight,
                    value,
                    layer,
                    end: StrategyEnd::Eye {
                        raster: eye.raster,
                        eye: eye.eye,
                        density: camera.hit_density(-eye.to_eye, eye.distance, cos) as f64,
                    },
                });
            }
        }
    }

    /// Light tracing's view of the light itself (s = 1, t = 1): the emitted radiance
    /// towards the eye over the position's density.
    fn connect_light_to_eye<S: SampleStream>(
        &self,
        e: &EmissionSample,
        rng: &mut S,
        out: &mut impl Splat,
    ) {
        let camera = &self.scene.camera;
        let Some(eye) = camera.sample_eye_connection(e.p, rng) else {
            return;
        };
        let cos = e.n.dot(eye.to_eye).abs();
        let le = self.scene.lights.emitted(e.light as usize, e.p, eye.to_eye);
        let density = e.pdf_choose * e.pdf_pos;
        if le.is_black() || cos == 0.0 || density.is_nan() || density <= 0.0 {
            return;
        }
        let value = le * (camera.hit_density(-eye.to_eye, eye.distance, cos) / density);
        if self.visible_from_eye(e.p, e.p_error, e.n, eye.eye) {
            let layer = layer_of(self.settings, 0, 1, 1);
            out.splat(eye.raster, layer, value);
        }
    }

    /// Whether nothing blocks the segment from the surface point `p` (rounding bound
    /// `p_error`, geometric normal `ng`) to the eye point `eye`.
    fn visible_from_eye(&self, p: Vec3, p_error: Vec3, ng: Vec3, eye: Vec3) -> bool {
        let o = offset_ray_origin(p, p_error, ng, eye - p);
        let ray = Ray::new(o, eye - o, 1.0 - 1e-4);
        !self.tracer.occluded(&ray)
    }
}
