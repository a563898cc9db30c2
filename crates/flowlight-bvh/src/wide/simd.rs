//! The SIMD tests of the traversal: eight boxes at once, four triangles at once.
//!
//! # Box test
//!
//! The slabs of all eight children: `t_near = max_a (near_a − o_a)·(1/d_a)`,
//! `t_far = (1 + 2γ₃)·min_a (far_a − o_a)·(1/d_a)`, where `near_a` is the min plane for
//! `d_a ≥ +0` and the max plane otherwise; a child is entered when `t_near ≤ t_far`,
//! `t_near < t_max` and `t_far > 0`. This is exactly the binary BVH's robust slab test
//! (pbrt-v4 §6.8.2): the slab distance is the first operand of `max`/`min` and the (never
//! NaN) accumulator the second, and these return the second operand when the first is NaN
//! (SSE2 `_mm_max_ps`, AVX `_mm256_max_ps`, NEON's compare-and-select, the scalar
//! `f32::max`), so a NaN slab distance (origin on the plane, `d_a = ±0`) leaves the interval
//! unconstrained, as in the binary test. On x86-64 CPUs with AVX2 (detected once, when the
//! tree is built) the eight boxes are one AVX pass and the whole traversal is compiled with
//! AVX2 enabled (`Bvh::traverse_avx2`, not FMA); elsewhere — x86-64 without AVX2, aarch64,
//! other targets — two 4-lane passes through glam's `Vec4` (SSE2, NEON or scalar) give the
//! same bits.
//!
//! # Triangle test
//!
//! The watertight test of [`crate::WatertightRay`] (Woop, Benthin &
//! Wald, JCGT 2013, with pbrt-v4's conservative `t` bound), evaluated on four lanes with the
//! same IEEE operations in the same order, no FMA (the AVX2 build enables no FMA either, and
//! Rust never contracts a multiply and an add), so each lane gives bit-for-bit the scalar
//! result. Packs where a lane's edge function is exactly 0 (ray through an edge or vertex)
//! take the scalar test, whose double-precision recomputation keeps the test watertight.

use super::{TriPack, WideNode, LANES, WIDTH};
use crate::triangle::{gamma, WatertightRay};
use flowlight_core::geometry::Ray;
use glam::Vec4;

/// Per-ray constants of the 8-wide slab test.
pub(super) struct BoxRay {
    org: [Vec4; 3],
    inv: [Vec4; 3],
    /// 1 where the direction component is negative (the near plane is the max plane).
    neg: [usize; 3],
}

impl BoxRay {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> BoxRay {
        let inv = [1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z];
        BoxRay {
            org: ray.origin.to_array().map(Vec4::splat),
            inv: inv.map(Vec4::splat),
            neg: inv.map(|i| usize::from(i < 0.0)),
        }
    }

    /// Bit `k` set when child `k` is entered before `t_max`; the entry distances (those of
    /// children not entered are unspecified). `AVX2` must only be set in code compiled with
    /// AVX2 enabled (see [`Bvh::traverse_avx2`](super::Bvh::traverse_avx2)).
    #[inline(always)]
    pub(super) fn test<const AVX2: bool>(
        &self,
        node: &WideNode,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: only reached from `traverse_avx2`, which requires AVX2.
            return unsafe { self.test_avx2(node, t_max) };
        }
        let (m0, t0) = self.test4(node, 0, t_max);
        let (m1, t1) = self.test4(node, 4, t_max);
        let (t0, t1) = (t0.to_array(), t1.to_array());
        (
            m0 | m1 << 4,
            [t0[0], t0[1], t0[2], t0[3], t1[0], t1[1], t1[2], t1[3]],
        )
    }

    /// The test on children `first .. first + 4` (SSE, or glam's NEON / scalar `Vec4`).
    #[inline(always)]
    pub(super) fn test4(&self, node: &WideNode, first: usize, t_max: f32) -> (u32, Vec4) {
        let b = |plane: usize| Vec4::from_slice(&node.bounds[plane][first..first + 4]);
        // `& 1` lets the compiler drop the bounds checks.
        let [x, y, z] = self.neg.map(|n| n & 1);
        let n0 = (b(x) - self.org[0]) * self.inv[0];
        let n1 = (b(2 + y) - self.org[1]) * self.inv[1];
        let n2 = (b(4 + z) - self.org[2]) * self.inv[2];
        let f0 = (b(1 - x) - self.org[0]) * self.inv[0];
        let f1 = (b(3 - y) - self.org[1]) * self.inv[1];
        let f2 = (b(5 - z) - self.org[2]) * self.inv[2];
        // The slab distance first: a NaN one yields the (never NaN) accumulator.
        let t0 = n0.max(n1.max(n2.max(Vec4::NEG_INFINITY)));
        let t1 = f0.min(f1.min(f2.min(Vec4::INFINITY))) * Vec4::splat(1.0 + 2.0 * gamma(3));
        let m = t0.cmple(t1) & t0.cmplt(Vec4::splat(t_max)) & t1.cmpgt(Vec4::ZERO);
        (m.bitmask(), t0)
    }

    /// The same operations as [`BoxRay::test4`] on all eight children at once.
    /// `_mm256_max_ps(a, b)` / `_mm256_min_ps(a, b)` return `b` when either is NaN, as the
    /// SSE instructions under glam's `max` / `min` do, so the results are identical.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn test_avx2(&self, node: &WideNode, t_max: f32) -> (u32, [f32; WIDTH]) {
        use std::arch::x86_64::*;
        let b = &node.bounds;
        let [x, y, z] = self.neg.map(|n| n & 1);
        let org = [
            _mm256_set1_ps(self.org[0].x),
            _mm256_set1_ps(self.org[1].x),
            _mm256_set1_ps(self.org[2].x),
        ];
        let inv = [
            _mm256_set1_ps(self.inv[0].x),
            _mm256_set1_ps(self.inv[1].x),
            _mm256_set1_ps(self.inv[2].x),
        ];
        // SAFETY (the loads): each row of `bounds` is eight f32s.
        let (n0, n1, n2, f0, f1, f2) = unsafe {
            (
                _mm256_loadu_ps(b[x].as_ptr()),
                _mm256_loadu_ps(b[2 + y].as_ptr()),
                _mm256_loadu_ps(b[4 + z].as_ptr()),
                _mm256_loadu_ps(b[1 - x].as_ptr()),
                _mm256_loadu_ps(b[3 - y].as_ptr()),
                _mm256_loadu_ps(b[5 - z].as_ptr()),
            )
        };
        let n0 = _mm256_mul_ps(_mm256_sub_ps(n0, org[0]), inv[0]);
        let n1 = _mm256_mul_ps(_mm256_sub_ps(n1, org[1]), inv[1]);
        let n2 = _mm256_mul_ps(_mm256_sub_ps(n2, org[2]), inv[2]);
        let f0 = _mm256_mul_ps(_mm256_sub_ps(f0, org[0]), inv[0]);
        let f1 = _mm256_mul_ps(_mm256_sub_ps(f1, org[1]), inv[1]);
        let f2 = _mm256_mul_ps(_mm256_sub_ps(f2, org[2]), inv[2]);
        let t0 = _mm256_max_ps(
            n0,
            _mm256_max_ps(n1, _mm256_max_ps(n2, _mm256_set1_ps(f32::NEG_INFINITY))),
        );
        let t1 = _mm256_mul_ps(
            _mm256_min_ps(
                f0,
                _mm256_min_ps(f1, _mm256_min_ps(f2, _mm256_set1_ps(f32::INFINITY))),
            ),
            _mm256_set1_ps(1.0 + 2.0 * gamma(3)),
        );
        let m = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1),
                _mm256_cmp_ps::<_CMP_LT_OQ>(t0, _mm256_set1_ps(t_max)),
            ),
            _mm256_cmp_ps::<_CMP_GT_OQ>(t1, _mm256_setzero_ps()),
        );
        let mut t = [0.0; WIDTH];
        // SAFETY: `t` holds eight f32s.
        unsafe { _mm256_storeu_ps(t.as_mut_ptr(), t0) };
        (_mm256_movemask_ps(m) as u32, t)
    }
}

/// Per-ray constants of the 4-lane watertight test: the origin and the shear in the
/// permuted axis order of [`WatertightRay`].
pub(super) struct PackRay {
    k: [usize; 3],
    org: [Vec4; 3],
    sx: Vec4,
    sy: Vec4,
    sz: Vec4,
}

/// Lane results of a pack test.
pub(super) struct Lanes {
    pub(super) mask: u32,
    pub(super) t: [f32; LANES],
    pub(super) b1: [f32; LANES],
    pub(super) b2: [f32; LANES],
}

impl Lanes {
    /// The hit a pack reports: any accepted lane for any hit, else the nearest accepted lane
    /// (ties: the lowest lane, as a sequential loop with a shrinking `t_max` would).
    #[inline(always)]
    /// `prims` is read only when `FILTER` is set.
    pub(super) fn pick<const ANY_HIT: bool, const FILTER: bool, F: Fn(u32, f32, f32) -> bool>(
        &self,
        prims: &[u32; LANES],
        accept: &F,
    ) -> Option<usize> {
        let mut mask = self.mask;
        if ANY_HIT {
            while mask != 0 {
                let k = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if !FILTER || accept(prims[k], self.b1[k], self.b2[k]) {
                    return Some(k);
                }
            }
            return None;
        }
        while mask != 0 {
            let mut best = mask.trailing_zeros() as usize;
            let mut rest = mask & (mask - 1);
            while rest != 0 {
                let k = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                if self.t[k] < self.t[best] {
                    best = k;
                }
            }
            if !FILTER || accept(prims[best], self.b1[best], self.b2[best]) {
                return Some(best);
            }
            mask &= !(1 << best);
        }
        None
    }
}

/// The scalar watertight test on each valid lane (same `t_max` for all lanes).
#[cold]
pub(super) fn scalar_pack_test(
    wray: &WatertightRay,
    pack: &TriPack,
    valid: u32,
    t_max: f32,
) -> Lanes {
    let mut l = Lanes {
        mask: 0,
        t: [0.0; LANES],
        b1: [0.0; LANES],
        b2: [0.0; LANES],
    };
    for k in 0..LANES {
        if valid & (1 << k) != 0 {
            if let Some((t, b1, b2)) = wray.intersect(&pack.triangle(k), t_max) {
                l.mask |= 1 << k;
                (l.t[k], l.b1[k], l.b2[k]) = (t, b1, b2);
            }
        }
    }
    l
}

impl PackRay {
    #[inline(always)]
    pub(super) fn new(ray: &Ray, w: &WatertightRay) -> PackRay {
        let (kz, sx, sy, sz) = w.shear();
        let kx = if kz == 2 { 0 } else { kz + 1 };
        let ky = if kx == 2 { 0 } else { kx + 1 };
        let o = ray.origin;
        PackRay {
            k: [kx, ky, kz],
            org: [o[kx], o[ky], o[kz]].map(Vec4::splat),
            sx: Vec4::splat(sx),
            sy: Vec4::splat(sy),
            sz: Vec4::splat(sz),
        }
    }

    /// The watertight test on the `valid` lanes of `pack`, lane for lane the operations of
    /// [`WatertightRay::intersect`]; `None` when a valid lane has an edge function that is
    /// exactly 0 (the scalar test must resolve it in double precision).
    #[inline(always)]
    pub(super) fn test(&self, pack: &TriPack, valid: u32, t_max: f32) -> Option<Lanes> {
        let [kx, ky, kz] = self.k;
        let zero = Vec4::ZERO;
        let v = &pack.v;
        let (q0x, q0y, p0z) = (
            v[0][kx] - self.org[0],
            v[0][ky] - self.org[1],
            v[0][kz] - self.org[2],
        );
        let (q1x, q1y, p1z) = (
            v[1][kx] - self.org[0],
            v[1][ky] - self.org[1],
            v[1][kz] - self.org[2],
        );
        let (q2x, q2y, p2z) = (
            v[2][kx] - self.org[0],
            v[2][ky] - self.org[1],
            v[2][kz] - self.org[2],
        );
        let p0x = q0x + self.sx * p0z;
        let p0y = q0y + self.sy * p0z;
        let p1x = q1x + self.sx * p1z;
        let p1y = q1y + self.sy * p1z;
        let p2x = q2x + self.sx * p2z;
        let p2y = q2y + self.sy * p2z;
        let e0 = p1x * p2y - p1y * p2x;
        let e1 = p2x * p0y - p2y * p0x;
        let e2 = p0x * p1y - p0y * p1x;
        if (e0.cmpeq(zero) | e1.cmpeq(zero) | e2.cmpeq(zero)).bitmask() & valid != 0 {
            return None;
        }
        let neg = e0.cmplt(zero) | e1.cmplt(zero) | e2.cmplt(zero);
        let pos = e0.cmpgt(zero) | e1.cmpgt(zero) | e2.cmpgt(zero);
        let det = e0 + e1 + e2;
        let t_scaled = e0 * (p0z * self.sz) + e1 * (p1z * self.sz) + e2 * (p2z * self.sz);
        let tmd = Vec4::splat(t_max) * det;
        let det_neg = det.cmplt(zero);
        let det_pos = det.cmpgt(zero);
        let bad_neg = det_neg & (t_scaled.cmpge(zero) | t_scaled.cmplt(tmd));
        let bad_pos = det_pos & (t_scaled.cmple(zero) | t_scaled.cmpgt(tmd));
        // det ≠ 0 and finite; the sign and range tests.
        let ok = !(neg & pos)
            & (det_neg | det_pos)
            & det.abs().cmplt(Vec4::INFINITY)
            & !(bad_neg | bad_pos);
        let mut mask = ok.bitmask() & valid;
        if mask == 0 {
            return Some(Lanes {
                mask,
                t: [0.0; LANES],
                b1: [0.0; LANES],
                b2: [0.0; LANES],
            });
        }
        let inv_det = Vec4::ONE / det;
        let t = t_scaled * inv_det;
        // The conservative bound on t (see `WatertightRay::intersect`).
        let max_z = p0z.abs().max(p1z.abs()).max(p2z.abs());
        let max_zt = max_z * self.sz.abs();
        let delta_z = Vec4::splat(gamma(3)) * max_zt;
        let max_xt = p0x.abs().max(p1x.abs()).max(p2x.abs());
        let max_yt = p0y.abs().max(p1y.abs()).max(p2y.abs());
        let max_qx = q0x.abs().max(q1x.abs()).max(q2x.abs());
        let max_qy = q0y.abs().max(q1y.abs()).max(q2y.abs());
        let g5 = Vec4::splat(gamma(5));
        let delta_x = g5 * (max_qx + self.sx.abs() * max_z);
        let delta_y = g5 * (max_qy + self.sy.abs() * max_z);
        let delta_e = Vec4::splat(2.0)
            * (Vec4::splat(gamma(2)) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t = Vec4::splat(3.0)
            * (Vec4::splat(gamma(3)) * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
            * inv_det.abs();
        mask &= (t.cmplt(Vec4::splat(t_max)) & t.cmpgt(delta_t)).bitmask();
        Some(Lanes {
            mask,
            t: t.to_array(),
            b1: (e1 * inv_det).to_array(),
            b2: (e2 * inv_det).to_array(),
        })
    }
}
