//! The 8-wide BVH behind [`Bvh`]: build, node and triangle layout, SIMD traversal.
//!
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
//!
//! Both arrays are [`HugeArray`]s: on 2 MiB pages where the system offers them, so that a
//! large tree's scattered loads do not also miss the TLB (module `huge_pages`).
//!
//! The build is in [`build`](mod@self::build), the queries in [`traversal`], their 8-lane
//! box test and 4-lane triangle test in [`simd`].

use crate::build::{Aabb, MAX_LEAF_SIZE};
use glam::{Vec3, Vec4};
use huge_pages::HugeArray;

mod build;
mod huge_pages;
mod simd;
#[cfg(test)]
mod tests;
mod traversal;

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
    /// Depth first, root at 0; empty when there is nothing to intersect. Nodes and packs
    /// lie on huge pages where the system offers them ([`HugeArray`]).
    nodes: HugeArray<WideNode>,
    packs: HugeArray<TriPack>,
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
impl Bvh {
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
}
