//! The 8-wide BVH behind [`Bvh`]: build, node and triangle layout, SIMD traversal.
//!
//! * **Build** — the binned-SAH splits of the binary build ([`crate::BinaryBvh`], Wald 2007,
//!   pbrt-v4 §7.3), applied top-down to widen each node to up to [`WIDTH`] (8) children:
//!   starting from the node's triangles as one child, the child with the largest surface area
//!   that is not a leaf is split by the SAH until there are eight children (the "wide BVH by
//!   repeated splitting of the largest child" of Wald, Benthin & Boulos, "Getting Rid of
//!   Packets", IRT 2008, and Embree's BVH4/BVH8 builders). Children of at most
//!   [`MAX_LEAF_SIZE`] triangles are leaves; so is a child of up to `LEAF_PACKS · 4` (8)
//!   triangles whose leaf cost the SAH finds no higher than its best split's (as Embree's
//!   leaves of several triangle blocks; ~30% fewer nodes, faster 100k-triangle traversal).
//!   The SAH of these splits counts leaf packs, `⌈n/4⌉`, not triangles (Embree's block
//!   rounding): a pack of one triangle costs one pass of the 4-lane test like a full one, so
//!   splits that fill packs win (about 40% fewer nodes, faster builds). No binary tree is
//!   materialised; the upper levels are built in parallel (rayon), their parts laid out
//!   once at the end in the depth-first order of the sequential build, and the result does
//!   not depend on the thread schedule.
//! * **Nodes** — 256 bytes, four cache lines: the eight children's boxes in SoA order
//!   (`min x` of the 8 children, `max x`, `min y`, …, each row 32 bytes: one AVX register or
//!   two SSE ones) and eight child references (interior node index, or leaf: first pack
//!   index and pack count, or empty). Empty slots have the box `(+∞, −∞)`, which no ray hits.
//!   Eight children rather than four: a third fewer levels, so fewer dependent cache misses
//!   per ray (Embree uses BVH8 on AVX2 machines for the same reason); measured 1.1–1.3× the
//!   4-wide tree's incoherent throughput (docs/performance.md).
//! * **Triangles** — each leaf is one or two consecutive *packs* of up to four triangles
//!   stored SoA (`v[vertex][axis]` holds that coordinate of the four triangles), so a pack is
//!   one pass of the watertight test over four lanes; the four original triangle indices
//!   (`u32::MAX` in unused lanes, which also gives the pack's lane count) follow the
//!   vertices (160 bytes a pack), so reporting a closest hit costs no extra cache miss, and
//!   `occluded` never reads them (the traversal returns pack and lane; only
//!   `intersect` looks the index up).
//! * **Box test** — the slabs of all eight children: `t_near = max_a (near_a − o_a)·(1/d_a)`,
//!   `t_far = (1 + 2γ₃)·min_a (far_a − o_a)·(1/d_a)`, where `near_a` is the min plane for
//!   `d_a ≥ +0` and the max plane otherwise; a child is entered when `t_near ≤ t_far`,
//!   `t_near < t_max` and `t_far > 0`. This is exactly the binary BVH's robust slab test
//!   (pbrt-v4 §6.8.2): the slab distance is the first operand of `max`/`min` and the (never
//!   NaN) accumulator the second, and these return the second operand when the first is NaN
//!   (SSE2 `_mm_max_ps`, AVX `_mm256_max_ps`, NEON's compare-and-select, the scalar
//!   `f32::max`), so a NaN slab distance (origin on the plane, `d_a = ±0`) leaves the interval
//!   unconstrained, as in the binary test. On x86-64 CPUs with AVX2 (detected once, when the
//!   tree is built) the eight boxes are one AVX pass and the whole traversal is compiled with
//!   AVX2 enabled (`Bvh::traverse_avx2`, not FMA); elsewhere — x86-64 without AVX2, aarch64,
//!   other targets — two 4-lane passes through glam's `Vec4` (SSE2, NEON or scalar) give the
//!   same bits.
//! * **Traversal** — iterative with a stack of (node, entry distance). Closest hit visits the
//!   entered children nearest first (entry distances sorted) and skips popped entries whose
//!   entry distance is no longer below `t_max`; any hit returns at the first accepted hit.
//!   When a node enters several children, all of them (node lines, or a leaf's first pack)
//!   are prefetched at once, so that their cache misses overlap rather than come one after
//!   the other as the children are visited (x86-64 `prefetcht0`; measured +7–25% at 1M
//!   triangles, neutral at 10k–100k).
//! * **Triangle test** — the watertight test of [`crate::WatertightRay`] (Woop, Benthin &
//!   Wald, JCGT 2013, with pbrt-v4's conservative `t` bound), evaluated on four lanes with the
//!   same IEEE operations in the same order, no FMA (the AVX2 build enables no FMA either, and
//!   Rust never contracts a multiply and an add), so each lane gives bit-for-bit the scalar
//!   result. Packs where a lane's edge function is exactly 0 (ray through an edge or vertex)
//!   take the scalar test, whose double-precision recomputation keeps the test watertight.
//! * **Hit filters** — candidates of a pack are offered to the filter nearest first; the
//!   first accepted one is the pack's closest accepted hit, rejected ones leave `t_max` as
//!   it is.
//! * **Floating-point mode** — queries run with flush-to-zero and denormals-are-zero set
//!   (`Bvh::traverse`), as Embree's do; hit filters run in the thread's own mode.

use crate::build::{
    decide, scan, Aabb, Decision, PrimRef, MAX_LEAF_SIZE, PARALLEL_BUILD_THRESHOLD,
};
use crate::triangle::{gamma, is_degenerate, WatertightRay};
use flowlight_core::denormals::{with_denormals_flushed, with_denormals_kept};
use flowlight_core::geometry::{HitFilter, Ray, TriangleHit};
use glam::{Vec3, Vec4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Children per node.
pub const WIDTH: usize = 8;
/// Triangles per leaf pack (lanes of the pack test).
const LANES: usize = 4;
/// Whether traversal prefetches all entered children of a node at once.
const PREFETCH: bool = true;
/// Most packs in one leaf (the SAH decides between a leaf of several packs and a node).
const LEAF_PACKS: usize = 2;
const _: () = assert!(LEAF_PACKS >= 1 && LEAF_PACKS <= 4 && MAX_LEAF_SIZE == LANES);
/// A child reference with this bit set is a leaf: `first pack << 2 | (packs − 1)` below it.
const LEAF_BIT: u32 = 1 << 31;
/// An unused child slot (its box is empty, so it is never entered).
const EMPTY_CHILD: u32 = u32::MAX;
/// Largest number of packs (leaves) a tree can address.
const MAX_PACKS: usize = (1 << 29) - 1;
/// Traversal stack: at most `WIDTH − 1` entries per level, and a path has at most
/// `MAX_SAH_DEPTH + 32` binary splits (see the binary build), so fewer levels than that.
const STACK_SIZE: usize = (WIDTH - 1) * 128;
/// The stack of trees whose bound (see [`stack_bound`]) is at most this.
const SMALL_STACK: usize = 96;

/// One node: the boxes of its eight children, SoA, and the child references.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct WideNode {
    /// `bounds[2a]`: the children's minimum along axis `a`; `bounds[2a + 1]`: the maximum.
    /// Each row is 32 bytes at a 32-byte aligned offset (one AVX register, two SSE ones).
    bounds: [[f32; WIDTH]; 6],
    child: [u32; WIDTH],
}

const _: () = assert!(std::mem::size_of::<WideNode>() == 256);

impl WideNode {
    const EMPTY: WideNode = WideNode {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [EMPTY_CHILD; WIDTH],
    };

    fn set(&mut self, k: usize, b: &Aabb, child: u32) {
        for a in 0..3 {
            self.bounds[2 * a][k] = b.min[a];
            self.bounds[2 * a + 1][k] = b.max[a];
        }
        self.child[k] = child;
    }
}

/// Up to four triangles, SoA: `v[vertex][axis]` holds that coordinate of each lane's triangle.
/// Unused lanes repeat lane 0 (they are masked out by the leaf's count). `prims`: each lane's
/// original triangle index (`u32::MAX` for unused lanes), stored right after the vertices so
/// that reporting a hit touches no other cache line.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TriPack {
    v: [[Vec4; 3]; 3],
    prims: [u32; LANES],
}

const _: () = assert!(std::mem::size_of::<TriPack>() == 160);

impl TriPack {
    fn new(tris: &[[Vec3; 3]], prims: [u32; LANES]) -> TriPack {
        debug_assert!(!tris.is_empty() && tris.len() <= LANES);
        let mut v = [[Vec4::ZERO; 3]; 3];
        for lane in 0..LANES {
            let t = &tris[if lane < tris.len() { lane } else { 0 }];
            for (vi, p) in t.iter().enumerate() {
                for a in 0..3 {
                    v[vi][a][lane] = p[a];
                }
            }
        }
        TriPack { v, prims }
    }

    /// The lanes that hold a triangle (the first ones).
    #[inline(always)]
    fn valid(&self) -> u32 {
        let used = |k: usize| u32::from(self.prims[k] != u32::MAX);
        (1 << (1 + used(1) + used(2) + used(3))) - 1
    }

    fn triangle(&self, lane: usize) -> [Vec3; 3] {
        let p = |vi: usize| {
            Vec3::new(
                self.v[vi][0][lane],
                self.v[vi][1][lane],
                self.v[vi][2][lane],
            )
        };
        [p(0), p(1), p(2)]
    }
}

/// A hit found by traversal: pack, lane, t, b1, b2 (the triangle id is looked up only when
/// the caller wants it, so `occluded` never loads it).
type RawHit = (usize, usize, f32, f32, f32);

/// The packs of a leaf over `refs[first .. first + len]` (`len ≤ LANES·LEAF_PACKS`):
/// `(first ref, count)` of each.
fn leaf_packs(first: usize, len: usize) -> impl ExactSizeIterator<Item = (u32, u8)> {
    debug_assert!((1..=LANES * LEAF_PACKS).contains(&len));
    (0..len.div_ceil(LANES)).map(move |p| {
        (
            (first + p * LANES) as u32,
            (len - p * LANES).min(LANES) as u8,
        )
    })
}

/// The child reference of a leaf of `n` packs from pack `first_pack` on.
fn leaf_ref(first_pack: usize, n: usize) -> u32 {
    LEAF_BIT | ((first_pack as u32) << 2) | (n as u32 - 1)
}

/// Appends the packs of a leaf over `refs[first .. first + len]` to `packs`; returns the
/// leaf's child reference.
fn push_leaf(packs: &mut Vec<(u32, u8)>, first: usize, len: usize) -> u32 {
    let first_pack = packs.len();
    packs.extend(leaf_packs(first, len));
    leaf_ref(first_pack, packs.len() - first_pack)
}

/// A 4-wide bounding volume hierarchy over a triangle soup, with closest-hit and any-hit
/// queries (optionally filtered); see the crate documentation and the `wide` module.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    /// Depth first, root at 0; empty when there is nothing to intersect.
    nodes: Vec<WideNode>,
    packs: Vec<TriPack>,
    bounds: (Vec3, Vec3),
    stored: usize,
    input_count: usize,
    /// Most traversal stack entries a ray can need (see [`stack_bound`]).
    stack_bound: usize,
    /// Whether queries test a node's eight boxes with one AVX2 pass (detected at build
    /// time) instead of two SSE passes.
    avx2: bool,
}

/// Whether this CPU runs the AVX2 box test (checked once per build).
fn detect_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Most entries the traversal stack can hold below node `r`: a node stacks all entered
/// children but the one it descends into, and an entry is only popped to descend into it,
/// so along any path the stack holds at most `Σ (children − 1)` of the nodes passed.
fn stack_bound(nodes: &[WideNode], r: u32) -> usize {
    if r & LEAF_BIT != 0 {
        return 0;
    }
    let n = &nodes[r as usize];
    let children = n.child.iter().filter(|&&c| c != EMPTY_CHILD);
    children.clone().count() - 1 + children.map(|&c| stack_bound(nodes, c)).max().unwrap_or(0)
}

/// A child during widening: `refs[start .. start + len]`, its boxes and binary depth, and
/// whether it is a leaf (at most [`MAX_LEAF_SIZE`] triangles, or the SAH chose a leaf of
/// up to [`LEAF_PACKS`] packs).
#[derive(Clone, Copy, Debug)]
struct Child {
    start: usize,
    len: usize,
    bounds: Aabb,
    cbounds: Aabb,
    depth: u32,
    leaf: bool,
}

impl Child {
    /// The root of a build over all of `refs` (not empty).
    fn root(refs: &[PrimRef]) -> Child {
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
struct Subtree {
    nodes: Vec<WideNode>,
    leaves: Vec<(u32, u8)>,
}

/// Splits the child with the largest area (among those that are not leaves) until there are
/// `WIDTH` children or none can be split; the children are returned in the order of their
/// triangle ranges.
fn widen(refs: &mut [PrimRef], root: Child) -> ([Child; WIDTH], usize) {
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
fn build_sequential(refs: &mut [PrimRef], base: usize, root: Child, out: &mut Subtree) -> u32 {
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
enum Part {
    Flat(Subtree),
    Fork(Box<Fork>),
}

/// A node whose non-leaf children were built in parallel.
struct Fork {
    /// Where the node's range starts in the final triangle order.
    base: usize,
    /// The node's children in order, with the subtree of each one that is not a leaf.
    children: Vec<(Child, Option<Part>)>,
    /// Nodes and packs of the whole part, its node included.
    nodes: usize,
    packs: usize,
}

impl Part {
    fn nodes(&self) -> usize {
        match self {
            Part::Flat(t) => t.nodes.len(),
            Part::Fork(f) => f.nodes,
        }
    }

    fn packs(&self) -> usize {
        match self {
            Part::Flat(t) => t.leaves.len(),
            Part::Fork(f) => f.packs,
        }
    }

    /// Writes the part's nodes to `nodes` and its packs to `packs` (each exactly its size
    /// long), depth first as [`build_sequential`] lays out a tree; the part's first node
    /// and pack are `node_base` and `pack_base` of the final arrays.
    fn write(
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
fn build_parallel(refs: &mut [PrimRef], base: usize, root: Child) -> Part {
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

/// The tree over `refs` (whose range is `root`), built in parallel where large and laid out
/// as [`build_sequential`] lays it out.
fn build_tree(refs: &mut [PrimRef], root: Child) -> Subtree {
    let part = build_parallel(refs, 0, root);
    assert!(part.packs() <= MAX_PACKS, "too many triangles for a Bvh");
    match part {
        Part::Flat(t) => t,
        part => {
            let mut t = Subtree {
                nodes: Vec::new(),
                leaves: vec![(0, 0); part.packs()],
            };
            t.nodes
                .par_extend(rayon::iter::repeat_n(WideNode::EMPTY, part.nodes()));
            part.write(&mut t.nodes, &mut t.leaves, 0, 0);
            t
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

    fn build_from(count: usize, triangle: impl Fn(usize) -> [Vec3; 3] + Sync) -> Bvh {
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
            nodes: Vec::new(),
            packs: Vec::new(),
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
        let packs = tree
            .leaves
            .par_iter()
            .map(|&(first, count)| {
                let r = &refs[first as usize..first as usize + count as usize];
                let mut tris = [[Vec3::ZERO; 3]; LANES];
                let mut prims = [u32::MAX; LANES];
                for (k, p) in r.iter().enumerate() {
                    tris[k] = triangle(p.index() as usize);
                    prims[k] = p.index();
                }
                TriPack::new(&tris[..r.len()], prims)
            })
            .collect();
        Bvh {
            nodes: tree.nodes,
            packs,
            bounds: (bounds.min.into(), bounds.max.into()),
            stored: refs.len(),
            stack_bound: bound,
            ..empty
        }
    }

    /// Number of triangles given to [`Bvh::build`], degenerate ones included.
    pub fn triangle_count(&self) -> usize {
        self.input_count
    }

    /// Number of (non-degenerate) triangles stored in the tree.
    pub fn stored_triangle_count(&self) -> usize {
        self.stored
    }

    /// Number of (4-wide) nodes; 0 when there is nothing to intersect.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Number of packs of up to four triangles (a leaf holds one or more).
    pub fn leaf_count(&self) -> usize {
        self.packs.len()
    }

    /// Bounds `(min, max)` of all non-degenerate triangles; `(+∞, -∞)` when there are none.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    /// Depth of the tree in wide nodes, leaves included (a root holding one leaf has depth 2,
    /// an empty tree 0).
    pub fn depth(&self) -> usize {
        fn rec(nodes: &[WideNode], r: u32) -> usize {
            if r & LEAF_BIT != 0 {
                return 1;
            }
            let n = &nodes[r as usize];
            1 + n
                .child
                .iter()
                .filter(|&&c| c != EMPTY_CHILD)
                .map(|&c| rec(nodes, c))
                .max()
                .unwrap_or(0)
        }
        if self.nodes.is_empty() {
            0
        } else {
            rec(&self.nodes, 0)
        }
    }

    /// Closest hit with `t ∈ (0, ray.t_max)`, or `None`.
    pub fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        self.traverse::<false, false, _>(ray, &|_, _, _| true)
            .map(|h| self.hit(h))
    }

    /// Whether any triangle is hit with `t ∈ (0, ray.t_max)`. Returns at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.traverse::<true, false, _>(ray, &|_, _, _| true)
            .is_some()
    }

    /// [`Bvh::intersect`] counting only the hits `accept` keeps (alpha testing): a rejected
    /// candidate does not shorten the ray, so traversal finds the closest accepted hit.
    /// `accept` runs in the thread's own floating-point mode, not the query's.
    pub fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        let accept = |p, b1, b2| with_denormals_kept(|| accept(p, b1, b2));
        self.traverse::<false, true, _>(ray, &accept)
            .map(|h| self.hit(h))
    }

    /// [`Bvh::occluded`] counting only the hits `accept` keeps (run as for
    /// [`Bvh::intersect_filtered`]).
    pub fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        let accept = |p, b1, b2| with_denormals_kept(|| accept(p, b1, b2));
        self.traverse::<true, true, _>(ray, &accept).is_some()
    }

    /// The traversal in the ray queries' floating-point mode, flush-to-zero and
    /// denormals-are-zero, as Embree's queries run ([`flowlight_core::denormals`]): a ray
    /// leaving a surface in a coordinate plane starts at a subnormal coordinate, and without
    /// the mode every product with it is a microcode assist on Intel CPUs (the Cornell box
    /// rendered with the BVH in 2.2× the CPU). Set once per query, or once per batch by the
    /// host (then this only reads it). The mode keeps the test watertight: the edge
    /// functions of an edge two triangles share are the same products in either triangle,
    /// flushed alike.
    #[inline(always)]
    fn traverse<const ANY_HIT: bool, const FILTER: bool, F: Fn(u32, f32, f32) -> bool>(
        &self,
        ray: &Ray,
        accept: &F,
    ) -> Option<RawHit> {
        if self.nodes.is_empty() {
            return None;
        }
        with_denormals_flushed(|| self.traverse_in_mode::<ANY_HIT, FILTER, F>(ray, accept))
    }

    /// Picks the traversal stack: a small one when the tree's bound allows (clearing a
    /// 3 KiB stack for every ray is measurable), else the largest one a tree can need.
    #[inline(always)]
    fn traverse_in_mode<const ANY_HIT: bool, const FILTER: bool, F: Fn(u32, f32, f32) -> bool>(
        &self,
        ray: &Ray,
        accept: &F,
    ) -> Option<RawHit> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is only set when the CPU supports AVX2 (`detect_avx2`).
            return unsafe {
                if self.stack_bound <= SMALL_STACK {
                    self.traverse_avx2::<ANY_HIT, FILTER, F, SMALL_STACK>(ray, accept)
                } else {
                    self.traverse_avx2::<ANY_HIT, FILTER, F, STACK_SIZE>(ray, accept)
                }
            };
        }
        if self.stack_bound <= SMALL_STACK {
            self.traverse_with::<ANY_HIT, FILTER, F, SMALL_STACK, false>(ray, accept)
        } else {
            self.traverse_with::<ANY_HIT, FILTER, F, STACK_SIZE, false>(ray, accept)
        }
    }

    /// The traversal compiled with AVX2 enabled, so that the 8-lane box test inlines.
    /// (Only AVX2, not FMA: the compiler never fuses separate multiplies and adds, so the
    /// triangle test keeps its rounding.)
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn traverse_avx2<
        const ANY_HIT: bool,
        const FILTER: bool,
        F: Fn(u32, f32, f32) -> bool,
        const STACK: usize,
    >(
        &self,
        ray: &Ray,
        accept: &F,
    ) -> Option<RawHit> {
        self.traverse_with::<ANY_HIT, FILTER, F, STACK, true>(ray, accept)
    }

    /// `AVX2`: test boxes with [`BoxRay::test_avx2`]; only set from [`Bvh::traverse_avx2`].
    #[inline(always)]
    fn traverse_with<
        const ANY_HIT: bool,
        const FILTER: bool,
        F: Fn(u32, f32, f32) -> bool,
        const STACK: usize,
        const AVX2: bool,
    >(
        &self,
        ray: &Ray,
        accept: &F,
    ) -> Option<RawHit> {
        let wray = WatertightRay::new(ray)?;
        let pray = PackRay::new(ray, &wray);
        let bray = BoxRay::new(ray);
        let mut t_max = ray.t_max;
        // The closest hit so far: pack, lane, t, b1, b2 (its triangle id is looked up once,
        // at the end, instead of at every closer hit).
        let mut hit: Option<RawHit> = None;
        let mut stack = Stack::<STACK>::new();
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT == 0 {
                let node = &self.nodes[cur as usize];
                let (mut mask, t_near) = bray.test::<AVX2>(node, t_max);
                if mask != 0 {
                    if PREFETCH && mask & (mask - 1) != 0 {
                        // Several children entered: ask for all of them now, so that their
                        // cache misses overlap instead of coming one after the other.
                        let mut m = mask;
                        while m != 0 {
                            let j = m.trailing_zeros() as usize;
                            m &= m - 1;
                            self.prefetch(node.child[j]);
                        }
                    }
                    if ANY_HIT || mask & (mask - 1) == 0 {
                        // One child, or any order: go down the first, stack the others.
                        let k = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        while mask != 0 {
                            let j = mask.trailing_zeros() as usize;
                            mask &= mask - 1;
                            stack.push((node.child[j], t_near[j]));
                        }
                        cur = node.child[k];
                        continue;
                    }
                    // Nearest first: sort the entered children by decreasing entry distance,
                    // stack all but the nearest.
                    let mut order = [(0u32, 0f32); WIDTH];
                    let mut n = 0;
                    while mask != 0 {
                        let j = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let e = (node.child[j], t_near[j]);
                        let mut i = n;
                        while i > 0 && order[i - 1].1 < e.1 {
                            order[i] = order[i - 1];
                            i -= 1;
                        }
                        order[i] = e;
                        n += 1;
                    }
                    stack.extend(&order[..n - 1]);
                    cur = order[n - 1].0;
                    continue;
                }
            } else {
                let first = ((cur & !LEAF_BIT) >> 2) as usize;
                for pack in first..=first + (cur & 3) as usize {
                    let p = &self.packs[pack];
                    let valid = p.valid();
                    let lanes = match pray.test(p, valid, t_max) {
                        Some(l) => l,
                        None => scalar_pack_test(&wray, p, valid, t_max),
                    };
                    if lanes.mask != 0 {
                        if let Some(k) = lanes.pick::<ANY_HIT, FILTER, F>(&p.prims, accept) {
                            let h = (pack, k, lanes.t[k], lanes.b1[k], lanes.b2[k]);
                            if ANY_HIT {
                                return Some(h);
                            }
                            t_max = h.2;
                            hit = Some(h);
                        }
                    }
                }
            }
            // Pop the next entry that can still hold a closer hit.
            loop {
                let Some((r, t)) = stack.pop() else {
                    return hit;
                };
                if ANY_HIT || t < t_max {
                    cur = r;
                    break;
                }
            }
        }
    }
}

impl Bvh {
    /// Asks the cache for the lines of a node (4) or of a leaf's first pack (a 160-byte pack
    /// at a 16-byte boundary spans up to 4); a hint, a no-op off x86-64.
    #[inline(always)]
    fn prefetch(&self, r: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let (p, last) = if r & LEAF_BIT != 0 {
                let pack = ((r & !LEAF_BIT) >> 2) as usize;
                let p = self.packs.as_ptr().wrapping_add(pack) as *const i8;
                (p, std::mem::size_of::<TriPack>() - 1)
            } else {
                let p = self.nodes.as_ptr().wrapping_add(r as usize) as *const i8;
                (p, std::mem::size_of::<WideNode>() - 1)
            };
            for off in [0, 64, 128, last] {
                // SAFETY: a prefetch never faults, whatever the address.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(off)) };
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = r;
    }

    #[inline(always)]
    fn hit(&self, (pack, lane, t, b1, b2): RawHit) -> TriangleHit {
        TriangleHit {
            t,
            prim: self.packs[pack].prims[lane],
            b1,
            b2,
        }
    }
}

/// The traversal stack of (node reference, entry distance) entries, left uninitialised: it
/// is set up for every ray, and zeroing even the small one (768 bytes) cost 63 instructions
/// and twelve cache-line writes per ray, 7% of a 10k-triangle tree's closest-hit
/// instructions (callgrind). Pushes are bounds-checked (the tree's [`stack_bound`] keeps
/// them in range; a branch that never fails is all it costs).
struct Stack<const N: usize> {
    entries: [std::mem::MaybeUninit<(u32, f32)>; N],
    /// Entries `..len` are initialised.
    len: usize,
}

impl<const N: usize> Stack<N> {
    #[inline(always)]
    fn new() -> Self {
        Stack {
            entries: [const { std::mem::MaybeUninit::uninit() }; N],
            len: 0,
        }
    }

    #[inline(always)]
    fn push(&mut self, e: (u32, f32)) {
        self.entries[self.len].write(e);
        self.len += 1;
    }

    #[inline(always)]
    fn extend(&mut self, es: &[(u32, f32)]) {
        for &e in es {
            self.push(e);
        }
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, f32)> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: entries below the old `len` were written by `push` and not popped since.
        Some(unsafe { self.entries[self.len].assume_init() })
    }
}

/// Per-ray constants of the 8-wide slab test.
struct BoxRay {
    org: [Vec4; 3],
    inv: [Vec4; 3],
    /// 1 where the direction component is negative (the near plane is the max plane).
    neg: [usize; 3],
}

impl BoxRay {
    #[inline(always)]
    fn new(ray: &Ray) -> BoxRay {
        let inv = [1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z];
        BoxRay {
            org: ray.origin.to_array().map(Vec4::splat),
            inv: inv.map(Vec4::splat),
            neg: inv.map(|i| usize::from(i < 0.0)),
        }
    }

    /// Bit `k` set when child `k` is entered before `t_max`; the entry distances (those of
    /// children not entered are unspecified). `AVX2` must only be set in code compiled with
    /// AVX2 enabled (see [`Bvh::traverse_avx2`]).
    #[inline(always)]
    fn test<const AVX2: bool>(&self, node: &WideNode, t_max: f32) -> (u32, [f32; WIDTH]) {
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
    fn test4(&self, node: &WideNode, first: usize, t_max: f32) -> (u32, Vec4) {
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
    unsafe fn test_avx2(&self, node: &WideNode, t_max: f32) -> (u32, [f32; WIDTH]) {
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
struct PackRay {
    k: [usize; 3],
    org: [Vec4; 3],
    sx: Vec4,
    sy: Vec4,
    sz: Vec4,
}

/// Lane results of a pack test.
struct Lanes {
    mask: u32,
    t: [f32; LANES],
    b1: [f32; LANES],
    b2: [f32; LANES],
}

impl Lanes {
    /// The hit a pack reports: any accepted lane for any hit, else the nearest accepted lane
    /// (ties: the lowest lane, as a sequential loop with a shrinking `t_max` would).
    #[inline(always)]
    /// `prims` is read only when `FILTER` is set.
    fn pick<const ANY_HIT: bool, const FILTER: bool, F: Fn(u32, f32, f32) -> bool>(
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
fn scalar_pack_test(wray: &WatertightRay, pack: &TriPack, valid: u32, t_max: f32) -> Lanes {
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
    fn new(ray: &Ray, w: &WatertightRay) -> PackRay {
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
    fn test(&self, pack: &TriPack, valid: u32, t_max: f32) -> Option<Lanes> {
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

    /// Children inside their parent's slot box, every stored triangle in exactly one valid
    /// lane, empty slots with empty boxes, the stack bound respected.
    /// Returns the number of leaves of more than one pack.
    fn check_structure(bvh: &Bvh, tris: &[[Vec3; 3]]) -> usize {
        let mut multi = 0;
        let mut seen = vec![0u32; tris.len()];
        let mut stack = vec![(0u32, Vec3::NEG_INFINITY, Vec3::INFINITY, 1usize)];
        assert!(bvh.stack_bound <= (WIDTH - 1) * bvh.depth());
        while let Some((r, lo, hi, depth)) = stack.pop() {
            assert!(depth <= bvh.depth());
            let inside = |p: Vec3| p.cmpge(lo).all() && p.cmple(hi).all();
            if r & LEAF_BIT != 0 {
                let first = ((r & !LEAF_BIT) >> 2) as usize;
                let packs = (r & 3) as usize + 1;
                multi += usize::from(packs > 1);
                assert!(packs <= LEAF_PACKS);
                for pack in first..first + packs {
                    let count = bvh.packs[pack].valid().count_ones() as usize;
                    for lane in 0..count {
                        let prim = bvh.packs[pack].prims[lane] as usize;
                        seen[prim] += 1;
                        let t = bvh.packs[pack].triangle(lane);
                        assert_eq!(t, tris[prim]);
                        assert!(t.iter().all(|&p| inside(p)));
                    }
                    assert!(bvh.packs[pack].prims[count..]
                        .iter()
                        .all(|&p| p == u32::MAX));
                }
                continue;
            }
            let n = &bvh.nodes[r as usize];
            for k in 0..WIDTH {
                let clo = Vec3::new(n.bounds[0][k], n.bounds[2][k], n.bounds[4][k]);
                let chi = Vec3::new(n.bounds[1][k], n.bounds[3][k], n.bounds[5][k]);
                if n.child[k] == EMPTY_CHILD {
                    assert_eq!((clo, chi), (Vec3::INFINITY, Vec3::NEG_INFINITY));
                    continue;
                }
                assert!(inside(clo) && inside(chi), "child box outside its parent's");
                if n.child[k] & LEAF_BIT == 0 {
                    assert!(n.child[k] > r, "depth-first order");
                }
                stack.push((n.child[k], clo, chi, depth + 1));
            }
        }
        for (i, t) in tris.iter().enumerate() {
            assert_eq!(seen[i], u32::from(!is_degenerate(t)), "triangle {i}");
        }
        multi
    }

    /// Degenerate triangles (the `BinaryBvh` test's set) are left out of the wide tree too:
    /// the first pass's placeholders never reach it, wherever they fall in the input.
    #[test]
    fn degenerate_triangles_are_not_stored_in_the_wide_tree() {
        let nan = f32::NAN;
        let good = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let bad = [
            [Vec3::ZERO, Vec3::ZERO, Vec3::X],
            [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            [Vec3::ZERO, Vec3::X, Vec3::new(nan, 0.0, 0.0)],
            [Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::INFINITY, 0.0)],
        ];
        for at in 0..=bad.len() {
            let mut tris = bad.to_vec();
            tris.insert(at, good);
            let bvh = Bvh::build(&tris);
            assert_eq!(bvh.triangle_count(), 5);
            assert_eq!(bvh.stored_triangle_count(), 1, "good triangle at {at}");
            assert_eq!(bvh.bounds(), (Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)));
            let down = Ray {
                origin: Vec3::new(0.25, 0.25, 1.0),
                dir: -Vec3::Z,
                t_max: f32::INFINITY,
            };
            assert_eq!(bvh.intersect(&down).map(|h| h.prim), Some(at as u32));
        }
        assert_eq!(Bvh::build(&bad).node_count(), 0);
    }

    /// The smallest subnormal halved and doubled by code that cannot be folded: itself in
    /// IEEE mode, 0 with flush-to-zero (see `flowlight_core::denormals`' own test).
    fn subnormal_round_trip() -> f32 {
        use std::hint::black_box;
        black_box(black_box(black_box(f32::from_bits(2)) * 0.5) * 2.0)
    }

    /// A ray leaving a floor at y = 0 starts at the smallest subnormal height, as
    /// `offset_ray_origin` places it: in the queries' flush-to-zero mode it still misses the
    /// floor it leaves and hits the ceiling, a hit filter sees IEEE denormals, and the
    /// thread's mode is back after every query.
    #[test]
    fn rays_from_a_subnormal_origin_run_in_the_query_mode() {
        let tris = [
            [
                Vec3::ZERO,
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 1.0),
            ],
            [
                Vec3::ZERO,
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            [Vec3::Y, Vec3::new(1.0, 1.0, 1.0), Vec3::new(1.0, 1.0, 0.0)],
            [Vec3::Y, Vec3::new(0.0, 1.0, 1.0), Vec3::new(1.0, 1.0, 1.0)],
        ];
        let bvh = Bvh::build(&tris);
        let mut rng = Rng::new(11, 0);
        for _ in 0..200 {
            let origin = Vec3::new(
                0.1 + 0.8 * rng.uniform(),
                f32::from_bits(1),
                0.1 + 0.8 * rng.uniform(),
            );
            let dir = Vec3::new(
                0.1 * (rng.uniform() - 0.5),
                1.0,
                0.1 * (rng.uniform() - 0.5),
            )
            .normalize();
            let ray = Ray {
                origin,
                dir,
                t_max: f32::INFINITY,
            };
            let h = bvh.intersect(&ray).expect("the ceiling");
            assert!(h.prim >= 2, "hit the floor it leaves: {h:?}");
            assert!((h.t * dir.y - 1.0).abs() < 1e-5, "t {}", h.t);
            assert_eq!(subnormal_round_trip(), f32::from_bits(2));
            let seen = std::cell::Cell::new(0.0f32);
            let keep_all = |_: u32, _: f32, _: f32| {
                seen.set(subnormal_round_trip());
                true
            };
            let f = bvh
                .intersect_filtered(&ray, &keep_all)
                .expect("the ceiling");
            assert_eq!((f.prim, f.t.to_bits()), (h.prim, h.t.to_bits()));
            assert_eq!(
                seen.get(),
                f32::from_bits(2),
                "the filter runs in IEEE mode"
            );
            let short = Ray { t_max: 0.5, ..ray };
            assert!(!bvh.occluded(&short) && !bvh.occluded_filtered(&short, &keep_all));
            assert!(bvh.occluded(&ray));
            assert_eq!(subnormal_round_trip(), f32::from_bits(2));
        }
    }

    #[test]
    fn structure_is_valid_and_deterministic() {
        for n in [1, 4, 5, 17, 3000, 40_000] {
            let tris = random_soup(n, n as u64);
            let bvh = Bvh::build(&tris);
            let multi = check_structure(&bvh, &tris);
            assert!(n < 3000 || multi > 0, "{n}: no leaf of two packs");
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            assert!(
                one.install(|| Bvh::build(&tris)) == bvh,
                "{n}: thread count matters"
            );
        }
        // Pathological centroids (2^-k): the SAH depth cap keeps the stack in bounds.
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
        check_structure(&Bvh::build(&tris), &tris);
    }

    /// The parallel build lays out its parts once at the end ([`Part::write`]); its nodes
    /// and packs are those of the whole tree built on one thread ([`build_sequential`]),
    /// entry for entry, with forks two and three levels deep (up to 150k triangles), and
    /// with a leaf among a fork's children (three triangles far from the rest).
    #[test]
    fn parallel_layout_is_the_sequential_layout() {
        let far = |t: [Vec3; 3]| t.map(|v| v * 0.01 + Vec3::splat(100.0));
        // (triangles, whether three of them lie far from the rest)
        let mut cases: Vec<(Vec<[Vec3; 3]>, bool)> = [100, 5_000, 40_000, 150_000]
            .into_iter()
            .map(|n| (random_soup(n, 7 + n as u64), false))
            .collect();
        let mut with_far_leaf = random_soup(6_000, 3);
        with_far_leaf.extend(random_soup(3, 4).into_iter().map(far));
        cases.push((with_far_leaf, true));
        for (tris, far_leaf) in cases {
            let n = tris.len();
            let mut refs: Vec<PrimRef> = tris
                .iter()
                .enumerate()
                .map(|(i, t)| PrimRef::new(t, i as u32))
                .collect();
            let root = Child::root(&refs);
            let mut seq_refs = refs.clone();
            let parallel = build_tree(&mut refs, root);
            let mut sequential = Subtree::default();
            build_sequential(&mut seq_refs, 0, root, &mut sequential);
            assert!(parallel.nodes.len() > 1 + n / 4096, "{n}: too few nodes");
            if far_leaf {
                let root = &parallel.nodes[0];
                assert!(
                    root.child
                        .iter()
                        .any(|&r| r != EMPTY_CHILD && r & LEAF_BIT != 0),
                    "the far triangles are a leaf of the root fork"
                );
            }
            assert!(parallel.nodes == sequential.nodes, "{n}: nodes differ");
            assert!(parallel.leaves == sequential.leaves, "{n}: packs differ");
            assert!(
                refs.iter()
                    .map(PrimRef::index)
                    .eq(seq_refs.iter().map(PrimRef::index)),
                "{n}: triangle order differs"
            );
        }
    }

    /// The indexed build is the build over the gathered triangles, degenerate ones included.
    #[test]
    fn indexed_build_is_the_gathered_build() {
        let mut rng = Rng::new(5, 5);
        let mut positions: Vec<Vec3> = (0..2000)
            .map(|_| Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 10.0)
            .collect();
        positions.push(positions[0]);
        let mut indices: Vec<[u32; 3]> = (0..5000)
            .map(|_| [0, 1, 2].map(|_| (rng.uniform() * 2000.0) as u32 % 2000))
            .collect();
        indices.push([0, 2000, 7]); // two vertices at the same place: degenerate
        indices.push([3, 3, 4]);
        let tris: Vec<[Vec3; 3]> = indices
            .iter()
            .map(|t| t.map(|k| positions[k as usize]))
            .collect();
        let bvh = Bvh::build_indexed(&positions, &indices);
        assert!(bvh == Bvh::build(&tris));
        assert_eq!(bvh.triangle_count(), indices.len());
        assert!(bvh.stored_triangle_count() <= indices.len() - 2);
    }

    /// Every lane of the pack test is bit for bit the scalar watertight test, on random rays
    /// and on axis-aligned rays through vertices (edge functions exactly 0: the scalar path).
    #[test]
    fn pack_test_is_the_scalar_test_lane_for_lane() {
        let mut rng = Rng::new(5, 5);
        let grid = |rng: &mut Rng| Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
        let (mut fast, mut slow, mut hits) = (0, 0, 0);
        for k in 0..20_000 {
            let count = 1 + k % 4;
            let tris: Vec<[Vec3; 3]> = (0..count)
                .map(|_| {
                    if k % 3 == 0 {
                        // Quarter-integer lattice triangles: exact zeros are common.
                        [0; 3].map(|_| (grid(&mut rng) * 8.0).floor() * 0.25)
                    } else {
                        [0; 3].map(|_| grid(&mut rng) * 2.0 - 1.0)
                    }
                })
                .filter(|t| !is_degenerate(t))
                .collect();
            if tris.is_empty() {
                continue;
            }
            let pack = TriPack::new(&tris, [0; LANES]);
            let valid = (1u32 << tris.len()) - 1;
            let (origin, dir) = if k % 3 == 0 {
                let v = tris[0][k % 3];
                let axis = k % 3;
                let mut o = v;
                o[axis] -= 3.0;
                let mut d = Vec3::ZERO;
                d[axis] = 1.0;
                (o, d)
            } else {
                let o = grid(&mut rng) * 6.0 - 3.0;
                (o, grid(&mut rng) * 2.0 - o)
            };
            let t_max = if k % 5 == 0 { 2.5 } else { f32::INFINITY };
            let ray = Ray::new(origin, dir, t_max);
            let w = WatertightRay::new(&ray).unwrap();
            let lanes = match PackRay::new(&ray, &w).test(&pack, valid, t_max) {
                Some(l) => {
                    fast += 1;
                    l
                }
                None => {
                    slow += 1;
                    scalar_pack_test(&w, &pack, valid, t_max)
                }
            };
            for (lane, tri) in tris.iter().enumerate() {
                let want = w.intersect(tri, t_max);
                let got = (lanes.mask & (1 << lane) != 0)
                    .then(|| (lanes.t[lane], lanes.b1[lane], lanes.b2[lane]));
                assert_eq!(
                    got.map(|(t, b1, b2)| [t, b1, b2].map(f32::to_bits)),
                    want.map(|(t, b1, b2)| [t, b1, b2].map(f32::to_bits)),
                    "lane {lane} of {tris:?} for {ray:?}"
                );
                hits += want.is_some() as usize;
            }
            assert_eq!(lanes.mask & !valid, 0, "an unused lane reported a hit");
        }
        assert!(
            fast > 10_000 && slow > 1000 && hits > 3000,
            "{fast} {slow} {hits}"
        );
    }

    /// `a` and `b` give the same closest hit and the same any-hit answer on `n` rays between
    /// random points around the soup; returns how many rays hit.
    fn assert_same_hits(a: &Bvh, b: &Bvh, seed: u64, n: usize) -> usize {
        let mut rng = Rng::new(seed, seed);
        let mut u = || rng.uniform();
        let mut hits = 0;
        for _ in 0..n {
            let o = Vec3::new(u(), u(), u()) * 14.0 - 2.0;
            let ray = Ray::new(o, Vec3::new(u(), u(), u()) * 10.0 - o, f32::INFINITY);
            let h = a.intersect(&ray);
            assert_eq!(h, b.intersect(&ray));
            assert_eq!(a.occluded(&ray), b.occluded(&ray));
            hits += h.is_some() as usize;
        }
        hits
    }

    /// The AVX2 and the SSE traversal give the same hits (where the CPU has AVX2).
    #[test]
    fn avx2_and_sse_agree() {
        let tris = random_soup(20_000, 78);
        let bvh = Bvh::build(&tris);
        assert_eq!(bvh.avx2, detect_avx2());
        let sse = Bvh {
            avx2: false,
            ..bvh.clone()
        };
        let hits = assert_same_hits(&bvh, &sse, 4, 20_000);
        assert!(hits > 5000, "{hits}");
    }

    /// The uninitialised stack pops what was pushed, last first, and reports empty.
    #[test]
    fn stack_is_last_in_first_out() {
        let mut s = Stack::<4>::new();
        assert_eq!(s.pop(), None);
        s.push((1, 0.5));
        s.extend(&[(2, 1.5), (3, f32::INFINITY)]);
        assert_eq!(s.pop(), Some((3, f32::INFINITY)));
        s.push((4, -0.0));
        let popped: Vec<_> = std::iter::from_fn(|| s.pop()).collect();
        assert_eq!(popped, [(4, -0.0), (2, 1.5), (1, 0.5)]);
        assert_eq!(s.pop(), None);
    }

    /// A push past the stack's capacity panics rather than writing past it.
    #[test]
    #[should_panic(expected = "index out of bounds")]
    fn stack_push_past_capacity_panics() {
        let mut s = Stack::<2>::new();
        s.extend(&[(1, 1.0), (2, 2.0), (3, 3.0)]);
    }

    /// The small-stack and the large-stack traversal give the same hits.
    #[test]
    fn both_stack_sizes_agree() {
        let tris = random_soup(5000, 77);
        let small = Bvh::build(&tris);
        assert!(small.stack_bound <= SMALL_STACK, "{}", small.stack_bound);
        let large = Bvh {
            stack_bound: STACK_SIZE,
            ..small.clone()
        };
        let hits = assert_same_hits(&small, &large, 3, 5000);
        assert!(hits > 1000, "{hits}");
    }

    #[test]
    fn box_test_is_the_binary_slab_test() {
        use crate::build::Node;
        use crate::traverse::SlabRay;
        let mut rng = Rng::new(9, 9);
        let mut u = || rng.uniform();
        for k in 0..20_000 {
            let mut node = WideNode::EMPTY;
            let mut boxes = Vec::new();
            for slot in 0..(1 + k % WIDTH) {
                let a = Vec3::new(u(), u(), u()) * 4.0 - 2.0;
                let b = a + Vec3::new(u(), u(), u()) * if k % 7 == 0 { 0.0 } else { 1.0 };
                let b = Aabb {
                    min: a.into(),
                    max: b.into(),
                };
                node.set(slot, &b, slot as u32 + 1);
                boxes.push(b);
            }
            // Origins on box planes with zero direction components now and then.
            let mut o = Vec3::new(u(), u(), u()) * 6.0 - 3.0;
            let mut d = Vec3::new(u(), u(), u()) * 2.0 - 1.0;
            if k % 5 == 0 {
                let axis = k % 3;
                o[axis] = boxes[0].min[axis];
                d[axis] = if k % 2 == 0 { 0.0 } else { -0.0 };
            }
            let t_max = if k % 3 == 0 { u() * 4.0 } else { f32::INFINITY };
            let ray = Ray::new(o, d, t_max);
            let (mask, t0) = BoxRay::new(&ray).test::<false>(&node, t_max);
            if detect_avx2() {
                assert_eq!(
                    (mask, t0.map(f32::to_bits)),
                    {
                        let (m, t) = BoxRay::new(&ray).test::<true>(&node, t_max);
                        (m, t.map(f32::to_bits))
                    },
                    "AVX2 and SSE box tests differ"
                );
            }
            let slab = SlabRay::new(&ray);
            for (slot, b) in boxes.iter().enumerate() {
                let want = slab.entry(&Node::interior(b, 0), t_max);
                assert_eq!(mask & (1 << slot) != 0, want.is_some(), "{b:?} {ray:?}");
                if let Some(e) = want {
                    assert_eq!(t0[slot].max(0.0), e);
                }
            }
            assert_eq!(mask >> boxes.len(), 0, "an empty slot was entered");
        }
    }
}
