//! Rays, surface hits, the hits intersectors report, local frames and explicit floating-point error handling for ray spawning.

use glam::{Vec2, Vec3};

/// A ray `origin + t·dir`, `t ∈ (0, t_max)`. `dir` need not be unit length, but every ray the
/// integrators trace has a unit direction so that `t` is a distance.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_max: f32,
}

impl Ray {
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3, t_max: f32) -> Self {
        Ray { origin, dir, t_max }
    }
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Everything an integrator needs to know about a ray's closest hit. Filled in by the host
/// for single-ray queries, or by the plugin from a batch's [`crate::mesh::CompactHit`] over
/// the scene view's vertex buffers ([`crate::mesh::MeshView::surface_hit`], the same code).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Hit point, interpolated from the triangle's vertices by barycentrics.
    pub p: Vec3,
    /// Conservative absolute error bound of `p` per axis (pbrt-v4 §6.8 style), used to spawn
    /// rays that never re-hit the surface they leave.
    pub p_error: Vec3,
    /// Unit geometric normal, oriented by the triangle's winding (counter-clockwise = front).
    pub ng: Vec3,
    /// Unit shading normal (interpolated vertex normal), on the same side as `ng`.
    pub ns: Vec3,
    /// Texture coordinates, set TEXCOORD_0 (0 when the mesh has none).
    pub uv: Vec2,
    /// Texture coordinates, set TEXCOORD_1 (0 when the mesh has none).
    pub uv1: Vec2,
    /// Vertex colour COLOR_0, linear RGBA ((1, 1, 1, 1) when the mesh has none).
    pub color: [f32; 4],
    /// Global triangle index in the scene.
    pub prim: u32,
    /// Index into the scene's material table.
    pub material: u32,
    /// Index into the scene's emitter table, or -1 when the triangle does not emit.
    pub emitter: i32,
}

/// Closest hit of a ray with a set of triangles, as the host's intersectors report it (the
/// pure-Rust `flowlight_bvh::Bvh` and Embree alike); the host turns it into a [`SurfaceHit`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    /// Ray parameter, `0 < t < ray.t_max`.
    pub t: f32,
    /// Index of the triangle in the intersector's triangle list (for `flowlight_bvh::Bvh`, the
    /// slice given to `Bvh::build`).
    pub prim: u32,
    /// Barycentric coordinate of the second vertex: `p = (1-b1-b2)·p0 + b1·p1 + b2·p2`.
    pub b1: f32,
    /// Barycentric coordinate of the third vertex.
    pub b2: f32,
}

/// Closest hit of a ray with instanced meshes (`flowlight_bvh::TwoLevelBvh`, Embree's
/// instances).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceHit {
    /// Ray parameter in world (= object) space, `0 < t < ray.t_max`.
    pub t: f32,
    /// Index of the instance.
    pub instance: u32,
    /// Index of the triangle in its mesh.
    pub prim: u32,
    /// Barycentric coordinates of vertices 1 and 2, as in [`TriangleHit`].
    pub b1: f32,
    pub b2: f32,
}

/// Decides whether a candidate hit of triangle `prim` at barycentrics `(b1, b2)` counts
/// (`true`) or the ray passes through it (`false`): alpha testing. It is called for
/// candidates in any order, possibly more than once per triangle, so it must be a pure
/// function of its arguments (and of the ray it was made for).
pub type HitFilter<'a> = &'a dyn Fn(u32, f32, f32) -> bool;

/// [`HitFilter`] for instances: `(instance, prim, b1, b2)`, `prim` the triangle's
/// index in its mesh. The same purity rules apply.
pub type InstanceHitFilter<'a> = &'a dyn Fn(u32, u32, f32, f32) -> bool;

/// Float error growth bound γ_n = nε/(1-nε) with ε = 2^-24 (pbrt-v4 §6.8.1).
#[inline]
pub fn gamma(n: i32) -> f32 {
    let e = f32::EPSILON * 0.5;
    (n as f32 * e) / (1.0 - n as f32 * e)
}

/// Error bound of a point interpolated by barycentrics `b` from `p0, p1, p2`:
/// γ_7·(|b0 p0| + |b1 p1| + |b2 p2|) (pbrt-v4, Triangle::InteractionFromIntersection).
#[inline]
pub fn barycentric_error(b: [f32; 3], p0: Vec3, p1: Vec3, p2: Vec3) -> Vec3 {
    ((b[0] * p0).abs() + (b[1] * p1).abs() + (b[2] * p2).abs()) * gamma(7)
}

/// The next float above `v` (the definition [`away_along`] is tested against).
#[cfg(test)]
fn next_float_up(v: f32) -> f32 {
    if v.is_infinite() && v > 0.0 {
        return v;
    }
    let v = if v == -0.0 { 0.0 } else { v };
    let bits = v.to_bits();
    let bits = if v >= 0.0 { bits + 1 } else { bits - 1 };
    f32::from_bits(bits)
}

/// The next float below `v`.
#[cfg(test)]
fn next_float_down(v: f32) -> f32 {
    if v.is_infinite() && v < 0.0 {
        return v;
    }
    let v = if v == 0.0 { -0.0 } else { v };
    let bits = v.to_bits();
    let bits = if v > 0.0 { bits - 1 } else { bits + 1 };
    f32::from_bits(bits)
}

/// Moves `p` off the surface along the geometric normal by its error bound, on the side `w`
/// points to, then rounds each coordinate away from the surface. The offset scales with the
/// magnitude of the triangle's coordinates, so it works for scenes at 1e-4 and at 1e5 alike,
/// unlike a fixed epsilon. (Wächter & Binder, Ray Tracing Gems ch. 6 motivate the idea;
/// the bound is pbrt-v4's `OffsetRayOrigin`.)
// Always inlined: called out of line, its vector arguments went through memory, and the
// load of `p_error` right after the caller's stores was a quarter of its samples (perf).
#[inline(always)]
pub fn offset_ray_origin(p: Vec3, p_error: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
    let d = ng.abs().dot(p_error);
    // Leave on the side `w` points to; rounding follows the normal's sign even when the bound is
    // zero (an axis-aligned plane through the origin), so the origin always leaves the plane.
    let n = if w.dot(ng) < 0.0 { -ng } else { ng };
    let po = p + n * d;
    Vec3::new(
        away_along(po.x, n.x),
        away_along(po.y, n.y),
        away_along(po.z, n.z),
    )
}

/// `v` moved one float towards the side of `n`'s sign: the next float up for n > 0, down for
/// n < 0, unchanged for n = 0 (or NaN), choosing by a select rather than branches on the
/// signs. Moving away from zero adds one to the bits, towards zero subtracts one; from ±0 it
/// gives the smallest subnormal of `n`'s sign; ±∞ stays (as an infinity towards its own side).
#[inline(always)]
fn away_along(v: f32, n: f32) -> f32 {
    if n == 0.0 || n.is_nan() || v.is_infinite() && (v > 0.0) == (n > 0.0) {
        return v;
    }
    if v == 0.0 {
        return if n > 0.0 {
            f32::from_bits(1)
        } else {
            -f32::from_bits(1)
        };
    }
    let bits = v.to_bits();
    // Same sign: away from zero (bits + 1); opposite: towards zero (bits − 1).
    let away = (bits >> 31) == (n.to_bits() >> 31);
    f32::from_bits(if away { bits + 1 } else { bits - 1 })
}

impl SurfaceHit {
    /// Both texture-coordinate sets, for [`crate::material::Material::resolve`].
    #[inline]
    pub fn uvs(&self) -> [Vec2; 2] {
        [self.uv, self.uv1]
    }

    /// A ray leaving this hit in direction `dir` (unit), safe from self-intersection.
    #[inline]
    pub fn spawn_ray(&self, dir: Vec3) -> Ray {
        Ray::new(
            offset_ray_origin(self.p, self.p_error, self.ng, dir),
            dir,
            f32::INFINITY,
        )
    }

    /// A shadow ray from this hit towards the point `target` that itself lies on a surface
    /// with normal `target_ng` and error `target_error`. Both ends are offset, and the ray
    /// stops just short of the target, so neither surface occludes the connection.
    #[inline]
    pub fn spawn_ray_to(&self, target: Vec3, target_error: Vec3, target_ng: Vec3) -> Ray {
        let o = offset_ray_origin(self.p, self.p_error, self.ng, target - self.p);
        let t = offset_ray_origin(target, target_error, target_ng, o - target);
        let d = t - o;
        let len = d.length();
        Ray::new(o, d / len, len * (1.0 - 1e-4))
    }

    /// [`SurfaceHit::spawn_ray_to`] for a visibility test only: the same two offset ends,
    /// but the direction is their difference, not normalised, and `t_max` is in its units
    /// (1 − 10⁻⁴: the same point short of the target). Ray queries take any direction
    /// length; the square root and division of the normalisation sat on the light
    /// connection's chain of dependent operations.
    #[inline(always)]
    pub fn shadow_ray_to(&self, target: Vec3, target_error: Vec3, target_ng: Vec3) -> Ray {
        let o = offset_ray_origin(self.p, self.p_error, self.ng, target - self.p);
        let t = offset_ray_origin(target, target_error, target_ng, o - target);
        Ray::new(o, t - o, 1.0 - 1e-4)
    }
}

/// An orthonormal frame whose `z` axis is a given unit vector (Duff et al. 2017).
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub x: Vec3,
    pub y: Vec3,
    pub z: Vec3,
}

impl Frame {
    #[inline]
    pub fn from_z(n: Vec3) -> Frame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let x = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let y = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { x, y, z: n }
    }
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.x), v.dot(self.y), v.dot(self.z))
    }
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn away_along_equals_next_float_up_and_down() {
        let values = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            1e-38,
            -1e-38,
            f32::from_bits(1),
            -f32::from_bits(1),
            3.5e7,
            -2.25e-3,
            f32::MAX,
            -f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        for &v in &values {
            for n in [1.0f32, 0.25, -1.0, -1e-20, 0.0, -0.0] {
                let want = if n > 0.0 {
                    next_float_up(v)
                } else if n < 0.0 {
                    next_float_down(v)
                } else {
                    v
                };
                let got = away_along(v, n);
                assert_eq!(got.to_bits(), want.to_bits(), "v {v:e} n {n:e}");
            }
        }
    }

    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
            Vec3::X,
        ] {
            let f = Frame::from_z(n);
            assert!(f.x.dot(f.y).abs() < 1e-5 && f.x.dot(f.z).abs() < 1e-5);
            assert!((f.x.length() - 1.0).abs() < 1e-5 && (f.y.length() - 1.0).abs() < 1e-5);
            let v = Vec3::new(0.1, 0.2, 0.9);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn offset_moves_to_the_requested_side_at_any_scale() {
        for scale in [1e-4f32, 1.0, 1e4, 1e5] {
            let p0 = Vec3::new(1.0, 0.0, 1.0) * scale;
            let p1 = Vec3::new(2.0, 0.0, 1.0) * scale;
            let p2 = Vec3::new(1.0, 0.0, 2.0) * scale;
            let b = [0.3, 0.3, 0.4];
            let p = p0 * b[0] + p1 * b[1] + p2 * b[2];
            let err = barycentric_error(b, p0, p1, p2);
            let up = offset_ray_origin(p, err, Vec3::Y, Vec3::Y);
            let down = offset_ray_origin(p, err, Vec3::Y, -Vec3::Y);
            assert!(up.y > 0.0, "scale {scale}");
            assert!(down.y < 0.0, "scale {scale}");
            // The offset is tiny relative to the scene.
            assert!(up.y < 1e-5 * scale, "scale {scale}: {}", up.y);
        }
    }

    /// A shadow ray for a visibility test leaves from the same offset origin as the
    /// normalised one and stops at the same point short of the target (to float rounding),
    /// at any scale: only the direction's length and `t_max`'s unit differ.
    #[test]
    fn shadow_ray_ends_where_the_normalised_ray_ends() {
        let mut r = crate::rng::Rng::new(41, 0);
        for scale in [1e-3f32, 1.0, 1e3, 1e5] {
            for _ in 0..200 {
                let mut v = || Vec3::new(r.uniform(), r.uniform(), r.uniform()) - 0.5;
                let hit = SurfaceHit {
                    t: 1.0,
                    p: v() * scale,
                    p_error: v().abs() * scale * 1e-6,
                    ng: v().normalize(),
                    ns: Vec3::Z,
                    uv: Vec2::ZERO,
                    uv1: Vec2::ZERO,
                    color: [1.0; 4],
                    prim: 0,
                    material: 0,
                    emitter: -1,
                };
                let (target, target_error, target_ng) =
                    (v() * scale * 4.0, v().abs() * scale * 1e-6, v().normalize());
                let a = hit.spawn_ray_to(target, target_error, target_ng);
                let b = hit.shadow_ray_to(target, target_error, target_ng);
                assert_eq!(a.origin, b.origin);
                let (ea, eb) = (a.at(a.t_max), b.at(b.t_max));
                assert!((ea - eb).length() <= 1e-5 * scale, "{ea} vs {eb}");
                assert!(a.dir.dot(b.dir) > 0.0 && (b.dir.normalize() - a.dir).length() < 1e-5);
            }
        }
    }
}
