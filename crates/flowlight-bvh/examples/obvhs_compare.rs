//! Measures the `obvhs` crate's CWBVH (PLOC build, 8-wide compressed nodes, SIMD traversal)
//! against our wide [`Bvh`] (4-wide when docs/performance.md quoted this comparison, 8-wide
//! now) on the ray benchmark's lumpy closed sphere: build time, and closest / any-hit
//! throughput on incoherent rays on one thread, with our watertight triangle test plugged
//! into obvhs' traversal (so only the hierarchies differ). Also counts
//! rays where obvhs' closest hit differs from ours (a box test that culls a box the ray
//! touches shows up here). Alternating rounds; prints medians and ranges of the ratios.
//!
//! `cargo run --release -p flowlight-bvh --example obvhs_compare [triangles] [rays] [rounds]`
//! (`OBVHS_PRESET=fast` for obvhs' `fast_build` preset instead of `medium_build`).

use std::time::{Duration, Instant};

use flowlight_bvh::{Bvh, WatertightRay};
mod common;

use common::{lumpy_sphere, rays};
use flowlight_core::geometry::Ray;
use glam::{Vec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::RayHit;
use obvhs::BvhBuildParams;

struct Obvhs {
    bvh: CwBvh,
    /// Triangles in `bvh.primitive_indices` order.
    tris: Vec<[Vec3; 3]>,
}

impl Obvhs {
    fn build(tris: &[[Vec3; 3]]) -> Obvhs {
        let t: Vec<obvhs::triangle::Triangle> = tris
            .iter()
            .map(|t| obvhs::triangle::Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect();
        let params = match std::env::var("OBVHS_PRESET").as_deref() {
            Ok("fast") => BvhBuildParams::fast_build(),
            _ => BvhBuildParams::medium_build(),
        };
        let bvh = build_cwbvh_from_tris(&t, params, &mut Duration::default());
        let tris = bvh
            .primitive_indices
            .iter()
            .map(|&i| tris[i as usize])
            .collect();
        Obvhs { bvh, tris }
    }

    fn ray(r: &Ray) -> obvhs::ray::Ray {
        obvhs::ray::Ray::new(Vec3A::from(r.origin), Vec3A::from(r.dir), 0.0, r.t_max)
    }

    /// Closest hit `(t, triangle)` with our watertight test.
    fn intersect(&self, r: &Ray) -> Option<(f32, u32)> {
        let w = WatertightRay::new(r)?;
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(Self::ray(r), &mut hit, |ray, id| {
            w.intersect(&self.tris[id], ray.tmax)
                .map_or(f32::INFINITY, |h| h.0)
        });
        found.then(|| (hit.t, self.bvh.primitive_indices[hit.primitive_id as usize]))
    }

    fn occluded(&self, r: &Ray) -> bool {
        let Some(w) = WatertightRay::new(r) else {
            return false;
        };
        !self.bvh.ray_traverse_miss(Self::ray(r), |ray, id| {
            w.intersect(&self.tris[id], ray.tmax)
                .map_or(f32::INFINITY, |h| h.0)
        })
    }
}

fn time(f: impl FnOnce() -> usize) -> f64 {
    let t = Instant::now();
    std::hint::black_box(f());
    t.elapsed().as_secs_f64()
}

fn stats(mut v: Vec<f64>) -> String {
    v.sort_by(f64::total_cmp);
    format!("{:.2} ({:.2}–{:.2})", v[v.len() / 2], v[0], v[v.len() - 1])
}

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args
        .next()
        .map_or(100_000, |s| s.parse().expect("triangles"));
    let n_rays: usize = args.next().map_or(500_000, |s| s.parse().expect("rays"));
    let rounds: usize = args.next().map_or(3, |s| s.parse().expect("rounds")).max(1);
    let tris = lumpy_sphere(n);
    let rays = rays(n_rays);
    let ours = Bvh::build(&tris);
    let theirs = Obvhs::build(&tris);
    let differ = rays
        .iter()
        .filter(|r| {
            let a = ours.intersect(r).map(|h| h.t);
            let b = theirs.intersect(r).map(|h| h.0);
            a != b
        })
        .count();
    println!(
        "{} triangles, {n_rays} rays; closest hit t differs on {differ} rays",
        tris.len()
    );
    let (mut build, mut closest, mut any) = (Vec::new(), Vec::new(), Vec::new());
    let mut abs = [
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
    ];
    for _ in 0..rounds {
        let ob = time(|| Obvhs::build(&tris).tris.len());
        let wb = time(|| Bvh::build(&tris).node_count());
        let oc = time(|| {
            rays.iter()
                .filter(|r| theirs.intersect(r).is_some())
                .count()
        });
        let wc = time(|| rays.iter().filter(|r| ours.intersect(r).is_some()).count());
        let oa = time(|| rays.iter().filter(|r| theirs.occluded(r)).count());
        let wa = time(|| rays.iter().filter(|r| ours.occluded(r)).count());
        build.push(ob / wb);
        closest.push(oc / wc);
        any.push(oa / wa);
        let mr = |s: f64| n_rays as f64 / s / 1e6;
        for (v, x) in abs.iter_mut().zip([wb, ob, mr(wc), mr(oc), mr(wa), mr(oa)]) {
            v.push(x);
        }
    }
    let [wb, ob, wc, oc, wa, oa] = abs;
    println!("build (s): ours {}, obvhs {}", stats(wb), stats(ob));
    println!(
        "closest (Mrays/s, 1 thread): ours {}, obvhs {}",
        stats(wc),
        stats(oc)
    );
    println!(
        "any hit (Mrays/s, 1 thread): ours {}, obvhs {}",
        stats(wa),
        stats(oa)
    );
    println!(
        "ours vs obvhs (time ratio obvhs / ours, > 1: ours faster): build {}, closest {}, any hit {}",
        stats(build),
        stats(closest),
        stats(any)
    );
}
