//! Builds a BVH over 1M random triangles and traces random rays; prints timings.
//!
//! `cargo run --release -p flowlight-bvh --example build_1m [triangles] [rays]`
//! Not a pass/fail benchmark: numbers depend on the machine.

use std::time::Instant;

use flowlight_bvh::Bvh;
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use glam::Vec3;
use rayon::prelude::*;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args
        .next()
        .map_or(1_000_000, |s| s.parse().expect("triangle count"));
    let n_rays: usize = args
        .next()
        .map_or(1_000_000, |s| s.parse().expect("ray count"));

    let mut rng = Rng::new(1, 1);
    let mut v = || Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
    // Small triangles scattered in a unit cube (edge ~ 2 / cbrt(n)).
    let size = 2.0 / (n as f32).cbrt();
    let tris: Vec<[Vec3; 3]> = (0..n)
        .map(|_| {
            let c = v();
            [
                c + (v() - 0.5) * size,
                c + (v() - 0.5) * size,
                c + (v() - 0.5) * size,
            ]
        })
        .collect();

    let threads = rayon::current_num_threads();
    let t = Instant::now();
    let bvh = Bvh::build(&tris);
    let build = t.elapsed();
    println!(
        "build: {n} triangles, {} nodes, depth {}, {:.3} s ({threads} threads)",
        bvh.node_count(),
        bvh.depth(),
        build.as_secs_f64()
    );
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let t = Instant::now();
    let bvh1 = one.install(|| Bvh::build(&tris));
    println!("build (1 thread): {:.3} s", t.elapsed().as_secs_f64());
    assert!(bvh1 == bvh, "build must not depend on the thread count");

    // Rays from random points in a slightly larger cube towards random points in the cube.
    let rays: Vec<Ray> = (0..n_rays)
        .map(|_| {
            let o = v() * 1.5 - 0.25;
            Ray::new(o, (v() - o).normalize(), f32::INFINITY)
        })
        .collect();
    let t = Instant::now();
    let hits = rays.iter().filter(|r| bvh.intersect(r).is_some()).count();
    let s = t.elapsed().as_secs_f64();
    println!(
        "intersect, 1 thread: {:.2} Mrays/s ({hits} hits)",
        n_rays as f64 / s / 1e6
    );
    let t = Instant::now();
    let hits = rays
        .par_iter()
        .filter(|r| bvh.intersect(r).is_some())
        .count();
    let s = t.elapsed().as_secs_f64();
    println!(
        "intersect, {threads} threads: {:.2} Mrays/s ({hits} hits)",
        n_rays as f64 / s / 1e6
    );
    let t = Instant::now();
    let occluded = rays.iter().filter(|r| bvh.occluded(r)).count();
    let s = t.elapsed().as_secs_f64();
    println!(
        "occluded, 1 thread: {:.2} Mrays/s ({occluded} occluded)",
        n_rays as f64 / s / 1e6
    );
    assert_eq!(hits, occluded);
}
