//! Build and incoherent-ray timings of [`Bvh`] alone, for comparing two versions of this
//! crate on a shared machine: each figure is the *minimum* over many short rounds (the
//! round least disturbed by other processes) and the median; rays on one thread, builds on
//! one thread and on rayon's default pool. Same meshes (closed
//! lumpy spheres) and rays (origins in a cube around the mesh, directions uniform on the
//! sphere) as `crates/flowlight-host/benches/rays.rs`, without Embree.
//!
//! `cargo run --release -p flowlight-bvh --example ab_timing [sizes] [rays] [rounds]`, e.g.
//! `... ab_timing 10000,100000,1000000 200000 9`. Not a pass/fail benchmark.

mod common;

use common::{lumpy_sphere, rays};
use std::time::Instant;

use flowlight_bvh::Bvh;

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
