//! Ray benchmark (not a test): incoherent closest-hit and any-hit throughput and build time of
//! the Embree intersector (one `rtcIntersect1` / `rtcOccluded1` per ray, and 8-lane packets),
//! the host's BVH intersector (the 8-wide `flowlight_bvh::Bvh`) and the binary
//! `flowlight_bvh::BinaryBvh` on closed meshes of ~10k, ~100k and ~1M triangles, with 1 and 2
//! threads (`FLOWLIGHT_BENCH_THREADS=1,2,16` for other counts). Every backend is called as the
//! host calls it: batches of [`BATCH`] rays through [`Intersector::intersect_batch`] /
//! [`Intersector::occluded_batch`]. Prints a Markdown table (docs/performance.md, "Target 2",
//! gives the latest figures): medians over `FLOWLIGHT_BENCH_REPEAT` rounds (default 5) with the
//! range, and each backend's ratio to Embree. Within a round the backends run one after the
//! other on the same rays, so a ratio compares runs made seconds apart (the machine may be
//! shared).
//!
//! `cargo bench -p flowlight-host --bench rays` (`FLOWLIGHT_BENCH_RAYS=N` rays per run,
//! default 1M; `FLOWLIGHT_BENCH_SIZES=10000,100000` to pick meshes;
//! `FLOWLIGHT_BENCH_REPEAT=R` rounds; `FLOWLIGHT_EMBREE_ROBUST=0` times Embree's fast mode
//! instead of the robust one renders use by default, `FLOWLIGHT_EMBREE_QUALITY` its build
//! quality; the first line on stderr names the mode). `FLOWLIGHT_BENCH_LEAKS=M` prints,
//! instead of the timings, how many of M million rays from inside each closed mesh slip
//! through it with Embree robust, Embree fast and the BVH.
//! `FLOWLIGHT_BENCH_CLOCK=cpu` measures the ray throughputs against the process's CPU time
//! divided by the thread count instead of wall time (Unix), which leaves out the time other
//! processes held the cores on a shared machine (builds stay in wall time).
//! `cargo build --release -p flowlight-host --bench rays` builds the same binary (under
//! `target/release/deps/rays-*`) from the release artifacts, without rebuilding every
//! dependency under the `bench` profile.

use flowlight_bvh::BinaryBvh;
use flowlight_core::geometry::Ray;
use flowlight_core::mesh::CompactHit;
use flowlight_core::rng::Rng;
use flowlight_core::sampling::uniform_sphere;
use flowlight_embree::{Packets, SceneOptions};
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
            Ray {
                origin: o,
                dir: uniform_sphere(rng.uniform2()),
                t_max: f32::INFINITY,
            }
        })
        .collect()
}

/// Rays per call, as the MCPT plugin's wavefront hands them to the host.
const BATCH: usize = 256;

/// A batch query: answers `rays` into its output slice and returns how many hit (so that
/// nothing is optimised away).
type Query = Box<dyn Fn(&[Ray]) -> usize + Sync>;

/// What ray throughputs are measured against (`FLOWLIGHT_BENCH_CLOCK`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Clock {
    Wall,
    /// The process's CPU time over the thread count.
    Cpu,
}

/// The process's CPU time so far, in seconds (all threads).
#[cfg(unix)]
fn process_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid place for the result.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_PROCESS_CPUTIME_ID) failed");
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

#[cfg(not(unix))]
fn process_cpu_seconds() -> f64 {
    panic!("FLOWLIGHT_BENCH_CLOCK=cpu needs a Unix system")
}

/// Mrays/s of `f` over `rays` on `threads` threads, in batches of [`BATCH`] rays.
fn throughput(
    rays: &[Ray],
    threads: usize,
    clock: Clock,
    f: &(dyn Fn(&[Ray]) -> usize + Sync),
) -> f64 {
    let cpu_start = (clock == Clock::Cpu).then(process_cpu_seconds);
    let start = Instant::now();
    let chunk = rays.len().div_ceil(threads);
    let hits: usize = std::thread::scope(|s| {
        let hs: Vec<_> = rays
            .chunks(chunk)
            .map(|c| s.spawn(move || c.chunks(BATCH).map(f).sum::<usize>()))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).sum()
    });
    std::hint::black_box(hits);
    let seconds = match cpu_start {
        Some(c) => (process_cpu_seconds() - c) / threads as f64,
        None => start.elapsed().as_secs_f64(),
    };
    rays.len() as f64 / seconds / 1e6
}

/// A backend under test: its name and its two batch queries.
struct Backend {
    name: &'static str,
    closest: Query,
    any: Query,
}

/// The host's two batch calls of `i` as [`Query`]s.
fn queries<I: Intersector + 'static>(i: I) -> (Query, Query) {
    let i = std::sync::Arc::new(i);
    let j = i.clone();
    (
        Box::new(move |rays| {
            let mut hits = [CompactHit::MISS; BATCH];
            let hits = &mut hits[..rays.len()];
            i.intersect_batch(rays, hits);
            hits.iter().filter(|h| h.is_hit()).count()
        }),
        Box::new(move |rays| {
            let mut blocked = [0u8; BATCH];
            let blocked = &mut blocked[..rays.len()];
            j.occluded_batch(rays, blocked);
            blocked.iter().map(|&b| b as usize).sum()
        }),
    )
}

/// Rays from inside a [`lumpy_sphere`] (origins within 0.3 of its centre, where every
/// radius is at least 0.8; uniform directions): each must hit, so a miss is a ray that
/// slipped through the closed mesh between two triangles.
fn inside_rays(rng: &mut Rng, out: &mut Vec<Ray>) {
    let dir = |rng: &mut Rng| uniform_sphere(rng.uniform2());
    out.clear();
    for _ in 0..BATCH {
        let o = dir(rng) * (0.3 * rng.uniform());
        out.push(Ray {
            origin: o,
            dir: dir(rng),
            t_max: f32::INFINITY,
        });
    }
}

/// `FLOWLIGHT_BENCH_LEAKS=M` (instead of the timings): how many of M million rays from
/// inside each closed mesh leak through it, for Embree in robust and in fast mode (8-lane packets, as renders of
/// scenes up to 100k triangles trace) and for the BVH. A measurement, not a test: the tests
/// aim rays at shared edges and vertices (tests/integration/embree.rs); this gives the rate for rays
/// that hit edges only by chance, as a render's do.
fn leak_table(sizes: &[usize], millions: usize) {
    println!("| triangles | backend | rays from inside | leaked |\n|---:|---|---:|---:|");
    for &n in sizes {
        let scene = lumpy_sphere(n);
        let mut backends: Vec<(&str, Box<dyn Intersector>)> = Vec::new();
        for (name, robust) in [("embree, robust", true), ("embree, fast", false)] {
            let options = SceneOptions {
                robust,
                packets: Packets::Always,
                ..SceneOptions::default()
            };
            match EmbreeIntersector::build_with(&scene, options) {
                Ok((e, _)) => backends.push((name, Box::new(e))),
                Err(e) => eprintln!("Embree: {e}"),
            }
        }
        backends.push(("bvh (8-wide)", Box::new(BvhIntersector::build(&scene).0)));
        for (name, backend) in &backends {
            let mut rng = Rng::new(11, 3);
            let (mut rays, mut hits) = (Vec::new(), vec![CompactHit::MISS; BATCH]);
            let (mut count, mut leaked) = (0usize, 0usize);
            while count < millions * 1_000_000 {
                inside_rays(&mut rng, &mut rays);
                backend.intersect_batch(&rays, &mut hits);
                count += rays.len();
                leaked += hits.iter().filter(|h| !h.is_hit()).count();
            }
            println!(
                "| {} | {name} | {count} | {leaked} |",
                scene.triangles.len()
            );
        }
    }
}

/// Builds every backend once; the build times of this round.
fn build_all(scene: &Scene, tris: &[[Vec3; 3]], embree: SceneOptions) -> (Vec<Backend>, Vec<f64>) {
    let mut out = Vec::new();
    let mut times = Vec::new();
    // Embree twice: single rays (the row every ratio divides by) and 8-lane packets (what renders of scenes up to 1M triangles use).
    for (name, packets) in [
        ("embree", Packets::Never),
        ("embree (8-lane packets)", Packets::Always),
    ] {
        let options = SceneOptions { packets, ..embree };
        match EmbreeIntersector::build_with(scene, options) {
            Ok((e, t)) => {
                let (closest, any) = queries(e);
                out.push(Backend { name, closest, any });
                times.push(t.as_secs_f64());
            }
            Err(e) => eprintln!("Embree: {e}"),
        }
    }
    let (b, t) = BvhIntersector::build(scene);
    let (closest, any) = queries(b);
    out.push(Backend {
        name: "bvh (8-wide)",
        closest,
        any,
    });
    times.push(t.as_secs_f64());
    let start = Instant::now();
    let bin = std::sync::Arc::new(BinaryBvh::build(tris));
    times.push(start.elapsed().as_secs_f64());
    let bin2 = bin.clone();
    out.push(Backend {
        name: "bvh-binary",
        closest: Box::new(move |rays| rays.iter().filter(|r| bin.intersect(r).is_some()).count()),
        any: Box::new(move |rays| rays.iter().filter(|r| bin2.occluded(r)).count()),
    });
    (out, times)
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// `median (min–max)` with `digits` decimals.
fn cell(v: &[f64], digits: usize) -> String {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    format!(
        "{:.*} ({:.*}–{:.*})",
        digits,
        median(v),
        digits,
        lo,
        digits,
        hi
    )
}

fn main() {
    let env = |k: &str| std::env::var(k).ok();
    let nrays: usize = env("FLOWLIGHT_BENCH_RAYS")
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let repeat: usize = env("FLOWLIGHT_BENCH_REPEAT")
        .and_then(|s| s.parse().ok())
        .unwrap_or(5)
        .max(1);
    // A comma-separated list of counts, or `default`.
    let counts = |k: &str, default: Vec<usize>| -> Vec<usize> {
        env(k)
            .map(|s| s.split(',').map(|x| x.trim().parse().unwrap()).collect())
            .unwrap_or(default)
    };
    let sizes = counts("FLOWLIGHT_BENCH_SIZES", vec![10_000, 100_000, 1_000_000]);
    // Thread counts to time each backend at (a many-core machine shows how each scales).
    let thread_counts = counts("FLOWLIGHT_BENCH_THREADS", vec![1, 2]);
    let clock = match env("FLOWLIGHT_BENCH_CLOCK").as_deref() {
        None | Some("wall") => Clock::Wall,
        Some("cpu") => Clock::Cpu,
        Some(c) => {
            eprintln!("rays: FLOWLIGHT_BENCH_CLOCK must be wall or cpu, not {c:?}");
            std::process::exit(2)
        }
    };
    let rays = rays(nrays);
    // The Embree scenes' mode: robust and medium quality unless `FLOWLIGHT_EMBREE_ROBUST=0`
    // or `FLOWLIGHT_EMBREE_QUALITY` say otherwise (the packet rows set their own policy).
    let embree_options = SceneOptions::from_env().unwrap_or_else(|e| {
        eprintln!("rays: {e}");
        std::process::exit(2)
    });
    match flowlight_embree::device() {
        Ok(d) => eprintln!(
            "Embree {} from {}; scenes {}, build quality {:?}",
            d.version_string(),
            d.library,
            if embree_options.robust {
                "robust (RTC_SCENE_FLAG_ROBUST)"
            } else {
                "fast (no RTC_SCENE_FLAG_ROBUST)"
            },
            embree_options.quality
        ),
        Err(e) => eprintln!("no Embree: {e}"),
    }
    eprintln!(
        "ray throughputs against {}",
        match clock {
            Clock::Wall => "wall time",
            Clock::Cpu => "the process's CPU time / threads",
        }
    );
    if let Some(m) = env("FLOWLIGHT_BENCH_LEAKS") {
        let millions = m.parse().expect("FLOWLIGHT_BENCH_LEAKS: millions of rays");
        return leak_table(&sizes, millions);
    }
    println!(
        "| triangles | backend | build (s) | build / Embree | threads | closest (Mrays/s) | \
         closest / Embree | any hit (Mrays/s) | any hit / Embree |"
    );
    println!("|---:|---|---:|---:|---:|---:|---:|---:|---:|");
    for &n in &sizes {
        let scene = lumpy_sphere(n);
        let tris = scene.triangle_vertices();
        // [backend] -> build times; [backend][threads] -> closest, any per round.
        let mut names = Vec::new();
        let mut builds: Vec<Vec<f64>> = Vec::new();
        let mut closest: Vec<Vec<Vec<f64>>> = Vec::new();
        let mut any: Vec<Vec<Vec<f64>>> = Vec::new();
        for round in 0..repeat {
            let (backends, times) = build_all(&scene, &tris, embree_options);
            if round == 0 {
                names = backends.iter().map(|b| b.name).collect();
                builds = vec![Vec::new(); names.len()];
                closest = vec![vec![Vec::new(); thread_counts.len()]; names.len()];
                any = vec![vec![Vec::new(); thread_counts.len()]; names.len()];
            }
            for (k, b) in backends.iter().enumerate() {
                builds[k].push(times[k]);
                for (ti, &threads) in thread_counts.iter().enumerate() {
                    closest[k][ti].push(throughput(&rays, threads, clock, &*b.closest));
                    any[k][ti].push(throughput(&rays, threads, clock, &*b.any));
                }
            }
        }
        let embree = names.iter().position(|&x| x == "embree");
        // Ratio of medians to Embree's (throughput: ours / Embree; build: ours / Embree).
        let ratio = |v: &[f64], e: Option<&Vec<f64>>| {
            e.map_or("–".to_string(), |e| {
                format!("{:.2}", median(v) / median(e))
            })
        };
        for k in 0..names.len() {
            for (ti, threads) in thread_counts.iter().enumerate() {
                println!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                    tris.len(),
                    names[k],
                    cell(&builds[k], 4),
                    ratio(&builds[k], embree.map(|e| &builds[e])),
                    threads,
                    cell(&closest[k][ti], 2),
                    ratio(&closest[k][ti], embree.map(|e| &closest[e][ti])),
                    cell(&any[k][ti], 2),
                    ratio(&any[k][ti], embree.map(|e| &any[e][ti])),
                );
            }
        }
    }
}
