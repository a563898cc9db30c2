//! The partition of a split: in place, gathering both sides' bounds and centroid bounds on
//! the way; in parallel for large nodes; by the object median where the SAH cannot split.

use super::{Aabb, Decision, PrimRef, PARALLEL_PARTITION_THRESHOLD, PARALLEL_SCAN_CHUNK};
use rayon::prelude::*;

/// In-place partition; returns the number of elements satisfying `pred` (moved to the front)
/// and the (bounds, centroid bounds) of both sides, gathered on the way (so the children need
/// no second pass over their triangles). Min/max are exact, so the boxes equal `scan`'s.
///
/// Hoare's scheme from both ends (as Embree's serial partition): each scan knows the side of
/// the elements it passes, so the four boxes grow in registers without a select, and an
/// element is moved only when it is on the wrong side. The single-pass scheme this replaces
/// (swap every left element to the front, pick the side's boxes by index) kept the boxes in
/// memory, a store-to-load chain per element; it was 36% of `decide`'s samples.
pub(super) fn partition(
    refs: &mut [PrimRef],
    pred: impl Fn(&PrimRef) -> bool,
) -> (usize, [(Aabb, Aabb); 2]) {
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
pub(super) fn partition_parallel(
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
pub(super) fn median_split(refs: &mut [PrimRef], axis: usize) -> Decision {
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
