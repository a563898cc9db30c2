//! The 4-wide [`Bvh`] against the binary [`BinaryBvh`] and brute force: same closest hit (same
//! `t`, same triangle or a tie at the same `t`), same any-hit answer, filtered queries that
//! find the closest *accepted* hit, on random soups large enough for the parallel build,
//! closed meshes, a pile of identical triangles, and scenes at tiny and huge scales.

use crate::common;

use common::*;
use flowlight_bvh::{intersect_triangle, BinaryBvh, Bvh};
use flowlight_core::geometry::{Ray, TriangleHit};
use flowlight_core::rng::Rng;
use glam::Vec3;
use rayon::prelude::*;

/// Rays from random points of a box around the triangles: half in random directions, half
/// aimed at random points of random triangles; a quarter with a finite `t_max`.
fn rays_at(tris: &[Tri], n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed, 11);
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for p in tris.iter().flatten() {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let pad = (hi - lo) * 0.2;
    let (lo, ext) = (lo - pad, hi - lo + 2.0 * pad);
    (0..n)
        .map(|k| {
            let o = lo + random_vec(&mut rng) * ext;
            let dir = if k % 2 == 0 {
                random_dir(&mut rng)
            } else {
                let t = tris[(rng.next_u32() as usize) % tris.len()];
                let (u, v) = (rng.uniform() * 0.5, rng.uniform() * 0.5);
                t[0] * (1.0 - u - v) + t[1] * u + t[2] * v - o
            };
            let t_max = if k % 4 == 1 {
                rng.uniform() * ext.length()
            } else {
                f32::INFINITY
            };
            Ray::new(o, dir, t_max)
        })
        .collect()
}

/// Brute-force closest hit among the triangles `accept` keeps.
fn brute_force_filtered(
    tris: &[Tri],
    ray: &Ray,
    accept: &dyn Fn(u32, f32, f32) -> bool,
) -> Option<TriangleHit> {
    let mut r = *ray;
    let mut best = None;
    for (i, t) in tris.iter().enumerate() {
        if let Some(h) = intersect_triangle(&r, t, i as u32) {
            if accept(h.prim, h.b1, h.b2) {
                r.t_max = h.t;
                best = Some(h);
            }
        }
    }
    best
}

/// `got` is `want` or, at the same `t`, another triangle that the ray hits at that `t` on its
/// own (a tie).
fn assert_same_hit(tris: &[Tri], ray: &Ray, got: Option<TriangleHit>, want: Option<TriangleHit>) {
    match (got, want) {
        (None, None) => {}
        (Some(g), Some(w)) if g.prim == w.prim => assert_eq!(g, w, "for {ray:?}"),
        (Some(g), Some(w)) => {
            assert!(
                (g.t - w.t).abs() <= 1e-5 * w.t.abs(),
                "{g:?} vs {w:?} for {ray:?}"
            );
            let alone = intersect_triangle(ray, &tris[g.prim as usize], g.prim);
            assert_eq!(alone, Some(g), "tie not confirmed for {ray:?}");
        }
        (g, w) => panic!("hit/miss differs: wide {g:?}, reference {w:?} for {ray:?}"),
    }
}

/// Wide vs binary on every ray, and (every `brute_every`-th ray) vs brute force, unfiltered
/// and with a filter that rejects every third triangle and the upper half of barycentric
/// `b1`. Returns the number of rays that hit.
fn check(tris: &[Tri], rays: &[Ray], brute_every: usize) -> usize {
    let wide = Bvh::build(tris);
    let binary = BinaryBvh::build(tris);
    assert_eq!(wide.stored_triangle_count(), binary.stored_triangle_count());
    assert_eq!(wide.bounds(), binary.bounds());
    let accept = |prim: u32, b1: f32, _b2: f32| !prim.is_multiple_of(3) && b1 < 0.5;
    rays.par_iter()
        .enumerate()
        .map(|(k, ray)| {
            let got = wide.intersect(ray);
            let want = binary.intersect(ray);
            assert_same_hit(tris, ray, got, want);
            assert_eq!(wide.occluded(ray), want.is_some(), "occluded for {ray:?}");
            let got_f = wide.intersect_filtered(ray, &accept);
            assert_same_hit(tris, ray, got_f, binary.intersect_filtered(ray, &accept));
            assert_eq!(
                wide.occluded_filtered(ray, &accept),
                got_f.is_some(),
                "filtered occluded for {ray:?}"
            );
            if let Some(h) = got_f {
                assert!(accept(h.prim, h.b1, h.b2), "rejected hit {h:?} reported");
            }
            if k % brute_every == 0 {
                assert_same_hit(tris, ray, got, brute_force(tris, ray));
                assert_same_hit(tris, ray, got_f, brute_force_filtered(tris, ray, &accept));
            }
            want.is_some() as usize
        })
        .sum()
}

#[test]
fn wide_agrees_with_binary_and_brute_force_on_a_large_soup() {
    // 30k triangles: the root's subtrees are built by the parallel path.
    let tris = random_soup(30_000, 20.0, 0.8, 21);
    let rays = rays_at(&tris, 40_000, 22);
    let hits = check(&tris, &rays, 200);
    assert!(hits > rays.len() / 3, "too few hits ({hits})");
}

#[test]
fn wide_agrees_on_closed_meshes_with_shared_edges() {
    let (v, f) = icosphere(4);
    let sphere = soup(&v, &f);
    let rays = rays_at(&sphere, 20_000, 23);
    let hits = check(&sphere, &rays, 50);
    assert!(hits > rays.len() / 3, "too few hits ({hits})");
    // Axis-aligned rays through the lattice vertices of a tessellated cube: every such ray
    // meets edges and vertices shared by several triangles.
    let (v, f) = grid_cube(10);
    let cube = soup(&v, &f);
    let bvh = Bvh::build(&cube);
    let mut n = 0;
    for i in 0..=10 {
        for j in 0..=10 {
            for (axis, sign) in [(0, 1.0), (1, -1.0), (2, 1.0)] {
                let (a, b) = (i as f32 / 10.0 * 2.0 - 1.0, j as f32 / 10.0 * 2.0 - 1.0);
                let mut o = [0.0; 3];
                o[(axis + 1) % 3] = a;
                o[(axis + 2) % 3] = b;
                o[axis] = -3.0 * sign;
                let mut d = [0.0; 3];
                d[axis] = sign;
                let ray = Ray::new(Vec3::from(o), Vec3::from(d), f32::INFINITY);
                let h = bvh.intersect(&ray).expect("a lattice ray must not leak");
                assert!((h.t - 2.0).abs() < 1e-5, "{h:?} for {ray:?}");
                assert!(bvh.occluded(&ray));
                n += 1;
            }
        }
    }
    assert_eq!(n, 11 * 11 * 3);
}

#[test]
fn identical_triangles_and_extreme_scales() {
    // 1000 copies of one triangle: centroids coincide, every hit is a tie.
    let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let pile = vec![t; 1000];
    let bvh = Bvh::build(&pile);
    let ray = Ray::new(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z, f32::INFINITY);
    let h = bvh.intersect(&ray).unwrap();
    assert_eq!(h.t, 2.0);
    assert_eq!((h.b1, h.b2), (0.25, 0.25));
    // The filter sees candidates until it accepts one: accept only triangle 617.
    let only = |p: u32, _: f32, _: f32| p == 617;
    assert_eq!(bvh.intersect_filtered(&ray, &only).unwrap().prim, 617);
    assert!(bvh.occluded_filtered(&ray, &only));
    assert!(!bvh.occluded_filtered(&ray, &|_, _, _| false));

    // The same soup at 1e-8 and 1e8 (the degeneracy test squares the edges' cross product, a
    // product of four coordinates, which must stay within f32's range): the hits scale with
    // it.
    let base = random_soup(3000, 10.0, 1.5, 31);
    let rays = rays_at(&base, 3000, 32);
    for scale in [1e-8f32, 1e8] {
        let tris: Vec<Tri> = base.iter().map(|t| t.map(|p| p * scale)).collect();
        let scaled: Vec<Ray> = rays
            .iter()
            .map(|r| Ray::new(r.origin * scale, r.dir, r.t_max * scale))
            .collect();
        let hits = check(&tris, &scaled, 10);
        assert!(hits > scaled.len() / 4, "scale {scale}: {hits} hits");
    }
}

#[test]
fn tree_shape_is_wide() {
    let tris = random_soup(20_000, 10.0, 0.5, 41);
    let wide = Bvh::build(&tris);
    // 20k triangles in packs of at most 4; every node but the root is some node's child, so
    // (nodes + packs − 1) / nodes counts the children per node, a leaf of two packs twice:
    // 2 for a binary tree, at most 8 children here, so at most 16 (fewer near the leaves,
    // where a node of 5–8 triangles has only two leaves to hold them).
    let packs = wide.leaf_count();
    assert!((5000..10_000).contains(&packs), "{packs} packs");
    let nodes = wide.node_count();
    let per_node = (nodes + packs - 1) as f64 / nodes as f64;
    assert!(
        per_node > 3.0 && per_node <= 16.0,
        "{per_node} packs and nodes per node ({nodes} nodes, {packs} packs)"
    );
    let binary = BinaryBvh::build(&tris);
    assert!(
        3 * wide.depth() <= binary.depth() + 3,
        "wide depth {}, binary depth {}",
        wide.depth(),
        binary.depth()
    );
    // Small inputs: a single pack below the root.
    let one = Bvh::build(&tris[..3]);
    assert_eq!((one.node_count(), one.leaf_count(), one.depth()), (1, 1, 2));
    assert_eq!(Bvh::build(&[]).depth(), 0);
}
