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
use crate::shading::{connect_light, side_consistent, Shading};
use crate::SampleContributions;
use flowlight_core::bsdf::volume;
use flowlight_core::light::area_to_solid_angle;
use flowlight_core::rng::Rng;
use flowlight_core::sampling::power_heuristic;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::Vec2;

/// Traces one entangled path tree through raster position `raster`, adding each contribution
/// to `out` with its lighting layer.
pub fn trace(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut Rng,
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
            if let Some(ls) = scene.lights.sample(rng.uniform(), rng.uniform2()) {
                if let Some(conn) = connect_light(scene, tracer, &hit, &shading, &ls) {
                    let f = bsdf.eval(shading.wo, conn.wi_local);
                    if !f.is_black() {
                        // A delta light cannot be hit by the BSDF sample: weight 1.
                        let w = if conn.delta {
                            1.0
                        } else {
                            power_heuristic(conn.pdf, bsdf.pdf(shading.wo, conn.wi_local))
                        };
                        out.add(
                            depth,
                            beta * f * conn.radiance * (conn.wi_local.z.abs() * w / conn.pdf),
                        );
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
            let beta_max = beta.max_component();
            let albedo = bsdf.albedo();
            settings
                .termination
                .probability_with_throughput(depth, albedo, beta_max)
        } else {
            0.0
        };
        last = t >= 1.0 || physical >= settings.max_ray_depth;
        if !last && t > 0.0 {
            if rng.uniform() < t {
                return;
            }
            beta /= 1.0 - t;
        }

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
        prev_delta = s.delta;
        prev_pdf = s.pdf;
        prev_p = hit.p;
        inside = volume::entered(scene.material(&hit), hit.ng, wi_world);
        ray = hit.spawn_ray(wi_world);
    }
}
