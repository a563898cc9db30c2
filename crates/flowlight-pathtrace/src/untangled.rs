//! Untangled MCPT (thesis §3.6–3.7): every path has exactly one connection to a light.
//!
//! At each vertex the sampler first picks a BSDF component (the strong node type, probability
//! p_m). At a Λβ vertex with lighting depth k it ends the path with an explicit light
//! connection with probability T_k, or extends it with probability 1 − T_k; light hit by
//! an extension from a Λβ vertex is ignored (the connection branch estimates it). At a Λα
//! vertex (specular, narrow glossy) it always extends, and an emitter hit after it ends the
//! path as an implicit path, with probability ζ_e when the emitter also scatters. Estimator:
//!
//!   X = L_e · Π wᵢfᵢ·|cos| / (p_m · p_d · (1 − T)) · w f·G / (p_m · T · p_A)   (explicit)
//!   X = L_e / ζ_e · Π wᵢfᵢ·|cos| / (p_m · p_d · (1 − T))                       (implicit)
//!
//! where fᵢ is the chosen component and wᵢ its mixture weight. Components are chosen with
//! p_m = wᵢ, so each factor wᵢfᵢ/p_m reduces to fᵢ.

use crate::settings::PathSettings;
use crate::shading::{connect_light, side_consistent, Shading};
use flowlight_core::bsdf::volume;
use flowlight_core::camera::Camera;
use flowlight_core::geometry::Ray;
use flowlight_core::light::{LightKind, LightSample};
use flowlight_core::path::{NodeClass, NodeType, Path, PathVertex};
use flowlight_core::sampler::SampleStream;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};

/// A stored light vertex: point `p` (with its error bound) and normal `n` (geometric and
/// shading alike), on primitive `prim` (`u32::MAX` for a light without one) of light `light`.
pub(crate) fn light_node(p: Vec3, p_error: Vec3, n: Vec3, prim: u32, light: i32) -> PathVertex {
    PathVertex {
        p,
        p_error,
        ng: n,
        ns: n,
        uv: Vec2::ZERO,
        uv1: Vec2::ZERO,
        color: [1.0; 4],
        prim,
        material: u32::MAX,
        emitter: light,
        node: NodeType::Light,
        component: 0,
    }
}

/// The light vertex of a ray that escaped into environment light `env`: a point one unit
/// along the ray, with the direction as its normal (the vertex at infinity of `measure.rs`).
pub(crate) fn environment_vertex(ray: &Ray, env: usize) -> PathVertex {
    light_node(
        ray.origin + ray.dir,
        Vec3::ZERO,
        ray.dir,
        u32::MAX,
        env as i32,
    )
}

/// The stored vertex of a light sample connected from `p_ref`. Area lights keep their point
/// and normal; a point or spot light its position (the normal slot holds the direction to
/// `p_ref`); a distant light a point one unit from `p_ref` towards it, with that direction
/// as its normal.
pub(crate) fn light_vertex(scene: &Scene, ls: &LightSample, p_ref: Vec3) -> PathVertex {
    let (p, n, prim) = match ls.kind {
        LightKind::Area => (ls.p, ls.n, scene.lights.emitters[ls.light as usize].prim),
        LightKind::Positional => (ls.p, (p_ref - ls.p).normalize_or_zero(), u32::MAX),
        LightKind::Directional | LightKind::Environment => (p_ref + ls.n, ls.n, u32::MAX),
    };
    light_node(p, ls.p_error, n, prim, ls.light as i32)
}

/// Probability ζ_e of ending at an emitter that also scatters light (thesis §3.6): the share
/// of the emitted radiance in emitted plus reflected, taking the reflected radiance as the
/// BSDF albedo times a unit incident radiance, clamped to [0.05, 0.95]. A bright lamp thus
/// almost always ends the path (its pixels are not noisy), a dim emitter that reflects
/// strongly often continues. Any value in (0, 1) is unbiased: both branches are divided by
/// their probability.
pub fn emission_termination(emitted: Rgb, albedo: f32) -> f32 {
    let e = emitted.luminance();
    if albedo <= 0.0 {
        return 1.0;
    }
    (e / (e + albedo)).clamp(0.05, 0.95)
}

/// One path sample: its estimate and its lighting layer. `value` is zero for paths that did
/// not reach a light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSample {
    pub value: Rgb,
    pub layer: u32,
}

/// Records vertices into an optional [`Path`] (ERPT seeds keep them; MCPT does not).
struct Recorder<'p> {
    path: Option<&'p mut Path>,
}

impl Recorder<'_> {
    fn push(&mut self, v: PathVertex) -> bool {
        match self.path.as_deref_mut() {
            None => true,
            Some(p) => {
                let i = p.vertex_count as usize;
                if i >= p.vertices.len() {
                    return false;
                }
                p.vertices[i] = v;
                p.vertex_count += 1;
                true
            }
        }
    }
}

/// Traces one untangled path through raster position `raster`. When `record` is given, the
/// path's vertices, layer and contribution are stored in it (vertex_count = 0 when the path
/// carries no light).
pub fn trace<S: SampleStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut S,
    raster: Vec2,
    record: Option<&mut Path>,
) -> PathSample {
    let camera: &Camera = &scene.camera;
    let mut rec = Recorder { path: record };
    if let Some(p) = rec.path.as_deref_mut() {
        p.raster = raster;
        p.vertex_count = 0;
        p.contribution = Rgb::ZERO;
    }
    let none = PathSample {
        value: Rgb::ZERO,
        layer: 0,
    };
    let mut ray = camera.sample_ray(raster, rng);
    // The ray's origin: the pinhole, the lens point, or this raster position's point on an
    // orthographic film.
    let eye = PathVertex::eye(ray.origin, camera.forward);
    rec.push(eye);

    let mut beta = Rgb::ONE;
    // σ_a of the absorbing volume the current ray runs through, if any.
    let mut inside: Option<Rgb> = None;
    let mut depth = 0u32; // lighting (virtual) depth of the last vertex
    let mut physical = 0u32;
    let mut after_alpha = true; // the eye behaves like a specular vertex
    let finish = |rec: &mut Recorder, value: Rgb, layer: u32| {
        if let Some(p) = rec.path.as_deref_mut() {
            p.contribution = value;
            p.layer = layer;
        }
        PathSample { value, layer }
    };

    loop {
        let Some(hit) = tracer.intersect(&ray) else {
            // Escaped after a Λα vertex (or the eye): an implicit path to the environment,
            // which does not scatter (ζ_e = 1). After a Λβ vertex the connection branch
            // estimates it.
            let le = scene.lights.environment_radiance(ray.dir);
            if !after_alpha || le.is_black() {
                return none;
            }
            let Some(env) = scene.lights.environment_index() else {
                return none;
            };
            let light = environment_vertex(&ray, env);
            if !rec.push(light) {
                return none;
            }
            return finish(&mut rec, beta * le, depth);
        };
        // Beer–Lambert absorption when the segment ran inside a volumetric material.
        if let Some(sigma) = inside.take() {
            beta *= volume::transmittance(sigma, hit.t);
        }
        let wo_world = -ray.dir;
        let bsdf = scene.bsdf(&hit);

        if hit.emitter >= 0 && after_alpha {
            let le = scene.lights.emitted(hit.emitter as usize, hit.p, wo_world);
            if !le.is_black() {
                let zeta = emission_termination(le, bsdf.albedo());
                if rng.uniform() < zeta {
                    if !rec.push(PathVertex::from_hit(&hit, NodeType::Light, 0)) {
                        return none;
                    }
                    return finish(&mut rec, beta * le / zeta, depth);
                }
                beta /= 1.0 - zeta;
            }
        }

        // `max_ray_depth` scattering events have been made: this hit may only end the path
        // on an emitter (above), as the entangled sampler's last BSDF sample does.
        if physical >= settings.max_ray_depth {
            return none;
        }
        physical += 1;
        let shading = Shading::new(&hit, wo_world);
        let (c, _p_select) = bsdf.choose_component(rng.uniform());
        let component = bsdf.component(c);
        let class = component.class_with(settings.narrow_glossy_alpha);
        // A Λα vertex before any lighting vertex belongs to the primordial mirror chain.
        let next_depth = if depth == 0 && class == NodeClass::Alpha {
            0
        } else {
            depth + 1
        };
        if next_depth > settings.path_depth {
            return none;
        }
        depth = next_depth;

        if class == NodeClass::Beta {
            let t = settings
                .termination
                .connection_probability(depth, component.albedo());
            if rng.uniform() < t {
                // Explicit path: connect this vertex to a point on a light.
                let Some(ls) = scene.lights.sample_from_pair(rng.uniform2()) else {
                    return none;
                };
                let Some(conn) = connect_light(scene, tracer, &hit, &shading, &ls) else {
                    return none;
                };
                let f = component.eval(shading.wo, conn.wi_local);
                // The mixture weight of the chosen component equals its selection
                // probability p_m, so w·f / p_m = f: the component's own value is the estimate.
                // conn.pdf is the solid-angle density p_A/G (area, environment) or the
                // selection probability (delta lights, whose radiance already holds 1/d²).
                let value = beta * f * conn.radiance * (conn.wi_local.z.abs() / (t * conn.pdf));
                let node = component.node_type(shading.wo, conn.wi_local);
                if !rec.push(PathVertex::from_hit(&hit, node, c as u8)) {
                    return none;
                }
                let light = light_vertex(scene, &ls, hit.p);
                if !rec.push(light) {
                    return none;
                }
                return finish(&mut rec, value, depth);
            }
            beta /= 1.0 - t;
        }

        let Some(s) = component.sample_with(shading.wo, rng.uniform(), rng.uniform2()) else {
            return none;
        };
        let wi_world = shading.frame.to_world(s.wi);
        if s.pdf <= 0.0 || !side_consistent(&hit, wi_world, s.wi) {
            return none;
        }
        // As above, the component's weight cancels its selection probability.
        beta *= s.f * (s.wi.z.abs() / s.pdf);
        if beta.is_black() {
            return none;
        }
        if !rec.push(PathVertex::from_hit(&hit, s.node, c as u8)) {
            return none;
        }
        after_alpha = class == NodeClass::Alpha;
        inside = volume::entered(scene.material(&hit), hit.ng, wi_world);
        ray = hit.spawn_ray(wi_world);
    }
}
