//! Entangled MCPT (thesis §3.7): at every vertex a light connection (next-event estimation)
//! and a BSDF-sampled extension, whose emitter hits are combined with the connections by
//! the power heuristic (Veach 1997). Depth-based termination decides after each vertex
//! whether the path goes on; survivors are divided by 1 − T_k.

use crate::settings::PathSettings;
use crate::shading::{connect_light, side_consistent, Shading};
use crate::SampleContributions;
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
    let mut depth = 0u32;
    let mut physical = 0u32;
    let mut prev_delta = true; // the pinhole eye is a Dirac: no MIS for the first hit
    let mut prev_pdf = 0.0f32;
    let mut prev_p = ray.origin;

    loop {
        let Some(hit) = tracer.intersect(&ray) else {
            return;
        };
        let wo_world = -ray.dir;

        if hit.emitter >= 0 {
            let le = scene.lights.emitters[hit.emitter as usize].radiance_towards(wo_world);
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
                if let Some(conn) = connect_light(scene, tracer, &hit, &shading, ls) {
                    let f = bsdf.eval(shading.wo, conn.wi_local);
                    if !f.is_black() {
                        let w = power_heuristic(
                            conn.pdf_solid_angle,
                            bsdf.pdf(shading.wo, conn.wi_local),
                        );
                        out.add(
                            depth,
                            beta * f
                                * conn.radiance
                                * (conn.wi_local.z.abs() * w / conn.pdf_solid_angle),
                        );
                    }
                }
            }
        }

        if depth > 0 {
            let t = settings.termination.probability(depth, bsdf.albedo());
            if rng.uniform() < t {
                return;
            }
            beta /= 1.0 - t;
        }
        if physical >= settings.max_ray_depth {
            return;
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
        ray = hit.spawn_ray(wi_world);
    }
}
