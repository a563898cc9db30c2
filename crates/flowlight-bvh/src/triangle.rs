//! The watertight ray/triangle test (Woop, Benthin & Wald, JCGT 2013) with pbrt-v4's
//! conservative `t` bound (§6.5.3, §6.8.4); see the crate documentation.

#[cfg(doc)]
use crate::Bvh;
use flowlight_core::geometry::{Ray, TriangleHit};
use glam::Vec3;

/// γ_n = nε/(1-nε), ε = 2⁻²⁴: bound on the relative error of n floating-point operations
/// (Higham; pbrt-v4 §6.8.1).
pub(crate) const fn gamma(n: u32) -> f32 {
    let e = f32::EPSILON * 0.5;
    (n as f32 * e) / (1.0 - n as f32 * e)
}

/// Whether a triangle can never be hit: a non-finite coordinate, or a cross product of two edges
/// that is exactly zero (repeated or collinear vertices), the test pbrt-v4's
/// `IntersectTriangle` starts with. Such triangles are not stored in a [`Bvh`].
pub fn is_degenerate(tri: &[Vec3; 3]) -> bool {
    if !(tri[0].is_finite() && tri[1].is_finite() && tri[2].is_finite()) {
        return true;
    }
    (tri[2] - tri[0]).cross(tri[1] - tri[0]).length_squared() == 0.0
}

/// The watertight ray/triangle test used by [`Bvh`] (Woop, Benthin & Wald 2013, with pbrt-v4's
/// conservative `t` bound), on a single triangle: a hit with `t ∈ (0, ray.t_max)`, reported
/// with the given `prim`. Degenerate triangles never hit. Looping over all triangles and
/// shrinking `t_max` gives exactly the hits a [`Bvh`] reports (up to ties in `t`).
pub fn intersect_triangle(ray: &Ray, tri: &[Vec3; 3], prim: u32) -> Option<TriangleHit> {
    if is_degenerate(tri) {
        return None;
    }
    let (t, b1, b2) = WatertightRay::new(ray)?.intersect(tri, ray.t_max)?;
    Some(TriangleHit { t, prim, b1, b2 })
}

/// Per-ray constants of the watertight test (Woop, Benthin & Wald 2013): the translation to the
/// ray origin, the axis permutation making the largest direction component `z`, and the shear
/// aligning the direction with +z. Precompute once per ray to test many triangles.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    org: Vec3,
    kz: u8,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl WatertightRay {
    /// `None` for rays that can hit nothing: non-finite origin or direction, zero direction,
    /// `t_max` not positive (or NaN).
    #[inline]
    pub fn new(ray: &Ray) -> Option<WatertightRay> {
        let d = ray.dir;
        if !(ray.origin.is_finite() && d.is_finite() && d != Vec3::ZERO && ray.t_max > 0.0) {
            return None;
        }
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let kx = if kz == 2 { 0 } else { kz + 1 };
        let ky = if kx == 2 { 0 } else { kx + 1 };
        let dz = d[kz];
        let (sx, sy, sz) = (-d[kx] / dz, -d[ky] / dz, 1.0 / dz);
        Some(WatertightRay {
            org: ray.origin,
            kz: kz as u8,
            sx,
            sy,
            sz,
        })
    }

    /// The dominant axis `kz` of the direction and the shear `(s_x, s_y, s_z)`.
    #[inline]
    pub(crate) fn shear(&self) -> (usize, f32, f32, f32) {
        (self.kz as usize, self.sx, self.sy, self.sz)
    }

    /// Returns `(t, b1, b2)` for a hit with `t ∈ (0, t_max)`.
    ///
    /// The degeneracy test of [`is_degenerate`] is *not* repeated here: filter degenerate
    /// triangles first (as [`Bvh`] and [`intersect_triangle`] do). For them the result is
    /// unspecified (it never panics).
    #[inline]
    // `!(a < b)` on purpose: NaN must fail the range tests.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn intersect(&self, tri: &[Vec3; 3], t_max: f32) -> Option<(f32, f32, f32)> {
        // Translate to the ray origin, permute, shear. Each vertex is transformed on its own,
        // so a vertex shared by two triangles gets bit-identical coordinates in both.
        // Permute with a branch on kz (the same for every triangle of a ray, so it predicts
        // well) instead of indexing arrays by kx/ky/kz, which forces the vertices to memory.
        let permute = |v: Vec3| -> Vec3 {
            match self.kz {
                0 => Vec3::new(v.y, v.z, v.x),
                1 => Vec3::new(v.z, v.x, v.y),
                _ => v,
            }
        };
        let p0 = permute(tri[0] - self.org);
        let p1 = permute(tri[1] - self.org);
        let p2 = permute(tri[2] - self.org);
        let (p0z, p1z, p2z) = (p0.z, p1.z, p2.z);
        let (q0x, q0y, q1x, q1y, q2x, q2y) = (p0.x, p0.y, p1.x, p1.y, p2.x, p2.y);
        let p0x = q0x + self.sx * p0z;
        let p0y = q0y + self.sy * p0z;
        let p1x = q1x + self.sx * p1z;
        let p1y = q1y + self.sy * p1z;
        let p2x = q2x + self.sx * p2z;
        let p2y = q2y + self.sy * p2z;

        // Edge functions. Plain products (no FMA), so the function of an edge shared by two
        // triangles is exactly negated when the edge is traversed the other way round.
        let mut e0 = p1x * p2y - p1y * p2x;
        let mut e1 = p2x * p0y - p2y * p0x;
        let mut e2 = p0x * p1y - p0y * p1x;
        if e0 == 0.0 || e1 == 0.0 || e2 == 0.0 {
            // Exactly on an edge in single precision: products of floats are exact in double
            // precision, so recompute there (Woop et al. 2013, §3.3).
            let (x0, y0, x1, y1, x2, y2) = (
                p0x as f64, p0y as f64, p1x as f64, p1y as f64, p2x as f64, p2y as f64,
            );
            e0 = (x1 * y2 - y1 * x2) as f32;
            e1 = (x2 * y0 - y2 * x0) as f32;
            e2 = (x0 * y1 - y0 * x1) as f32;
        }
        if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
            return None;
        }
        let det = e0 + e1 + e2;
        if det == 0.0 || !det.is_finite() {
            return None;
        }

        // Scaled hit distance, compared against the range without dividing.
        let t_scaled = e0 * (p0z * self.sz) + e1 * (p1z * self.sz) + e2 * (p2z * self.sz);
        if det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det) {
            return None;
        }
        if det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det) {
            return None;
        }
        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;
        if !(t < t_max) {
            return None;
        }

        // Make sure t is conservatively greater than zero (pbrt-v4 `IntersectTriangle`,
        // §6.8.4). pbrt bounds the error of the sheared x, y by γ₅(|x| + |z|), using
        // |s_x|, |s_y| ≤ 1; for grazing rays (s_x ≈ 0) that exceeds the tiny sheared
        // coordinates by orders of magnitude and rejects valid hits. The error of
        // `x + s_x·z` is bounded by γ₅(|x| + |s_x·z|) just as well, which stays tight.
        let max_z = p0z.abs().max(p1z.abs()).max(p2z.abs());
        let max_zt = max_z * self.sz.abs();
        let delta_z = gamma(3) * max_zt;
        let max_xt = p0x.abs().max(p1x.abs()).max(p2x.abs());
        let max_yt = p0y.abs().max(p1y.abs()).max(p2y.abs());
        let max_qx = q0x.abs().max(q1x.abs()).max(q2x.abs());
        let max_qy = q0y.abs().max(q1y.abs()).max(q2y.abs());
        let delta_x = gamma(5) * (max_qx + self.sx.abs() * max_z);
        let delta_y = gamma(5) * (max_qy + self.sy.abs() * max_z);
        let delta_e = 2.0 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t =
            3.0 * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv_det.abs();
        if !(t > delta_t) {
            return None;
        }
        Some((t, e1 * inv_det, e2 * inv_det))
    }
}
