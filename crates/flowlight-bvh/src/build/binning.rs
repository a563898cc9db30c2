//! Binning and the SAH sweep: a bin index is one clamped float-to-i32 conversion per axis
//! ([`Binner::bins_of`]); the binning adds runs of references that share their bins at once
//! ([`Binner::fill`]); [`best_split`] sweeps the three axes together and can weigh the SAH by
//! leaf packs instead of triangles.

use super::{Aabb, PrimRef, MAX_LEAF_SIZE, PARALLEL_SCAN_CHUNK, PARALLEL_SCAN_THRESHOLD, SAH_BINS};
use glam::{BVec3A, Mat3A, Vec3A};
use rayon::prelude::*;

#[derive(Clone, Copy, Debug)]
pub(super) struct Bin {
    pub(super) bounds: Aabb,
    pub(super) count: u32,
}

pub(super) type Bins = [[Bin; SAH_BINS]; 3];

/// Empty bins, written in place. A `const` of the bins was copied with `memmove`, which at
/// 2,304 bytes takes its `rep movsb` path; the fill's first loads of those bins then waited
/// for the copy's stores (a string copy's stores are not forwarded to loads), a fixed cost
/// on every node, and most nodes are small.
#[inline(always)]
pub(super) fn empty_bins() -> Bins {
    let empty = Bin {
        bounds: Aabb::EMPTY,
        count: 0,
    };
    [[empty; SAH_BINS]; 3]
}

/// The bins of one reference on the three axes, as integers in one register, so that two
/// references' bins compare with one instruction.
#[derive(Clone, Copy)]
pub(super) struct BinKey(
    #[cfg(target_arch = "x86_64")] std::arch::x86_64::__m128i,
    #[cfg(not(target_arch = "x86_64"))] [u32; 3],
);

impl BinKey {
    /// The key of clamped bin coordinates ([`Binner::clamped`]: each lane in
    /// [0, SAH_BINS − 1], not NaN).
    #[inline(always)]
    pub(super) fn of(f: Vec3A) -> BinKey {
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
    pub(super) fn same(self, o: BinKey) -> bool {
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
    pub(super) fn indices(self) -> [usize; 3] {
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
pub(super) struct Binner {
    pub(super) cmin: Vec3A,
    pub(super) scale: Vec3A,
    pub(super) active: [bool; 3],
}

impl Binner {
    pub(super) fn new(c: &Aabb) -> Binner {
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
    pub(super) fn bins_of(&self, c: Vec3A) -> [usize; 3] {
        BinKey::of(self.clamped(c)).indices()
    }

    /// `(c − cmin)·scale` clamped to [0, SAH_BINS − 1], NaN to 0: the bins before truncation.
    #[inline(always)]
    pub(super) fn clamped(&self, c: Vec3A) -> Vec3A {
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
    pub(super) fn left_of(&self, axis: usize, split: usize) -> impl Fn(&PrimRef) -> bool {
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
    pub(super) fn fill(&self, refs: &[PrimRef]) -> Bins {
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

    pub(super) fn fill_parallel(&self, refs: &[PrimRef]) -> Bins {
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
pub(super) fn best_split(
    bins: &Bins,
    active: [bool; 3],
    blocks: bool,
) -> Option<(f32, usize, usize)> {
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
pub(super) fn areas3(b: &[Aabb; 3]) -> Vec3A {
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
