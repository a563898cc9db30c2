//! Ray queries on a [`BinaryBvh`]: the robust slab test (pbrt-v4 §6.8.2) and the iterative,
//! nearer-child-first traversal behind the closest-hit, any-hit and filtered queries; see the
//! crate documentation.

use crate::build::{BinaryBvh, Node};
use crate::triangle::{gamma, WatertightRay};
use flowlight_core::geometry::{HitFilter, Ray, TriangleHit};

/// Traversal stack size. The build caps the depth well below this (see [`MAX_SAH_DEPTH`]).
pub(crate) const STACK_SIZE: usize = 128;

impl BinaryBvh {
    /// Closest hit with `t ∈ (0, ray.t_max)`, or `None`.
    pub fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        self.traverse::<false, _>(ray, &mut 0, &|_, _, _| true)
    }

    /// Whether any triangle is hit with `t ∈ (0, ray.t_max)`. Returns at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.traverse::<true, _>(ray, &mut 0, &|_, _, _| true)
            .is_some()
    }

    /// [`BinaryBvh::intersect`] counting only the hits `accept` keeps (alpha testing): a rejected
    /// candidate does not shorten the ray, so traversal finds the closest accepted hit.
    pub fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        self.traverse::<false, _>(ray, &mut 0, &accept)
    }

    /// [`BinaryBvh::occluded`] counting only the hits `accept` keeps.
    pub fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        self.traverse::<true, _>(ray, &mut 0, &accept).is_some()
    }

    /// Iterative traversal with a fixed stack, nearer child first. `ANY_HIT` returns the first
    /// hit found instead of the closest. `tests` counts ray/triangle tests (for tests; the
    /// public queries pass a dead local that the optimiser removes).
    #[inline(always)]
    fn traverse<const ANY_HIT: bool, F: Fn(u32, f32, f32) -> bool>(
        &self,
        ray: &Ray,
        tests: &mut usize,
        accept: &F,
    ) -> Option<TriangleHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let wray = WatertightRay::new(ray)?;
        let slab = SlabRay::new(ray);
        let mut t_max = ray.t_max;
        let mut hit = None;
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        let mut idx = 0usize;
        loop {
            let node = &self.nodes[idx];
            if slab.hits(node, t_max) {
                if node.count > 0 {
                    let first = node.offset as usize;
                    let last = first + node.count as usize;
                    for (tri, &prim) in self.tris[first..last]
                        .iter()
                        .zip(&self.prim_ids[first..last])
                    {
                        *tests += 1;
                        if let Some((t, b1, b2)) = wray.intersect(tri, t_max) {
                            if !accept(prim, b1, b2) {
                                continue;
                            }
                            t_max = t;
                            hit = Some(TriangleHit { t, prim, b1, b2 });
                            if ANY_HIT {
                                return hit;
                            }
                        }
                    }
                } else {
                    // Visit the child on the side the ray comes from first.
                    let (near, far) = if slab.neg[node.axis as usize] {
                        (node.offset as usize, idx + 1)
                    } else {
                        (idx + 1, node.offset as usize)
                    };
                    stack[sp] = far as u32;
                    sp += 1;
                    idx = near;
                    continue;
                }
            }
            if sp == 0 {
                return hit;
            }
            sp -= 1;
            idx = stack[sp] as usize;
        }
    }
}

/// Per-ray constants of the slab test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlabRay {
    org: [f32; 3],
    /// `1/dir`: ±∞ for zero components, following the sign of zero.
    inv: [f32; 3],
    /// Whether `inv` is negative (true for `dir = -0.0`).
    pub(crate) neg: [bool; 3],
}

impl SlabRay {
    #[inline]
    pub(crate) fn new(ray: &Ray) -> SlabRay {
        let inv = [1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z];
        SlabRay {
            org: ray.origin.to_array(),
            inv,
            neg: [inv[0] < 0.0, inv[1] < 0.0, inv[2] < 0.0],
        }
    }

    /// Robust slab test (pbrt-v4 `Bounds3::IntersectP`): the far distance is enlarged by
    /// `1 + 2γ₃`, covering the rounding error of the near and far distances. A slab whose
    /// distance is NaN (origin exactly on the slab's plane, direction component zero) does
    /// not constrain the interval: `f32::min`/`max` ignore NaN operands.
    #[inline(always)]
    pub(crate) fn hits(&self, node: &Node, t_max: f32) -> bool {
        self.entry(node, t_max).is_some()
    }

    /// Entry distance (clamped to 0) of a ray that hits `node`'s box before `t_max`.
    #[inline(always)]
    pub(crate) fn entry(&self, node: &Node, t_max: f32) -> Option<f32> {
        let mut t0 = f32::NEG_INFINITY;
        let mut t1 = f32::INFINITY;
        for a in 0..3 {
            let (lo, hi) = if self.neg[a] {
                (node.max[a], node.min[a])
            } else {
                (node.min[a], node.max[a])
            };
            t0 = t0.max((lo - self.org[a]) * self.inv[a]);
            t1 = t1.min((hi - self.org[a]) * self.inv[a]);
        }
        t1 *= 1.0 + 2.0 * gamma(3);
        (t0 <= t1 && t0 < t_max && t1 > 0.0).then_some(t0.max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{Aabb, MAX_LEAF_SIZE};
    use glam::Vec3;

    #[test]
    fn slab_test_handles_signed_zero_and_planes() {
        let node = Node::interior(
            &Aabb {
                min: glam::Vec3A::ZERO,
                max: glam::Vec3A::ONE,
            },
            0,
        );
        // dir.y = -0.0 with the origin inside the slab must not be culled.
        let r = Ray::new(
            Vec3::new(-1.0, 0.5, 0.5),
            Vec3::new(1.0, -0.0, 0.0),
            f32::INFINITY,
        );
        assert!(SlabRay::new(&r).hits(&node, r.t_max));
        // Origin on the slab plane y = 1 with dir.y = 0: (1-1)·∞ = NaN must be ignored.
        let r = Ray::new(
            Vec3::new(-1.0, 1.0, 0.5),
            Vec3::new(1.0, 0.0, 0.0),
            f32::INFINITY,
        );
        assert!(SlabRay::new(&r).hits(&node, r.t_max));
        let r = Ray::new(
            Vec3::new(-1.0, 1.0, 0.5),
            Vec3::new(1.0, -0.0, 0.0),
            f32::INFINITY,
        );
        assert!(SlabRay::new(&r).hits(&node, r.t_max));
        // Outside the slab with a zero component: miss.
        let r = Ray::new(
            Vec3::new(-1.0, 1.5, 0.5),
            Vec3::new(1.0, 0.0, 0.0),
            f32::INFINITY,
        );
        assert!(!SlabRay::new(&r).hits(&node, r.t_max));
        // Box behind the ray, or beyond t_max.
        let r = Ray::new(
            Vec3::new(2.0, 0.5, 0.5),
            Vec3::new(1.0, 0.0, 0.0),
            f32::INFINITY,
        );
        assert!(!SlabRay::new(&r).hits(&node, r.t_max));
        let r = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::new(1.0, 0.0, 0.0), 0.5);
        assert!(!SlabRay::new(&r).hits(&node, r.t_max));
        // Touching an edge of the box exactly.
        let r = Ray::new(
            Vec3::new(-1.0, -1.0, 0.5),
            Vec3::new(1.0, 1.0, 0.0),
            f32::INFINITY,
        );
        assert!(SlabRay::new(&r).hits(&node, r.t_max));
    }

    #[test]
    fn occluded_exits_at_the_first_hit() {
        // 4096 parallel squares stacked along z, all crossed by the ray.
        let mut tris = Vec::new();
        for k in 0..4096 {
            let z = k as f32 * 0.01;
            let (a, b, c, d) = (
                Vec3::new(-1.0, -1.0, z),
                Vec3::new(1.0, -1.0, z),
                Vec3::new(1.0, 1.0, z),
                Vec3::new(-1.0, 1.0, z),
            );
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
        let bvh = BinaryBvh::build(&tris);
        // From the far end towards the near end: the closest hit is the last layer reached.
        let ray = Ray::new(Vec3::new(0.3, 0.2, 100.0), -Vec3::Z, f32::INFINITY);
        let mut any_tests = 0;
        let any = bvh
            .traverse::<true, _>(&ray, &mut any_tests, &|_, _, _| true)
            .unwrap();
        let mut closest_tests = 0;
        let closest = bvh
            .traverse::<false, _>(&ray, &mut closest_tests, &|_, _, _| true)
            .unwrap();
        assert!(
            any_tests <= MAX_LEAF_SIZE,
            "occluded tested {any_tests} triangles"
        );
        assert!(closest_tests > any_tests);
        assert!((closest.t - (100.0 - 40.95)).abs() < 1e-3, "{closest:?}");
        assert!(any.t >= closest.t);
        assert!(bvh.occluded(&ray));
    }
}
