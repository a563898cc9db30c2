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
//!
//! The references and their boxes are in [`prims`], the binning and the SAH sweep in
//! [`binning`], the partitions of a split in [`partition`](mod@self::partition).

use crate::triangle::is_degenerate;
use glam::Vec3;
use rayon::prelude::*;

mod binning;
mod partition;
mod prims;
#[cfg(test)]
mod tests;

use binning::{best_split, Binner};
use partition::{median_split, partition, partition_parallel};
pub(crate) use prims::{scan, scan_seq, Aabb, PrimRef};

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
