//! Per-vertex shading helpers shared by both samplers.

use flowlight_core::geometry::{Frame, SurfaceHit};
use flowlight_core::light::LightSample;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::Vec3;

/// The shading frame at a hit and the outgoing direction in it.
pub(crate) struct Shading {
    pub frame: Frame,
    pub wo: Vec3,
}

impl Shading {
    pub fn new(hit: &SurfaceHit, wo_world: Vec3) -> Shading {
        let frame = Frame::from_z(hit.ns);
        Shading {
            wo: frame.to_local(wo_world),
            frame,
        }
    }
}

/// Rejects directions whose side of the shading normal differs from their side of the
/// geometric normal: with interpolated normals they would leak light through the surface.
#[inline]
pub(crate) fn side_consistent(hit: &SurfaceHit, w_world: Vec3, w_local: Vec3) -> bool {
    let g = w_world.dot(hit.ng);
    g * w_local.z > 0.0
}

/// An unoccluded light sample as seen from a hit.
pub(crate) struct Connection {
    pub wi_local: Vec3,
    /// Emitted radiance arriving along −wi.
    pub radiance: Rgb,
    /// |cos θ_light| / d²: converts the area density to the measure at the hit.
    pub geometry: f32,
    /// Solid-angle density of the light sample seen from the hit.
    pub pdf_solid_angle: f32,
    pub pdf_area: f32,
}

/// Samples a point on the lights and returns the connection if it carries light and is
/// visible. `None` for back-facing, grazing, occluded or degenerate connections.
pub(crate) fn connect_light(
    scene: &Scene,
    tracer: &Tracer,
    hit: &SurfaceHit,
    shading: &Shading,
    ls: LightSample,
) -> Option<Connection> {
    let d = ls.p - hit.p;
    let dist2 = d.length_squared();
    if !(dist2 > 0.0 && dist2.is_finite()) {
        return None;
    }
    let wi_world = d / dist2.sqrt();
    let cos_light = ls.n.dot(-wi_world).abs();
    if cos_light <= 0.0 || ls.pdf_area <= 0.0 {
        return None;
    }
    let radiance = scene.lights.emitters[ls.emitter as usize].radiance_towards(-wi_world);
    if radiance.is_black() {
        return None;
    }
    let wi_local = shading.frame.to_local(wi_world);
    if !side_consistent(hit, wi_world, wi_local) {
        return None;
    }
    if tracer.occluded(&hit.spawn_ray_to(ls.p, ls.p_error, ls.n)) {
        return None;
    }
    let geometry = cos_light / dist2;
    Some(Connection {
        wi_local,
        radiance,
        geometry,
        pdf_solid_angle: ls.pdf_area / geometry,
        pdf_area: ls.pdf_area,
    })
}
