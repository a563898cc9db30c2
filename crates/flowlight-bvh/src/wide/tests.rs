//! Tests of the 8-wide tree: structure, determinism, SIMD tests against the scalar ones.

use super::build::*;
use super::simd::*;
use super::traversal::*;
use super::*;
use crate::build::PrimRef;
use crate::triangle::{is_degenerate, WatertightRay};
use flowlight_core::geometry::Ray;
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
        assert!(
            parallel.nodes[..] == sequential.nodes[..],
            "{n}: nodes differ"
        );
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

/// A tree whose packs fill more than a huge page lies on its own advised mappings (Linux),
/// and answers every ray as the same tree copied to the heap does.
#[test]
fn a_large_tree_on_huge_pages_answers_as_on_the_heap() {
    let tris = random_soup(60_000, 79);
    let bvh = Bvh::build(&tris);
    assert!(bvh.packs.len() * std::mem::size_of::<TriPack>() >= 2 << 20);
    assert_eq!(bvh.packs.advised(), cfg!(target_os = "linux"));
    let heap = Bvh {
        nodes: HugeArray::on_heap(&bvh.nodes),
        packs: HugeArray::on_heap(&bvh.packs),
        ..bvh.clone()
    };
    assert!(!heap.packs.advised() && heap == bvh);
    let hits = assert_same_hits(&bvh, &heap, 5, 20_000);
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
