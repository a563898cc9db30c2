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
//!
//! The light end xₙ sets the measure of the last step (J(x_{n−1} → xₙ) above is replaced by):
//!
//! ```text
//! area light           |n_n·ω| / |xₙ − x_{n−1}|²   xₙ a free point on the emitter (area measure)
//! point / spot light   1 / |xₙ − x_{n−1}|²          xₙ fixed: a Dirac in position
//! environment          1                            xₙ a free direction ω (solid-angle measure)
//! directional light    1                            xₙ fixed: a Dirac in direction
//! ```
//!
//! and L_e is the emitted radiance towards x_{n−1}: L(xₙ, ω), I(ω)/1 with the 1/d² above,
//! L_env(ω), or the directional light's irradiance at normal incidence E (its radiance is
//! E·δ(ω − ω_sun)). A **light vertex at infinity** (environment, directional light) stores the
//! unit direction from the scene towards the light in `ng`/`ns`; its `p` is only a nominal
//! point one unit from x_{n−1} ([`distant_vertex`]), and every direction towards it is that
//! stored direction ([`direction`]). Veach 1997 §8.2 (directions at infinity as an extra
//! solid-angle factor of the path measure), thesis §3.2 (point lights).
//!
//! A path tracer's estimate is again f/p: next-event estimation of the environment divides by
//! the environment's solid-angle density, of a directional light by its selection probability
//! alone (a Dirac); an escaped ray after a Dirac vertex (or the eye) sees L_env(ω) with no
//! density at all, the direction being fixed by the Dirac chain. A Dirac light (point, spot,
//! directional) can only end a path after a smooth vertex: nothing else reaches it.

use flowlight_core::bsdf::{volume, Bsdf, Component};
use flowlight_core::geometry::Frame;
use flowlight_core::light::LightKind;
use flowlight_core::path::{NodeType, Path, PathVertex};
use flowlight_core::Rgb;
use flowlight_sdk::Scene;
use glam::{Vec2, Vec3};
use std::borrow::Cow;

/// Node type as mutations must preserve it (the weak type, thesis §3.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeakNode {
    /// The camera vertex x₀.
    Eye,
    /// The last vertex: on a light (an emitter, a punctual light or the environment).
    Light,
    /// Diffuse or glossy: a free vertex that can be connected to.
    Smooth,
    /// A mirror-like (Dirac) reflection.
    DiracReflection,
    /// A Dirac transmission (refraction through glass).
    DiracTransmission,
}

impl WeakNode {
    /// The weak type of a stored vertex.
    pub fn of(v: &PathVertex) -> WeakNode {
        match v.node {
            NodeType::Eye => WeakNode::Eye,
            NodeType::Light => WeakNode::Light,
            NodeType::SpecularReflection => WeakNode::DiracReflection,
            NodeType::SpecularTransmission => WeakNode::DiracTransmission,
            _ => WeakNode::Smooth,
        }
    }

    /// True for the two Dirac types.
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
/// Borrowed from the scene's table where the material's BSDF is constant (no copy).
pub fn vertex_bsdf<'a>(scene: &Scene<'a>, v: &PathVertex) -> Option<Cow<'a, Bsdf>> {
    if let Some(b) = scene.constant_bsdf(v.material, v.color) {
        return Some(Cow::Borrowed(b));
    }
    let m = scene.materials.get(v.material as usize)?;
    let mut r = m.resolve(v.uvs(), v.color, scene.textures);
    scene.orient_layers(&mut r.material.layers, v.prim, v.p, v.ns);
    Some(Cow::Owned(Bsdf::from_material(&r.material, r.base)))
}

/// Directions at an interior vertex: local frame, wo (to the previous vertex), wi (to the next).
pub fn local_directions(
    v: &PathVertex,
    prev: Vec3,
    next: Vec3,
) -> Option<(Frame, Vec3, Vec3, Vec3, Vec3)> {
    local_directions_towards(v, prev, (next - v.p).try_normalize()?)
}

/// [`local_directions`] with the world direction `wi_w` to the next vertex given (a vertex at
/// infinity has no position to take it from).
pub fn local_directions_towards(
    v: &PathVertex,
    prev: Vec3,
    wi_w: Vec3,
) -> Option<(Frame, Vec3, Vec3, Vec3, Vec3)> {
    let wo_w = (prev - v.p).try_normalize()?;
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

/// Unified light index of a light vertex, if it names one of the scene's lights.
pub fn light_index(scene: &Scene, v: &PathVertex) -> Option<usize> {
    usize::try_from(v.emitter)
        .ok()
        .filter(|&i| v.node == NodeType::Light && i < scene.lights.count())
}

/// Whether `v` is a light vertex at infinity (an environment direction or a directional
/// light): its `ng` holds the unit direction towards the light (module docs).
pub fn is_distant(scene: &Scene, v: &PathVertex) -> bool {
    light_index(scene, v).is_some_and(|i| scene.lights.kind(i).is_distant())
}

/// Unit direction from vertex `a` towards vertex `b`: the stored direction when `b` is at
/// infinity, else from the positions. `None` for coincident points.
pub fn direction(scene: &Scene, a: &PathVertex, b: &PathVertex) -> Option<Vec3> {
    if is_distant(scene, b) {
        b.ng.try_normalize()
    } else {
        (b.p - a.p).try_normalize()
    }
}

/// Whether `a` and `b` are the same point of path space: the same position, or, at infinity,
/// the same light and direction (the nominal positions of distant vertices differ whenever
/// the vertex before them moved).
pub fn same_vertex(scene: &Scene, a: &PathVertex, b: &PathVertex) -> bool {
    match (is_distant(scene, a), is_distant(scene, b)) {
        (true, true) => a.emitter == b.emitter && a.ng == b.ng,
        (false, false) => a.p == b.p,
        _ => false,
    }
}

/// The light vertex at infinity of light `light` in unit direction `dir` seen from `from`: the
/// direction in its normal slots, a nominal position one unit along it. The seed samplers
/// (`flowlight-pathtrace`) store distant light vertices the same way.
pub fn distant_vertex(from: Vec3, dir: Vec3, light: usize) -> PathVertex {
    PathVertex {
        p: from + dir,
        p_error: Vec3::ZERO,
        ng: dir,
        ns: dir,
        uv: Vec2::ZERO,
        uv1: Vec2::ZERO,
        color: [1.0; 4],
        prim: u32::MAX,
        material: u32::MAX,
        emitter: light as i32,
        node: NodeType::Light,
        component: 0,
    }
}

/// The target function f(x) of a complete path (module docs). Zero for a path that does not
/// end on an emitter, breaks a Dirac constraint or leaks through a shading normal.
pub fn measurement(scene: &Scene, path: &Path) -> Rgb {
    let v = path.vertices();
    if v.len() < 2 {
        return Rgb::ZERO;
    }
    let n = v.len() - 1;
    let light = &v[n];
    let Some(li) = light_index(scene, light) else {
        return Rgb::ZERO;
    };
    let kind = scene.lights.kind(li);
    // Nothing but a smooth vertex reaches a Dirac light (no sampled direction hits it).
    if kind.is_delta() && WeakNode::of(&v[n - 1]) != WeakNode::Smooth {
        return Rgb::ZERO;
    }
    let Some(to_light) = direction(scene, &v[n - 1], light) else {
        return Rgb::ZERO;
    };
    // The light end: emitted radiance towards x_{n-1} and the measure factor of the last step
    // (module docs' table).
    let (mut f, light_factor) = match kind {
        LightKind::Area => (
            scene.lights.emitted(li, light.p, -to_light),
            area_jacobian(v[n - 1].p, light.p, light.ng),
        ),
        LightKind::Positional => {
            let Some(l) = scene.lights.punctual_at(li) else {
                return Rgb::ZERO;
            };
            (
                l.intensity_towards(-to_light),
                1.0 / (v[n - 1].p - light.p).length_squared(),
            )
        }
        LightKind::Directional => {
            let Some(l) = scene.lights.punctual_at(li) else {
                return Rgb::ZERO;
            };
            // A Dirac in direction: the vertex must hold the light's own direction.
            if to_light.dot(-l.direction) < 1.0 - DIRAC_TOLERANCE {
                return Rgb::ZERO;
            }
            (l.intensity, 1.0)
        }
        LightKind::Environment => (scene.lights.environment_radiance(to_light), 1.0),
    };
    for k in 1..n {
        let x = &v[k];
        let Some(bsdf) = vertex_bsdf(scene, x) else {
            return Rgb::ZERO;
        };
        let Some(wi_w) = direction(scene, x, &v[k + 1]) else {
            return Rgb::ZERO;
        };
        let Some((_, wo_w, wi_w, wo, wi)) = local_directions_towards(x, v[k - 1].p, wi_w) else {
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
        // A segment to infinity leaves the scene, so it runs inside no closed volume (the path
        // tracers' escaped and shadow rays apply none either).
        let to_infinity = k + 1 == n && is_distant(scene, light);
        if let Some(m) = scene
            .materials
            .get(x.material as usize)
            .filter(|_| !to_infinity)
        {
            f *= volume::segment_transmittance(m, x.ng, wi_w, (v[k + 1].p - x.p).length());
        }
        if f.is_black() {
            return f;
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testscene::*;
    use std::f32::consts::PI;

    fn close(a: Rgb, b: f32) -> bool {
        (a.g - b).abs() <= 1e-5 * b.abs().max(1e-6)
    }

    #[test]
    fn a_directional_light_gives_e_times_the_brdf_and_cosine_with_no_distance_factor() {
        let scene = scene();
        let x1 = floor(Vec3::new(0.2, 0.0, -0.5));
        let cos = sun_travel().y.abs();
        let f = measurement(&scene, &path(&[eye(), x1, sun(x1.p)], 8));
        assert!(close(f, SUN * ALBEDO / PI * cos), "{f:?}");
        // The nominal position of the vertex at infinity does not matter ...
        let mut far = sun(x1.p);
        far.p = Vec3::new(40.0, -7.0, 3.0);
        assert_eq!(measurement(&scene, &path(&[eye(), x1, far], 8)), f);
        // ... its direction does: a Dirac in direction, nothing but the sun's own counts.
        let off = distant_vertex(x1.p, Vec3::Y, SUN_INDEX);
        assert!(measurement(&scene, &path(&[eye(), x1, off], 8)).is_black());
        // The eye cannot see it, nor a mirror reflect it into the eye (a Dirac after a Dirac).
        assert!(measurement(&scene, &path(&[eye(), sun(eye().p)], 8)).is_black());
        let m = mirror(Vec3::new(0.0, 0.0, -1.0), Vec3::Y);
        assert!(measurement(&scene, &path(&[eye(), m, sun(m.p)], 8)).is_black());
    }

    #[test]
    fn the_environment_is_a_direction_in_solid_angle() {
        let scene = scene();
        let x1 = floor(Vec3::new(0.2, 0.0, -0.5));
        for dir in [
            Vec3::Y,
            Vec3::new(0.5, 1.0, -0.2),
            Vec3::new(-2.0, 0.3, 1.0),
        ] {
            let w = dir.normalize();
            let f = measurement(&scene, &path(&[eye(), x1, sky(x1.p, w)], 8));
            assert!(close(f, SKY * ALBEDO / PI * w.y), "{dir}: {f:?}");
        }
        // Below the floor: nothing (the direction leaves through the surface).
        let below = sky(x1.p, Vec3::new(0.0, -1.0, 0.3));
        assert!(measurement(&scene, &path(&[eye(), x1, below], 8)).is_black());
        // The eye sees the sky itself: f = L_env, in the film measure alone.
        let up = sky(eye().p, Vec3::new(0.1, 0.4, -1.0));
        assert!(close(measurement(&scene, &path(&[eye(), up], 8)), SKY));
        // A mirror reflects it with its Fresnel coefficient (a metal of base colour 1: 1);
        // a sky vertex off the mirror direction is not on the path.
        let m = mirror(Vec3::new(0.0, 0.0, -1.0), Vec3::Y);
        let into = (m.p - eye().p).normalize();
        let reflected = Vec3::new(into.x, -into.y, into.z);
        let f = measurement(&scene, &path(&[eye(), m, sky(m.p, reflected)], 8));
        assert!(close(f, SKY), "{f:?}");
        let f = measurement(&scene, &path(&[eye(), m, sky(m.p, Vec3::Y)], 8));
        assert!(f.is_black());
    }

    #[test]
    fn an_area_light_keeps_its_area_jacobian() {
        let scene = scene();
        let x1 = floor(Vec3::new(0.2, 0.0, -0.5));
        let l = lamp(Vec3::new(0.1, 2.0, -0.2));
        let d = l.p - x1.p;
        let w = d.normalize();
        let want = LAMP * ALBEDO / PI * w.y * w.y / d.length_squared();
        let f = measurement(&scene, &path(&[eye(), x1, l], 8));
        assert!(close(f, want), "{f:?} vs {want}");
    }

    #[test]
    fn distant_vertices_compare_by_direction() {
        let scene = scene();
        let a = sky(Vec3::ZERO, Vec3::Y);
        let mut b = a;
        b.p = Vec3::splat(5.0);
        assert!(is_distant(&scene, &a) && same_vertex(&scene, &a, &b));
        assert!(!same_vertex(&scene, &a, &sky(Vec3::ZERO, Vec3::X)));
        assert!(!same_vertex(
            &scene,
            &a,
            &distant_vertex(Vec3::ZERO, Vec3::Y, SUN_INDEX)
        ));
        let x = floor(Vec3::ZERO);
        assert!(!is_distant(&scene, &x) && !is_distant(&scene, &lamp(Vec3::Y)));
        assert_eq!(direction(&scene, &x, &b), Some(Vec3::Y));
    }
}
