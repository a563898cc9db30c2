//! Per-vertex shading helpers of the path samplers: the shading frame, light samples and their
//! connections, and the value of a connection.

use flowlight_core::bsdf::{Bsdf, BsdfAt};
use flowlight_core::geometry::{Frame, Ray, SurfaceHit};
use flowlight_core::light::{LightSample, ShadowTarget};
use flowlight_core::sampling::power_heuristic_over;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};

/// The shading frame at a hit and the outgoing direction in it.
pub struct Shading {
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

/// A vertex's light sample from its numbers, or `None` without one. Where every light is
/// behind the surface for a BSDF that only reflects ([`Scene::lights_behind`]), every
/// connection would be zero ([`Bsdf::is_zero_between`]), so none is sampled: the same
/// contributions and, since the caller draws the numbers either way, the same numbers after
/// it, without the light sample and its geometry. On `dragon.toml`, back-lit, that is the
/// dragon's far side. The light sample of every sampler whose connection from a
/// reflection-only vertex adds nothing where it is zero (MCPT, ERPT's seeds).
#[inline]
pub(crate) fn light_sample(
    scene: &Scene,
    bsdf: &Bsdf,
    hit: &SurfaceHit,
    shading: &Shading,
    u: Vec2,
) -> Option<LightSample> {
    if bsdf.reflects_only() && scene.lights_behind(hit.p, hit.ns, shading.wo.z) {
        return None;
    }
    scene.lights.sample_from_pair(u)
}

/// Rejects directions whose side of the shading normal differs from their side of the
/// geometric normal: with interpolated normals they would leak light through the surface.
#[inline]
pub(crate) fn side_consistent(hit: &SurfaceHit, w_world: Vec3, w_local: Vec3) -> bool {
    let g = w_world.dot(hit.ng);
    g * w_local.z > 0.0
}

/// An unoccluded light sample as seen from a hit.
#[derive(Clone, Copy, Debug)]
pub struct Connection {
    pub wi_local: Vec3,
    /// Radiance arriving along −wi (area, environment), I/d² (point, spot) or the irradiance
    /// at normal incidence (directional).
    pub radiance: Rgb,
    /// What the estimator divides by: the solid-angle density of the sample seen from the hit,
    /// or, for a delta light, its selection probability.
    pub pdf: f32,
    /// A delta light: no BSDF sample can reach it, so no MIS weight.
    pub delta: bool,
}

/// The BSDF value f at a light connection from a vertex, `bsdf` at its outgoing direction
/// ([`Bsdf::at`]), and the factor the estimate multiplies by: the connection's MIS weight against that
/// vertex's BSDF sample (power heuristic) divided by the connection's density, in one
/// division ([`power_heuristic_over`]); `None` where f is black. The estimate is
/// β · f · L · |cos θ_i| · factor. A delta light cannot be hit by the BSDF sample: weight 1,
/// factor 1/pdf, no BSDF density needed. Otherwise f and the density come from one
/// [`Bsdf::eval_pdf`] pass, which gives `eval` and `pdf` bit for bit. The one place the
/// samplers weight a connection, so the path-at-a-time and wavefront tracers agree by
/// construction. Where [`Bsdf::is_zero_between`] says f is zero, it is `None` without an
/// evaluation (the evaluation's answer too).
#[inline]
pub(crate) fn connection_bsdf(bsdf: &BsdfAt, conn: &Connection) -> Option<(Rgb, f32)> {
    if bsdf.is_zero_between(conn.wi_local) {
        return None;
    }
    if conn.delta {
        let f = bsdf.eval(conn.wi_local);
        return (!f.is_black()).then(|| (f, 1.0 / conn.pdf));
    }
    let (f, pdf) = bsdf.eval_pdf(conn.wi_local);
    (!f.is_black()).then(|| (f, power_heuristic_over(conn.pdf, pdf)))
}

/// The contribution β · f · L · |cos θ_i| · (MIS weight / density) of an unoccluded
/// connection ([`connection_bsdf`]); `None` where f is black. One expression for the
/// samplers that evaluate it before the shadow ray and those that evaluate it after.
#[inline]
pub(crate) fn connection_value(beta: Rgb, bsdf: &BsdfAt, conn: &Connection) -> Option<Rgb> {
    let (f, w_over_pdf) = connection_bsdf(bsdf, conn)?;
    Some(beta * f * conn.radiance * (conn.wi_local.z.abs() * w_over_pdf))
}

/// Turns a light sample into a connection from `hit` if it carries light and is visible.
/// `None` for back-facing, grazing, occluded, outside-the-cone or degenerate connections.
pub(crate) fn connect_light(
    scene: &Scene,
    tracer: &Tracer,
    hit: &SurfaceHit,
    shading: &Shading,
    ls: &LightSample,
) -> Option<Connection> {
    let (conn, shadow) = light_connection(scene, hit, shading, ls)?;
    (!tracer.occluded(&shadow.ray(hit))).then_some(conn)
}

/// Where a connection's shadow ray goes, built only for the connections that are traced
/// ([`ShadowRay::ray`]): its two offset ends (`SurfaceHit::shadow_ray_to`, 3.6% of a
/// Cornell box render against 7.4% for the rest of the light connection, perf) are wasted on
/// a connection then dropped.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShadowRay {
    target: ShadowTarget,
    wi: Vec3,
}

impl ShadowRay {
    /// The ray from `hit`, the point the connection was made from.
    #[inline(always)]
    pub fn ray(&self, hit: &SurfaceHit) -> Ray {
        match self.target {
            ShadowTarget::Point { p, p_error, n } => hit.shadow_ray_to(p, p_error, n),
            ShadowTarget::Infinity => hit.spawn_ray(self.wi),
        }
    }
}

/// [`connect_light`] without the visibility test: the connection and the shadow ray that
/// decides it (traced later, in a batch, by the wavefront sampler).
#[inline(always)]
pub(crate) fn light_connection(
    scene: &Scene,
    hit: &SurfaceHit,
    shading: &Shading,
    ls: &LightSample,
) -> Option<(Connection, ShadowRay)> {
    let inc = scene.lights.incident(ls, hit.p)?;
    if inc.radiance.is_black() || !(inc.pdf > 0.0 && inc.pdf.is_finite()) {
        return None;
    }
    let wi_local = shading.frame.to_local(inc.wi);
    if !side_consistent(hit, inc.wi, wi_local) {
        return None;
    }
    let shadow = ShadowRay {
        target: inc.target,
        wi: inc.wi,
    };
    let conn = Connection {
        wi_local,
        radiance: inc.radiance,
        pdf: inc.pdf,
        delta: inc.delta,
    };
    Some((conn, shadow))
}
