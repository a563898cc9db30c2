//! The target function of the chains and the weak path type.
//!
//! A path x₀ (eye) … xₙ (light) is measured in the product of the film measure for the eye
//! ray and the area measure for every vertex that is a free coordinate (Veach 1997, §8.2).
//! A vertex following a Dirac (specular) vertex is not free: it is where the specular
//! direction lands. So, with J(a→b) = |n_b·ω| / |b − a|² the area Jacobian,
//!
//! ```text
//! f(x) = L_e(xₙ → xₙ₋₁) · Π_{k smooth} f_s(x_k) |cos θ_k| J(x_k → x_{k+1}) · Π_{k Dirac} w_c F_k
//! ```
//!
//! where F_k is the Dirac lobe's coefficient (Fresnel reflectance, or transmittance with the
//! radiance scaling) and w_c its mixture weight. A path tracer's estimate of the same path is
//! f(x)/p(x) with p in the same measure, so BSDF-sampled steps contribute f_s|cos|/p_ω exactly
//! as in path tracing (the Jacobian cancels).

use flowlight_core::bsdf::{volume, Bsdf, Component};
use flowlight_core::geometry::Frame;
use flowlight_core::light::LightKind;
use flowlight_core::path::{NodeType, Path, PathVertex};
use flowlight_core::Rgb;
use flowlight_sdk::Scene;
use glam::{Vec2, Vec3};

/// Node type as mutations must preserve it (the weak type, thesis §3.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeakNode {
    Eye,
    Light,
    /// Diffuse or glossy: a free vertex that can be connected to.
    Smooth,
    DiracReflection,
    DiracTransmission,
}

impl WeakNode {
    pub fn of(v: &PathVertex) -> WeakNode {
        match v.node {
            NodeType::Eye => WeakNode::Eye,
            NodeType::Light => WeakNode::Light,
            NodeType::SpecularReflection => WeakNode::DiracReflection,
            NodeType::SpecularTransmission => WeakNode::DiracTransmission,
            _ => WeakNode::Smooth,
        }
    }

    pub fn is_dirac(self) -> bool {
        matches!(
            self,
            WeakNode::DiracReflection | WeakNode::DiracTransmission
        )
    }

    /// Whether a hard reconnection may end at (or start from) a vertex of this type.
    pub fn connectable(self) -> bool {
        matches!(self, WeakNode::Smooth | WeakNode::Light)
    }
}

/// The Dirac direction of `component` for outgoing `wo` (local frame) and its coefficient
/// (f·|cos θ_i| of the lobe), for reflection or transmission. `None` when the lobe is not a
/// Dirac lobe of that kind (or total internal reflection forbids the transmission).
pub fn dirac_scatter(component: &Component, wo: Vec3, transmission: bool) -> Option<(Vec3, Rgb)> {
    // The dielectric chooses reflection when uc < R/(R+T): ask for the branch we need.
    let uc = if transmission { 1.0 - 1e-7 } else { 0.0 };
    let s = component.sample_with(wo, uc, Vec2::splat(0.5))?;
    (s.delta && s.node.is_transmission() == transmission).then(|| (s.wi, s.f * s.wi.z.abs()))
}

/// The first component of `bsdf` that has a Dirac lobe of the given kind.
pub fn dirac_component(
    bsdf: &Bsdf,
    wo: Vec3,
    transmission: bool,
) -> Option<(usize, Component, f32)> {
    bsdf.components()
        .enumerate()
        .filter(|(_, (c, _))| c.is_delta())
        .find(|(_, (c, _))| dirac_scatter(c, wo, transmission).is_some())
        .map(|(i, (c, w))| (i, c, w))
}

/// The BSDF at a stored vertex, with the material's textures and vertex colour applied at
/// the vertex's texture coordinates (the same BSDF [`Scene::bsdf`] gives at the hit).
pub fn vertex_bsdf(scene: &Scene, v: &PathVertex) -> Option<Bsdf> {
    let m = scene.materials.get(v.material as usize)?;
    let r = m.resolve(v.uvs(), v.color, scene.textures);
    Some(Bsdf::from_material(&r.material, r.base))
}

/// Directions at an interior vertex: local frame, wo (to the previous vertex), wi (to the next).
pub fn local_directions(
    v: &PathVertex,
    prev: Vec3,
    next: Vec3,
) -> Option<(Frame, Vec3, Vec3, Vec3, Vec3)> {
    let wo_w = (prev - v.p).try_normalize()?;
    let wi_w = (next - v.p).try_normalize()?;
    let frame = Frame::from_z(v.ns);
    Some((
        frame,
        wo_w,
        wi_w,
        frame.to_local(wo_w),
        frame.to_local(wi_w),
    ))
}

/// Same side of the geometric and the shading normal (no light leaks through shading normals).
#[inline]
pub fn side_consistent(ng: Vec3, w_world: Vec3, w_local: Vec3) -> bool {
    ng.dot(w_world) * w_local.z > 0.0
}

/// Area Jacobian |n_b·ω| / |b − a|² of landing at `b` (normal `nb`) from `a`.
#[inline]
pub fn area_jacobian(a: Vec3, b: Vec3, nb: Vec3) -> f32 {
    let d = b - a;
    let d2 = d.length_squared();
    // NaN fails the comparison too.
    if d2.is_nan() || d2 <= 0.0 {
        return 0.0;
    }
    nb.dot(d).abs() / (d2 * d2.sqrt())
}

/// How far a stored direction may stray from the Dirac direction recomputed from positions.
const DIRAC_TOLERANCE: f32 = 1e-3;

/// The target function f(x) of a complete path (module docs). Zero for a path that does not
/// end on an emitter, breaks a Dirac constraint or leaks through a shading normal.
pub fn measurement(scene: &Scene, path: &Path) -> Rgb {
    let v = path.vertices();
    if v.len() < 2 {
        return Rgb::ZERO;
    }
    let n = v.len() - 1;
    let light = &v[n];
    let Some(to_prev) = (v[n - 1].p - light.p).try_normalize() else {
        return Rgb::ZERO;
    };
    // The light end: emitted radiance towards x_{n-1} and the measure factor of the last step
    // (the area Jacobian for an area light; 1/d² for a point or spot light, whose position is
    // a Dirac and no free coordinate). Distant lights are not part of this path space.
    let Some(li) = usize::try_from(light.emitter)
        .ok()
        .filter(|&i| i < scene.lights.count())
    else {
        return Rgb::ZERO;
    };
    let (mut f, light_factor) = match scene.lights.kind(li) {
        LightKind::Area => (
            scene.lights.emitted(li, light.p, to_prev),
            area_jacobian(v[n - 1].p, light.p, light.ng),
        ),
        LightKind::Positional => {
            let Some(l) = scene.lights.punctual_at(li) else {
                return Rgb::ZERO;
            };
            (
                l.intensity_towards(to_prev),
                1.0 / (v[n - 1].p - light.p).length_squared(),
            )
        }
        LightKind::Directional | LightKind::Environment => return Rgb::ZERO,
    };
    for k in 1..n {
        let x = &v[k];
        let Some(bsdf) = vertex_bsdf(scene, x) else {
            return Rgb::ZERO;
        };
        let Some((_, wo_w, wi_w, wo, wi)) = local_directions(x, v[k - 1].p, v[k + 1].p) else {
            return Rgb::ZERO;
        };
        if !side_consistent(x.ng, wo_w, wo) || !side_consistent(x.ng, wi_w, wi) {
            return Rgb::ZERO;
        }
        match WeakNode::of(x) {
            WeakNode::Smooth => {
                let jacobian = if k + 1 == n {
                    light_factor
                } else {
                    area_jacobian(x.p, v[k + 1].p, v[k + 1].ng)
                };
                f *= bsdf.eval(wo, wi) * (wi.z.abs() * jacobian);
            }
            kind @ (WeakNode::DiracReflection | WeakNode::DiracTransmission) => {
                let c = x.component as usize;
                let Some((component, weight)) = bsdf.components().nth(c) else {
                    return Rgb::ZERO;
                };
                let Some((dir, coefficient)) =
                    dirac_scatter(&component, wo, kind == WeakNode::DiracTransmission)
                else {
                    return Rgb::ZERO;
                };
                if dir.dot(wi) < 1.0 - DIRAC_TOLERANCE {
                    return Rgb::ZERO;
                }
                f *= coefficient * weight;
            }
            WeakNode::Eye | WeakNode::Light => return Rgb::ZERO,
        }
        // Beer–Lambert absorption when the segment to the next vertex runs inside a volume.
        if let Some(m) = scene.materials.get(x.material as usize) {
            f *= volume::segment_transmittance(m, x.ng, wi_w, (v[k + 1].p - x.p).length());
        }
        if f.is_black() {
            return f;
        }
    }
    f
}
