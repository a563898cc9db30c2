//! Builds a BVH over 1M random triangles and traces random rays; prints timings, then the
//! same for the binary `BinaryBvh` in alternating rounds (one thread) as ratios.
//!
//! `cargo run --release -p flowlight-bvh --example build_1m [triangles] [rays] [rounds]`
//! Not a pass/fail benchmark: numbers depend on the machine.

use std::time::Instant;

use flowlight_bvh::{BinaryBvh, Bvh};
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

    let rounds: usize = args.next().map_or(3, |s| s.parse().expect("rounds")).max(1);
    let mut ratios = [Vec::new(), Vec::new(), Vec::new()];
    for _ in 0..rounds {
        let time = |f: &dyn Fn() -> usize| {
            let t = Instant::now();
            std::hint::black_box(f());
            t.elapsed().as_secs_f64()
        };
        let (wb, bb) = (
            time(&|| Bvh::build(&tris).node_count()),
            time(&|| BinaryBvh::build(&tris).node_count()),
        );
        let bin = BinaryBvh::build(&tris);
        let wc = time(&|| rays.iter().filter(|r| bvh.intersect(r).is_some()).count());
        let bc = time(&|| rays.iter().filter(|r| bin.intersect(r).is_some()).count());
        let wa = time(&|| rays.iter().filter(|r| bvh.occluded(r)).count());
        let ba = time(&|| rays.iter().filter(|r| bin.occluded(r)).count());
        ratios[0].push(bb / wb);
        ratios[1].push(bc / wc);
        ratios[2].push(ba / wa);
    }
    for (name, r) in ["build", "closest", "any hit"].iter().zip(&mut ratios) {
        r.sort_by(f64::total_cmp);
        println!(
            "wide speed-up over binary, {name}: median {:.2} (range {:.2}–{:.2})",
            r[r.len() / 2],
            r[0],
            r[r.len() - 1]
        );
    }
}
