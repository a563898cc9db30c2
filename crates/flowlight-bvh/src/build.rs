//! Binned SAH build (Wald 2007; pbrt-v4 §7.3) and the depth-first flattened node layout
//! (pbrt-v4 `LinearBVHNode`); see the crate documentation for the method.
//!
//! Shared by [`BinaryBvh`], the widening of [`crate::Bvh`] and the top level of
//! [`crate::TwoLevelBvh`]. Boxes are `Vec3A` (SIMD unions); a [`PrimRef`] is a box and an
//! index (32 bytes, the index in the `w` lane), its centroid recomputed when needed; a bin
//! index is one clamped float-to-i32 conversion per axis ([`Binner::bins_of`]); the binning
//! adds runs of references that share their bins at once ([`Binner::fill`]); the partition
//! of a split gathers
//! both children's bounds and centroid bounds, so the widening needs no second pass over
//! them; [`decide`] can weigh the SAH by leaf packs instead of triangles ([`best_split`]).

use crate::triangle::is_degenerate;
use glam::{BVec3A, BVec4A, Mat3A, Vec3, Vec3A, Vec4};
use rayon::prelude::*;

/// Largest number of triangles in a leaf.
pub const MAX_LEAF_SIZE: usize = 4;
/// Number of SAH bins per axis.
pub const SAH_BINS: usize = 16;
/// Below this depth the SAH chooses splits; deeper nodes use object-median splits, which halve
/// the triangle count, so the depth stays below `MAX_SAH_DEPTH + 32 < STACK_SIZE`.
const MAX_SAH_DEPTH: u32 = 64;
/// Subtrees with fewer triangles than this are built sequentially.
pub(crate) const PARALLEL_BUILD_THRESHOLD: usize = 4096;
/// Nodes with at least this many triangles compute bounds and bins in parallel.
pub(crate) const PARALLEL_SCAN_THRESHOLD: usize = 1 << 16;
const PARALLEL_SCAN_CHUNK: usize = 1 << 14;
/// Nodes with at least this many triangles are partitioned in parallel
/// ([`partition_parallel`]). Below it the blocks' pass and the swaps cost about what they
/// save on two threads, and another parallel region is another wait for the pool's
/// threads to wake.
const PARALLEL_PARTITION_THRESHOLD: usize = 1 << 17;
/// SAH cost of traversing a node relative to intersecting one triangle. pbrt-v4 uses 1/2; a
/// node visit is mostly a cache miss while a leaf's triangles are contiguous. 2 gave 3×
/// fewer nodes and faster incoherent rays on 1M-triangle soups, but made the Cornell box
/// 30% slower (1.9 vs 2.8 Mrays/s on one thread); 1 is as fast as 1/2 there.
const TRAVERSAL_COST: f32 = 1.0;

/// One flattened node, 32 bytes (pbrt-v4 `LinearBVHNode`).
///
/// Interior (`count == 0`): the first child is the next node, `offset` is the second child.
/// Leaf (`count > 0`): triangles `offset .. offset + count` of the reordered array.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Node {
    pub(crate) min: [f32; 3],
    pub(crate) offset: u32,
    pub(crate) max: [f32; 3],
    pub(crate) count: u16,
    pub(crate) axis: u16,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

impl Node {
    pub(crate) fn leaf(b: &Aabb, first: u32, count: usize) -> Node {
        debug_assert!(count > 0 && count <= MAX_LEAF_SIZE);
        Node {
            min: b.min.to_array(),
            offset: first,
            max: b.max.to_array(),
            count: count as u16,
            axis: 0,
        }
    }
    pub(crate) fn interior(b: &Aabb, axis: usize) -> Node {
        Node {
            min: b.min.to_array(),
            offset: 0,
            max: b.max.to_array(),
            count: 0,
            axis: axis as u16,
        }
    }
}

/// The binary BVH over a triangle soup, with closest-hit and any-hit queries: the reference
/// the wide [`crate::Bvh`] is tested and benchmarked against (its build is also the top level
/// of [`crate::TwoLevelBvh`]).
#[derive(Clone, Debug, PartialEq)]
pub struct BinaryBvh {
    pub(crate) nodes: Vec<Node>,
    /// Non-degenerate triangles in leaf order.
    pub(crate) tris: Vec<[Vec3; 3]>,
    /// Original index of each entry of `tris`.
    pub(crate) prim_ids: Vec<u32>,
    input_count: usize,
}

impl BinaryBvh {
    /// Builds the hierarchy. `prim` in hits is the index into `triangles`. Degenerate
    /// triangles (see [`is_degenerate`]) are skipped. Panics if there are more than `u32::MAX`
    /// triangles.
    pub fn build(triangles: &[[Vec3; 3]]) -> BinaryBvh {
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
            .map(|r| triangles[r.index() as usize])
            .collect();
        let prim_ids = refs.par_iter().map(|r| r.index()).collect();
        BinaryBvh {
            nodes,
            tris,
            prim_ids,
            input_count: triangles.len(),
        }
    }

    /// Number of triangles given to [`BinaryBvh::build`], degenerate ones included.
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

/// A box; `Vec3A` (16 bytes, SIMD) so that unions are two vector instructions.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Aabb {
    pub(crate) min: Vec3A,
    pub(crate) max: Vec3A,
}

impl Aabb {
    pub(crate) const EMPTY: Aabb = Aabb {
        min: Vec3A::INFINITY,
        max: Vec3A::NEG_INFINITY,
    };

    #[inline]
    pub(crate) fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    #[inline]
    pub(crate) fn grow(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Surface area; 0 for an empty box.
    #[inline]
    pub(crate) fn area(&self) -> f32 {
        let d = self.max - self.min;
        if d.x < 0.0 || d.y < 0.0 || d.z < 0.0 {
            0.0
        } else {
            2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
        }
    }
}

/// A triangle during the build: bounds and original index in 32 bytes (Embree's `PrimRef`
/// layout): the index's bits ride in the `w` lane of the lower corner, the upper corner's
/// `w` is unused. The binning and the partitions stream over these, so at 48 bytes (a
/// `Vec3A` box and a `u32`, padded) a third of their memory traffic and of every swap was
/// padding. The centroid is recomputed from the bounds where needed, which is cheaper than
/// moving it around. [`PrimRef::bounds`] clears `w`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}

const _: () = assert!(std::mem::size_of::<PrimRef>() == 32);

impl PrimRef {
    /// A placeholder for a degenerate triangle in [`crate::Bvh`]'s first pass, removed before
    /// the build: the only reference whose `hi.w` is not 0.
    pub(crate) const DEGENERATE: PrimRef = PrimRef {
        lo: Vec4::ZERO,
        hi: Vec4::new(0.0, 0.0, 0.0, 1.0),
    };

    /// Whether this is [`PrimRef::DEGENERATE`].
    #[inline(always)]
    pub(crate) fn is_degenerate_marker(&self) -> bool {
        self.hi.w != 0.0
    }

    pub(crate) fn new(t: &[Vec3; 3], index: u32) -> PrimRef {
        let [a, b, c] = t.map(Vec3A::from);
        PrimRef::from_bounds(
            Aabb {
                min: a.min(b).min(c),
                max: a.max(b).max(c),
            },
            index,
        )
    }

    /// The reference of triangle (or instance) `index` with box `b`. Floats are moved as bits,
    /// so the index survives copies whatever its bit pattern.
    #[inline(always)]
    pub(crate) fn from_bounds(b: Aabb, index: u32) -> PrimRef {
        PrimRef {
            lo: b.min.extend(f32::from_bits(index)),
            hi: b.max.extend(0.0),
        }
    }

    /// The box, its `w` lanes cleared: the index's bits are a denormal float for every index
    /// below 2²³, and arithmetic on a lane holding one (the centroid's halving, an area's
    /// difference) takes the CPU's slow denormal path. With the index left in place the 1M
    /// build ran 5× slower. The select is a bitwise AND.
    #[inline(always)]
    pub(crate) fn bounds(&self) -> Aabb {
        let xyz = BVec4A::new(true, true, true, false);
        Aabb {
            min: Vec3A::from_vec4(Vec4::select(xyz, self.lo, Vec4::ZERO)),
            max: Vec3A::from_vec4(self.hi),
        }
    }

    /// Index of the triangle in the build's input (of the instance in the two-level build).
    #[inline(always)]
    pub(crate) fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }

    /// Centroid of the bounds. Halve first: `min + max` can overflow for coordinates near
    /// f32::MAX.
    #[inline(always)]
    pub(crate) fn centroid(&self) -> Vec3A {
        let b = self.bounds();
        b.min * 0.5 + b.max * 0.5
    }

    /// Coordinate `axis` (0–2) of the centroid, by the same operations as [`Self::centroid`].
    #[inline(always)]
    fn centroid_on(&self, axis: usize) -> f32 {
        self.lo[axis] * 0.5 + self.hi[axis] * 0.5
    }
}

/// Node bounds and centroid bounds.
pub(crate) fn scan_seq(refs: &[PrimRef]) -> (Aabb, Aabb) {
    let mut b = Aabb::EMPTY;
    let mut c = Aabb::EMPTY;
    for r in refs {
        b = b.union(r.bounds());
        c.grow(r.centroid());
    }
    (b, c)
}

/// Same as [`scan_seq`]; min/max are exact, so the parallel reduction is deterministic.
pub(crate) fn scan(refs: &[PrimRef]) -> (Aabb, Aabb) {
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

/// Empty bins, written in place. A `const` of the bins was copied with `memmove`, which at
/// 2,304 bytes takes its `rep movsb` path; the fill's first loads of those bins then waited
/// for the copy's stores (a string copy's stores are not forwarded to loads), a fixed cost
/// on every node, and most nodes are small.
#[inline(always)]
fn empty_bins() -> Bins {
    let empty = Bin {
        bounds: Aabb::EMPTY,
        count: 0,
    };
    [[empty; SAH_BINS]; 3]
}

/// The bins of one reference on the three axes, as integers in one register, so that two
/// references' bins compare with one instruction.
#[derive(Clone, Copy)]
struct BinKey(
    #[cfg(target_arch = "x86_64")] std::arch::x86_64::__m128i,
    #[cfg(not(target_arch = "x86_64"))] [u32; 3],
);

impl BinKey {
    /// The key of clamped bin coordinates ([`Binner::clamped`]: each lane in
    /// [0, SAH_BINS − 1], not NaN).
    #[inline(always)]
    fn of(f: Vec3A) -> BinKey {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: SSE2 is part of the x86_64 baseline.
            BinKey(unsafe { std::arch::x86_64::_mm_cvttps_epi32(f.into()) })
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            BinKey(f.to_array().map(|x| x as u32))
        }
    }

    /// Whether both keys name the same bins on all three axes (the fourth lane, whatever
    /// it holds, is ignored).
    #[inline(always)]
    fn same(self, o: BinKey) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            // SAFETY: SSE2 is part of the x86_64 baseline.
            unsafe { _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(self.0, o.0))) & 7 == 7 }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self.0 == o.0
        }
    }

    /// The bin on each axis.
    #[inline(always)]
    fn indices(self) -> [usize; 3] {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: an `__m128i` is 16 plain bytes, as is `[i32; 4]`.
            let v: [i32; 4] = unsafe { std::mem::transmute(self.0) };
            [v[0] as usize, v[1] as usize, v[2] as usize]
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self.0.map(|x| x as usize)
        }
    }
}

/// Maps centroids to bins along each axis with non-zero centroid extent.
#[derive(Clone, Copy, Debug)]
struct Binner {
    cmin: Vec3A,
    scale: Vec3A,
    active: [bool; 3],
}

impl Binner {
    fn new(c: &Aabb) -> Binner {
        let ext = c.max - c.min;
        let active = [ext.x > 0.0, ext.y > 0.0, ext.z > 0.0];
        let scale = Vec3A::from([0, 1, 2].map(|a| {
            if active[a] {
                SAH_BINS as f32 / ext[a]
            } else {
                0.0
            }
        }));
        Binner {
            cmin: c.min,
            scale,
            active,
        }
    }

    /// Bins of a centroid on the three axes: `⌊(c_a − cmin_a)·scale_a⌋` clamped to the bins,
    /// NaN and negatives to bin 0 (the SSE `max` returns its second operand, 0, for a NaN
    /// first one), overflow to the last bin — what the saturating cast
    /// `(f as usize).min(SAH_BINS − 1)` gives, without its cost (a float to 64-bit integer
    /// conversion with range checks was 15% of a build). Binning and partitioning both use this
    /// definition (the fill through [`BinKey`], the partition through [`Binner::left_of`]), so
    /// they agree exactly; the tests check both against this function, the reference the
    /// build itself does not call.
    #[cfg(test)]
    fn bins_of(&self, c: Vec3A) -> [usize; 3] {
        BinKey::of(self.clamped(c)).indices()
    }

    /// `(c − cmin)·scale` clamped to [0, SAH_BINS − 1], NaN to 0: the bins before truncation.
    #[inline(always)]
    fn clamped(&self, c: Vec3A) -> Vec3A {
        ((c - self.cmin) * self.scale)
            .max(Vec3A::ZERO)
            .min(Vec3A::splat((SAH_BINS - 1) as f32))
    }

    /// Whether a reference falls left of the split before bin `split` (1 to `SAH_BINS − 1`)
    /// on `axis`: `bins_of(centroid)[axis] < split`, from that axis alone. The same IEEE
    /// operations on that lane give the same bin as the binning's; `⌊clamp(f)⌋ < split` is
    /// `clamp(f) < split` (an integer bound), which is `!(f ≥ split)` (NaN clamps to bin 0,
    /// the left).
    #[inline(always)]
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN must go left
    fn left_of(&self, axis: usize, split: usize) -> impl Fn(&PrimRef) -> bool {
        let (cmin, scale, limit) = (self.cmin[axis], self.scale[axis], split as f32);
        move |r| !((r.centroid_on(axis) - cmin) * scale >= limit)
    }

    /// Bins `refs`: each bin's box and count on each axis (an axis without extent puts
    /// everything in its bin 0, which [`best_split`] ignores). The same bins as
    /// [`Binner::bins_of`] gives.
    ///
    /// References in mesh order come in runs that fall in the same bins on all three axes
    /// (neighbouring triangles; the partitions keep runs together). A run's box and count
    /// grow in registers and go to the bins when the run ends. Adding each reference to its
    /// bins instead made every update load what the previous one had just stored (a
    /// store-forwarding chain per reference and axis). Min and max are exact, so the bins
    /// are the same either way.
    fn fill(&self, refs: &[PrimRef]) -> Bins {
        let mut bins = empty_bins();
        let Some(first) = refs.first() else {
            return bins;
        };
        let flush = |bins: &mut Bins, key: BinKey, b: Aabb, n: u32| {
            for (axis_bins, k) in bins.iter_mut().zip(key.indices()) {
                let bin = &mut axis_bins[k];
                bin.bounds = bin.bounds.union(b);
                bin.count += n;
            }
        };
        let mut run_key = BinKey::of(self.clamped(first.centroid()));
        let mut run_box = Aabb::EMPTY;
        let mut run_len = 0u32;
        for r in refs {
            let key = BinKey::of(self.clamped(r.centroid()));
            if !key.same(run_key) {
                flush(&mut bins, run_key, run_box, run_len);
                run_key = key;
                run_box = Aabb::EMPTY;
                run_len = 0;
            }
            run_box = run_box.union(r.bounds());
            run_len += 1;
        }
        flush(&mut bins, run_key, run_box, run_len);
        bins
    }

    fn fill_parallel(&self, refs: &[PrimRef]) -> Bins {
        if refs.len() < PARALLEL_SCAN_THRESHOLD {
            return self.fill(refs);
        }
        refs.par_chunks(PARALLEL_SCAN_CHUNK)
            .map(|c| self.fill(c))
            .reduce(empty_bins, |mut a, b| {
                for (aa, ba) in a.iter_mut().zip(&b) {
                    for (x, y) in aa.iter_mut().zip(ba) {
                        x.bounds = x.bounds.union(y.bounds);
                        x.count += y.count;
                    }
                }
                a
            })
    }
}

/// Best SAH split: `(cost = Σ area·count, axis, first bin of the right side)`. With
/// `blocks`, `count` is the number of leaf packs, `⌈n / MAX_LEAF_SIZE⌉`, rather than of
/// triangles (the wide tree tests a pack of up to four triangles in one pass, so a pack of
/// one costs what a full one does; Embree's builders use the same block rounding).
///
/// The three axes sweep together: their boxes' areas come from one transposed pass
/// ([`areas3`]) instead of three scalar ones. In small nodes, most of the build's nodes,
/// this sweep was most of `decide`'s time. Ties go as in one axis after the other, each
/// from the last bin down: the first of the lowest axis is kept (checked against that
/// formulation by the test `three_axis_sweep_is_the_per_axis_sweep`).
fn best_split(bins: &Bins, active: [bool; 3], blocks: bool) -> Option<(f32, usize, usize)> {
    let weights = |n: [u32; 3]| {
        Vec3A::from(n.map(|n| {
            if blocks {
                n.div_ceil(MAX_LEAF_SIZE as u32) as f32
            } else {
                n as f32
            }
        }))
    };
    let mut left_area = [Vec3A::ZERO; SAH_BINS];
    let mut left_weight = [Vec3A::ZERO; SAH_BINS];
    let mut acc = [Aabb::EMPTY; 3];
    let mut n = [0u32; 3];
    for i in 0..SAH_BINS - 1 {
        for a in 0..3 {
            acc[a] = acc[a].union(bins[a][i].bounds);
            n[a] += bins[a][i].count;
        }
        left_area[i] = areas3(&acc);
        left_weight[i] = weights(n);
    }
    // Each axis keeps its lowest finite cost, the first one met from the last bin down, in
    // its lane: selects, not branches (which cost came first was a coin toss for the branch
    // predictor, about a third of this function's time in small nodes). The products and
    // the sum are those of one lane at a time, so the costs are the same bits.
    let active = BVec3A::new(active[0], active[1], active[2]);
    let mut best_cost = Vec3A::INFINITY;
    let mut best_bin = Vec3A::ZERO;
    let mut acc = [Aabb::EMPTY; 3];
    let mut n = [0u32; 3];
    for i in (1..SAH_BINS).rev() {
        for a in 0..3 {
            acc[a] = acc[a].union(bins[a][i].bounds);
            n[a] += bins[a][i].count;
        }
        let right_weight = weights(n);
        let (lw, la) = (left_weight[i - 1], left_area[i - 1]);
        let cost = la * lw + areas3(&acc) * right_weight;
        // Both sides hold references (a weight is 0 exactly for an empty side).
        let better = active
            & right_weight.cmpgt(Vec3A::ZERO)
            & lw.cmpgt(Vec3A::ZERO)
            & cost.is_finite_mask()
            & cost.cmplt(best_cost);
        best_cost = Vec3A::select(better, cost, best_cost);
        best_bin = Vec3A::select(better, Vec3A::splat(i as f32), best_bin);
    }
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        let cost = best_cost[axis];
        if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
            best = Some((cost, axis, best_bin[axis] as usize));
        }
    }
    best
}

/// [`Aabb::area`] of three boxes at once: their extents transposed so that each product is
/// one SIMD multiply over the three boxes, with the same operations in the same order per
/// lane (so the same bits), 0 for an empty box.
#[inline(always)]
fn areas3(b: &[Aabb; 3]) -> Vec3A {
    let d = Mat3A::from_cols(
        b[0].max - b[0].min,
        b[1].max - b[1].min,
        b[2].max - b[2].min,
    )
    .transpose();
    let (x, y, z) = (d.x_axis, d.y_axis, d.z_axis);
    let area = 2.0 * (x * y + y * z + z * x);
    let empty = x.cmplt(Vec3A::ZERO) | y.cmplt(Vec3A::ZERO) | z.cmplt(Vec3A::ZERO);
    Vec3A::select(empty, Vec3A::ZERO, area)
}

pub(crate) enum Decision {
    Leaf,
    /// `refs[..mid]` and `refs[mid..]` are the children; `axis` orders traversal. `sides`:
    /// the (bounds, centroid bounds) of the two children when the split computed them.
    Split {
        mid: usize,
        axis: usize,
        sides: Option<[(Aabb, Aabb); 2]>,
    },
}

/// In-place partition; returns the number of elements satisfying `pred` (moved to the front)
/// and the (bounds, centroid bounds) of both sides, gathered on the way (so the children need
/// no second pass over their triangles). Min/max are exact, so the boxes equal `scan`'s.
///
/// Hoare's scheme from both ends (as Embree's serial partition): each scan knows the side of
/// the elements it passes, so the four boxes grow in registers without a select, and an
/// element is moved only when it is on the wrong side. The single-pass scheme this replaces
/// (swap every left element to the front, pick the side's boxes by index) kept the boxes in
/// memory, a store-to-load chain per element; it was 36% of `decide`'s samples.
fn partition(refs: &mut [PrimRef], pred: impl Fn(&PrimRef) -> bool) -> (usize, [(Aabb, Aabb); 2]) {
    let (mut lb, mut lc, mut rb, mut rc) = (Aabb::EMPTY, Aabb::EMPTY, Aabb::EMPTY, Aabb::EMPTY);
    let mut i = 0;
    let mut j = refs.len();
    loop {
        while i < j && pred(&refs[i]) {
            lb = lb.union(refs[i].bounds());
            lc.grow(refs[i].centroid());
            i += 1;
        }
        while i < j && !pred(&refs[j - 1]) {
            rb = rb.union(refs[j - 1].bounds());
            rc.grow(refs[j - 1].centroid());
            j -= 1;
        }
        if i == j {
            break;
        }
        // refs[i] belongs right and refs[j − 1] left (j − 1 > i: both scans stopped).
        refs.swap(i, j - 1);
        lb = lb.union(refs[i].bounds());
        lc.grow(refs[i].centroid());
        rb = rb.union(refs[j - 1].bounds());
        rc.grow(refs[j - 1].centroid());
        i += 1;
        j -= 1;
    }
    (i, [(lb, lc), (rb, rc)])
}

/// [`partition`] of a large range on the thread pool: fixed blocks of
/// [`PARALLEL_SCAN_CHUNK`] references are partitioned in parallel, then the right-side
/// references left of the split point are swapped with the left-side references right of
/// it, the i-th with the i-th. The sides and their boxes are [`partition`]'s (min and max
/// are exact); the order within each side differs from it, but depends only on the input,
/// not on the threads. The sequential partition of the upper nodes was the part of a build
/// that no second thread could help with (the root's six largest splits of a 1M build:
/// about 10 ms).
fn partition_parallel(
    refs: &mut [PrimRef],
    pred: impl Fn(&PrimRef) -> bool + Sync,
) -> (usize, [(Aabb, Aabb); 2]) {
    if refs.len() < PARALLEL_PARTITION_THRESHOLD {
        return partition(refs, pred);
    }
    let blocks: Vec<(usize, [(Aabb, Aabb); 2])> = refs
        .par_chunks_mut(PARALLEL_SCAN_CHUNK)
        .map(|block| partition(block, &pred))
        .collect();
    let mid: usize = blocks.iter().map(|b| b.0).sum();
    let mut sides = [(Aabb::EMPTY, Aabb::EMPTY); 2];
    for (_, b) in &blocks {
        for (s, b) in sides.iter_mut().zip(b) {
            *s = (s.0.union(b.0), s.1.union(b.1));
        }
    }
    // Block k holds its left references at [s, s + l) and its right ones at [s + l, e).
    // Misplaced: right ones below `mid`, left ones at or above it (as many of each).
    let ranges = blocks.iter().enumerate().map(|(k, &(l, _))| {
        let s = k * PARALLEL_SCAN_CHUNK;
        (s, s + l, (s + PARALLEL_SCAN_CHUNK).min(refs.len()))
    });
    let right_below: Vec<(usize, usize)> = ranges
        .clone()
        .map(|(_, m, e)| (m.min(mid), e.min(mid)))
        .filter(|(a, b)| a < b)
        .collect();
    let left_above: Vec<(usize, usize)> = ranges
        .map(|(s, m, _)| (s.max(mid), m.max(mid)))
        .filter(|(a, b)| a < b)
        .collect();
    let (lo, hi) = refs.split_at_mut(mid);
    let mut above = left_above.iter().flat_map(|&(a, b)| a - mid..b - mid);
    for i in right_below.iter().flat_map(|&(a, b)| a..b) {
        let j = above.next().expect("as many misplaced on each side");
        std::mem::swap(&mut lo[i], &mut hi[j]);
    }
    debug_assert!(above.next().is_none());
    (mid, sides)
}

/// Object median split along `axis` (ties broken by index, so the result is deterministic).
fn median_split(refs: &mut [PrimRef], axis: usize) -> Decision {
    let mid = refs.len() / 2;
    refs.select_nth_unstable_by(mid, |a, b| {
        a.centroid()[axis]
            .total_cmp(&b.centroid()[axis])
            .then(a.index().cmp(&b.index()))
    });
    Decision::Split {
        mid,
        axis,
        sides: None,
    }
}

/// Chooses between a leaf and a split, and partitions `refs` for a split. `blocks`: the SAH
/// counts leaf packs instead of triangles (see [`best_split`]). Up to `max_leaf` triangles,
/// a leaf is chosen when its cost (triangles, or packs with `blocks`) is at most the best
/// split's.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN extents and costs must take the fallbacks
pub(crate) fn decide(
    refs: &mut [PrimRef],
    bounds: &Aabb,
    cbounds: &Aabb,
    depth: u32,
    parallel: bool,
    blocks: bool,
    max_leaf: usize,
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
            sides: None,
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
    let Some((cost, axis, split)) = best_split(&bins, binner.active, blocks) else {
        return if n <= MAX_LEAF_SIZE {
            Decision::Leaf
        } else {
            median_split(refs, longest)
        };
    };
    if n <= max_leaf {
        let area = bounds.area();
        let split_cost = TRAVERSAL_COST + cost / area;
        let leaf_cost = if blocks {
            n.div_ceil(MAX_LEAF_SIZE) as f32
        } else {
            n as f32
        };
        // A flat or overflowing box gives a non-finite ratio: keep the small leaf then.
        if !(area > 0.0 && split_cost.is_finite()) || leaf_cost <= split_cost {
            return Decision::Leaf;
        }
    }
    let left = binner.left_of(axis, split);
    let (mid, sides) = if parallel {
        partition_parallel(refs, left)
    } else {
        partition(refs, left)
    };
    debug_assert!(mid > 0 && mid < n);
    Decision::Split {
        mid,
        axis,
        sides: Some(sides),
    }
}

/// Builds the subtree over `refs` (which start at `base` in the final triangle order) as a
/// depth-first node array whose interior offsets are relative to the array's start.
pub(crate) fn build_parallel(refs: &mut [PrimRef], base: u32, depth: u32) -> Vec<Node> {
    if refs.len() < PARALLEL_BUILD_THRESHOLD {
        let mut out = Vec::with_capacity(refs.len());
        build_sequential(refs, base, depth, &mut out);
        return out;
    }
    let (bounds, cbounds) = scan(refs);
    match decide(refs, &bounds, &cbounds, depth, true, false, MAX_LEAF_SIZE) {
        Decision::Leaf => vec![Node::leaf(&bounds, base, refs.len())],
        Decision::Split { mid, axis, .. } => {
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
    match decide(refs, &bounds, &cbounds, depth, false, false, MAX_LEAF_SIZE) {
        Decision::Leaf => out.push(Node::leaf(&bounds, base, refs.len())),
        Decision::Split { mid, axis, .. } => {
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
    use crate::traverse::STACK_SIZE;
    use flowlight_core::geometry::Ray;
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
    fn check_structure(bvh: &BinaryBvh) {
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

    /// Centroid coordinates every bin test must place: NaN, both infinities, a negative value
    /// and both zeros.
    const NAN_INFINITIES_NEGATIVE_ZEROS: [f32; 6] =
        [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, -0.0, 0.0];

    /// The clamped conversion of `Binner::bins_of` is the saturating cast it replaced.
    #[test]
    fn bin_index_is_the_saturating_cast() {
        let binner = Binner {
            cmin: Vec3A::ZERO,
            scale: Vec3A::ONE,
            active: [true; 3],
        };
        let mut rng = Rng::new(2, 2);
        let special = NAN_INFINITIES_NEGATIVE_ZEROS.into_iter().chain([
            0.999_999_9,
            1.0,
            14.999_999,
            15.0,
            15.5,
            16.0,
            1e30,
            f32::MAX,
        ]);
        let random = (0..10_000).map(|_| rng.uniform() * 40.0 - 10.0);
        for f in special.chain(random) {
            let k = binner.bins_of(Vec3A::new(f, f * 0.5, -f));
            let want = [f, f * 0.5, -f].map(|x| (x as usize).min(SAH_BINS - 1));
            assert_eq!(k, want, "{f}");
        }
    }

    /// The per-axis sweep `best_split` replaced (one axis after the other, scalar areas).
    fn best_split_per_axis(
        bins: &Bins,
        active: [bool; 3],
        blocks: bool,
    ) -> Option<(f32, usize, usize)> {
        let weight = |n: u32| {
            if blocks {
                n.div_ceil(MAX_LEAF_SIZE as u32) as f32
            } else {
                n as f32
            }
        };
        let mut best: Option<(f32, usize, usize)> = None;
        for axis in 0..3 {
            if !active[axis] {
                continue;
            }
            let b = &bins[axis];
            let mut left_area = [0.0f32; SAH_BINS];
            let mut left_count = [0u32; SAH_BINS];
            // Empty bins are skipped: one leaves the sweep's box and count as they were, and the
            // split before it gives the same sides as the split after it, which the reverse sweep
            // has already weighed (and `<` keeps). Small nodes leave most of the bins empty.
            let mut acc = Aabb::EMPTY;
            let mut n = 0;
            let mut area = 0.0;
            for i in 0..SAH_BINS - 1 {
                if b[i].count != 0 {
                    acc = acc.union(b[i].bounds);
                    n += b[i].count;
                    area = acc.area();
                }
                left_area[i] = area;
                left_count[i] = n;
            }
            let mut acc = Aabb::EMPTY;
            let mut n = 0;
            for i in (1..SAH_BINS).rev() {
                if b[i].count == 0 {
                    continue;
                }
                acc = acc.union(b[i].bounds);
                n += b[i].count;
                if left_count[i - 1] == 0 {
                    continue;
                }
                let cost = left_area[i - 1] * weight(left_count[i - 1]) + acc.area() * weight(n);
                if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, i));
                }
            }
        }
        best
    }

    /// The three-axis sweep returns what the per-axis sweep returned, bit for bit, on random
    /// bins with empty, flat, huge and infinite boxes and inactive axes.
    #[test]
    fn three_axis_sweep_is_the_per_axis_sweep() {
        let mut rng = Rng::new(9, 9);
        for round in 0..20_000 {
            let mut bins = empty_bins();
            let active = [0, 1, 2].map(|_| rng.uniform() < 0.9);
            let scale = [1.0, 1e-3, 1e30, f32::MAX][round % 4];
            let fill = rng.uniform();
            for (a, axis_bins) in bins.iter_mut().enumerate() {
                if !active[a] {
                    continue;
                }
                for bin in axis_bins.iter_mut() {
                    if rng.uniform() < fill {
                        continue;
                    }
                    let p = Vec3A::new(rng.uniform(), rng.uniform(), rng.uniform()) * scale;
                    let mut e = Vec3A::new(rng.uniform(), rng.uniform(), rng.uniform()) * scale;
                    if rng.uniform() < 0.1 {
                        e.y = 0.0; // flat
                    }
                    if rng.uniform() < 0.02 {
                        e.x = f32::INFINITY;
                    }
                    bin.bounds = Aabb { min: p, max: p + e };
                    bin.count = 1 + (rng.uniform() * 9.0) as u32;
                }
            }
            for blocks in [false, true] {
                let got = best_split(&bins, active, blocks);
                let want = best_split_per_axis(&bins, active, blocks);
                assert_eq!(
                    got.map(|(c, a, i)| (c.to_bits(), a, i)),
                    want.map(|(c, a, i)| (c.to_bits(), a, i)),
                    "round {round}"
                );
            }
        }
    }

    /// The partition's one-axis test puts a reference where the binning counted it.
    #[test]
    fn split_test_is_the_bin_test() {
        let binner = Binner {
            cmin: Vec3A::new(-1.0, 0.0, 2.0),
            scale: Vec3A::new(1.0, 3.0, 0.5),
            active: [true; 3],
        };
        let mut rng = Rng::new(3, 3);
        let special = NAN_INFINITIES_NEGATIVE_ZEROS.into_iter().chain([
            1.0 / 3.0,
            4.999_999_5,
            5.0,
            14.0,
            31.999_998,
            32.0,
            1e30,
            f32::MAX,
        ]);
        let random = (0..10_000).map(|_| rng.uniform() * 60.0 - 10.0);
        for f in special.chain(random) {
            // A point box: its centroid is the point (halves of equal floats add up exactly).
            let p = Vec3A::new(f, f * 0.5, -f);
            let r = PrimRef::from_bounds(Aabb { min: p, max: p }, 7);
            let bins = binner.bins_of(r.centroid());
            for (axis, bin) in bins.into_iter().enumerate() {
                for split in 1..SAH_BINS {
                    let left = binner.left_of(axis, split)(&r);
                    assert_eq!(left, bin < split, "{f} axis {axis} split {split}");
                }
            }
        }
    }

    /// Fisher–Yates, so that references in mesh order lose their runs.
    fn shuffle(refs: &mut [PrimRef], rng: &mut Rng) {
        for i in (1..refs.len()).rev() {
            let j = ((rng.uniform() * (i + 1) as f32) as usize).min(i);
            refs.swap(i, j);
        }
    }

    /// The binning by runs gives each bin the box and count that adding every reference to
    /// its own bins gives, bit for bit: on a coherent strip (long runs), on the same strip
    /// shuffled (runs of one), with a flat axis, and on empty and one-reference slices.
    #[test]
    fn run_binning_is_the_per_reference_binning() {
        let per_reference = |binner: &Binner, refs: &[PrimRef]| {
            let mut bins = empty_bins();
            for r in refs {
                for (a, k) in binner.bins_of(r.centroid()).into_iter().enumerate() {
                    bins[a][k].bounds = bins[a][k].bounds.union(r.bounds());
                    bins[a][k].count += 1;
                }
            }
            bins
        };
        let same = |a: &Bins, b: &Bins| {
            a.iter().flatten().zip(b.iter().flatten()).all(|(x, y)| {
                x.count == y.count
                    && x.bounds.min.to_array().map(f32::to_bits)
                        == y.bounds.min.to_array().map(f32::to_bits)
                    && x.bounds.max.to_array().map(f32::to_bits)
                        == y.bounds.max.to_array().map(f32::to_bits)
            })
        };
        let mut rng = Rng::new(21, 4);
        for flat_axis in [None, Some(1)] {
            // A strip of small triangles along a curve, in order.
            let mut refs: Vec<PrimRef> = (0..5000)
                .map(|i| {
                    let t = i as f32 / 5000.0;
                    let mut c = Vec3::new((t * 9.0).sin(), (t * 7.0).cos(), t * 3.0);
                    let mut e = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 0.01;
                    let mut f = Vec3::new(e.z, e.x, e.y);
                    if let Some(a) = flat_axis {
                        (c[a], e[a], f[a]) = (0.25, 0.0, 0.0);
                    }
                    PrimRef::new(&[c, c + e, c + f], i)
                })
                .collect();
            for shuffled in [false, true] {
                if shuffled {
                    shuffle(&mut refs, &mut rng);
                }
                let (_, c) = scan_seq(&refs);
                let binner = Binner::new(&c);
                assert_eq!(binner.active[1], flat_axis.is_none());
                for slice in [&refs[..], &refs[..0], &refs[..1], &refs[17..40]] {
                    let (runs, each) = (binner.fill(slice), per_reference(&binner, slice));
                    assert!(
                        same(&runs, &each),
                        "shuffled {shuffled}, {} refs",
                        slice.len()
                    );
                }
                let spanned = binner.fill(&refs)[0].iter().filter(|b| b.count > 0).count();
                assert!(spanned > SAH_BINS / 2, "the strip spans the bins");
            }
        }
    }

    /// The parallel partition splits into the sides the sequential one gives, with the same
    /// four boxes bit for bit: on a coherent strip (blocks mostly on one side) and shuffled,
    /// with the split in the middle and near either end, and on a range that ends in a
    /// partial block.
    #[test]
    fn parallel_partition_is_the_partition_up_to_order() {
        let bits = |b: &Aabb| {
            (
                b.min.to_array().map(f32::to_bits),
                b.max.to_array().map(f32::to_bits),
            )
        };
        let mut rng = Rng::new(5, 8);
        let n = 3 * PARALLEL_PARTITION_THRESHOLD + 1234;
        let mut refs: Vec<PrimRef> = (0..n)
            .map(|i| {
                let t = i as f32 / n as f32;
                let c = Vec3::new(t * 10.0, (t * 40.0).sin(), rng.uniform());
                PrimRef::new(&[c, c + Vec3::X * 0.01, c + Vec3::Y * 0.02], i as u32)
            })
            .collect();
        for shuffled in [false, true] {
            if shuffled {
                shuffle(&mut refs, &mut rng);
            }
            for cut in [0.02, 0.5, 0.97] {
                let pred = |r: &PrimRef| r.centroid().x < cut * 10.0;
                let (mut seq, mut par) = (refs.clone(), refs.clone());
                let (m_seq, s_seq) = partition(&mut seq, pred);
                let (m_par, s_par) = partition_parallel(&mut par, pred);
                assert_eq!(m_par, m_seq, "shuffled {shuffled}, cut {cut}");
                assert!(m_par > 0 && m_par < n);
                assert!(par[..m_par].iter().all(pred) && !par[m_par..].iter().any(pred));
                for (a, b) in s_seq.iter().zip(&s_par) {
                    assert_eq!((bits(&a.0), bits(&a.1)), (bits(&b.0), bits(&b.1)));
                }
                let mut ids: Vec<u32> = par.iter().map(PrimRef::index).collect();
                ids.sort_unstable();
                assert!(
                    ids.iter().copied().eq(0..n as u32),
                    "a reference lost or doubled"
                );
            }
        }
    }

    /// A reference keeps its index, whatever its bits as a float (denormal, NaN, signalling
    /// NaN), through copies and partitions, and its box reads back without it.
    #[test]
    fn prim_ref_keeps_any_index_and_a_clean_box() {
        let indices = [
            0,
            1,
            (1 << 23) - 1,
            1 << 23,
            0x7f80_0001,
            0x7fc0_0000,
            0xff80_0001,
            u32::MAX,
        ];
        let mut refs: Vec<PrimRef> = indices
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                let x = k as f32;
                let t = [
                    Vec3::new(x, 0.0, 0.0),
                    Vec3::new(x + 1.0, 2.0, 0.0),
                    Vec3::new(x, 0.0, 3.0),
                ];
                PrimRef::new(&t, i)
            })
            .collect();
        let (mid, sides) = partition(&mut refs, |r| r.index() % 2 == 1);
        assert_eq!(mid, indices.iter().filter(|&&i| i % 2 == 1).count());
        let mut back: Vec<u32> = refs.iter().map(PrimRef::index).collect();
        back.sort_unstable();
        let mut want = indices.to_vec();
        want.sort_unstable();
        assert_eq!(back, want);
        for r in &refs {
            let b = r.bounds();
            assert_eq!(b.area(), 2.0 * (1.0 * 2.0 + 2.0 * 3.0 + 3.0 * 1.0));
            let c = r.centroid();
            assert_eq!((c.y, c.z), (1.0, 1.5));
        }
        for (b, c) in sides {
            assert!(b.area().is_finite() && c.area().is_finite());
        }
    }

    #[test]
    fn structure_is_valid() {
        for n in [1, 2, 5, 100, 3000, 20_000] {
            let tris = random_soup(n, n as u64);
            let bvh = BinaryBvh::build(&tris);
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
        let bvh = BinaryBvh::build(&tris);
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
        let bvh = BinaryBvh::build(&tris);
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
        let bvh = BinaryBvh::build(&tris);
        check_structure(&bvh);
        assert!(bvh.depth() < STACK_SIZE);
    }

    #[test]
    fn build_is_deterministic_across_thread_counts() {
        let tris = random_soup(60_000, 9);
        let a = BinaryBvh::build(&tris);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = one.install(|| BinaryBvh::build(&tris));
        let four = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let c = four.install(|| BinaryBvh::build(&tris));
        assert!(a == b && b == c);
        check_structure(&a);
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
        let bvh = BinaryBvh::build(&tris);
        assert_eq!(bvh.triangle_count(), 5);
        assert_eq!(bvh.stored_triangle_count(), 1);
        assert_eq!(bvh.prim_ids, vec![4]);
        let (lo, hi) = bvh.bounds();
        assert_eq!((lo, hi), (Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)));
        let nan_only = BinaryBvh::build(&tris[2..3]);
        assert_eq!(nan_only.node_count(), 0);
        assert!(nan_only
            .intersect(&Ray::new(Vec3::Z, -Vec3::Z, f32::INFINITY))
            .is_none());
    }
}
