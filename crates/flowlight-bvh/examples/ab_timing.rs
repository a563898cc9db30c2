//! Build and incoherent-ray timings of [`Bvh`] alone, for comparing two versions of this
//! crate on a shared machine: each figure is the *minimum* over many short rounds (the
//! round least disturbed by other processes) and the median; rays on one thread, builds on
//! one thread and on rayon's default pool. Same meshes (closed
//! lumpy spheres) and rays (origins in a cube around the mesh, directions uniform on the
//! sphere) as `crates/flowlight-host/benches/rays.rs`, without Embree.
//!
//! `cargo run --release -p flowlight-bvh --example ab_timing [sizes] [rays] [rounds]`, e.g.
//! `... ab_timing 10000,100000,1000000 200000 9`. Not a pass/fail benchmark.

use std::time::Instant;

use flowlight_bvh::Bvh;
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use glam::Vec3;

/// A lumpy closed sphere of about `n` triangles (the ray benchmark's mesh).
fn lumpy_sphere(n: usize) -> Vec<[Vec3; 3]> {
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

fn rays(n: usize) -> Vec<Ray> {
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

fn main() {
    let mut args = std::env::args().skip(1);
    let sizes: Vec<usize> = args.next().map_or(vec![10_000, 100_000, 1_000_000], |s| {
        s.split(',').map(|x| x.parse().expect("size")).collect()
    });
    let n_rays: usize = args.next().map_or(200_000, |s| s.parse().expect("rays"));
    let rounds: usize = args.next().map_or(9, |s| s.parse().expect("rounds"));
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let rays = rays(n_rays);
    for n in sizes {
        let tris = lumpy_sphere(n);
        let bvh = Bvh::build(&tris);
        let (mut build, mut build_all, mut closest, mut any) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut hits = 0;
        for _ in 0..rounds {
            let t = Instant::now();
            std::hint::black_box(one.install(|| Bvh::build(&tris)));
            build.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            std::hint::black_box(Bvh::build(&tris));
            build_all.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            hits = rays.iter().filter(|r| bvh.intersect(r).is_some()).count();
            closest.push(n_rays as f64 / t.elapsed().as_secs_f64() / 1e6);
            let t = Instant::now();
            std::hint::black_box(rays.iter().filter(|r| bvh.occluded(r)).count());
            any.push(n_rays as f64 / t.elapsed().as_secs_f64() / 1e6);
        }
        for v in [&mut build, &mut build_all, &mut closest, &mut any] {
            v.sort_by(f64::total_cmp);
        }
        println!(
            "{} tris, {} nodes, {} packs, {hits} hits | build 1 thread: min {:.4} s, median {:.4} s | build {} threads: min {:.4} s, median {:.4} s | closest: max {:.3}, median {:.3} Mrays/s | any hit: max {:.3}, median {:.3} Mrays/s",
            tris.len(),
            bvh.node_count(),
            bvh.leaf_count(),
            build[0],
            build[rounds / 2],
            rayon::current_num_threads(),
            build_all[0],
            build_all[rounds / 2],
            closest[rounds - 1],
            closest[rounds / 2],
            any[rounds - 1],
            any[rounds / 2],
        );
    }
}
