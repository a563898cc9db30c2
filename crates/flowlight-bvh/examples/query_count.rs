//! A fixed set of closest-hit and any-hit queries on one mesh, and nothing else, for
//! counting the traversal's instructions with callgrind: counts are the same from run to
//! run whatever else the machine is doing, where timings on a shared machine move ±30%.
//! Same meshes and rays as `ab_timing`; `--miss` moves every ray away from the mesh, so
//! that only the per-ray set-up and the root node's test are left.
//!
//! ```sh
//! cargo build --release -p flowlight-bvh --example query_count
//! valgrind --tool=callgrind --callgrind-out-file=cg.out \
//!     target/release/examples/query_count 10000 100000 [--miss]
//! callgrind_annotate --inclusive=yes cg.out | grep traverse_avx2
//! ```
//!
//! The instructions of `Bvh::traverse_avx2` divided by twice the ray count (each ray is
//! traced once closest-hit, once any-hit) are the instructions per query.

mod common;

use common::{lumpy_sphere, rays};
use flowlight_bvh::Bvh;
use glam::Vec3;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let miss = args.iter().any(|a| a == "--miss");
    let mut nums = args.iter().filter(|a| !a.starts_with("--"));
    let n: usize = nums
        .next()
        .map_or(10_000, |s| s.parse().expect("triangles"));
    let n_rays: usize = nums.next().map_or(100_000, |s| s.parse().expect("rays"));
    let mut rays = rays(n_rays);
    if miss {
        for r in &mut rays {
            r.origin += Vec3::splat(100.0);
            r.dir = Vec3::new(0.3, 0.4, 0.5).normalize();
        }
    }
    let bvh = Bvh::build(&lumpy_sphere(n));
    let closest = rays.iter().filter(|r| bvh.intersect(r).is_some()).count();
    let any = rays.iter().filter(|r| bvh.occluded(r)).count();
    println!("{n_rays} rays: {closest} closest hits, {any} occluded");
}
