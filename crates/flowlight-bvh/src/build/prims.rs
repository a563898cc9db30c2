//! Boxes and primitive references: a [`PrimRef`] is a triangle's box with its index in the
//! spare lane (32 bytes), its centroid recomputed when needed; [`scan`] gathers the bounds
//! and centroid bounds of a range, in parallel when large.

use super::{PARALLEL_SCAN_CHUNK, PARALLEL_SCAN_THRESHOLD};
use glam::{BVec4A, Vec3, Vec3A, Vec4};
use rayon::prelude::*;

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
    pub(super) fn centroid_on(&self, axis: usize) -> f32 {
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
