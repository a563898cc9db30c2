//! Watertightness, grazing and axis-aligned rays, ray ranges, empty input.

use crate::common;

use common::*;
use flowlight_bvh::{intersect_triangle, Bvh};
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use glam::Vec3;

/// Shoots rays from `origins` (inside the closed mesh) exactly at every vertex, every edge
/// midpoint and random points on every edge; all must hit, near the aimed-at point.
fn assert_no_leaks(verts: &[Vec3], faces: &[[u32; 3]], origins: &[Vec3], seed: u64) -> usize {
    let tris = soup(verts, faces);
    let bvh = Bvh::build(&tris);
    let mut rng = Rng::new(seed, 5);
    let mut targets: Vec<Vec3> = verts.to_vec();
    for (a, b) in edges(faces) {
        let (a, b) = (verts[a as usize], verts[b as usize]);
        targets.push(a * 0.5 + b * 0.5);
        for _ in 0..2 {
            let s = rng.uniform();
            targets.push(a + (b - a) * s);
        }
    }
    let mut rays = 0;
    for &o in origins {
        for &target in &targets {
            let d = target - o;
            for dir in [d, d.normalize()] {
                let ray = Ray::new(o, dir, f32::INFINITY);
                let hit = bvh
                    .intersect(&ray)
                    .unwrap_or_else(|| panic!("leak: {ray:?} aimed at {target}"));
                assert!(bvh.occluded(&ray), "occluded leak: {ray:?}");
                let dist = (ray.at(hit.t) - target).length();
                assert!(
                    dist < 1e-4,
                    "hit {dist} away from the aimed-at point, {ray:?}"
                );
                rays += 1;
            }
            // The per-triangle test alone is watertight too (no BVH involved).
            let ray = Ray::new(o, d, f32::INFINITY);
            assert!(
                brute_force(&tris, &ray).is_some(),
                "brute-force leak: {ray:?}"
            );
        }
    }
    rays
}

#[test]
fn no_leaks_through_icosphere_edges_and_vertices() {
    let (v, f) = icosphere(3);
    let origins = [
        Vec3::ZERO,
        Vec3::new(0.3, -0.2, 0.1),
        Vec3::new(-0.5, 0.4, 0.35),
        Vec3::new(1e-3, 0.7, -1e-3),
    ];
    let rays = assert_no_leaks(&v, &f, &origins, 1);
    assert!(rays > 50_000);
}

#[test]
fn no_leaks_through_cube_edges_and_vertices() {
    let (v, f) = grid_cube(8);
    // The centre and lattice points: rays to lattice vertices then have zero components
    // and origins on the planes of node bounds.
    let origins = [
        Vec3::ZERO,
        Vec3::new(0.25, -0.5, 0.75),
        Vec3::new(-0.3, 0.61, 0.05),
        Vec3::splat(-0.75),
    ];
    let rays = assert_no_leaks(&v, &f, &origins, 2);
    assert!(rays > 10_000);
}

#[test]
fn axis_aligned_rays_through_cube_lattice() {
    // Rays along ±x/±y/±z (other components +0 or -0) from every interior lattice point of a
    // tessellated cube: they hit the faces exactly at lattice vertices and edges.
    let n = 8;
    let (v, f) = grid_cube(n);
    let bvh = Bvh::build(&soup(&v, &f));
    let coord = |i: u32| -1.0 + 2.0 * i as f32 / n as f32;
    let mut count = 0;
    for i in 1..n {
        for j in 1..n {
            for k in 1..n {
                let o = Vec3::new(coord(i), coord(j), coord(k));
                for axis in 0..3 {
                    for sign in [1.0f32, -1.0] {
                        for zero in [0.0f32, -0.0] {
                            let mut d = Vec3::splat(zero);
                            d[axis] = sign;
                            let ray = Ray::new(o, d, f32::INFINITY);
                            let hit = bvh
                                .intersect(&ray)
                                .unwrap_or_else(|| panic!("leak: {ray:?}"));
                            let expected = 1.0 - sign * o[axis];
                            assert_eq!(hit.t, expected, "{ray:?}");
                            assert!(bvh.occluded(&ray));
                            // Just short of the wall: nothing.
                            let short = Ray::new(o, d, expected * 0.999);
                            assert!(bvh.intersect(&short).is_none() && !bvh.occluded(&short));
                            count += 1;
                        }
                    }
                }
            }
        }
    }
    assert_eq!(count, 7 * 7 * 7 * 12);
}

/// Two triangles covering the square `[-1, 1]²` in the plane z = 0.
fn ground() -> Vec<Tri> {
    let (a, b, c, d) = (
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    );
    vec![[a, b, c], [a, c, d]]
}

#[test]
fn grazing_rays_hit_where_expected() {
    let tris = ground();
    let bvh = Bvh::build(&tris);
    let mut rng = Rng::new(3, 3);
    for k in 0..2000 {
        // Angles down to 1e-6 rad above the plane.
        let theta = 10f32.powf(-1.0 - 5.0 * rng.uniform());
        let phi = std::f32::consts::TAU * rng.uniform();
        let dir = Vec3::new(
            theta.cos() * phi.cos(),
            theta.cos() * phi.sin(),
            -theta.sin(),
        );
        let target = Vec3::new(rng.uniform() * 1.8 - 0.9, rng.uniform() * 1.8 - 0.9, 0.0);
        let dist = 0.1 + rng.uniform();
        let o = target - dir * dist;
        let ray = Ray::new(o, dir, f32::INFINITY);
        // Exact answer in double precision for the rounded ray.
        let t_exact = -(o.z as f64) / dir.z as f64;
        let hit = bvh
            .intersect(&ray)
            .unwrap_or_else(|| panic!("grazing miss {k}: {ray:?}"));
        assert!(
            ((hit.t as f64 - t_exact) / t_exact).abs() < 1e-5,
            "{hit:?} vs {t_exact}"
        );
        assert_eq!(
            Some(hit),
            brute_force(&tris, &ray)
                .filter(|h| h.prim == hit.prim)
                .or(Some(hit))
        );
        // Barycentrics reconstruct the hit point.
        let [p0, p1, p2] = tris[hit.prim as usize];
        let p = p0 * (1.0 - hit.b1 - hit.b2) + p1 * hit.b1 + p2 * hit.b2;
        assert!(
            (p - ray.at(hit.t)).length() < 1e-4 * hit.t.max(1.0),
            "{p} vs {}",
            ray.at(hit.t)
        );
        // The same ray going up, or parallel to the plane just above it, misses.
        let up = Ray::new(o, Vec3::new(dir.x, dir.y, -dir.z), f32::INFINITY);
        assert!(bvh.intersect(&up).is_none() && !bvh.occluded(&up));
        let parallel = Ray::new(o, Vec3::new(dir.x, dir.y, 0.0), f32::INFINITY);
        assert!(bvh.intersect(&parallel).is_none());
    }
}

#[test]
fn rays_in_the_plane_of_a_triangle_do_not_hit_it() {
    let tris = ground();
    let bvh = Bvh::build(&tris);
    for dir in [
        Vec3::X,
        -Vec3::X,
        Vec3::Y,
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(1.0, 0.3, -0.0),
    ] {
        for o in [
            Vec3::new(-2.0, 0.1, 0.0),
            Vec3::new(-2.0, -2.0, 0.0),
            Vec3::ZERO,
        ] {
            let ray = Ray::new(o, dir, f32::INFINITY);
            assert!(bvh.intersect(&ray).is_none(), "{ray:?}");
            assert!(!bvh.occluded(&ray), "{ray:?}");
        }
    }
}

#[test]
fn axis_aligned_rays_with_signed_zeros() {
    // A unit triangle in x = 1; rays along +x with ±0 in y and z, some exactly along its edges.
    let tri = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(1.0, 0.0, 1.0),
    ];
    let bvh = Bvh::build(&[tri]);
    for (y, z, expect) in [
        (0.25, 0.25, true),
        (0.0, 0.5, true), // on an edge, and on the box's y plane
        (0.5, 0.0, true),
        (0.0, 0.0, true), // at a vertex
        (1.0, 0.0, true),
        (0.5, 0.5, true), // on the hypotenuse
        (0.6, 0.6, false),
        (-0.1, 0.5, false),
    ] {
        for (dy, dz) in [(0.0, 0.0), (-0.0, 0.0), (0.0, -0.0), (-0.0, -0.0)] {
            let ray = Ray::new(Vec3::new(-1.0, y, z), Vec3::new(1.0, dy, dz), f32::INFINITY);
            let hit = bvh.intersect(&ray);
            assert_eq!(hit.is_some(), expect, "{ray:?}");
            assert_eq!(bvh.occluded(&ray), expect, "{ray:?}");
            assert_eq!(hit, intersect_triangle(&ray, &tri, 0));
            if let Some(h) = hit {
                assert_eq!(h.t, 2.0);
                assert_eq!(h.prim, 0);
            }
            // Going the other way (-x with signed zeros) from the far side.
            let back = Ray::new(
                Vec3::new(3.0, y, z),
                Vec3::new(-1.0, -dy, dz),
                f32::INFINITY,
            );
            assert_eq!(
                bvh.intersect(&back).map(|h| h.t),
                expect.then_some(2.0),
                "{back:?}"
            );
        }
    }
}

#[test]
fn hits_respect_the_open_ray_interval() {
    let tri = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    let bvh = Bvh::build(&[tri]);
    let o = Vec3::new(0.25, 0.25, 1.0);
    let down = |t_max| Ray::new(o, -Vec3::Z, t_max);
    assert_eq!(bvh.intersect(&down(f32::INFINITY)).unwrap().t, 1.0);
    assert_eq!(bvh.intersect(&down(1.0001)).unwrap().t, 1.0);
    // t_max is exclusive.
    assert!(bvh.intersect(&down(1.0)).is_none());
    assert!(!bvh.occluded(&down(1.0)));
    assert!(bvh.occluded(&down(1.0001)));
    // Behind the origin, at the origin, non-positive or NaN t_max: nothing.
    assert!(bvh
        .intersect(&Ray::new(o, Vec3::Z, f32::INFINITY))
        .is_none());
    assert!(bvh
        .intersect(&Ray::new(
            Vec3::new(0.25, 0.25, 0.0),
            -Vec3::Z,
            f32::INFINITY
        ))
        .is_none());
    assert!(bvh.intersect(&down(0.0)).is_none() && bvh.intersect(&down(-1.0)).is_none());
    assert!(bvh.intersect(&down(f32::NAN)).is_none() && !bvh.occluded(&down(f32::NAN)));
    // Invalid rays: zero or NaN direction, NaN origin.
    assert!(bvh
        .intersect(&Ray::new(o, Vec3::ZERO, f32::INFINITY))
        .is_none());
    assert!(bvh
        .intersect(&Ray::new(o, Vec3::new(f32::NAN, 0.0, -1.0), f32::INFINITY))
        .is_none());
    assert!(bvh
        .intersect(&Ray::new(Vec3::splat(f32::NAN), -Vec3::Z, f32::INFINITY))
        .is_none());
    // Barycentrics: p = (1-b1-b2) p0 + b1 p1 + b2 p2.
    let h = bvh
        .intersect(&Ray::new(
            Vec3::new(0.125, 0.5, 2.0),
            -Vec3::Z,
            f32::INFINITY,
        ))
        .unwrap();
    assert_eq!((h.t, h.b1, h.b2), (2.0, 0.125, 0.5));
}

#[test]
fn closest_of_many_overlapping_layers() {
    // Layers at z = 0..99 crossing the ray, in shuffled order; the closest must be found from
    // either side.
    let mut rng = Rng::new(9, 9);
    let mut zs: Vec<u32> = (0..100).collect();
    for i in (1..zs.len()).rev() {
        zs.swap(i, rng.next_u32() as usize % (i + 1));
    }
    let tris: Vec<Tri> = zs
        .iter()
        .map(|&z| {
            let z = z as f32;
            [
                Vec3::new(-1.0, -1.0, z),
                Vec3::new(2.0, -1.0, z),
                Vec3::new(-1.0, 2.0, z),
            ]
        })
        .collect();
    let bvh = Bvh::build(&tris);
    let up = bvh
        .intersect(&Ray::new(Vec3::new(0.1, 0.1, -0.5), Vec3::Z, f32::INFINITY))
        .unwrap();
    assert_eq!((up.t, tris[up.prim as usize][0].z), (0.5, 0.0));
    let down = bvh
        .intersect(&Ray::new(
            Vec3::new(0.1, 0.1, 150.0),
            -Vec3::Z,
            f32::INFINITY,
        ))
        .unwrap();
    assert_eq!((down.t, tris[down.prim as usize][0].z), (51.0, 99.0));
    let mid = bvh
        .intersect(&Ray::new(
            Vec3::new(0.1, 0.1, 42.5),
            -Vec3::Z,
            f32::INFINITY,
        ))
        .unwrap();
    assert_eq!((mid.t, tris[mid.prim as usize][0].z), (0.5, 42.0));
}

#[test]
fn empty_input_never_hits() {
    for bvh in [
        Bvh::build(&[]),
        Bvh::build(&[[Vec3::ZERO, Vec3::ZERO, Vec3::X]]),
    ] {
        assert_eq!(bvh.node_count(), 0);
        assert_eq!(bvh.stored_triangle_count(), 0);
        let (lo, hi) = bvh.bounds();
        assert!(lo.cmpgt(hi).all());
        let mut rng = Rng::new(1, 1);
        for _ in 0..100 {
            let ray = Ray::new(random_vec(&mut rng), random_dir(&mut rng), f32::INFINITY);
            assert!(bvh.intersect(&ray).is_none());
            assert!(!bvh.occluded(&ray));
        }
    }
    assert_eq!(Bvh::build(&[]).triangle_count(), 0);
}

#[test]
fn large_coordinates_build_and_trace() {
    // Coordinates near f32::MAX must not overflow the centroid or the SAH into NaN.
    let big = f32::MAX / 4.0;
    let tris = vec![
        [
            Vec3::new(-big, -big, 1.0),
            Vec3::new(big, -big, 1.0),
            Vec3::new(-big, big, 1.0),
        ],
        [
            Vec3::new(-1.0, -1.0, 2.0),
            Vec3::new(1.0, -1.0, 2.0),
            Vec3::new(-1.0, 1.0, 2.0),
        ],
        [
            Vec3::new(big, big, 3.0),
            Vec3::new(big * 0.5, big, 3.0),
            Vec3::new(big, big * 0.5, 3.0),
        ],
    ];
    let bvh = Bvh::build(&tris);
    let (lo, hi) = bvh.bounds();
    assert!(lo.is_finite() && hi.is_finite());
    let hit = bvh
        .intersect(&Ray::new(
            Vec3::new(-0.5, -0.5, 5.0),
            -Vec3::Z,
            f32::INFINITY,
        ))
        .unwrap();
    assert_eq!((hit.prim, hit.t), (1, 3.0));
}

#[test]
fn reported_t_is_conservatively_positive() {
    // Origins on the triangle (up to rounding) and directions from steep to grazing: whenever a
    // hit is reported, the exact plane distance of the rounded ray (in f64) must be positive,
    // i.e. the t bound never lets a hit behind the origin through.
    let mut rng = Rng::new(21, 21);
    let mut hits = 0;
    let mut checked = 0;
    for _ in 0..2000 {
        let scale = 10f32.powf(rng.uniform() * 8.0 - 4.0);
        let offset = (random_vec(&mut rng) - 0.5) * scale * 100.0;
        let tri = [0, 1, 2].map(|_| offset + (random_vec(&mut rng) - 0.5) * scale);
        let [p0, p1, p2] = tri.map(|p| p.as_dvec3());
        let n = (p1 - p0).cross(p2 - p0).normalize();
        for _ in 0..50 {
            let (u, v) = (rng.uniform(), rng.uniform());
            let (u, v) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            let o = tri[0] * (1.0 - u - v) + tri[1] * u + tri[2] * v;
            let mut d = random_dir(&mut rng);
            if rng.uniform() < 0.5 {
                // Nearly in the plane: remove most of the normal component.
                let nf = n.as_vec3();
                d = (d - nf * d.dot(nf) * (1.0 - 10f32.powf(-6.0 * rng.uniform()))).normalize();
            }
            let ray = Ray::new(o, d, f32::INFINITY);
            let t_exact = n.dot(p0 - o.as_dvec3()) / n.dot(d.as_dvec3());
            checked += 1;
            if let Some(h) = intersect_triangle(&ray, &tri, 0) {
                hits += 1;
                assert!(
                    t_exact > 0.0,
                    "hit at t = {} but the exact t is {t_exact}: {ray:?} {tri:?}",
                    h.t
                );
            }
        }
    }
    assert_eq!(checked, 100_000);
    // Some rays whose origin rounded to below the surface do hit (legitimately); not too many.
    assert!(hits < checked / 4, "{hits} self-hits");
}

#[test]
fn edge_functions_that_round_to_zero_are_resolved_exactly() {
    // Ray along +z from the origin (no shear, so the sheared coordinates are the vertex
    // coordinates). The edge p1 → p2 passes within an ulp or so of the ray: its single
    // precision edge function often rounds to exactly 0 although the exact value is not, and
    // the hit must then follow the exact sign (Woop et al. 2013, §3.3: recompute in f64,
    // where products of f32 values are exact).
    let mut rng = Rng::new(33, 33);
    let exact = |a: Vec3, b: Vec3| (a.x as f64) * (b.y as f64) - (a.y as f64) * (b.x as f64);
    let mut rounded_to_zero = 0;
    for _ in 0..20_000 {
        let p1 = Vec3::new(0.5 + rng.uniform() * 0.5, 0.5 + rng.uniform() * 0.5, 1.0);
        let k = 0.5 + rng.uniform() * 1.5;
        let mut p2 = Vec3::new(-p1.x * k, -p1.y * k, 1.0);
        let ulps = (rng.next_u32() % 5) as i32 - 2;
        p2.x = f32::from_bits((p2.x.to_bits() as i32 + ulps) as u32);
        let side = if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
        let p0 = Vec3::new(p1.y * side, -p1.x * side, 1.0);
        let tri = [p0, p1, p2];
        let e = [exact(p1, p2), exact(p2, p0), exact(p0, p1)];
        if p1.x * p2.y - p1.y * p2.x == 0.0 && e[0] != 0.0 {
            rounded_to_zero += 1;
        }
        let inside = e.iter().all(|&v| v >= 0.0) || e.iter().all(|&v| v <= 0.0);
        let ray = Ray::new(Vec3::ZERO, Vec3::Z, f32::INFINITY);
        let hit = intersect_triangle(&ray, &tri, 0);
        assert_eq!(hit.is_some(), inside, "{tri:?}, exact edge functions {e:?}");
        assert_eq!(Bvh::build(&[tri]).intersect(&ray), hit);
    }
    assert!(
        rounded_to_zero > 100,
        "only {rounded_to_zero} edge functions rounded to 0"
    );
}
