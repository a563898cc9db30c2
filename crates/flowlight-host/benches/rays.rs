//! Ray benchmark (not a test): incoherent closest-hit and any-hit throughput and build time
//! of the Embree and BVH intersectors on closed meshes of ~10k, ~100k and ~1M triangles, with
//! 1 and 2 threads. Prints a Markdown table (docs/performance.md holds the last one).
//!
//! `cargo bench -p flowlight-host --bench rays` (`FLOWLIGHT_BENCH_RAYS=N` rays per run,
//! default 1M; `FLOWLIGHT_BENCH_SIZES=10000,100000` to pick meshes).

use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use flowlight_host::intersector::{BvhIntersector, EmbreeIntersector, Intersector};
use flowlight_scene::Scene;
use glam::Vec3;
use std::time::Instant;

/// A lumpy closed sphere (latitude/longitude grid with poles) of about `n` triangles.
fn lumpy_sphere(n: usize) -> Scene {
    let nv = ((n as f64 / 4.0).sqrt().round() as usize).max(4); // rings
    let nu = 2 * nv; // segments: 2·nu·(nv−1) ≈ n triangles
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
    let south = (pos.len() - 1) as u32;
    let at = |i: usize, j: usize| (1 + (i - 1) * nu + j % nu) as u32;
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
    Scene {
        positions: pos,
        triangles: tris,
        ..Default::default()
    }
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

/// Mrays/s of `f` over `rays` on `threads` threads.
fn throughput(rays: &[Ray], threads: usize, f: &(dyn Fn(&Ray) -> bool + Sync)) -> f64 {
    let start = Instant::now();
    let chunk = rays.len().div_ceil(threads);
    let hits: usize = std::thread::scope(|s| {
        let hs: Vec<_> = rays
            .chunks(chunk)
            .map(|c| s.spawn(move || c.iter().filter(|r| f(r)).count()))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).sum()
    });
    std::hint::black_box(hits);
    rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6
}

fn main() {
    let nrays: usize = std::env::var("FLOWLIGHT_BENCH_RAYS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let sizes: Vec<usize> = std::env::var("FLOWLIGHT_BENCH_SIZES")
        .ok()
        .map(|s| s.split(',').map(|x| x.trim().parse().unwrap()).collect())
        .unwrap_or(vec![10_000, 100_000, 1_000_000]);
    let rays = rays(nrays);
    match flowlight_embree::device() {
        Ok(d) => eprintln!("Embree {} from {}", d.version_string(), d.library),
        Err(e) => eprintln!("no Embree: {e}"),
    }
    println!(
        "| triangles | backend | build (s) | threads | closest (Mrays/s) | any hit (Mrays/s) |"
    );
    println!("|---:|---|---:|---:|---:|---:|");
    let mut closest1 = Vec::new();
    for &n in &sizes {
        let scene = lumpy_sphere(n);
        let mut backends: Vec<(Box<dyn Intersector>, f64)> = Vec::new();
        match EmbreeIntersector::build(&scene) {
            Ok((e, t)) => backends.push((Box::new(e), t.as_secs_f64())),
            Err(e) => eprintln!("Embree: {e}"),
        }
        let (b, t) = BvhIntersector::build(&scene);
        backends.push((Box::new(b), t.as_secs_f64()));
        for (isect, build) in &backends {
            for threads in [1, 2] {
                let c = throughput(&rays, threads, &|r| isect.intersect(r).is_some());
                let a = throughput(&rays, threads, &|r| isect.occluded(r));
                if threads == 1 {
                    closest1.push((n, isect.name(), c));
                }
                println!(
                    "| {} | {} | {:.3} | {} | {:.2} | {:.2} |",
                    scene.triangles.len(),
                    isect.name(),
                    build,
                    threads,
                    c,
                    a
                );
            }
        }
    }
    for &n in &sizes {
        let get = |name| {
            closest1
                .iter()
                .find(|x| x.0 == n && x.1 == name)
                .map(|x| x.2)
        };
        if let (Some(e), Some(b)) = (get("embree"), get("bvh")) {
            eprintln!(
                "{n} triangles: BVH closest hit is {:.2}x slower than Embree (1 thread)",
                e / b
            );
        }
    }
}
