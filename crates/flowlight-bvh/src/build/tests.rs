//! Tests of the binned SAH build: binning, sweeps and partitions against their plain
//! formulations, and the structure of the trees.

use super::binning::*;
use super::partition::*;
use super::*;
use crate::traverse::STACK_SIZE;
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use glam::Vec3A;

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
                assert!(Vec3::from(cn.min).cmpge(lo).all() && Vec3::from(cn.max).cmple(hi).all());
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
