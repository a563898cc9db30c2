//! Shared helpers for the integration tests: meshes, random rays, brute force.
#![allow(dead_code)]

use std::collections::HashMap;

use flowlight_bvh::{intersect_triangle, is_degenerate, WatertightRay};
use flowlight_core::geometry::{Ray, TriangleHit};
use flowlight_core::rng::Rng;
use glam::Vec3;

pub type Tri = [Vec3; 3];

/// Triangles with their indices, degenerate ones removed, for [`brute_force_fast`].
pub fn valid_triangles(tris: &[Tri]) -> Vec<(u32, Tri)> {
    tris.iter()
        .enumerate()
        .filter(|(_, t)| !is_degenerate(t))
        .map(|(i, t)| (i as u32, *t))
        .collect()
}

/// Same as [`brute_force`] with the per-ray constants and degeneracy tests hoisted out.
pub fn brute_force_fast(valid: &[(u32, Tri)], ray: &Ray) -> Option<TriangleHit> {
    let w = WatertightRay::new(ray)?;
    let mut t_max = ray.t_max;
    let mut best = None;
    for (prim, t) in valid {
        if let Some((t, b1, b2)) = w.intersect(t, t_max) {
            t_max = t;
            best = Some(TriangleHit {
                t,
                prim: *prim,
                b1,
                b2,
            });
        }
    }
    best
}

/// Closest hit by testing every triangle with the same watertight test the BVH uses.
pub fn brute_force(tris: &[Tri], ray: &Ray) -> Option<TriangleHit> {
    let mut r = *ray;
    let mut best = None;
    for (i, t) in tris.iter().enumerate() {
        if let Some(h) = intersect_triangle(&r, t, i as u32) {
            r.t_max = h.t;
            best = Some(h);
        }
    }
    best
}

pub fn random_vec(rng: &mut Rng) -> Vec3 {
    Vec3::new(rng.uniform(), rng.uniform(), rng.uniform())
}

pub fn random_dir(rng: &mut Rng) -> Vec3 {
    let z = 1.0 - 2.0 * rng.uniform();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * rng.uniform();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Random triangles of size ~`size` with centres in `[0, extent]³`.
pub fn random_soup(n: usize, extent: f32, size: f32, seed: u64) -> Vec<Tri> {
    let mut rng = Rng::new(seed, 1);
    (0..n)
        .map(|_| {
            let c = random_vec(&mut rng) * extent;
            let mut v = || c + (random_vec(&mut rng) - 0.5) * size;
            [v(), v(), v()]
        })
        .collect()
}

/// Closed icosphere of radius 1: vertices shared bit-exactly between neighbouring triangles.
pub fn icosphere(subdivisions: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut verts: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, verts: &mut Vec<Vec3>| {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                verts.push(((verts[a as usize] + verts[b as usize]) * 0.5).normalize());
                verts.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for &[a, b, c] in &faces {
            let ab = mid(a, b, &mut verts);
            let bc = mid(b, c, &mut verts);
            let ca = mid(c, a, &mut verts);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (verts, faces)
}

/// Closed cube `[-1, 1]³`, each face split into `n × n` quads of two triangles. Vertices lie on
/// the lattice `-1 + 2i/n` and are shared bit-exactly.
pub fn grid_cube(n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut verts = Vec::new();
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let coord = |i: u32| -1.0 + 2.0 * i as f32 / n as f32;
    let mut vid = |l: [u32; 3], verts: &mut Vec<Vec3>| {
        *index.entry(l).or_insert_with(|| {
            verts.push(Vec3::new(coord(l[0]), coord(l[1]), coord(l[2])));
            verts.len() as u32 - 1
        })
    };
    let mut faces = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, n] {
            for i in 0..n {
                for j in 0..n {
                    let corner = |di: u32, dj: u32| {
                        let mut l = [0u32; 3];
                        l[axis] = side;
                        l[u] = i + di;
                        l[v] = j + dj;
                        l
                    };
                    let q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                    let q = q.map(|l| vid(l, &mut verts));
                    // Outward winding: counter-clockwise seen from outside.
                    if side == n {
                        faces.push([q[0], q[1], q[2]]);
                        faces.push([q[0], q[2], q[3]]);
                    } else {
                        faces.push([q[0], q[2], q[1]]);
                        faces.push([q[0], q[3], q[2]]);
                    }
                }
            }
        }
    }
    (verts, faces)
}

pub fn soup(verts: &[Vec3], faces: &[[u32; 3]]) -> Vec<Tri> {
    faces.iter().map(|f| f.map(|i| verts[i as usize])).collect()
}

/// Undirected edges of an indexed mesh, each once.
pub fn edges(faces: &[[u32; 3]]) -> Vec<(u32, u32)> {
    let mut e: Vec<(u32, u32)> = faces
        .iter()
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}
