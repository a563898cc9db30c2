//! Pure-Rust bounding volume hierarchy over triangle soups.
//!
//! * **Build**: binned surface-area-heuristic (SAH) construction in the style of Wald,
//!   "On fast Construction of SAH-based Bounding Volume Hierarchies" (IEEE RT 2007) and
//!   pbrt-v4 §7.3 (`BVHAggregate::buildRecursive`): [`SAH_BINS`] bins over the centroid bounds
//!   on each of the three axes, leaves of at most [`MAX_LEAF_SIZE`] triangles, and an object
//!   median split when the SAH cannot separate the triangles (all centroids equal, non-finite
//!   costs). The upper levels of the tree are built in parallel with `rayon::join`; the result
//!   does not depend on the thread schedule (same input, same tree).
//! * **Layout**: the tree is flattened depth-first into 32-byte nodes (pbrt-v4's
//!   `LinearBVHNode`): the first child of an interior node directly follows it, the node stores
//!   the index of its second child. Triangles are copied in leaf order into one array so that
//!   a leaf's triangles are contiguous in memory.
//! * **Traversal**: iterative with a fixed-size stack, nearer child first according to the
//!   sign of the ray direction on the node's split axis. The ray/box slab test uses the
//!   precomputed reciprocal direction (±∞ for zero components, the sign of `-0.0` respected)
//!   and pbrt-v4's robust `tMax *= 1 + 2γ₃` scaling (§6.8.2, `Bounds3::IntersectP`), so
//!   rounding never culls a box the ray touches.
//! * **Ray/triangle**: the watertight test of Woop, Benthin & Wald, "Watertight Ray/Triangle
//!   Intersection", JCGT 2(1), 2013, with the double-precision recomputation of edge functions
//!   that evaluate to exactly 0, and pbrt-v4's conservative lower bound on `t`
//!   (`IntersectTriangle`, §6.5.3 and §6.8.4) with a tighter, still conservative, shear error
//!   term so that grazing hits are kept (see [`WatertightRay::intersect`]). Rays through an
//!   edge or vertex shared by triangles of a closed mesh hit at least one of them.
//! * **Hit filtering** (alpha MASK / BLEND): [`Bvh::intersect_filtered`] and
//!   [`Bvh::occluded_filtered`] ask a [`HitFilter`] about every candidate before accepting
//!   it, like Embree's filter callbacks; a rejected candidate leaves `t_max` unchanged, so
//!   the closest accepted hit is found. The unfiltered queries compile the filter away.
//!
//! Instancing: [`TwoLevelBvh`] is a hierarchy over instances (affine transforms) of per-mesh
//! [`Bvh`]s; see the `instanced` module.
//!
//! Degenerate triangles (zero area, repeated vertices, collinear vertices, NaN or infinite
//! coordinates) are left out of the tree and never reported as hits.

use flowlight_core::geometry::Ray;
use glam::Vec3;
use rayon::prelude::*;

mod instanced;
pub use instanced::{Instance, InstanceHit, InstanceHitFilter, TwoLevelBvh};

/// Largest number of triangles in a leaf.
pub const MAX_LEAF_SIZE: usize = 4;
/// Number of SAH bins per axis.
pub const SAH_BINS: usize = 16;

/// Traversal stack size. The build caps the depth well below this (see [`MAX_SAH_DEPTH`]).
const STACK_SIZE: usize = 128;
/// Below this depth the SAH chooses splits; deeper nodes use object-median splits, which halve
/// the triangle count, so the depth stays below `MAX_SAH_DEPTH + 32 < STACK_SIZE`.
const MAX_SAH_DEPTH: u32 = 64;
/// Subtrees with fewer triangles than this are built sequentially.
const PARALLEL_BUILD_THRESHOLD: usize = 4096;
/// Nodes with at least this many triangles compute bounds and bins in parallel.
const PARALLEL_SCAN_THRESHOLD: usize = 1 << 16;
const PARALLEL_SCAN_CHUNK: usize = 1 << 14;
/// SAH cost of traversing a node relative to intersecting one triangle. pbrt-v4 uses 1/2; a
/// node visit is mostly a cache miss while a leaf's triangles are contiguous. 2 gave 3×
/// fewer nodes and faster incoherent rays on 1M-triangle soups, but made the Cornell box
/// 30% slower (1.9 vs 2.8 Mrays/s on one thread); 1 is as fast as 1/2 there.
const TRAVERSAL_COST: f32 = 1.0;

/// γ_n = nε/(1-nε), ε = 2⁻²⁴: bound on the relative error of n floating-point operations
/// (Higham; pbrt-v4 §6.8.1).
const fn gamma(n: u32) -> f32 {
    let e = f32::EPSILON * 0.5;
    (n as f32 * e) / (1.0 - n as f32 * e)
}

/// Decides whether a candidate hit of triangle `prim` at barycentrics `(b1, b2)` counts
/// (`true`) or the ray passes through it (`false`): alpha testing. It is called for
/// candidates in any order, possibly more than once per triangle, so it must be a pure
/// function of its arguments (and of the ray it was made for).
pub type HitFilter<'a> = &'a dyn Fn(u32, f32, f32) -> bool;

/// Closest hit of a ray with the triangles of a [`Bvh`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    /// Ray parameter, `0 < t < ray.t_max`.
    pub t: f32,
    /// Index of the triangle in the slice given to [`Bvh::build`].
    pub prim: u32,
    /// Barycentric coordinate of the second vertex: `p = (1-b1-b2)·p0 + b1·p1 + b2·p2`.
    pub b1: f32,
    /// Barycentric coordinate of the third vertex.
    pub b2: f32,
}

/// One flattened node, 32 bytes (pbrt-v4 `LinearBVHNode`).
///
/// Interior (`count == 0`): the first child is the next node, `offset` is the second child.
/// Leaf (`count > 0`): triangles `offset .. offset + count` of the reordered array.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    min: [f32; 3],
    offset: u32,
    max: [f32; 3],
    count: u16,
    axis: u16,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

impl Node {
    fn leaf(b: &Aabb, first: u32, count: usize) -> Node {
        debug_assert!(count > 0 && count <= MAX_LEAF_SIZE);
        Node {
            min: b.min.to_array(),
            offset: first,
            max: b.max.to_array(),
            count: count as u16,
            axis: 0,
        }
    }
    fn interior(b: &Aabb, axis: usize) -> Node {
        Node {
            min: b.min.to_array(),
            offset: 0,
            max: b.max.to_array(),
            count: 0,
            axis: axis as u16,
        }
    }
}

/// A bounding volume hierarchy over a triangle soup, with closest-hit and any-hit queries.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    nodes: Vec<Node>,
    /// Non-degenerate triangles in leaf order.
    tris: Vec<[Vec3; 3]>,
    /// Original index of each entry of `tris`.
    prim_ids: Vec<u32>,
    input_count: usize,
}

impl Bvh {
    /// Builds the hierarchy. `prim` in hits is the index into `triangles`. Degenerate
    /// triangles (see [`is_degenerate`]) are skipped. Panics if there are more than `u32::MAX`
    /// triangles.
    pub fn build(triangles: &[[Vec3; 3]]) -> Bvh {
        assert!(
            triangles.len() <= u32::MAX as usize,
            "too many triangles for a Bvh"
        );
        let mut refs: Vec<PrimRef> = triangles
            .par_iter()
            .enumerate()
            .filter(|(_, t)| !is_degenerate(t))
            .map(|(i, t)| PrimRef::new(t, i as u32))
            .collect();
        let nodes = if refs.is_empty() {
            Vec::new()
        } else {
            build_parallel(&mut refs, 0, 0)
        };
        let tris = refs
            .par_iter()
            .map(|r| triangles[r.index as usize])
            .collect();
        let prim_ids = refs.par_iter().map(|r| r.index).collect();
        Bvh {
            nodes,
            tris,
            prim_ids,
            input_count: triangles.len(),
        }
    }

    /// Closest hit with `t ∈ (0, ray.t_max)`, or `None`.
    pub fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        self.traverse::<false, _>(ray, &mut 0, &|_, _, _| true)
    }

    /// Whether any triangle is hit with `t ∈ (0, ray.t_max)`. Returns at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.traverse::<true, _>(ray, &mut 0, &|_, _, _| true)
            .is_some()
    }

    /// [`Bvh::intersect`] counting only the hits `accept` keeps (alpha testing): a rejected
    /// candidate does not shorten the ray, so traversal finds the closest accepted hit.
    pub fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        self.traverse::<false, _>(ray, &mut 0, &accept)
    }

    /// [`Bvh::occluded`] counting only the hits `accept` keeps.
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

    /// Number of triangles given to [`Bvh::build`], degenerate ones included.
    pub fn triangle_count(&self) -> usize {
        self.input_count
    }

    /// Number of (non-degenerate) triangles stored in the tree.
    pub fn stored_triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Number of flattened nodes (0 when there is nothing to intersect).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bounds `(min, max)` of all non-degenerate triangles; `(+∞, -∞)` when there are none.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        match self.nodes.first() {
            Some(n) => (Vec3::from(n.min), Vec3::from(n.max)),
            None => (Vec3::INFINITY, Vec3::NEG_INFINITY),
        }
    }

    /// Depth of the tree (a single leaf has depth 1, an empty tree 0).
    pub fn depth(&self) -> usize {
        fn rec(nodes: &[Node], i: usize) -> usize {
            let n = &nodes[i];
            if n.count > 0 {
                1
            } else {
                1 + rec(nodes, i + 1).max(rec(nodes, n.offset as usize))
            }
        }
        if self.nodes.is_empty() {
            0
        } else {
            rec(&self.nodes, 0)
        }
    }
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

/// Per-ray constants of the slab test.
#[derive(Clone, Copy, Debug)]
struct SlabRay {
    org: [f32; 3],
    /// `1/dir`: ±∞ for zero components, following the sign of zero.
    inv: [f32; 3],
    /// Whether `inv` is negative (true for `dir = -0.0`).
    neg: [bool; 3],
}

impl SlabRay {
    #[inline]
    fn new(ray: &Ray) -> SlabRay {
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
    fn hits(&self, node: &Node, t_max: f32) -> bool {
        self.entry(node, t_max).is_some()
    }

    /// Entry distance (clamped to 0) of a ray that hits `node`'s box before `t_max`.
    #[inline(always)]
    fn entry(&self, node: &Node, t_max: f32) -> Option<f32> {
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

// ----------------------------------------------------------------------------------------------
// Build
// ----------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug)]
struct Aabb {
    min: Vec3,
    max: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    #[inline]
    fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    #[inline]
    fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Surface area; 0 for an empty box.
    #[inline]
    fn area(&self) -> f32 {
        let d = self.max - self.min;
        if d.x < 0.0 || d.y < 0.0 || d.z < 0.0 {
            0.0
        } else {
            2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
        }
    }
}

/// A triangle during the build: bounds, centroid of the bounds, original index.
#[derive(Clone, Copy, Debug)]
struct PrimRef {
    bounds: Aabb,
    centroid: Vec3,
    index: u32,
}

impl PrimRef {
    fn new(t: &[Vec3; 3], index: u32) -> PrimRef {
        let min = t[0].min(t[1]).min(t[2]);
        let max = t[0].max(t[1]).max(t[2]);
        // Halve first: `min + max` can overflow for coordinates near f32::MAX.
        PrimRef {
            bounds: Aabb { min, max },
            centroid: min * 0.5 + max * 0.5,
            index,
        }
    }
}

/// Node bounds and centroid bounds.
fn scan_seq(refs: &[PrimRef]) -> (Aabb, Aabb) {
    let mut b = Aabb::EMPTY;
    let mut c = Aabb::EMPTY;
    for r in refs {
        b = b.union(r.bounds);
        c.grow(r.centroid);
    }
    (b, c)
}

/// Same as [`scan_seq`]; min/max are exact, so the parallel reduction is deterministic.
fn scan(refs: &[PrimRef]) -> (Aabb, Aabb) {
    if refs.len() < PARALLEL_SCAN_THRESHOLD {
        return scan_seq(refs);
    }
    refs.par_chunks(PARALLEL_SCAN_CHUNK).map(scan_seq).reduce(
        || (Aabb::EMPTY, Aabb::EMPTY),
        |a, b| (a.0.union(b.0), a.1.union(b.1)),
    )
}

#[derive(Clone, Copy, Debug)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

type Bins = [[Bin; SAH_BINS]; 3];
const EMPTY_BINS: Bins = [[Bin {
    bounds: Aabb::EMPTY,
    count: 0,
}; SAH_BINS]; 3];

/// Maps centroids to bins along each axis with non-zero centroid extent.
#[derive(Clone, Copy, Debug)]
struct Binner {
    cmin: Vec3,
    scale: [f32; 3],
    active: [bool; 3],
}

impl Binner {
    fn new(c: &Aabb) -> Binner {
        let ext = c.max - c.min;
        let active = [ext.x > 0.0, ext.y > 0.0, ext.z > 0.0];
        let scale = [0, 1, 2].map(|a| {
            if active[a] {
                SAH_BINS as f32 / ext[a]
            } else {
                0.0
            }
        });
        Binner {
            cmin: c.min,
            scale,
            active,
        }
    }

    /// Bin of a centroid along `axis`. Saturating casts map NaN and negatives to 0, overflow to
    /// the last bin. Binning and partitioning both use this function, so they agree exactly.
    #[inline]
    fn bin(&self, c: Vec3, axis: usize) -> usize {
        (((c[axis] - self.cmin[axis]) * self.scale[axis]) as usize).min(SAH_BINS - 1)
    }

    fn fill(&self, refs: &[PrimRef]) -> Bins {
        let mut bins = EMPTY_BINS;
        for r in refs {
            for (a, axis_bins) in bins.iter_mut().enumerate() {
                if self.active[a] {
                    let b = &mut axis_bins[self.bin(r.centroid, a)];
                    b.bounds = b.bounds.union(r.bounds);
                    b.count += 1;
                }
            }
        }
        bins
    }

    fn fill_parallel(&self, refs: &[PrimRef]) -> Bins {
        if refs.len() < PARALLEL_SCAN_THRESHOLD {
            return self.fill(refs);
        }
        refs.par_chunks(PARALLEL_SCAN_CHUNK)
            .map(|c| self.fill(c))
            .reduce(
                || EMPTY_BINS,
                |mut a, b| {
                    for (aa, ba) in a.iter_mut().zip(&b) {
                        for (x, y) in aa.iter_mut().zip(ba) {
                            x.bounds = x.bounds.union(y.bounds);
                            x.count += y.count;
                        }
                    }
                    a
                },
            )
    }
}

/// Best SAH split: `(cost = Σ area·count, axis, first bin of the right side)`.
fn best_split(bins: &Bins, active: [bool; 3]) -> Option<(f32, usize, usize)> {
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if !active[axis] {
            continue;
        }
        let b = &bins[axis];
        let mut left_area = [0.0f32; SAH_BINS];
        let mut left_count = [0u32; SAH_BINS];
        let mut acc = Aabb::EMPTY;
        let mut n = 0;
        for i in 0..SAH_BINS - 1 {
            acc = acc.union(b[i].bounds);
            n += b[i].count;
            left_area[i] = acc.area();
            left_count[i] = n;
        }
        let mut acc = Aabb::EMPTY;
        let mut n = 0;
        for i in (1..SAH_BINS).rev() {
            acc = acc.union(b[i].bounds);
            n += b[i].count;
            if n == 0 || left_count[i - 1] == 0 {
                continue;
            }
            let cost = left_area[i - 1] * left_count[i - 1] as f32 + acc.area() * n as f32;
            if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, i));
            }
        }
    }
    best
}

enum Decision {
    Leaf,
    /// `refs[..mid]` and `refs[mid..]` are the children; `axis` orders traversal.
    Split {
        mid: usize,
        axis: usize,
    },
}

/// In-place stable-order-independent partition; returns the number of elements satisfying `pred`.
fn partition(refs: &mut [PrimRef], pred: impl Fn(&PrimRef) -> bool) -> usize {
    let mut i = 0;
    for j in 0..refs.len() {
        if pred(&refs[j]) {
            refs.swap(i, j);
            i += 1;
        }
    }
    i
}

/// Object median split along `axis` (ties broken by index, so the result is deterministic).
fn median_split(refs: &mut [PrimRef], axis: usize) -> Decision {
    let mid = refs.len() / 2;
    refs.select_nth_unstable_by(mid, |a, b| {
        a.centroid[axis]
            .total_cmp(&b.centroid[axis])
            .then(a.index.cmp(&b.index))
    });
    Decision::Split { mid, axis }
}

/// Chooses between a leaf and a split, and partitions `refs` for a split.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN extents and costs must take the fallbacks
fn decide(
    refs: &mut [PrimRef],
    bounds: &Aabb,
    cbounds: &Aabb,
    depth: u32,
    parallel: bool,
) -> Decision {
    let n = refs.len();
    if n <= 1 {
        return Decision::Leaf;
    }
    let ext = cbounds.max - cbounds.min;
    let longest = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    if !(ext[longest] > 0.0) {
        // All centroids coincide: the SAH cannot separate them.
        if n <= MAX_LEAF_SIZE {
            return Decision::Leaf;
        }
        return Decision::Split {
            mid: n / 2,
            axis: longest,
        };
    }
    if depth >= MAX_SAH_DEPTH {
        return if n <= MAX_LEAF_SIZE {
            Decision::Leaf
        } else {
            median_split(refs, longest)
        };
    }
    let binner = Binner::new(cbounds);
    let bins = if parallel {
        binner.fill_parallel(refs)
    } else {
        binner.fill(refs)
    };
    let Some((cost, axis, split)) = best_split(&bins, binner.active) else {
        return if n <= MAX_LEAF_SIZE {
            Decision::Leaf
        } else {
            median_split(refs, longest)
        };
    };
    if n <= MAX_LEAF_SIZE {
        let area = bounds.area();
        let split_cost = TRAVERSAL_COST + cost / area;
        // A flat or overflowing box gives a non-finite ratio: keep the small leaf then.
        if !(area > 0.0 && split_cost.is_finite()) || n as f32 <= split_cost {
            return Decision::Leaf;
        }
    }
    let mid = partition(refs, |r| binner.bin(r.centroid, axis) < split);
    debug_assert!(mid > 0 && mid < n);
    Decision::Split { mid, axis }
}

/// Builds the subtree over `refs` (which start at `base` in the final triangle order) as a
/// depth-first node array whose interior offsets are relative to the array's start.
fn build_parallel(refs: &mut [PrimRef], base: u32, depth: u32) -> Vec<Node> {
    if refs.len() < PARALLEL_BUILD_THRESHOLD {
        let mut out = Vec::with_capacity(refs.len());
        build_sequential(refs, base, depth, &mut out);
        return out;
    }
    let (bounds, cbounds) = scan(refs);
    match decide(refs, &bounds, &cbounds, depth, true) {
        Decision::Leaf => vec![Node::leaf(&bounds, base, refs.len())],
        Decision::Split { mid, axis } => {
            let (l, r) = refs.split_at_mut(mid);
            let (left, right) = rayon::join(
                || build_parallel(l, base, depth + 1),
                || build_parallel(r, base + mid as u32, depth + 1),
            );
            let mut out = Vec::with_capacity(1 + left.len() + right.len());
            let mut node = Node::interior(&bounds, axis);
            node.offset = (1 + left.len()) as u32;
            out.push(node);
            for (children, shift) in [(&left, 1u32), (&right, node.offset)] {
                out.extend(children.iter().map(|&c| {
                    let mut c = c;
                    if c.count == 0 {
                        c.offset += shift;
                    }
                    c
                }));
            }
            out
        }
    }
}

fn build_sequential(refs: &mut [PrimRef], base: u32, depth: u32, out: &mut Vec<Node>) {
    let (bounds, cbounds) = scan_seq(refs);
    match decide(refs, &bounds, &cbounds, depth, false) {
        Decision::Leaf => out.push(Node::leaf(&bounds, base, refs.len())),
        Decision::Split { mid, axis } => {
            let idx = out.len();
            out.push(Node::interior(&bounds, axis));
            let (l, r) = refs.split_at_mut(mid);
            build_sequential(l, base, depth + 1, out);
            out[idx].offset = out.len() as u32;
            build_sequential(r, base + mid as u32, depth + 1, out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::rng::Rng;

    fn random_soup(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
        let mut rng = Rng::new(seed, 0);
        let mut v = || Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
        (0..n)
            .map(|_| {
                let c = v() * 10.0;
                [c + v() - 0.5, c + v() - 0.5, c + v() - 0.5]
            })
            .collect()
    }

    /// Checks structure: children inside parents, leaves inside their bounds, each stored
    /// triangle in exactly one leaf, depth within the stack.
    fn check_structure(bvh: &Bvh) {
        let mut seen = vec![0u32; bvh.tris.len()];
        let mut stack = vec![(0usize, 1usize)];
        while let Some((i, depth)) = stack.pop() {
            assert!(depth <= STACK_SIZE);
            let n = &bvh.nodes[i];
            let (lo, hi) = (Vec3::from(n.min), Vec3::from(n.max));
            if n.count > 0 {
                assert!(n.count as usize <= MAX_LEAF_SIZE);
                let range = n.offset as usize..n.offset as usize + n.count as usize;
                for (s, tri) in seen[range.clone()].iter_mut().zip(&bvh.tris[range]) {
                    *s += 1;
                    for p in tri {
                        assert!(p.cmpge(lo).all() && p.cmple(hi).all());
                    }
                }
            } else {
                for c in [i + 1, n.offset as usize] {
                    assert!(c > i && c < bvh.nodes.len());
                    let cn = &bvh.nodes[c];
                    assert!(
                        Vec3::from(cn.min).cmpge(lo).all() && Vec3::from(cn.max).cmple(hi).all()
                    );
                    stack.push((c, depth + 1));
                }
            }
        }
        assert!(
            seen.iter().all(|&s| s == 1),
            "every triangle in exactly one leaf"
        );
        // Depth-first: every node is reachable, so the count matches.
        let leaves = bvh.nodes.iter().filter(|n| n.count > 0).count();
        assert_eq!(bvh.nodes.len(), 2 * leaves - 1);
    }

    #[test]
    fn structure_is_valid() {
        for n in [1, 2, 5, 100, 3000, 20_000] {
            let tris = random_soup(n, n as u64);
            let bvh = Bvh::build(&tris);
            assert_eq!(bvh.triangle_count(), n);
            assert_eq!(bvh.stored_triangle_count(), n);
            check_structure(&bvh);
            let mut ids = bvh.prim_ids.clone();
            ids.sort();
            assert!(ids.iter().enumerate().all(|(i, &p)| i as u32 == p));
            for (t, &p) in bvh.tris.iter().zip(&bvh.prim_ids) {
                assert_eq!(*t, tris[p as usize]);
            }
        }
    }

    #[test]
    fn sah_tree_is_reasonable() {
        let tris = random_soup(20_000, 3);
        let bvh = Bvh::build(&tris);
        // Balanced-ish: far from a degenerate list.
        assert!(bvh.depth() < 40, "depth {}", bvh.depth());
        assert!(
            bvh.node_count() < 2 * tris.len(),
            "{} nodes",
            bvh.node_count()
        );
    }

    #[test]
    fn coincident_centroids_fall_back_to_median() {
        // 1000 copies of the same triangle: SAH cannot split, the median split must.
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let tris = vec![t; 1000];
        let bvh = Bvh::build(&tris);
        check_structure(&bvh);
        assert!(bvh.depth() <= 12, "depth {}", bvh.depth());
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, f32::INFINITY))
            .unwrap();
        assert!((hit.t - 1.0).abs() < 1e-6);
    }

    #[test]
    fn pathological_distribution_keeps_depth_bounded() {
        // Centroids at 2^-k: each SAH split peels off little; the depth cap must hold.
        let tris: Vec<[Vec3; 3]> = (0..3000)
            .map(|k| {
                let x = 0.5f32.powi(k % 140) * 1e6;
                let o = Vec3::new(x, (k / 140) as f32, 0.0);
                [
                    o,
                    o + Vec3::new(x * 1e-3, 0.0, 0.0),
                    o + Vec3::new(0.0, 0.5, 0.5),
                ]
            })
            .collect();
        let bvh = Bvh::build(&tris);
        check_structure(&bvh);
        assert!(bvh.depth() < STACK_SIZE);
    }

    #[test]
    fn build_is_deterministic_across_thread_counts() {
        let tris = random_soup(60_000, 9);
        let a = Bvh::build(&tris);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = one.install(|| Bvh::build(&tris));
        let four = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let c = four.install(|| Bvh::build(&tris));
        assert!(a == b && b == c);
        check_structure(&a);
    }

    #[test]
    fn slab_test_handles_signed_zero_and_planes() {
        let node = Node::interior(
            &Aabb {
                min: Vec3::ZERO,
                max: Vec3::ONE,
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
        let bvh = Bvh::build(&tris);
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

    #[test]
    fn degenerate_triangles_are_not_stored() {
        let nan = f32::NAN;
        let tris = [
            [Vec3::ZERO, Vec3::ZERO, Vec3::X],               // repeated vertex
            [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],            // collinear
            [Vec3::ZERO, Vec3::X, Vec3::new(nan, 0.0, 0.0)], // NaN
            [Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::INFINITY, 0.0)], // Inf
            [Vec3::ZERO, Vec3::X, Vec3::Y],                  // fine
        ];
        let bvh = Bvh::build(&tris);
        assert_eq!(bvh.triangle_count(), 5);
        assert_eq!(bvh.stored_triangle_count(), 1);
        assert_eq!(bvh.prim_ids, vec![4]);
        let (lo, hi) = bvh.bounds();
        assert_eq!((lo, hi), (Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)));
        let nan_only = Bvh::build(&tris[2..3]);
        assert_eq!(nan_only.node_count(), 0);
        assert!(nan_only
            .intersect(&Ray::new(Vec3::Z, -Vec3::Z, f32::INFINITY))
            .is_none());
    }
}
