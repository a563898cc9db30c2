//! The BVH must report exactly what a brute-force loop over all triangles reports, with the
//! same watertight test: same hit/miss, same `t`, same triangle (or, on ties such as shared
//! edges, another triangle at the same `t`), and `occluded` agreeing with the closest hit.

use crate::common;

use common::*;
use flowlight_bvh::{intersect_triangle, is_degenerate, Bvh};
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use glam::Vec3;
use rayon::prelude::*;

const RAYS: usize = 100_000;

/// A mix of random rays: random directions, rays aimed at points on random triangles, and
/// axis-aligned rays (other components ±0) through triangle vertices, so that origins lie
/// exactly on node bounding planes. A third of the rays get a finite `t_max`.
fn random_rays(tris: &[Tri], n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed, 7);
    let finite: Vec<&Tri> = tris
        .iter()
        .filter(|t| t.iter().all(|p| p.is_finite()))
        .collect();
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for t in &finite {
        for p in t.iter() {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    let pad = (hi - lo) * 0.25;
    let (lo, ext) = (lo - pad, hi - lo + 2.0 * pad);
    (0..n)
        .map(|k| {
            let mut o = lo + random_vec(&mut rng) * ext;
            let tri = finite[(rng.next_u32() as usize) % finite.len()];
            let dir = match k % 10 {
                0..=3 => random_dir(&mut rng),
                4..=7 => {
                    let (u, v) = (rng.uniform(), rng.uniform());
                    let (u, v) = if u + v > 1.0 {
                        (1.0 - u, 1.0 - v)
                    } else {
                        (u, v)
                    };
                    let target = tri[0] * (1.0 - u - v) + tri[1] * u + tri[2] * v;
                    let d = target - o;
                    if k % 2 == 0 {
                        d
                    } else {
                        d.normalize()
                    }
                }
                _ => {
                    let axis = (rng.next_u32() % 3) as usize;
                    let vertex = tri[(rng.next_u32() % 3) as usize];
                    let mut d = Vec3::ZERO;
                    for a in 0..3 {
                        if a == axis {
                            d[a] = if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
                        } else {
                            d[a] = if rng.uniform() < 0.5 { 0.0 } else { -0.0 };
                            // Pass exactly through a vertex (half of the time).
                            if k % 20 < 10 {
                                o[a] = vertex[a];
                            }
                        }
                    }
                    d
                }
            };
            let t_max = if rng.uniform() < 0.33 {
                rng.uniform() * ext.length()
            } else {
                f32::INFINITY
            };
            Ray::new(o, dir, t_max)
        })
        .collect()
}

fn rel_diff(a: f32, b: f32) -> f32 {
    (a - b).abs() / a.abs().max(b.abs()).max(f32::MIN_POSITIVE)
}

/// Compares the BVH with brute force on every ray; returns the number of hits.
fn check_agreement(tris: &[Tri], rays: &[Ray]) -> usize {
    let bvh = Bvh::build(tris);
    assert_eq!(bvh.triangle_count(), tris.len());
    let valid = valid_triangles(tris);
    rays.par_iter()
        .enumerate()
        .map(|(k, ray)| {
            let got = bvh.intersect(ray);
            let want = brute_force_fast(&valid, ray);
            if k % 64 == 0 {
                // The plain per-triangle function must agree with the hoisted loop.
                assert_eq!(brute_force(tris, ray), want);
            }
            match (got, want) {
                (None, None) => {}
                (Some(g), Some(w)) => {
                    assert!(
                        rel_diff(g.t, w.t) <= 1e-5,
                        "t differs: {g:?} vs {w:?} for {ray:?}"
                    );
                    assert!(
                        g.t > 0.0 && g.t < ray.t_max,
                        "{g:?} outside (0, t_max) for {ray:?}"
                    );
                    assert!(
                        !is_degenerate(&tris[g.prim as usize]),
                        "hit a degenerate triangle: {g:?}"
                    );
                    if g.prim == w.prim {
                        assert_eq!(g, w, "same triangle, different hit for {ray:?}");
                    } else {
                        // A tie (shared edge or vertex, coincident triangles): the BVH's
                        // triangle on its own must give the same t.
                        let alone = intersect_triangle(ray, &tris[g.prim as usize], g.prim)
                            .unwrap_or_else(|| panic!("BVH hit {g:?} not confirmed for {ray:?}"));
                        assert_eq!(alone, g);
                    }
                }
                (g, w) => panic!("hit/miss differs: bvh {g:?}, brute force {w:?} for {ray:?}"),
            }
            assert_eq!(
                bvh.occluded(ray),
                want.is_some(),
                "occluded disagrees for {ray:?}"
            );
            want.is_some() as usize
        })
        .sum()
}

#[test]
fn agrees_with_brute_force_on_random_soup() {
    let tris = random_soup(2000, 10.0, 1.5, 1);
    let rays = random_rays(&tris, RAYS, 2);
    let hits = check_agreement(&tris, &rays);
    assert!(
        hits > RAYS / 3,
        "too few hits ({hits}) for a meaningful test"
    );
}

/// ~30% degenerate triangles: repeated vertices, a single point, exactly collinear vertices,
/// NaN and infinite coordinates; plus needles that are thin but not degenerate.
fn degenerate_mesh(n: usize, seed: u64) -> Vec<Tri> {
    let mut tris = random_soup(n, 10.0, 1.5, seed);
    let mut rng = Rng::new(seed, 3);
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    for (i, t) in tris.iter_mut().enumerate() {
        let [a, b, c] = *t;
        *t = match (i % 10, (i / 10) % 8) {
            (0..=2, 0) => [a, a, b],
            (0..=2, 1) => [b, a, a],
            (0..=2, 2) => [c, c, c],
            (0..=2, 3) => {
                let s = 0.1 + rng.uniform();
                [
                    a,
                    a + Vec3::new(s, 0.0, 0.0),
                    a + Vec3::new(2.0 * s, 0.0, 0.0),
                ]
            }
            (0..=2, 4) => {
                // Exactly collinear along a diagonal: quarter-integer coordinates.
                let p = (a * 4.0).round() * 0.25;
                [p, p + Vec3::splat(0.25), p + Vec3::splat(0.75)]
            }
            (0..=2, 5) => [a, Vec3::new(b.x, nan, b.z), c],
            (0..=2, 6) => [a, b, Vec3::new(c.x, c.y, inf)],
            (0..=2, 7) => [Vec3::splat(nan), b, Vec3::new(-inf, 0.0, 0.0)],
            (3, _) => [a, b, a + (b - a) * 0.5 + (c - a) * 1e-6], // needle, not degenerate
            _ => *t,
        };
    }
    tris
}

#[test]
fn agrees_with_brute_force_on_degenerate_mesh() {
    let tris = degenerate_mesh(2000, 5);
    let degenerate = tris.iter().filter(|t| is_degenerate(t)).count();
    assert!(
        degenerate * 10 >= tris.len() * 3 - 10,
        "{degenerate} degenerate triangles"
    );
    let bvh = Bvh::build(&tris);
    assert_eq!(bvh.stored_triangle_count(), tris.len() - degenerate);
    let (lo, hi) = bvh.bounds();
    assert!(lo.is_finite() && hi.is_finite());
    let rays = random_rays(&tris, RAYS, 6);
    let hits = check_agreement(&tris, &rays);
    assert!(hits > RAYS / 4, "too few hits ({hits})");
}

#[test]
fn degenerate_triangles_never_hit() {
    // Rays aimed straight at points of degenerate triangles only.
    let tris = degenerate_mesh(500, 8);
    let bvh = Bvh::build(&tris);
    let mut rng = Rng::new(4, 4);
    for (i, t) in tris.iter().enumerate().filter(|(_, t)| is_degenerate(t)) {
        for _ in 0..20 {
            let target = t[0] * 0.5 + t[1] * 0.25 + t[2] * 0.25;
            let o = target + random_dir(&mut rng) * 3.0;
            let ray = Ray::new(o, target - o, f32::INFINITY);
            assert!(
                intersect_triangle(&ray, t, i as u32).is_none(),
                "degenerate {t:?} hit"
            );
            if let Some(h) = bvh.intersect(&ray) {
                assert!(!is_degenerate(&tris[h.prim as usize]));
            }
        }
    }
}

#[test]
fn agrees_with_brute_force_on_closed_meshes() {
    let (v, f) = icosphere(3);
    let sphere = soup(&v, &f);
    assert_eq!(sphere.len(), 1280);
    let rays = random_rays(&sphere, RAYS, 11);
    let hits = check_agreement(&sphere, &rays);
    assert!(hits > RAYS / 4, "too few hits ({hits})");

    // A finely tessellated cube: axis-aligned rays through lattice vertices hit shared edges
    // and vertices, where ties between triangles are the rule.
    let (v, f) = grid_cube(12);
    let cube = soup(&v, &f);
    let rays = random_rays(&cube, RAYS / 4, 12);
    let hits = check_agreement(&cube, &rays);
    assert!(hits > RAYS / 16, "too few hits ({hits})");
}
