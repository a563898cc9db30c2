//! Closest-hit and any-hit queries over the 8-wide tree.
//!
//! # Traversal
//!
//! Iterative with a stack of (node, entry distance). Closest hit visits the
//! entered children nearest first (entry distances sorted) and skips popped entries whose
//! entry distance is no longer below `t_max`; any hit returns at the first accepted hit.
//! When a node enters several children, all of them (node lines, or a leaf's first pack)
//! are prefetched at once, so that their cache misses overlap rather than come one after
//! the other as the children are visited (x86-64 `prefetcht0`; measured +7–25% at 1M
//! triangles, neutral at 10k–100k).
//!
//! # Hit filters
//!
//! Candidates of a pack are offered to the filter nearest first; the
//! first accepted one is the pack's closest accepted hit, rejected ones leave `t_max` as
//! it is.
//!
//! # Floating-point mode
//!
//! Queries run with flush-to-zero and denormals-are-zero set
//! (`Bvh::traverse`), as Embree's do; hit filters run in the thread's own mode.

use super::simd::{scalar_pack_test, BoxRay, PackRay};
use super::{Bvh, RawHit, TriPack, WideNode, LEAF_BIT, PREFETCH, SMALL_STACK, STACK_SIZE, WIDTH};
use crate::triangle::WatertightRay;
use flowlight_core::denormals::{with_denormals_flushed, with_denormals_kept};
use flowlight_core::geometry::{HitFilter, Ray, TriangleHit};

impl Bvh {
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
pub(super) struct Stack<const N: usize> {
    entries: [std::mem::MaybeUninit<(u32, f32)>; N],
    /// Entries `..len` are initialised.
    len: usize,
}

impl<const N: usize> Stack<N> {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Stack {
            entries: [const { std::mem::MaybeUninit::uninit() }; N],
            len: 0,
        }
    }

    #[inline(always)]
    pub(super) fn push(&mut self, e: (u32, f32)) {
        self.entries[self.len].write(e);
        self.len += 1;
    }

    #[inline(always)]
    pub(super) fn extend(&mut self, es: &[(u32, f32)]) {
        for &e in es {
            self.push(e);
        }
    }

    #[inline(always)]
    pub(super) fn pop(&mut self) -> Option<(u32, f32)> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: entries below the old `len` were written by `push` and not popped since.
        Some(unsafe { self.entries[self.len].assume_init() })
    }
}
