//! Pure-Rust bounding volume hierarchy over triangle soups.
//!
//! * **Build**: binned surface-area-heuristic (SAH) construction in the style of Wald,
//!   "On fast Construction of SAH-based Bounding Volume Hierarchies" (IEEE RT 2007) and
//!   pbrt-v4 §7.3 (`BVHAggregate::buildRecursive`): [`SAH_BINS`] bins over the centroid bounds
//!   on each of the three axes, leaves of at most [`MAX_LEAF_SIZE`] triangles, and an object
//!   median split when the SAH cannot separate the triangles (all centroids equal, non-finite
//!   costs). The upper levels of the tree are built in parallel with `rayon::join`; the result
//!   does not depend on the thread schedule (same input, same tree).
//! * **Layout**: [`Bvh`] is 8-wide (module `wide`): each node is widened to up to eight
//!   children by repeatedly splitting its largest child with the same SAH, weighted by leaf
//!   packs rather than triangles (Wald, Benthin & Boulos 2008; Embree's BVH8), stored as
//!   256-byte nodes with the children's boxes in SoA order, and each leaf is a pack of up to
//!   four triangles stored SoA with their ids; both arrays lie on 2 MiB pages where Linux
//!   offers them (`wide::huge_pages`), so a large tree's scattered loads do not also miss the
//!   TLB. [`BinaryBvh`], the binary tree of the plain-SAH
//!   splits flattened depth-first into 32-byte nodes (pbrt-v4's `LinearBVHNode`), is kept as
//!   the reference the wide tree is tested and benchmarked against, and as the top level of
//!   [`TwoLevelBvh`].
//! * **Traversal**: iterative with a fixed-size stack. [`Bvh`] tests the eight child boxes of
//!   a node at once — one AVX pass on x86-64 CPUs with AVX2 (detected at build time, the
//!   traversal compiled for it through `#[target_feature]`), else two 4-lane passes of
//!   glam's `Vec4` (SSE2, NEON or scalar), same bits either way — visits entered children
//!   nearest first for the closest hit, and tests a leaf's four triangles at once with a
//!   4-lane version of the watertight test that gives each lane bit for bit the scalar
//!   result; [`BinaryBvh`] visits
//!   the nearer child first according to the sign of the ray direction on the node's split
//!   axis. The ray/box slab test uses the
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
//! Module map: `build` (the binned-SAH build and [`BinaryBvh`]), `traverse` (its slab test
//! and queries), `wide` ([`Bvh`]: widening, node and pack layout, SIMD box and triangle
//! tests, traversal), `triangle` (the watertight ray/triangle test) and `instanced`
//! ([`TwoLevelBvh`]). The hits and filters ([`TriangleHit`], [`InstanceHit`],
//! [`HitFilter`], [`InstanceHitFilter`]) live in `flowlight_core::geometry`, shared with the
//! Embree intersector.
//!
//! [`TriangleHit`]: flowlight_core::geometry::TriangleHit
//! [`InstanceHit`]: flowlight_core::geometry::InstanceHit
//! [`HitFilter`]: flowlight_core::geometry::HitFilter
//! [`InstanceHitFilter`]: flowlight_core::geometry::InstanceHitFilter
//!
//! Instancing: [`TwoLevelBvh`] is a hierarchy over instances (affine transforms) of per-mesh
//! [`Bvh`]s; see the `instanced` module.
//!
//! Degenerate triangles (zero area, repeated vertices, collinear vertices, NaN or infinite
//! coordinates) are left out of the tree and never reported as hits.

mod build;
mod instanced;
mod traverse;
mod triangle;
mod wide;

pub use build::{BinaryBvh, MAX_LEAF_SIZE, SAH_BINS};
pub use instanced::{Instance, TwoLevelBvh};
pub use triangle::{intersect_triangle, is_degenerate, WatertightRay};
pub use wide::{Bvh, WIDTH};
