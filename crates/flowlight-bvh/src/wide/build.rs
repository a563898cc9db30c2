//! Building the 8-wide tree.
//!
//! # Build
//!
//! The binned-SAH splits of the binary build ([`crate::BinaryBvh`], Wald 2007,
//! pbrt-v4 §7.3), applied top-down to widen each node to up to [`WIDTH`] (8) children:
//! starting from the node's triangles as one child, the child with the largest surface area
//! that is not a leaf is split by the SAH until there are eight children (the "wide BVH by
//! repeated splitting of the largest child" of Wald, Benthin & Boulos, "Getting Rid of
//! Packets", IRT 2008, and Embree's BVH4/BVH8 builders). Children of at most
//! [`MAX_LEAF_SIZE`] triangles are leaves; so is a child of up to `LEAF_PACKS · 4` (8)
//! triangles whose leaf cost the SAH finds no higher than its best split's (as Embree's
//! leaves of several triangle blocks; ~30% fewer nodes, faster 100k-triangle traversal).
//! The SAH of these splits counts leaf packs, `⌈n/4⌉`, not triangles (Embree's block
//! rounding): a pack of one triangle costs one pass of the 4-lane test like a full one, so
//! splits that fill packs win (about 40% fewer nodes, faster builds). No binary tree is
//! materialised; the upper levels are built in parallel (rayon), their parts laid out
//! once at the end in the depth-first order of the sequential build, and the result does
//! not depend on the thread schedule.

use super::huge_pages::HugeArray;
use super::{
    detect_avx2, leaf_packs, leaf_ref, push_leaf, stack_bound, Bvh, TriPack, WideNode, EMPTY_CHILD,
    LANES, LEAF_BIT, LEAF_PACKS, MAX_PACKS, STACK_SIZE, WIDTH,
};
use crate::build::{
    decide, scan, Aabb, Decision, PrimRef, MAX_LEAF_SIZE, PARALLEL_BUILD_THRESHOLD,
};
use crate::triangle::is_degenerate;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A child during widening: `refs[start .. start + len]`, its boxes and binary depth, and
/// whether it is a leaf (at most [`MAX_LEAF_SIZE`] triangles, or the SAH chose a leaf of
/// up to [`LEAF_PACKS`] packs).
#[derive(Clone, Copy, Debug)]
pub(super) struct Child {
    pub(super) start: usize,
    pub(super) len: usize,
    pub(super) bounds: Aabb,
    pub(super) cbounds: Aabb,
    pub(super) depth: u32,
    pub(super) leaf: bool,
}

impl Child {
    /// The root of a build over all of `refs` (not empty).
    pub(super) fn root(refs: &[PrimRef]) -> Child {
        let (bounds, cbounds) = scan(refs);
        Child {
            start: 0,
            len: refs.len(),
            bounds,
            cbounds,
            depth: 0,
            leaf: refs.len() <= MAX_LEAF_SIZE,
        }
    }
}

/// Nodes and packs of a subtree; child references are relative to the subtree (its root
/// node is 0, its first pack is pack 0). `leaves` are the packs, `(first ref, count)`,
/// absolute.
#[derive(Default)]
pub(super) struct Subtree {
    pub(super) nodes: Vec<WideNode>,
    pub(super) leaves: Vec<(u32, u8)>,
}

/// Splits the child with the largest area (among those that are not leaves) until there are
/// `WIDTH` children or none can be split; the children are returned in the order of their
/// triangle ranges.
pub(super) fn widen(refs: &mut [PrimRef], root: Child) -> ([Child; WIDTH], usize) {
    let max_leaf = LANES * LEAF_PACKS;
    let mut ch = [root; WIDTH];
    let mut n = 1;
    while n < WIDTH {
        let Some(i) = (0..n).filter(|&i| !ch[i].leaf).max_by(|&a, &b| {
            ch[a]
                .bounds
                .area()
                .total_cmp(&ch[b].bounds.area())
                .then(b.cmp(&a))
        }) else {
            break;
        };
        let c = ch[i];
        let slice = &mut refs[c.start..c.start + c.len];
        let (mid, sides) = match decide(slice, &c.bounds, &c.cbounds, c.depth, true, true, max_leaf)
        {
            Decision::Split { mid, sides, .. } => (mid, sides),
            Decision::Leaf if c.len <= max_leaf => {
                ch[i].leaf = true;
                continue;
            }
            // `decide` returns no other leaf (above MAX_LEAF_SIZE triangles).
            Decision::Leaf => (c.len / 2, None),
        };
        let (l, r) = slice.split_at(mid);
        let ((lb, lc), (rb, rc)) = match sides {
            Some([l, r]) => (l, r),
            None if c.len >= PARALLEL_BUILD_THRESHOLD => rayon::join(|| scan(l), || scan(r)),
            None => (scan(l), scan(r)),
        };
        ch[i] = Child {
            start: c.start,
            len: mid,
            bounds: lb,
            cbounds: lc,
            depth: c.depth + 1,
            leaf: mid <= MAX_LEAF_SIZE,
        };
        ch[n] = Child {
            start: c.start + mid,
            len: c.len - mid,
            bounds: rb,
            cbounds: rc,
            depth: c.depth + 1,
            leaf: c.len - mid <= MAX_LEAF_SIZE,
        };
        n += 1;
    }
    // Children left unsplit when the node filled up: one the SAH would make a leaf becomes
    // one here, rather than a node holding a single leaf. (A split only reorders the
    // child's range; its subtree is built from the same set of triangles.)
    let max_leaf = LANES * LEAF_PACKS;
    for c in &mut ch[..n] {
        if !c.leaf && c.len <= max_leaf {
            let slice = &mut refs[c.start..c.start + c.len];
            let d = decide(slice, &c.bounds, &c.cbounds, c.depth, false, true, max_leaf);
            c.leaf = matches!(d, Decision::Leaf);
        }
    }
    ch[..n].sort_unstable_by_key(|c| c.start);
    (ch, n)
}

/// Builds the subtree of `root` (whose range is all of `refs`, at `base` in the final order)
/// into `out`, sequentially; returns its node index.
pub(super) fn build_sequential(
    refs: &mut [PrimRef],
    base: usize,
    root: Child,
    out: &mut Subtree,
) -> u32 {
    let (ch, n) = widen(refs, root);
    let idx = out.nodes.len();
    out.nodes.push(WideNode::EMPTY);
    for (k, c) in ch[..n].iter().enumerate() {
        let child = if c.leaf {
            push_leaf(&mut out.leaves, base + c.start, c.len)
        } else {
            let sub = Child { start: 0, ..*c };
            build_sequential(
                &mut refs[c.start..c.start + c.len],
                base + c.start,
                sub,
                out,
            )
        };
        out.nodes[idx].set(k, &c.bounds, child);
    }
    idx as u32
}

/// A subtree built in parallel, before its nodes and packs are laid out: either built on one
/// thread ([`Subtree`], references relative to itself) or a node whose children were built
/// in parallel. Each part's size is known, so [`Part::write`] can place every node and pack
/// in the final arrays once, all parts at the same time. (Merging the children's arrays
/// into the parent's at each parallel level copied the upper part of the tree once per
/// level, on one thread at the root, into fresh memory each time.)
pub(super) enum Part {
    Flat(Subtree),
    Fork(Box<Fork>),
}

/// A node whose non-leaf children were built in parallel.
pub(super) struct Fork {
    /// Where the node's range starts in the final triangle order.
    base: usize,
    /// The node's children in order, with the subtree of each one that is not a leaf.
    children: Vec<(Child, Option<Part>)>,
    /// Nodes and packs of the whole part, its node included.
    nodes: usize,
    packs: usize,
}

impl Part {
    pub(super) fn nodes(&self) -> usize {
        match self {
            Part::Flat(t) => t.nodes.len(),
            Part::Fork(f) => f.nodes,
        }
    }

    pub(super) fn packs(&self) -> usize {
        match self {
            Part::Flat(t) => t.leaves.len(),
            Part::Fork(f) => f.packs,
        }
    }

    /// Writes the part's nodes to `nodes` and its packs to `packs` (each exactly its size
    /// long), depth first as [`build_sequential`] lays out a tree; the part's first node
    /// and pack are `node_base` and `pack_base` of the final arrays.
    pub(super) fn write(
        self,
        nodes: &mut [WideNode],
        packs: &mut [(u32, u8)],
        node_base: u32,
        pack_base: u32,
    ) {
        debug_assert_eq!((nodes.len(), packs.len()), (self.nodes(), self.packs()));
        match self {
            Part::Flat(t) => {
                let pack_shift = pack_base << 2;
                for (out, node) in nodes.iter_mut().zip(&t.nodes) {
                    *out = *node;
                    for r in &mut out.child {
                        if *r == EMPTY_CHILD {
                        } else if *r & LEAF_BIT != 0 {
                            *r += pack_shift;
                        } else {
                            *r += node_base;
                        }
                    }
                }
                packs.copy_from_slice(&t.leaves);
            }
            Part::Fork(f) => {
                let (root, mut nodes) = nodes.split_first_mut().expect("a fork has a node");
                *root = WideNode::EMPTY;
                let mut packs = packs;
                let (mut node_at, mut pack_at) = (node_base + 1, pack_base);
                let mut jobs = Vec::with_capacity(f.children.len());
                for (k, (c, sub)) in f.children.into_iter().enumerate() {
                    let child = match sub {
                        None => {
                            let leaf = leaf_packs(f.base + c.start, c.len);
                            let n = leaf.len();
                            let (mine, rest) = std::mem::take(&mut packs).split_at_mut(n);
                            for (out, p) in mine.iter_mut().zip(leaf) {
                                *out = p;
                            }
                            packs = rest;
                            let r = leaf_ref(pack_at as usize, n);
                            pack_at += n as u32;
                            r
                        }
                        Some(sub) => {
                            let (n, p) = (sub.nodes(), sub.packs());
                            let (sub_nodes, rest) = std::mem::take(&mut nodes).split_at_mut(n);
                            nodes = rest;
                            let (sub_packs, rest) = std::mem::take(&mut packs).split_at_mut(p);
                            packs = rest;
                            jobs.push((sub, sub_nodes, sub_packs, node_at, pack_at));
                            let r = node_at;
                            node_at += n as u32;
                            pack_at += p as u32;
                            r
                        }
                    };
                    root.set(k, &c.bounds, child);
                }
                jobs.into_par_iter()
                    .for_each(|(sub, n, p, nb, pb)| sub.write(n, p, nb, pb));
            }
        }
    }
}

/// Builds the subtree of `root` (range: all of `refs`), its children in parallel when large.
pub(super) fn build_parallel(refs: &mut [PrimRef], base: usize, root: Child) -> Part {
    if refs.len() < PARALLEL_BUILD_THRESHOLD {
        let mut out = Subtree {
            nodes: Vec::with_capacity(refs.len() / 2),
            leaves: Vec::with_capacity(refs.len() / 2),
        };
        build_sequential(refs, base, root, &mut out);
        return Part::Flat(out);
    }
    let (ch, n) = widen(refs, root);
    let mut slices = Vec::with_capacity(n);
    let mut rest = refs;
    for c in &ch[..n] {
        let (s, r) = rest.split_at_mut(c.len);
        slices.push((s, *c));
        rest = r;
    }
    let children: Vec<(Child, Option<Part>)> = slices
        .into_par_iter()
        .map(|(s, c)| {
            let sub = (!c.leaf).then(|| build_parallel(s, base + c.start, Child { start: 0, ..c }));
            (c, sub)
        })
        .collect();
    let nodes = 1 + children
        .iter()
        .flat_map(|(_, s)| s)
        .map(Part::nodes)
        .sum::<usize>();
    let packs = children
        .iter()
        .map(|(c, s)| {
            s.as_ref()
                .map_or_else(|| leaf_packs(0, c.len).len(), Part::packs)
        })
        .sum();
    Part::Fork(Box::new(Fork {
        base,
        children,
        nodes,
        packs,
    }))
}

/// The nodes and packs of a whole tree: [`Subtree`] with the nodes in their final memory.
pub(super) struct Tree {
    pub(super) nodes: HugeArray<WideNode>,
    pub(super) leaves: Vec<(u32, u8)>,
}

/// The tree over `refs` (whose range is `root`), built in parallel where large and laid out
/// as [`build_sequential`] lays it out.
pub(super) fn build_tree(refs: &mut [PrimRef], root: Child) -> Tree {
    let part = build_parallel(refs, 0, root);
    assert!(part.packs() <= MAX_PACKS, "too many triangles for a Bvh");
    match part {
        Part::Flat(t) => Tree {
            nodes: HugeArray::from_slice(&t.nodes),
            leaves: t.leaves,
        },
        part => {
            // Filled in parallel before the write, so that the pages are faulted in (as
            // huge pages) by both threads rather than by the write's first thread.
            let mut nodes = HugeArray::from_fn(part.nodes(), |_| WideNode::EMPTY);
            let mut leaves = vec![(0, 0); part.packs()];
            part.write(&mut nodes, &mut leaves, 0, 0);
            Tree { nodes, leaves }
        }
    }
}

impl Bvh {
    /// Builds the hierarchy. `prim` in hits is the index into `triangles`. Degenerate
    /// triangles (see [`is_degenerate`]) are skipped. Panics if there are more than `u32::MAX`
    /// triangles.
    pub fn build(triangles: &[[Vec3; 3]]) -> Bvh {
        Bvh::build_from(triangles.len(), |i| triangles[i])
    }

    /// [`Bvh::build`] over an indexed mesh: triangle `i` has the vertices
    /// `positions[indices[i][k]]`, and `prim` in hits is `i`. The same tree as `build` over the
    /// gathered triangles, without gathering them first (36 bytes a triangle, and at 1M
    /// triangles a sequential pass the build would wait for). Panics if an index is out of
    /// range or there are more than `u32::MAX` triangles.
    pub fn build_indexed(positions: &[Vec3], indices: &[[u32; 3]]) -> Bvh {
        Bvh::build_from(indices.len(), |i| indices[i].map(|k| positions[k as usize]))
    }

    pub(super) fn build_from(count: usize, triangle: impl Fn(usize) -> [Vec3; 3] + Sync) -> Bvh {
        assert!(count <= u32::MAX as usize, "too many triangles for a Bvh");
        // An indexed collect writes each reference in place; a `filter_map` collect gathers
        // per-thread pieces and copies them together (5% of a 1M build's samples). The
        // degenerate triangles, rare, get a marker and are removed afterwards.
        let degenerate = AtomicBool::new(false);
        let mut refs: Vec<PrimRef> = (0..count)
            .into_par_iter()
            .map(|i| {
                let t = triangle(i);
                if is_degenerate(&t) {
                    degenerate.store(true, Ordering::Relaxed);
                    PrimRef::DEGENERATE
                } else {
                    PrimRef::new(&t, i as u32)
                }
            })
            .collect();
        if degenerate.into_inner() {
            refs.retain(|r| !r.is_degenerate_marker());
        }
        let empty = Bvh {
            nodes: HugeArray::from_slice(&[]),
            packs: HugeArray::from_slice(&[]),
            bounds: (Vec3::INFINITY, Vec3::NEG_INFINITY),
            stored: 0,
            input_count: count,
            stack_bound: 0,
            avx2: detect_avx2(),
        };
        if refs.is_empty() {
            return empty;
        }
        let root = Child::root(&refs);
        let bounds = root.bounds;
        let tree = build_tree(&mut refs, root);
        let bound = stack_bound(&tree.nodes, 0);
        // The SAH depth cap keeps trees far below this (`MAX_SAH_DEPTH + 32` binary levels).
        assert!(bound <= STACK_SIZE, "BVH too deep for the traversal stack");
        let packs = HugeArray::from_fn(tree.leaves.len(), |i| {
            let (first, count) = tree.leaves[i];
            let r = &refs[first as usize..first as usize + count as usize];
            let mut tris = [[Vec3::ZERO; 3]; LANES];
            let mut prims = [u32::MAX; LANES];
            for (k, p) in r.iter().enumerate() {
                tris[k] = triangle(p.index() as usize);
                prims[k] = p.index();
            }
            TriPack::new(&tris[..r.len()], prims)
        });
        Bvh {
            nodes: tree.nodes,
            packs,
            bounds: (bounds.min.into(), bounds.max.into()),
            stored: refs.len(),
            stack_bound: bound,
            ..empty
        }
    }
}
