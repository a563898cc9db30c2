//! The meshes and rays the BVH examples share with `crates/flowlight-host/benches/rays.rs`:
//! closed lumpy spheres as triangle soups, and incoherent rays around them.

use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use glam::Vec3;

/// A lumpy closed sphere of about `n` triangles (the ray benchmark's mesh).
pub fn lumpy_sphere(n: usize) -> Vec<[Vec3; 3]> {
    let nv = ((n as f64 / 4.0).sqrt().round() as usize).max(4);
    let nu = 2 * nv;
    let r = |th: f32, ph: f32| {
        1.0 + 0.15 * (5.0 * th).sin() * (7.0 * ph).cos()
            + 0.05 * (23.0 * th).cos() * (19.0 * ph).sin()
    };
    let mut pos = vec![Vec3::new(0.0, 0.0, r(0.0, 0.0))];
    for i in 1..nv {
        let th = std::f32::consts::PI * i as f32 / nv as f32;
        for j in 0..nu {
            let ph = std::f32::consts::TAU * j as f32 / nu as f32;
            let d = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
            pos.push(d * r(th, ph));
        }
    }
    pos.push(Vec3::new(0.0, 0.0, -r(std::f32::consts::PI, 0.0)));
    let south = pos.len() - 1;
    let at = |i: usize, j: usize| 1 + (i - 1) * nu + j % nu;
    let mut tris = Vec::new();
    for j in 0..nu {
        tris.push([0, at(1, j), at(1, j + 1)]);
        tris.push([south, at(nv - 1, j + 1), at(nv - 1, j)]);
    }
    for i in 1..nv - 1 {
        for j in 0..nu {
            tris.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            tris.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    tris.iter().map(|t| t.map(|i| pos[i])).collect()
}

/// `n` incoherent rays: origins uniform in the cube [-1.5, 1.5]³, directions uniform on the
/// sphere, `t_max = ∞` (the ray benchmark's).
pub fn rays(n: usize) -> Vec<Ray> {
    let mut rng = Rng::new(7, 1);
    (0..n)
        .map(|_| {
            let o = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 3.0 - Vec3::splat(1.5);
            let z = 1.0 - 2.0 * rng.uniform();
            let a = std::f32::consts::TAU * rng.uniform();
            let s = (1.0 - z * z).max(0.0).sqrt();
            Ray {
                origin: o,
                dir: Vec3::new(s * a.cos(), s * a.sin(), z),
                t_max: f32::INFINITY,
            }
        })
        .collect()
}
