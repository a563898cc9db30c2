//! Entangled MCPT (thesis §3.7): at every vertex a light connection (next-event estimation)
//! and a BSDF-sampled extension, whose emitter hits (and escapes to the environment) are
//! combined with the connections by the power heuristic (Veach 1997). Delta lights (point,
//! spot, directional) are reached only by the connection, with weight 1. The termination
//! distribution (depth-based, or the throughput roulette from `rr_depth` on) decides after
//! each vertex's light connection whether the path goes on; survivors are divided by 1 − T_k.
//!
//! Where the path cannot go on (T_k = 1 at the path-space depth N, or the physical depth cap)
//! the vertex's BSDF sample is still traced, for emission only: its light connection was
//! weighted against that sample, so without it layer N would lose the BSDF-sampled share
//! (in the white furnace of albedo ½ at N = 1: 1.245 instead of 1.5).

use crate::settings::PathSettings;
use crate::shading::{
    connect_light, connection_value, light_connection, light_sample, side_consistent, Connection,
    Shading,
};
use crate::SampleContributions;
use flowlight_core::bsdf::volume;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::area_to_solid_angle;
use flowlight_core::mesh::CompactHit;
use flowlight_core::rng::Rng;
use flowlight_core::sampler::{SampleStream, SLOT_BSDF, SLOT_LIGHT, SLOT_ROULETTE};
use flowlight_core::sampling::power_heuristic;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};
use std::borrow::Cow;

/// Traces one entangled path tree through raster position `raster`, adding each contribution
/// to `out` with its lighting layer. `rng` is any [`SampleStream`]: independent numbers
/// ([`Rng`]) or a pixel's stratified samples ([`flowlight_core::sobol::SobolSampler`]).
pub fn trace<S: SampleStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut S,
    raster: Vec2,
    out: &mut SampleContributions,
) {
    let mut ray = scene.camera.generate_ray(raster);
    let mut beta = Rgb::ONE;
    // σ_a of the absorbing volume the current ray runs through, if any.
    let mut inside: Option<Rgb> = None;
    let mut depth = 0u32;
    let mut physical = 0u32;
    let mut prev_delta = true; // the pinhole eye is a Dirac: no MIS for the first hit
    let mut prev_pdf = 0.0f32;
    let mut prev_p = ray.origin;
    // Product of η'² over the refractions so far: undoes their 1/η'² radiance scaling in β
    // for the throughput roulette (termination.rs), so a path inside glass is not cut more
    // often than one outside.
    let mut eta2 = 1.0f32;

    let mut last = false; // the previous vertex was the path's last: emission only
    loop {
        let Some(hit) = tracer.intersect(&ray) else {
            // Escaped: the environment, MIS-weighted against its light sample.
            let le = scene.lights.environment_radiance(ray.dir);
            if !le.is_black() {
                let w = if prev_delta {
                    1.0
                } else {
                    power_heuristic(prev_pdf, scene.lights.pdf_environment(ray.dir))
                };
                out.add(depth, beta * le * w);
            }
            return;
        };
        // Beer–Lambert absorption when the segment ran inside a volumetric material.
        if let Some(sigma) = inside.take() {
            beta *= volume::transmittance(sigma, hit.t);
        }
        let wo_world = -ray.dir;

        if hit.emitter >= 0 {
            let le = scene.lights.emitted(hit.emitter as usize, hit.p, wo_world);
            if !le.is_black() {
                let w = if prev_delta {
                    1.0
                } else {
                    let pdf_light = area_to_solid_angle(
                        scene.lights.pdf_area(hit.emitter as usize),
                        prev_p,
                        hit.p,
                        hit.ng,
                    );
                    power_heuristic(prev_pdf, pdf_light)
                };
                out.add(depth, beta * le * w);
            }
        }
        if last {
            return;
        }

        let bsdf = scene.bsdf(&hit);
        let next_depth = if depth == 0 && bsdf.is_delta() {
            0
        } else {
            depth + 1
        };
        if next_depth > settings.path_depth {
            return;
        }
        depth = next_depth;
        physical += 1;
        let shading = Shading::new(&hit, wo_world);

        if bsdf.has_non_delta() {
            rng.seek(physical, SLOT_LIGHT);
            let u_light = rng.uniform2();
            if let Some(ls) = light_sample(scene, &bsdf, &hit, &shading, u_light) {
                if let Some(conn) = connect_light(scene, tracer, &hit, &shading, &ls) {
                    if let Some(value) = connection_value(beta, &bsdf, shading.wo, &conn) {
                        out.add(depth, value);
                    }
                }
            }
        }

        // The light sample above was MIS-weighted against a BSDF sample of the same vertex, so
        // that BSDF sample must be traced whenever it can be drawn, also when the path cannot
        // go on (T_k = 1 at the deepest layer, or the physical depth cap): then the extension
        // only looks for emission (which belongs to this vertex's layer, Dirac lobes included)
        // and the path ends there. A random stop (T_k < 1) is fine: survivors are divided by
        // 1 − T_k.
        let t = if depth > 0 {
            let beta_max = beta.max_component() * eta2;
            let albedo = bsdf.albedo();
            settings
                .termination
                .probability_with_throughput(depth, albedo, beta_max)
        } else {
            0.0
        };
        last = t >= 1.0 || physical >= settings.max_ray_depth;
        if !last && t > 0.0 {
            rng.seek(physical, SLOT_ROULETTE);
            if rng.uniform() < t {
                return;
            }
            beta /= 1.0 - t;
        }

        rng.seek(physical, SLOT_BSDF);
        let Some(s) = bsdf.sample(shading.wo, rng.uniform(), rng.uniform2()) else {
            return;
        };
        let wi_world = shading.frame.to_world(s.wi);
        if !side_consistent(&hit, wi_world, s.wi) {
            return;
        }
        beta *= s.f * (s.wi.z.abs() / s.pdf);
        if beta.is_black() {
            return;
        }
        eta2 *= s.eta * s.eta;
        prev_delta = s.delta;
        prev_pdf = s.pdf;
        prev_p = hit.p;
        inside = volume::entered(scene.material(&hit), hit.ng, wi_world);
        ray = hit.spawn_ray(wi_world);
    }
}

/// The state of one path of a [`Wavefront`] between two bounces: exactly the locals of
/// [`trace`]'s loop.
#[derive(Clone, Debug)]
struct PathState<S> {
    rng: S,
    ray: Ray,
    beta: Rgb,
    inside: Option<Rgb>,
    depth: u32,
    physical: u32,
    prev_delta: bool,
    prev_pdf: f32,
    prev_p: Vec3,
    eta2: f32,
    last: bool,
}

/// Reusable buffers of [`trace_wavefront`] (one per work unit, so no allocation per path).
pub struct Wavefront<S = Rng> {
    paths: Vec<PathState<S>>,
    /// Indices of the paths still going, in their original order.
    active: Vec<u32>,
    rays: Vec<Ray>,
    hits: Vec<CompactHit>,
    shadow_rays: Vec<Ray>,
    /// Per shadow ray: what it adds to which path when unblocked.
    shadow_owner: Vec<ShadowOwner>,
    blocked: Vec<u8>,
}

/// The light connection behind a shadow ray of a [`Wavefront`]: the path and layer it adds
/// to, and its contribution, or what that needs where it is evaluated once the ray is known
/// to be unblocked.
#[derive(Clone, Copy, Debug)]
struct ShadowOwner {
    path: u32,
    layer: u32,
    pending: PendingConnection,
}

#[derive(Clone, Copy, Debug)]
enum PendingConnection {
    /// Evaluated at the vertex: its BSDF was built for the hit (textures, vertex colour) and
    /// is not kept.
    Value(Rgb),
    /// The vertex's BSDF is its material's entry in the scene's table
    /// ([`Scene::constant_bsdf`]): evaluated after the shadow ray, and only if unblocked.
    /// Half of the dragon's shadow rays are blocked (`dragon.toml`), and on it the BSDF
    /// value and density cost about half a BSDF sample (callgrind: 340 instructions per
    /// `Bsdf::eval_pdf` against 650 per `Bsdf::sample`).
    Deferred {
        material: u32,
        beta: Rgb,
        wo: Vec3,
        conn: Connection,
    },
}

impl<S> Default for Wavefront<S> {
    fn default() -> Self {
        Wavefront {
            paths: Vec::new(),
            active: Vec::new(),
            rays: Vec::new(),
            hits: Vec::new(),
            shadow_rays: Vec::new(),
            shadow_owner: Vec::new(),
            blocked: Vec::new(),
        }
    }
}

/// Traces `starts.len()` entangled paths as a wavefront: the camera rays as one batch (marked
/// coherent), then per bounce one batch of extension rays and one of shadow rays, so the host
/// is called twice per bounce instead of twice per vertex. Path `i` starts from
/// `starts[i]` = (its generator, its raster position) and adds its contributions to `out[i]`
/// (cleared first).
///
/// Each path draws the same random numbers in the same order and makes the same float
/// operations as [`trace`] (its shadow ray is traced before its next extension ray, as there;
/// shading uses [`Scene::surface`] on the compact hit, the host's own surface code), so
/// `out[i]` equals what [`trace`] gives for the same start, bit for bit, and so does the
/// image whatever the batch size. Like [`trace`], a connection from a vertex whose BSDF is
/// its material's table entry is evaluated only once its shadow ray is known to be
/// unblocked. Differences that change no pixel: a connection that the BSDF's sides say is
/// black ([`flowlight_core::bsdf::Bsdf::is_zero_between`]) is not traced, and one from a
/// vertex whose BSDF is built for the hit is evaluated first and not traced where black.
pub fn trace_wavefront<S: SampleStream + Clone>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
    wf: &mut Wavefront<S>,
    out: &mut [SampleContributions],
) {
    debug_assert_eq!(starts.len(), out.len());
    wf.paths.clear();
    wf.active.clear();
    for (i, (rng, raster)) in starts.iter().enumerate() {
        let ray = scene.camera.generate_ray(*raster);
        wf.paths.push(PathState {
            rng: rng.clone(),
            ray,
            beta: Rgb::ONE,
            inside: None,
            depth: 0,
            physical: 0,
            prev_delta: true,
            prev_pdf: 0.0,
            prev_p: ray.origin,
            eta2: 1.0,
            last: false,
        });
        wf.active.push(i as u32);
        out[i].clear();
    }
    let mut coherent = true;
    while !wf.active.is_empty() {
        wf.rays.clear();
        wf.rays
            .extend(wf.active.iter().map(|&i| wf.paths[i as usize].ray));
        tracer.intersect_batch(&wf.rays, coherent, &mut wf.hits);
        coherent = false;
        wf.shadow_rays.clear();
        wf.shadow_owner.clear();
        let mut kept = 0;
        for k in 0..wf.active.len() {
            let i = wf.active[k];
            let path = &mut wf.paths[i as usize];
            let compact = wf.hits[k];
            let o = &mut out[i as usize];
            scene.prefetch_surfaces(&wf.hits, k);
            let going = if compact.is_hit() {
                let hit = scene.surface(&path.ray, &compact);
                let shadows = (&mut wf.shadow_rays, &mut wf.shadow_owner);
                vertex(scene, settings, path, i, &hit, o, shadows)
            } else {
                escape(scene, path, o);
                false
            };
            if going {
                wf.active[kept] = i;
                kept += 1;
            }
        }
        wf.active.truncate(kept);
        if !wf.shadow_rays.is_empty() {
            tracer.occluded_batch(&wf.shadow_rays, &mut wf.blocked);
            for (owner, &b) in wf.shadow_owner.iter().zip(&wf.blocked) {
                if b != 0 {
                    continue;
                }
                let value = match owner.pending {
                    PendingConnection::Value(value) => value,
                    PendingConnection::Deferred {
                        material,
                        beta,
                        wo,
                        conn,
                    } => {
                        // The table entry `scene.bsdf` borrowed at the vertex.
                        let bsdf = scene.constant_bsdf(material, [1.0; 4]);
                        match bsdf.and_then(|b| connection_value(beta, b, wo, &conn)) {
                            Some(value) if !value.is_black() => value,
                            _ => continue,
                        }
                    }
                };
                out[owner.path as usize].add(owner.layer, value);
            }
        }
    }
}

/// [`trace`]'s escape branch: the environment, MIS-weighted against its light sample.
#[inline]
fn escape<S>(scene: &Scene, path: &PathState<S>, out: &mut SampleContributions) {
    let le = scene.lights.environment_radiance(path.ray.dir);
    if !le.is_black() {
        let w = if path.prev_delta {
            1.0
        } else {
            power_heuristic(path.prev_pdf, scene.lights.pdf_environment(path.ray.dir))
        };
        out.add(path.depth, path.beta * le * w);
    }
}

/// [`trace`]'s loop body at a hit of path `index`, with the light connection's shadow ray
/// and its [`ShadowOwner`] pushed onto `shadows` instead of traced (in place: a connection
/// returned through the caller's stack was reloaded wider than it was stored, a stall on
/// every connection). Returns whether the path goes on (with `path.ray`).
#[inline]
fn vertex<S: SampleStream>(
    scene: &Scene,
    settings: &PathSettings,
    path: &mut PathState<S>,
    index: u32,
    hit: &SurfaceHit,
    out: &mut SampleContributions,
    (shadow_rays, shadow_owner): (&mut Vec<Ray>, &mut Vec<ShadowOwner>),
) -> bool {
    if let Some(sigma) = path.inside.take() {
        path.beta *= volume::transmittance(sigma, hit.t);
    }
    let wo_world = -path.ray.dir;
    if hit.emitter >= 0 {
        let le = scene.lights.emitted(hit.emitter as usize, hit.p, wo_world);
        if !le.is_black() {
            let w = if path.prev_delta {
                1.0
            } else {
                let pdf_light = area_to_solid_angle(
                    scene.lights.pdf_area(hit.emitter as usize),
                    path.prev_p,
                    hit.p,
                    hit.ng,
                );
                power_heuristic(path.prev_pdf, pdf_light)
            };
            out.add(path.depth, path.beta * le * w);
        }
    }
    if path.last {
        return false;
    }
    let bsdf = scene.bsdf(hit);
    let next_depth = if path.depth == 0 && bsdf.is_delta() {
        0
    } else {
        path.depth + 1
    };
    if next_depth > settings.path_depth {
        return false;
    }
    path.depth = next_depth;
    path.physical += 1;
    let depth = path.depth;
    let shading = Shading::new(hit, wo_world);
    let rng = &mut path.rng;

    if bsdf.has_non_delta() {
        rng.seek(path.physical, SLOT_LIGHT);
        let u_light = rng.uniform2();
        if let Some(ls) = light_sample(scene, &bsdf, hit, &shading, u_light) {
            if let Some((conn, shadow_ray)) = light_connection(scene, hit, &shading, &ls) {
                let pending = match &bsdf {
                    _ if bsdf.is_zero_between(shading.wo, conn.wi_local) => None,
                    Cow::Borrowed(_) => Some(PendingConnection::Deferred {
                        material: hit.material,
                        beta: path.beta,
                        wo: shading.wo,
                        conn,
                    }),
                    Cow::Owned(b) => connection_value(path.beta, b, shading.wo, &conn)
                        .filter(|value| !value.is_black())
                        .map(PendingConnection::Value),
                };
                if let Some(pending) = pending {
                    shadow_rays.push(shadow_ray.ray(hit));
                    shadow_owner.push(ShadowOwner {
                        path: index,
                        layer: depth,
                        pending,
                    });
                }
            }
        }
    }

    // From here on the path may end; its shadow ray (already pushed) counts either way.
    let t = if depth > 0 {
        // The same decision as the path-at-a-time `trace` (same stream, same throughput).
        settings.termination.probability_with_throughput(
            depth,
            bsdf.albedo(),
            path.beta.max_component() * path.eta2,
        )
    } else {
        0.0
    };
    path.last = t >= 1.0 || path.physical >= settings.max_ray_depth;
    if !path.last && t > 0.0 {
        rng.seek(path.physical, SLOT_ROULETTE);
        if rng.uniform() < t {
            return false;
        }
        path.beta /= 1.0 - t;
    }
    rng.seek(path.physical, SLOT_BSDF);
    let Some(s) = bsdf.sample(shading.wo, rng.uniform(), rng.uniform2()) else {
        return false;
    };
    let wi_world = shading.frame.to_world(s.wi);
    if !side_consistent(hit, wi_world, s.wi) {
        return false;
    }
    path.beta *= s.f * (s.wi.z.abs() / s.pdf);
    if path.beta.is_black() {
        return false;
    }
    path.eta2 *= s.eta * s.eta;
    path.prev_delta = s.delta;
    path.prev_pdf = s.pdf;
    path.prev_p = hit.p;
    path.inside = volume::entered(scene.material(hit), hit.ng, wi_world);
    path.ray = hit.spawn_ray(wi_world);
    true
}
