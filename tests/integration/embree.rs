//! The Embree backend against the pure-Rust BVH: per-ray agreement over the repo's scenes and a
//! closed mesh (rays through shared edges and vertices, grazing rays), and a Cornell box
//! render with each backend. The Stanford dragon must have been fetched (`bash .ci/setup`).

use crate::common;

use common::*;
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use flowlight_embree::{Packets, SceneOptions};
use flowlight_host::intersector::{BvhIntersector, EmbreeIntersector, Intersector};
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_scene::config::{load_config, Intersector as Choice};
use flowlight_scene::Scene;
use glam::{Vec2, Vec3};
use std::collections::BTreeMap;
use std::time::Instant;

fn load(rel: &str) -> Scene {
    let path = scene_config(rel);
    assert!(
        path.exists(),
        "{} is missing: run `bash .ci/setup` (it fetches the Stanford dragon)",
        path.display()
    );
    flowlight_scene::load_gltf(&path, &BTreeMap::new()).unwrap_or_else(|e| panic!("{e}"))
}

fn random_dir(rng: &mut Rng) -> Vec3 {
    let z = 1.0 - 2.0 * rng.uniform();
    let a = std::f32::consts::TAU * rng.uniform();
    let s = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(s * a.cos(), s * a.sin(), z)
}

/// Rays from points in the scene's bounds (grown by 20 %) in random directions; a quarter
/// with finite `t_max`.
fn box_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let (lo, hi) = scene.bounds().unwrap();
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.6);
    let mut rng = Rng::new(seed, 3);
    (0..n)
        .map(|i| {
            let u = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - Vec3::ONE;
            let t_max = if i % 4 == 0 {
                rng.uniform() * h.length() * 2.0
            } else {
                f32::INFINITY
            };
            Ray {
                origin: c + u * h,
                dir: random_dir(&mut rng),
                t_max,
            }
        })
        .collect()
}

/// A closed, lumpy sphere with shared vertices (latitude/longitude grid with poles).
fn closed_mesh(rings: usize) -> Scene {
    let segs = 2 * rings;
    let r = |th: f32, ph: f32| 1.0 + 0.2 * (3.0 * th).sin() * (5.0 * ph).cos();
    let mut pos = vec![Vec3::new(0.0, 0.0, r(0.0, 0.0))];
    for i in 1..rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segs {
            let ph = std::f32::consts::TAU * j as f32 / segs as f32;
            pos.push(Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r(th, ph));
        }
    }
    pos.push(Vec3::new(0.0, 0.0, -r(std::f32::consts::PI, 0.0)));
    let south = (pos.len() - 1) as u32;
    let at = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as u32;
    let mut tris = Vec::new();
    for j in 0..segs {
        tris.push([0, at(1, j), at(1, j + 1)]);
        tris.push([south, at(rings - 1, j + 1), at(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
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

/// Rays at the closed mesh's shared edges and vertices: from inside (they must hit: a miss
/// is a leak), and grazing ones from outside at 3°–10° to the triangle's plane through an edge (shallower
/// rays touch the neighbouring triangle tangentially, where either answer is right).
fn edge_rays(scene: &Scene, n: usize, seed: u64) -> (Vec<Ray>, Vec<Ray>, Vec<Ray>) {
    let mut rng = Rng::new(seed, 5);
    let p = &scene.positions;
    let (mut inside, mut at_vertex, mut grazing) = (Vec::new(), Vec::new(), Vec::new());
    while inside.len() + at_vertex.len() < n / 2 {
        let t = scene.triangles[(rng.next_u32() as usize) % scene.triangles.len()];
        let k = (rng.next_u32() % 3) as usize;
        let (a, b) = (p[t[k] as usize], p[t[(k + 1) % 3] as usize]);
        // A point on the edge, sometimes exactly a vertex.
        let s = match rng.next_u32() % 4 {
            0 => 0.0,
            _ => rng.uniform(),
        };
        let q = a + (b - a) * s;
        let o = random_dir(&mut rng) * 0.3 * rng.uniform();
        let ray = Ray {
            origin: o,
            dir: (q - o).normalize(),
            t_max: f32::INFINITY,
        };
        if s == 0.0 {
            at_vertex.push(ray)
        } else {
            inside.push(ray)
        }
        // Grazing: along the edge's tangent plane, tilted into the surface.
        let n = (b - a).cross(p[t[(k + 2) % 3] as usize] - a);
        let n_out = (n * n.dot(q).signum()).normalize();
        let along = (b - a).normalize();
        let angle = (3.0 + 7.0 * rng.uniform()).to_radians();
        let dir = (along * angle.cos() - n_out * angle.sin()).normalize();
        if s == 0.0 {
            continue; // through a vertex: covered from inside above
        }
        grazing.push(Ray {
            origin: q - dir * 0.5,
            dir,
            t_max: f32::INFINITY,
        });
    }
    (inside, at_vertex, grazing)
}

#[derive(Default, Debug)]
struct Tally {
    rays: usize,
    hits: usize,
    /// Hit in one backend, miss in the other.
    hit_miss: usize,
    /// Distance off by more than 1e-5 relative.
    distance: usize,
    /// Different primitive, not a tie on a shared edge or vertex.
    prim: usize,
    /// Different primitive at the same distance: on a shared edge or vertex, or where two
    /// triangles overlap in one plane (the Cornell box's blocks stand on the floor).
    ties: usize,
    /// Same primitive, hit points further apart than 1e-4 of the triangle plus the
    /// distance tolerance.
    point: usize,
    /// Rays whose origin lies on a surface (a hit closer than 1e-5 of the scene's size).
    on_surface: usize,
    /// `occluded` disagrees with `intersect` of the same backend.
    occluded: usize,
    /// Rays from inside the closed mesh that escaped (per backend: Embree, BVH).
    leaks: [usize; 2],
    worst: Vec<String>,
}

fn compare(
    name: &str,
    scene: &Scene,
    rays: &[Ray],
    a: &dyn Intersector,
    b: &dyn Intersector,
    must_hit: bool,
) -> Tally {
    let mut t = Tally::default();
    let (lo, hi) = scene.bounds().unwrap();
    let diag = (hi - lo).length();
    let tri = |i: u32| scene.triangles[i as usize].map(|v| scene.positions[v as usize]);
    let shares_vertex = |i: u32, j: u32| {
        let (x, y) = (tri(i), tri(j));
        x.iter().any(|p| y.contains(p))
    };
    for r in rays {
        t.rays += 1;
        let (ha, hb) = (a.intersect(r), b.intersect(r));
        if a.occluded(r) != ha.is_some() || b.occluded(r) != hb.is_some() {
            t.occluded += 1;
        }
        if must_hit {
            t.leaks[0] += ha.is_none() as usize;
            t.leaks[1] += hb.is_none() as usize;
        }
        // A hit closer than 1e-5 of the scene's size means the random origin lies on a
        // surface: an ill-posed query that the renderer never makes (its origins are offset
        // by the float-error bound). Counted, not compared.
        let near = [ha, hb].iter().flatten().any(|h| h.t < 1e-5 * diag);
        if near {
            t.on_surface += 1;
            continue;
        }
        match (ha, hb) {
            (None, None) => {}
            (Some(x), Some(y)) => {
                t.hits += 1;
                // Relative 1e-5, with a floor of a few ulps of the coordinates for hits
                // right next to the origin.
                // The floor grows as 1/cos at grazing incidence, where t is ill-conditioned.
                let v = tri(x.prim);
                let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
                let cos = n.dot(r.dir).abs().max(1e-3);
                let floor = 8.0 * f32::EPSILON * (r.origin.abs().max_element() + x.t) / cos;
                if (x.t - y.t).abs() > 1e-5 * x.t.max(y.t) + floor {
                    t.distance += 1;
                    if t.worst.len() < 5 {
                        t.worst.push(format!("{name}: {r:?} t {} vs {}", x.t, y.t));
                    }
                }
                if x.prim != y.prim {
                    if shares_vertex(x.prim, y.prim)
                        || (hits_at(r, tri(x.prim), y.t) && hits_at(r, tri(y.prim), x.t))
                    {
                        t.ties += 1;
                    } else {
                        t.prim += 1;
                        if t.worst.len() < 5 {
                            t.worst
                                .push(format!("{name}: {r:?} prim {} vs {}", x.prim, y.prim));
                        }
                    }
                } else {
                    let v = tri(x.prim);
                    let pt = |b1: f32, b2: f32| v[0] * (1.0 - b1 - b2) + v[1] * b1 + v[2] * b2;
                    let size = (v[1] - v[0]).length().max((v[2] - v[0]).length());
                    if (pt(x.b1, x.b2) - pt(y.b1, y.b2)).length() > 1e-4 * size + 1e-5 * x.t + floor
                    {
                        t.point += 1;
                    }
                }
            }
            _ => {
                t.hit_miss += 1;
                if t.worst.len() < 5 {
                    t.worst
                        .push(format!("{name}: {r:?} embree {ha:?} bvh {hb:?}"));
                }
            }
        }
    }
    t
}

/// Whether `ray` meets triangle `v` at distance `t` (to 1e-5 relative), computed in f64.
fn hits_at(ray: &Ray, v: [Vec3; 3], t: f32) -> bool {
    let d = |a: Vec3| a.as_dvec3();
    let (o, dir) = (d(ray.origin), d(ray.dir));
    let (p0, e1, e2) = (d(v[0]), d(v[1]) - d(v[0]), d(v[2]) - d(v[0]));
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return false;
    }
    let s = o - p0;
    let (u, q) = (s.dot(p) / det, s.cross(e1));
    let (w, tt) = (dir.dot(q) / det, e2.dot(q) / det);
    let tol = 1e-5;
    u >= -tol
        && w >= -tol
        && u + w <= 1.0 + tol
        && (tt - t as f64).abs() <= 1e-5 * tt.abs() + 1e-6 * (o.abs().max_element() + tt.abs())
}

fn backends(scene: &Scene) -> (Box<dyn Intersector>, Box<dyn Intersector>) {
    let (e, _) = EmbreeIntersector::build(scene).unwrap_or_else(|e| panic!("{e}"));
    let (b, _) = BvhIntersector::build(scene);
    (Box::new(e), Box::new(b))
}

#[test]
fn embree_and_bvh_agree_on_a_million_rays() {
    let mut total = Tally::default();
    let mut report = Vec::new();
    fn check(report: &mut Vec<String>, total: &mut Tally, name: &str, t: Tally) {
        report.push(format!("{name}: {t:?}"));
        // Ties on shared edges can go either way; they must stay rare for random rays.
        assert!(
            t.hit_miss == 0 && t.distance == 0 && t.prim == 0 && t.point == 0 && t.occluded == 0,
            "{name}: backends disagree: {t:#?}"
        );
        assert_eq!(
            t.leaks,
            [0, 0],
            "{name}: rays leaked out of the closed mesh: {t:#?}"
        );
        total.rays += t.rays;
        total.hits += t.hits;
        total.ties += t.ties;
    }

    for (rel, n, seed) in [
        ("cornell-box/cornell-box.gltf", 250_000, 1),
        ("furnace/furnace.gltf", 50_000, 2),
        ("stanford-dragon/dragon.gltf", 300_000, 3),
    ] {
        let scene = load(rel);
        let (e, b) = backends(&scene);
        let rays = box_rays(&scene, n, seed);
        let t = compare(rel, &scene, &rays, e.as_ref(), b.as_ref(), false);
        assert!(t.ties * 100 <= t.rays, "{rel}: too many ties: {t:#?}");
        assert!(t.on_surface * 1000 <= t.rays, "{rel}: {t:#?}");
        check(&mut report, &mut total, rel, t);
    }

    let mesh = closed_mesh(120);
    let (e, b) = backends(&mesh);
    let (inside, at_vertex, grazing) = edge_rays(&mesh, 470_000, 4);
    let name = "closed mesh, from inside through edges";
    let t = compare(name, &mesh, &inside, e.as_ref(), b.as_ref(), true);
    check(&mut report, &mut total, name, t);
    // Through vertices: the BVH must not leak. Embree 4.4 in robust mode lets about 1 % of
    // these rays through (measured: ~460 of 50k; ~40 % without robust mode): a known
    // limitation, bounded here so that losing robust mode fails (docs/embree.md).
    let name = "closed mesh, from inside through vertices";
    let t = compare(name, &mesh, &at_vertex, e.as_ref(), b.as_ref(), true);
    report.push(format!("{name}: {t:?}"));
    assert_eq!(t.leaks[1], 0, "{name}: the BVH leaked: {t:#?}");
    assert!(
        t.leaks[0] * 50 <= t.rays,
        "{name}: Embree leaked too often: {t:#?}"
    );
    assert_eq!(t.hit_miss, t.leaks[0], "{t:#?}");
    assert!(
        t.distance == 0 && t.prim == 0 && t.point == 0 && t.occluded == 0,
        "{t:#?}"
    );
    total.rays += t.rays;
    total.hits += t.hits;
    let name = "closed mesh, grazing";
    let t = compare(name, &mesh, &grazing, e.as_ref(), b.as_ref(), false);
    check(&mut report, &mut total, name, t);

    eprintln!("{}", report.join("\n"));
    assert!(total.rays >= 1_000_000, "{} rays", total.rays);
    assert!(
        total.hits > total.rays / 3,
        "too few hits to compare: {total:?}"
    );
}

/// A whole MCPT render through Embree's 16-lane packets is the single-ray render, pixel for
/// pixel: the Cornell box (38 triangles, so packets by default) with each policy. The camera
/// rays' coherent packets are off here: they break ties between triangles at one distance
/// their own way (`coherent_batches_find_the_single_rays_hits_but_for_ties`).
#[test]
fn packet_and_single_ray_renders_are_the_same_image() {
    let render_with = |packets: Packets| {
        let mut cfg = load_config(&scene_config("cornell-box/cornell-box.toml")).unwrap();
        cfg.width = 40;
        cfg.height = 40;
        cfg.intersector = Choice::Embree;
        let ov = Overrides {
            spp: Some(16),
            threads: Some(2),
            ..Default::default()
        };
        let mut s = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
        let options = SceneOptions {
            packets,
            coherent: false,
            ..SceneOptions::default()
        };
        let (e, _) = EmbreeIntersector::build_with(&s.scene, options).unwrap();
        match &e {
            EmbreeIntersector::Flat(f) => assert_eq!(f.uses_packets(), packets == Packets::Always),
            EmbreeIntersector::Instanced { .. } => panic!("the Cornell box is flat"),
        }
        s.intersector = std::sync::Arc::new(e);
        s.exr_path = None;
        s.png_path = None;
        render(&s).frame.image()
    };
    let (a, b) = (render_with(Packets::Always), render_with(Packets::Never));
    assert!(a.iter().any(|c| c.luminance() > 0.0));
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        let bits = |c: &flowlight_core::Rgb| [c.r, c.g, c.b].map(f32::to_bits);
        assert_eq!(bits(x), bits(y), "pixel {i}: {x:?} vs {y:?}");
    }
}

#[test]
fn cornell_renders_agree_between_backends() {
    let render_with = |choice: Choice, seed: u64| {
        let mut cfg = load_config(&scene_config("cornell-box/cornell-box.toml")).unwrap();
        cfg.width = 48;
        cfg.height = 48;
        cfg.seed = seed;
        cfg.intersector = choice;
        let ov = Overrides {
            spp: Some(64),
            threads: Some(2),
            ..Default::default()
        };
        let mut s = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
        s.exr_path = None;
        s.png_path = None;
        let name = s.intersector.name();
        let out = render(&s);
        (name, out)
    };
    let (ne, e) = render_with(Choice::Embree, 11);
    let (nb, b) = render_with(Choice::Bvh, 12);
    assert_eq!((ne, nb), ("embree", "bvh"));
    let lum = |c: flowlight_core::Rgb| c.luminance();
    let (ei, bi) = (e.frame.image(), b.frame.image());
    let (me, se) = mean_and_stderr(&ei, lum);
    let (mb, sb) = mean_and_stderr(&bi, lum);
    let z = (me - mb) / (se * se + sb * sb).sqrt();
    assert!(me > 0.0 && mb > 0.0);
    assert!(
        z.abs() < 4.0,
        "mean luminance embree {me} ± {se}, bvh {mb} ± {sb}: z = {z}"
    );
    // Per 8×8 block: no block more than 5 standard errors apart.
    let (w, h) = (48, 48);
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            let block = |img: &[flowlight_core::Rgb]| {
                let px: Vec<_> = (0..64)
                    .map(|k| img[(by * 8 + k / 8) * w + bx * 8 + k % 8])
                    .collect();
                mean_and_stderr(&px, lum)
            };
            let ((m1, s1), (m2, s2)) = (block(&ei), block(&bi));
            let z = (m1 - m2) / (s1 * s1 + s2 * s2).sqrt().max(1e-6);
            assert!(
                z.abs() < 5.0,
                "block ({bx},{by}): embree {m1} ± {s1}, bvh {m2} ± {s2}"
            );
        }
    }
}

#[test]
fn dragon_loads_and_builds_in_seconds() {
    let start = Instant::now();
    let scene = load("stanford-dragon/dragon.gltf");
    let load_time = start.elapsed();
    assert!(scene.triangles.len() > 500_000, "{}", scene.triangles.len());
    let (_, bvh) = BvhIntersector::build(&scene);
    let (e, embree) = EmbreeIntersector::build(&scene).unwrap();
    assert_eq!(e.name(), "embree");
    eprintln!(
        "dragon: {} triangles, load {load_time:?}, BVH build {bvh:?}, Embree build {embree:?}",
        scene.triangles.len()
    );
    // Generous for a loaded 2-core CI machine in the dev profile; minutes would fail.
    assert!(load_time.as_secs_f64() < 20.0, "load {load_time:?}");
    assert!(bvh.as_secs_f64() < 20.0, "BVH build {bvh:?}");
    assert!(embree.as_secs_f64() < 20.0, "Embree build {embree:?}");
}

/// Camera rays in raster order through Embree's coherent packets
/// ([`Intersector::intersect_coherent_batch`]) find the single rays' hits: the same
/// distance, bit for bit, for every ray, and the same triangle but for ties (rays that meet
/// two triangles at one distance: on the Cornell box, the ceiling's two coplanar quads, the
/// whole ceiling and one over the lamp's footprint, at the lamp's rim). Rays at a closed
/// mesh's shared edges, which the coherent traversal need not see as coherent, still never
/// slip through in robust mode.
#[test]
fn coherent_batches_find_the_single_rays_hits_but_for_ties() {
    use flowlight_core::mesh::CompactHit;
    let check = |e: &dyn Intersector, rays: &[Ray], what: &str| -> usize {
        assert_eq!(e.name(), "embree", "{what}");
        let mut hits = vec![CompactHit::MISS; rays.len()];
        let mut plain = vec![CompactHit::MISS; rays.len()];
        e.intersect_coherent_batch(rays, &mut hits);
        e.intersect_batch(rays, &mut plain);
        let (mut lit, mut ties) = (0, 0);
        for (i, (ray, got)) in rays.iter().zip(&hits).enumerate() {
            let want = e.intersect(ray);
            assert_eq!(
                want.map(|w| w.t.to_bits()),
                got.is_hit().then_some(got.t.to_bits()),
                "{what} ray {i}: {ray:?} {got:?} {want:?}"
            );
            if let Some(w) = want {
                lit += 1;
                ties += usize::from(w.prim != got.prim);
            }
            assert_eq!(plain[i].t.to_bits(), got.t.to_bits(), "{what} ray {i}");
        }
        assert!(ties * 1000 <= lit, "{what}: {ties} ties of {lit} hits");
        lit
    };
    for (rel, n) in [
        ("cornell-box/cornell-box.toml", 65_536),
        ("stanford-dragon/dragon.toml", 16_384),
    ] {
        let s = Renderer::prepare(&scene_config(rel), &Overrides::default())
            .unwrap_or_else(|e| panic!("{e}"));
        let cam = s.camera;
        let mut rng = Rng::new(9, 2);
        let rays: Vec<Ray> = (0..n)
            .map(|i| {
                let (x, y) = (i % cam.width, i / cam.width % cam.height);
                cam.generate_ray(
                    Vec2::new(x as f32, y as f32) + Vec2::new(rng.uniform(), rng.uniform()),
                )
            })
            .collect();
        let lit = check(s.intersector.as_ref(), &rays, rel);
        assert!(lit > n as usize / 4, "{rel}: {lit} hits");
    }
    let mesh = closed_mesh(120);
    let (inside, _, _) = edge_rays(&mesh, 200_000, 6);
    let (e, _) = EmbreeIntersector::build(&mesh).unwrap();
    let mut hits = vec![CompactHit::MISS; inside.len()];
    e.intersect_coherent_batch(&inside, &mut hits);
    let leaked = hits.iter().filter(|h| !h.is_hit()).count();
    assert_eq!(
        leaked,
        0,
        "{leaked} of {} edge rays slipped through",
        inside.len()
    );
}
