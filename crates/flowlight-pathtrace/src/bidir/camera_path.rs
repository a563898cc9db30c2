//! Camera subpaths and the strategies that end on them: hitting a light (s = 0), a light
//! sample (s = 1), connections to the vertices of the pixel sample's own light subpath
//! (s ≥ 2) and merges with every light vertex of the iteration within the radius
//! (Veach 1997 §10.2; Georgiev et al. 2012 §4–5). Each contribution is weighed by
//! [`super::mis`] and added to the sample's contributions in its layer.
//!
//! Photon mapping alone ([`Techniques::PPM`]) follows the camera path through Dirac events
//! only: it merges at each vertex with a non-Dirac part and stops at the first non-Dirac
//! event; a light reached by Dirac events alone is seen by hitting it.

use super::grid::HashGrid;
use super::light_path::layer_of;
use super::mis::{self, ConnectionDensities, Iteration, Partial, Techniques};
use super::strategy_seeds::{StrategyEnd, StrategyEvent, StrategyRecorder};
use super::vertex::{self, adjoint_cos, importance_bsdf, LightVertex, Side, Surface};
use super::BidirSettings;
use crate::shading::{light_connection, light_sample, side_consistent, Shading};
use crate::walk::{Step, WalkState};
use crate::SampleContributions;
use flowlight_core::bsdf::{volume, Bsdf, BsdfAt};
use flowlight_core::geometry::{Frame, Ray, SurfaceHit};
use flowlight_core::light::{LightKind, LightSample, PunctualKind};
use flowlight_core::sampler::SampleStream;
use flowlight_core::sampling::uniform_cone_pdf;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};
use std::cell::RefCell;
use std::f32::consts::PI;

/// The light vertices a camera path merges with and the grid over them.
#[derive(Clone, Copy)]
pub struct MergeSet<'a> {
    pub grid: &'a HashGrid,
    pub vertices: &'a [LightVertex],
}

/// What every camera subpath of an iteration shares.
pub struct CameraPaths<'a, 'b> {
    pub scene: &'a Scene<'b>,
    pub tracer: &'a Tracer<'a>,
    pub settings: &'a BidirSettings,
    pub it: &'a Iteration,
    /// Centre and radius of the sphere holding the scene ([`super::light_path::LightPaths`]).
    pub sphere: (Vec3, f32),
    /// Where ERPT's BDPT seeds record the subpath and its strategies ([`StrategyRecorder`]).
    pub recorder: Option<&'a RefCell<StrategyRecorder>>,
}

/// A camera vertex: what its strategies share.
struct Here<'a> {
    hit: &'a SurfaceHit,
    bsdf: &'a Bsdf,
    at: &'a BsdfAt<'a>,
    shading: &'a Shading,
    frame: Frame,
    beta: Rgb,
    partial: Partial,
    /// Lighting depth of the vertex.
    depth: u32,
    /// Camera vertices up to here, the eye included (t).
    t: u32,
}

/// Counters of one camera path.
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraCounts {
    pub connections: u64,
    pub merges: u64,
}

impl CameraPaths<'_, '_> {
    /// Traces the camera subpath through `raster` with the numbers of `rng` (any
    /// [`SampleStream`]), adding its weighed contributions to `out`: connections to `own`
    /// (the vertices of the sample's light subpath) and merges with `merges`. With
    /// [`BidirSettings::only_strategy`] (s, t) it makes that strategy alone and stops at its
    /// t-th vertex.
    pub fn trace<S: SampleStream>(
        &self,
        rng: S,
        raster: Vec2,
        own: &[LightVertex],
        merges: Option<MergeSet>,
        out: &mut SampleContributions,
        counts: &mut CameraCounts,
    ) {
        let (scene, it, settings) = (self.scene, self.it, self.settings);
        let mut rng = rng;
        let ray = scene.camera.sample_ray(raster, &mut rng);
        if let Some(r) = self.recorder {
            r.borrow_mut().camera_start(ray.origin);
        }
        let mut state = WalkState::start(rng, ray);
        let mut partial = Partial::default();
        let mut t = 1u32;
        let mut all_dirac = true;
        loop {
            let Some(hit) = self.tracer.intersect(&state.ray) else {
                if !settings.wants(0, t + 1) {
                    return;
                }
                self.escaped(&state, &partial, t, all_dirac, out);
                return;
            };
            if let Some(sigma) = state.inside.take() {
                state.beta *= volume::transmittance(sigma, hit.t);
            }
            let cos_in = hit.ns.dot(state.ray.dir).abs();
            if cos_in == 0.0 {
                return;
            }
            if t == 1 {
                let density = scene.camera.hit_density(state.ray.dir, hit.t, cos_in);
                partial = Partial::camera_start(it, density * it.film_pixels);
            } else {
                partial.arrive(it, hit.t * hit.t, cos_in, true);
            }
            t += 1;
            if let Some(r) = self.recorder {
                r.borrow_mut().camera_hit(&hit, state.step, state.prev_p);
            }
            if hit.emitter >= 0 && settings.wants(0, t) {
                self.emitter_hit(&state, &hit, &partial, t, all_dirac, out);
            }
            if state.last {
                return;
            }
            let bsdf = scene.bsdf(&hit);
            let depth = if state.depth == 0 && bsdf.is_delta() {
                0
            } else {
                state.depth + 1
            };
            if depth > settings.path.path_depth {
                return;
            }
            state.depth = depth;
            state.physical += 1;
            let shading = Shading::new(&hit, -state.ray.dir);
            let at = bsdf.at(shading.wo);
            if bsdf.has_non_delta() {
                let here = Here {
                    hit: &hit,
                    bsdf: &bsdf,
                    at: &at,
                    shading: &shading,
                    frame: Frame::from_z(hit.ns),
                    beta: state.beta,
                    partial,
                    depth,
                    t,
                };
                if it.techniques.connect {
                    let u = state.rng.uniform2();
                    if settings.wants(1, t) {
                        self.sample_light(&here, u, out);
                    }
                    for y in own.iter().filter(|y| settings.wants(y.length + 1, t)) {
                        counts.connections += u64::from(self.connect(&here, y, out));
                    }
                }
                if let Some(set) = merges {
                    counts.merges += self.merge(&here, set, out);
                }
            }
            if settings.only_strategy.is_some_and(|(_, last)| t >= last) {
                return;
            }
            let roulette = vertex::termination(
                &settings.path.termination,
                depth,
                bsdf.albedo(),
                state.beta.max_component() * state.eta2,
            );
            state.last = roulette >= 1.0 || state.physical >= settings.path.max_ray_depth;
            if let Some(r) = self.recorder {
                let rolled = !state.last && roulette > 0.0;
                r.borrow_mut()
                    .camera_scatter(if rolled { 1.0 - roulette } else { 1.0 });
            }
            let surface = Surface {
                hit: &hit,
                bsdf: &bsdf,
                shading: &shading,
                at: &at,
            };
            let going = vertex::scatter(
                scene,
                it,
                Side::Camera,
                (&mut state, &mut partial),
                &surface,
                roulette,
            );
            let dirac = matches!(state.step, Step::Dirac(_));
            if !going || (it.techniques == Techniques::PPM && !dirac) {
                return;
            }
            all_dirac &= dirac;
        }
    }

    /// The environment along an escaped ray, weighed against its light sample and light
    /// tracing from it.
    fn escaped<S>(
        &self,
        state: &WalkState<S>,
        partial: &Partial,
        t: u32,
        all_dirac: bool,
        out: &mut SampleContributions,
    ) {
        let lights = &self.scene.lights;
        let dir = state.ray.dir;
        let le = lights.environment_radiance(dir);
        if le.is_black() {
            return;
        }
        let weight = if t == 1 {
            1.0
        } else if !self.it.techniques.connect {
            f32::from(all_dirac)
        } else {
            let direct = lights.pdf_environment(dir);
            let (pos, pdf_dir) = lights.emission_pdf_environment(dir, self.sphere.1);
            mis::emitter_hit(self.it, partial, direct, pos * pdf_dir)
        };
        let layer = layer_of(self.settings, state.depth, 0, t + 1);
        if let Some(v) = mis::weighted(state.beta * le, weight) {
            out.add(layer, v);
            if let (Some(r), Some(light)) = (self.recorder, lights.environment_index()) {
                let (pdf, dirac) = match state.step {
                    Step::Eye => (1.0, false),
                    Step::Dirac(p) => (p as f64, true),
                    Step::Smooth(p) => (p as f64, false),
                };
                let end = StrategyEnd::Escape {
                    dir,
                    light,
                    pdf,
                    dirac,
                };
                r.borrow_mut().event(StrategyEvent {
                    s: 0,
                    t: t + 1,
                    weight,
                    value: v,
                    layer,
                    end,
                });
            }
        }
    }

    /// The emission of the emitter at `hit`, weighed against its light sample and light
    /// tracing from it.
    fn emitter_hit<S>(
        &self,
        state: &WalkState<S>,
        hit: &SurfaceHit,
        partial: &Partial,
        t: u32,
        all_dirac: bool,
        out: &mut SampleContributions,
    ) {
        let lights = &self.scene.lights;
        let i = hit.emitter as usize;
        let le = lights.emitted(i, hit.p, -state.ray.dir);
        if le.is_black() {
            return;
        }
        let weight = if t == 2 {
            1.0
        } else if !self.it.techniques.connect {
            f32::from(all_dirac)
        } else {
            let (pos, pdf_dir) = lights.emission_pdf_area(i, -state.ray.dir);
            mis::emitter_hit(self.it, partial, lights.pdf_area(i), pos * pdf_dir)
        };
        let layer = layer_of(self.settings, state.depth, 0, t);
        if let Some(v) = mis::weighted(state.beta * le, weight) {
            out.add(layer, v);
            if let Some(r) = self.recorder {
                r.borrow_mut().event(StrategyEvent {
                    s: 0,
                    t,
                    weight,
                    value: v,
                    layer,
                    end: StrategyEnd::Hit,
                });
            }
        }
    }

    /// A light sample at the vertex (s = 1).
    fn sample_light(&self, here: &Here, u: Vec2, out: &mut SampleContributions) {
        let scene = self.scene;
        let Some(ls) = light_sample(scene, here.bsdf, here.hit, here.shading, u) else {
            return;
        };
        let Some((conn, shadow)) = light_connection(scene, here.hit, here.shading, &ls) else {
            return;
        };
        let (f, forward) = here.at.eval_pdf(conn.wi_local);
        if f.is_black() {
            return;
        }
        let cos_x = conn.wi_local.z.abs();
        let reverse = here.bsdf.pdf(conn.wi_local, here.shading.wo);
        let ratio = self.emission_ratio(&ls, here.hit.p, cos_x);
        let bsdf_forward = if conn.delta { 0.0 } else { forward };
        let weight = mis::light_sample(
            self.it,
            &here.partial,
            bsdf_forward,
            reverse,
            conn.pdf,
            ratio,
        );
        let value = here.beta * f * conn.radiance * (cos_x / conn.pdf);
        let Some(value) = mis::weighted(value, weight) else {
            return;
        };
        if !self.tracer.occluded(&shadow.ray(here.hit)) {
            let layer = layer_of(self.settings, here.depth, 1, here.t);
            out.add(layer, value);
            if let Some(r) = self.recorder {
                // What next-event estimation divides by: the area density of an area light.
                let pdf = if ls.kind == LightKind::Area {
                    ls.pdf
                } else {
                    conn.pdf
                };
                let vertex = crate::untangled::light_vertex(scene, &ls, here.hit.p);
                r.borrow_mut().event(StrategyEvent {
                    s: 1,
                    t: here.t,
                    weight,
                    value,
                    layer,
                    end: StrategyEnd::LightSample {
                        vertex,
                        pdf: pdf as f64,
                    },
                });
            }
        }
    }

    /// p_e · |cos θ_x| / (p_direct · cos θ_light) of a light sample seen from `p`
    /// ([`mis::light_sample`]): the selection cancels; what is left is the light's
    /// directional density towards `p` as an area density there, or for a light at
    /// infinity the density of its disc.
    fn emission_ratio(&self, ls: &LightSample, p: Vec3, cos_x: f32) -> f32 {
        let lights = &self.scene.lights;
        let d2 = (ls.p - p).length_squared();
        match ls.kind {
            LightKind::Area => {
                let w = (p - ls.p).normalize_or_zero();
                lights.emission_pdf_area(ls.light as usize, w).1 * cos_x / d2
            }
            LightKind::Positional => {
                let pdf_dir = match lights.punctual_at(ls.light as usize) {
                    Some(l) if l.kind == PunctualKind::Spot => uniform_cone_pdf(l.cos_outer),
                    _ => 1.0 / (4.0 * PI),
                };
                pdf_dir * cos_x / d2
            }
            LightKind::Directional | LightKind::Environment => {
                cos_x / (PI * self.sphere.1 * self.sphere.1)
            }
        }
    }

    /// The connection of the vertex to light vertex `y` (s ≥ 2); whether it was made.
    fn connect(&self, here: &Here, y: &LightVertex, out: &mut SampleContributions) -> bool {
        let depth = here.depth + y.length;
        if depth > self.settings.path.path_depth {
            return false;
        }
        let d = y.hit.p - here.hit.p;
        let d2 = d.length_squared();
        if !(d2 > 0.0 && d2.is_finite()) {
            return false;
        }
        let dir = d / d2.sqrt();
        let wi = here.frame.to_local(dir);
        if !side_consistent(here.hit, dir, wi) {
            return false;
        }
        let (f_camera, camera_forward) = here.at.eval_pdf(wi);
        if f_camera.is_black() {
            return false;
        }
        let y_bsdf = importance_bsdf(self.scene, &y.hit);
        let y_frame = Frame::from_z(y.hit.ns);
        let (y_wo, y_wi) = (y_frame.to_local(-dir), y_frame.to_local(y.towards_light));
        if !side_consistent(&y.hit, -dir, y_wo) {
            return false;
        }
        let (f_light, light_reverse) = y_bsdf.at(y_wo).eval_pdf(y_wi);
        if f_light.is_black() {
            return false;
        }
        let (cos_camera, cos_light) = (wi.z.abs(), y_wo.z.abs());
        let densities = ConnectionDensities {
            camera_forward: camera_forward * cos_light / d2,
            camera_reverse: here.bsdf.pdf(wi, here.shading.wo),
            light_forward: y_bsdf.pdf(y_wi, y_wo) * cos_camera / d2,
            light_reverse,
        };
        let weight = mis::connection(self.it, &here.partial, &y.partial, &densities);
        let geometry = cos_camera * adjoint_cos(&y.hit, y.towards_light, -dir) / d2;
        let value = here.beta * f_camera * f_light * y.beta * geometry;
        let Some(value) = mis::weighted(value, weight) else {
            return false;
        };
        let ray: Ray = here.hit.shadow_ray_to(y.hit.p, y.hit.p_error, y.hit.ng);
        if self.tracer.occluded(&ray) {
            return false;
        }
        let layer = layer_of(self.settings, depth, y.length + 1, here.t);
        out.add(layer, value);
        if let Some(r) = self.recorder {
            r.borrow_mut().event(StrategyEvent {
                s: y.length + 1,
                t: here.t,
                weight,
                value,
                layer,
                end: StrategyEnd::LightVertex,
            });
        }
        true
    }

    /// The merges of the vertex with the light vertices within the radius; how many.
    fn merge(&self, here: &Here, set: MergeSet, out: &mut SampleContributions) -> u64 {
        let it = self.it;
        let mut count = 0;
        let scale = here.beta * it.vm_normalisation;
        set.grid.query(
            here.hit.p,
            |i| set.vertices[i as usize].hit.p,
            |i| {
                let y = &set.vertices[i as usize];
                let depth = here.depth + y.length - 1;
                if depth > self.settings.path.path_depth {
                    return;
                }
                let wi = here.frame.to_local(y.towards_light);
                if !side_consistent(here.hit, y.towards_light, wi) {
                    return;
                }
                let (f, forward) = here.at.eval_pdf(wi);
                if f.is_black() {
                    return;
                }
                let weight = if it.techniques.weighs() {
                    let reverse = here.bsdf.pdf(wi, here.shading.wo);
                    mis::merge(it, &here.partial, &y.partial, forward, reverse)
                } else {
                    1.0
                };
                if let Some(v) = mis::weighted(scale * f * y.beta, weight) {
                    count += 1;
                    out.add(layer_of(self.settings, depth, y.length + 1, here.t), v);
                }
            },
        );
        count
    }
}
