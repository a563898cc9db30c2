//! The batched ray interface (ABI 4): batches answer exactly what single-ray queries answer,
//! the plugin-side surface data built from compact hits equals the host's `SurfaceHit`, and
//! the wavefront path tracer gives every sample bit for bit the contributions of the
//! path-at-a-time one.

use crate::common;

use common::{renderer, renderer_from, scene_config, scratch};
use flowlight_core::geometry::Ray;
use flowlight_core::mesh::CompactHit;
use flowlight_core::rng::Rng;
use flowlight_core::sampler::{PairAhead, SampleStream, SLOT_BSDF_PAIR, SLOT_LIGHT};
use flowlight_core::sobol::SobolSampler;
use flowlight_host::intersector::UnitTracer;
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_pathtrace::sampler::BranchStream;
use flowlight_pathtrace::{entangled, PathSettings, SampleContributions};
use flowlight_sdk::{Params, Scene, Tracer};
use flowlight_testkit::gltf::{octahedra_gltf, octahedra_placements, png8, Quad};
use glam::{Vec2, Vec3};

/// Rays from a sphere around the scene towards random points inside its box, and the
/// camera's rays through a jittered grid (the coherent kind).
fn probe_rays(s: &Renderer, n: usize, seed: u64) -> (Vec<Ray>, Vec<Ray>) {
    let (lo, hi) = s.scene.bounds().unwrap();
    let (c, r) = ((lo + hi) * 0.5, (hi - lo).length());
    let mut rng = Rng::new(seed, 1);
    let incoherent = (0..n)
        .map(|_| {
            let o = c
                + (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5)
                    .normalize_or_zero()
                    * r;
            let t = lo + (hi - lo) * Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
            // Half of them stop short, so any-hit answers both ways.
            let t_max = if rng.uniform() < 0.5 {
                f32::INFINITY
            } else {
                (t - o).length() * rng.uniform()
            };
            Ray::new(o, (t - o).normalize(), t_max)
        })
        .collect();
    let cam = s.camera;
    let camera = (0..n)
        .map(|i| {
            // Raster order, as a tile's camera rays come.
            let (x, y) = (i as u32 % cam.width, i as u32 / cam.width % cam.height);
            cam.generate_ray(Vec2::new(x as f32, y as f32) + rng.uniform2())
        })
        .collect();
    (incoherent, camera)
}

/// Checks batches against single rays and the lazy surface data against the host's, on
/// `rays`; returns the number of hits seen.
fn check_batches(s: &Renderer, rays: &[Ray], coherent: bool, what: &str) -> usize {
    // SAFETY: the renderer keeps the view's data alive while `scene` is used.
    let scene = unsafe { Scene::from_view(s.instance.view()) };
    let mut single = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let mut batched = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = batched.table();
    let tracer = Tracer::new(&table);
    let (mut hits, mut blocked) = (Vec::new(), Vec::new());
    tracer.intersect_batch(rays, coherent, &mut hits);
    tracer.occluded_batch(rays, &mut blocked);
    assert_eq!((hits.len(), blocked.len()), (rays.len(), rays.len()));
    let mut n_hits = 0;
    let mut ties = 0;
    for (i, ray) in rays.iter().enumerate() {
        let want = single.closest(ray);
        let got = hits[i];
        match want {
            None => assert_eq!(got, CompactHit::MISS, "{what} ray {i}"),
            // A coherent batch may take the other of two triangles at the same distance.
            Some(w) if coherent && w.prim != got.prim && w.t.to_bits() == got.t.to_bits() => {
                n_hits += 1;
                ties += 1;
            }
            Some(w) => {
                n_hits += 1;
                assert_eq!(
                    (
                        got.t.to_bits(),
                        got.prim,
                        got.b1.to_bits(),
                        got.b2.to_bits()
                    ),
                    (w.t.to_bits(), w.prim, w.b1.to_bits(), w.b2.to_bits()),
                    "{what} ray {i}"
                );
                // The plugin's surface data is the host's record, every field bit for bit.
                let host = single.intersect(ray);
                assert_eq!(host.hit, 1);
                let lazy = scene.surface(ray, &got);
                assert_eq!(
                    format!("{lazy:?}"),
                    format!("{:?}", host.surface),
                    "{what} ray {i}"
                );
            }
        }
        assert_eq!(blocked[i] != 0, single.blocked(ray), "{what} ray {i}");
    }
    assert!(ties * 100 <= n_hits, "{what}: {ties} ties of {n_hits} hits");
    n_hits
}

fn check_renderer(s: &Renderer, what: &str) {
    let (incoherent, camera) = probe_rays(s, 3000, 0x5eed);
    let a = check_batches(s, &incoherent, false, &format!("{what} incoherent"));
    let b = check_batches(s, &camera, true, &format!("{what} camera"));
    assert!(a > 100 && b > 50, "{what}: too few hits ({a}, {b})");
}

fn with_intersector(config: &str, isect: &str) -> Renderer {
    let mut cfg = flowlight_scene::config::load_config(&scene_config(config))
        .unwrap_or_else(|e| panic!("{e}"));
    cfg.intersector = match isect {
        "bvh" => flowlight_scene::config::Intersector::Bvh,
        _ => flowlight_scene::config::Intersector::Embree,
    };
    cfg.width = 32;
    cfg.height = 32;
    let ov = Overrides {
        spp: Some(1),
        threads: Some(1),
        ..Default::default()
    };
    Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"))
}

const BODY: &str = r#"
[render]
width = 32
height = 32
spp = 1
intersector = "ISECT"
[camera]
position = [12.0, 2.0, 6.0]
look_at = [12.0, 1.0, -2.0]
fov_y = 100.0
[integrator]
plugin = "mcpt"
"#;

#[test]
fn batches_equal_single_rays_and_lazy_surfaces_equal_host_hits() {
    for isect in ["bvh", "embree"] {
        // A flat scene (the Cornell box) and one with mirrored, non-uniformly scaled
        // instances of a mesh stored once.
        let s = with_intersector("cornell-box/cornell-box.toml", isect);
        assert_eq!(s.intersector.name(), isect);
        check_renderer(&s, &format!("{isect} cornell"));
        let placements = octahedra_placements(9);
        let s = renderer_from(
            &format!("batch-inst-{isect}"),
            &octahedra_gltf(&placements, false, "{}"),
            &BODY.replace("ISECT", isect),
            1,
        );
        assert!(s.scene.is_instanced());
        check_renderer(&s, &format!("{isect} instances"));
    }
}

/// A quad whose right half is cut away by alpha MASK, normal-mapped (a tilted normal in the
/// texture) and instanced once more at z = −1: filtered queries, normal mapping and an
/// instance in one scene.
#[test]
fn batches_see_alpha_cut_outs_and_normal_maps_like_single_rays() {
    for isect in ["bvh", "embree"] {
        let dir = scratch(&format!("batch-alpha-{isect}"));
        let q = Quad {
            images: vec![
                png8(2, 1, 4, &[255, 255, 255, 255, 255, 255, 255, 0]),
                png8(2, 1, 3, &[200, 128, 230, 90, 160, 240]),
            ],
            textures: r#"{"source": 0, "sampler": 0}, {"source": 1, "sampler": 0}"#.into(),
            samplers: r#"{"magFilter": 9728}"#.into(),
            material: r#"{"alphaMode": "MASK", "normalTexture": {"index": 1, "scale": 0.8},
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}"#
                .into(),
            second_node: Some([0.5, 0.0, -1.0]),
            ..Quad::default()
        };
        q.write(&dir, "cut.gltf");
        let toml = format!(
            r#"scene = "cut.gltf"
[render]
width = 32
height = 32
spp = 1
intersector = "{isect}"
[environment]
color = [1, 1, 1]
[camera]
position = [0.7, 0.5, 3.0]
look_at = [0.7, 0.5, 0.0]
fov_y = 30.0
[integrator]
plugin = "mcpt"
"#
        );
        let cfg = dir.join("cut.toml");
        std::fs::write(&cfg, toml).unwrap();
        let ov = Overrides {
            threads: Some(1),
            ..Default::default()
        };
        let s = Renderer::prepare(&cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
        assert!(s.scene.has_alpha() && s.scene.is_instanced());
        check_renderer(&s, &format!("{isect} alpha"));
    }
}

/// The wavefront sampler against the path-at-a-time one, sample by sample, bit for bit: with
/// every BSDF built per hit, and with the untextured materials' BSDFs from the scene's table
/// (as plugins see them), whose light connections the wavefront evaluates only after their
/// shadow rays.
fn wavefront_matches(s: &Renderer, what: &str) {
    // SAFETY: the renderer keeps the view's data alive while `scene` is used.
    let scene = unsafe { Scene::from_view(s.instance.view()) };
    wavefront_matches_in(s, &scene, &format!("{what}, BSDFs per hit"));
    let mut tabled = scene;
    // SAFETY: `_table` outlives `tabled`, the only scene that points at it.
    let _table = unsafe { tabled.attach_constant_bsdfs() };
    assert!(tabled.material_bsdfs.iter().any(Option::is_some), "{what}");
    wavefront_matches_in(s, &tabled, &format!("{what}, table BSDFs"));
}

/// Unsplit paths, and paths split into three branches at their first lighting vertex (whose
/// contributions the wavefront merges after the first branch's, in branch order).
fn wavefront_matches_in(s: &Renderer, scene: &Scene, what: &str) {
    let defaults = PathSettings::from_params(&Params::from_slice(&[])).unwrap();
    for branches in [1, 3] {
        let settings = PathSettings {
            branches,
            ..defaults.clone()
        };
        wavefront_matches_with(s, scene, &settings, &format!("{what}, {branches} branches"));
    }
}

fn wavefront_matches_with(s: &Renderer, scene: &Scene, settings: &PathSettings, what: &str) {
    let scene = *scene;
    // The wavefront's camera rays are a coherent batch; Embree's coherent packets may break a
    // tie between two triangles at one distance otherwise than the walk's single rays
    // (tests/integration/embree.rs), so this comparison of the two samplers' logic uses plain packets.
    let plain = (s.intersector.name() == "embree").then(|| {
        let options = flowlight_embree::SceneOptions {
            coherent: false,
            ..Default::default()
        };
        flowlight_host::intersector::EmbreeIntersector::build_with(&s.scene, options)
            .unwrap_or_else(|e| panic!("{e}"))
            .0
    });
    let intersector: &dyn flowlight_host::intersector::Intersector = match &plain {
        Some(e) => e,
        None => s.intersector.as_ref(),
    };
    let mut ut = UnitTracer::new(&s.scene, intersector);
    let table = ut.table();
    let tracer = Tracer::new(&table);
    let settings = settings.clone();
    let n = 1500;
    let mut starts = Vec::new();
    for i in 0..n {
        let mut rng = Rng::new(Rng::hash(&[7, i as u64]), 0);
        let raster = rng.uniform2() * Vec2::new(s.camera.width as f32, s.camera.height as f32);
        starts.push((rng, raster));
    }
    let mut wf = entangled::Wavefront::default();
    let mut out = vec![SampleContributions::default(); n as usize];
    // Two batch sizes: the answer must not depend on the split.
    for chunk in [n as usize, 97] {
        for (c, o) in starts.chunks(chunk).zip(out.chunks_mut(chunk)) {
            entangled::trace_wavefront(&scene, &tracer, &settings, c, &mut wf, o);
        }
        let mut nonzero = 0;
        for (i, (rng, raster)) in starts.iter().enumerate() {
            let mut want = SampleContributions::default();
            entangled::trace(&scene, &tracer, &settings, rng, *raster, &mut want);
            let bits = |c: &SampleContributions| {
                c.entries
                    .iter()
                    .map(|(l, v)| (*l, v.r.to_bits(), v.g.to_bits(), v.b.to_bits()))
                    .collect::<Vec<_>>()
            };
            assert_eq!(
                bits(&out[i]),
                bits(&want),
                "{what} sample {i} (batch {chunk})"
            );
            nonzero += !want.entries.is_empty() as usize;
        }
        assert!(nonzero > n as usize / 4, "{what}: {nonzero} lit samples");
    }
}

/// Skipping the light sample where every light is behind a reflection-only surface
/// (`Scene::lights_behind`) changes no contribution: the wavefront with the scene's light
/// bound against the same wavefront without it, sample by sample, bit for bit, in the room
/// lit from behind a partition, where the bound does skip at many camera hits.
#[test]
fn skipping_lights_behind_a_surface_changes_no_contribution() {
    let s = renderer("indirect-room/indirect-room.toml", 1, &[]);
    // SAFETY: the renderer keeps the view's data alive while the scenes are used.
    let mut scene = unsafe { Scene::from_view(s.instance.view()) };
    // SAFETY: `_table` outlives `scene` and `blind`, the scenes that point at it.
    let _table = unsafe { scene.attach_constant_bsdfs() };
    assert!(scene.light_bound.is_some());
    let blind = Scene {
        light_bound: None,
        ..scene
    };
    let mut ut = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = ut.table();
    let tracer = Tracer::new(&table);
    let settings = PathSettings::from_params(&Params::from_slice(&[])).unwrap();
    let n = 20_000;
    let (w, h) = (s.camera.width as f32, s.camera.height as f32);
    let mut starts = Vec::new();
    let mut skipped = 0;
    for i in 0..n {
        let mut rng = Rng::new(Rng::hash(&[11, i as u64]), 0);
        let raster = rng.uniform2() * Vec2::new(w, h);
        let ray = scene.camera.generate_ray(raster);
        if let Some(hit) = tracer.intersect(&ray) {
            let wo_z = (-ray.dir).dot(hit.ns);
            let bsdf = scene.bsdf(&hit);
            skipped += (bsdf.reflects_only() && scene.lights_behind(hit.p, hit.ns, wo_z)) as usize;
        }
        starts.push((rng, raster));
    }
    assert!(
        skipped > n / 20,
        "{skipped} camera hits with every light behind"
    );
    let mut wf = entangled::Wavefront::default();
    let trace = |scene: &Scene, wf: &mut entangled::Wavefront| {
        let mut out = vec![SampleContributions::default(); n];
        entangled::trace_wavefront(scene, &tracer, &settings, &starts, wf, &mut out);
        out.iter()
            .map(|c| {
                c.entries
                    .iter()
                    .map(|(l, v)| (*l, v.r.to_bits(), v.g.to_bits(), v.b.to_bits()))
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let (with, without) = (trace(&scene, &mut wf), trace(&blind, &mut wf));
    let lit = with.iter().filter(|c| !c.is_empty()).count();
    assert!(lit > n / 20, "{lit} lit samples");
    for (i, (a, b)) in with.iter().zip(&without).enumerate() {
        assert_eq!(a, b, "sample {i}");
    }
}

#[test]
fn wavefront_gives_each_sample_the_path_at_a_time_contributions() {
    wavefront_matches(&renderer("cornell-box/cornell-box.toml", 1, &[]), "cornell");
    wavefront_matches(
        &renderer("glass-caustic/glass-caustic.toml", 1, &[]),
        "glass",
    );
    // Textured materials (a BSDF built per hit, its connections evaluated before the shadow
    // ray) beside untextured glTF ones (table BSDFs, evaluated after it).
    wavefront_matches(
        &renderer("blender-showcase/showcase.toml", 1, &[]),
        "showcase",
    );
}

/// A Sobol' stream for the test below: with `wrong` `None` it gives no pair ahead (the
/// trait's `pair_ahead`: every number drawn in its turn); with `Some(slot)` its pairs ahead
/// for that slot are wrong (each coordinate moved by ½, the key kept), so a path that takes
/// one draws another light point or direction than in turn.
#[derive(Clone)]
struct TestStream {
    inner: SobolSampler,
    wrong: Option<u32>,
}

impl SampleStream for TestStream {
    fn uniform(&mut self) -> f32 {
        self.inner.uniform()
    }
    fn uniform2(&mut self) -> Vec2 {
        self.inner.uniform2()
    }
    fn seek(&mut self, vertex: u32, slot: u32) {
        self.inner.seek(vertex, slot)
    }
    fn pair_ahead(&self, vertex: u32, slot: u32) -> Option<PairAhead> {
        let a = self.inner.pair_ahead(vertex, slot)?;
        if self.wrong != Some(slot) {
            return None;
        }
        let moved = (a.value + Vec2::splat(0.5)).fract();
        Some(PairAhead { value: moved, ..a })
    }
    fn uniform2_ahead(&mut self, ahead: Option<PairAhead>) -> Vec2 {
        self.inner.uniform2_ahead(ahead)
    }
}

impl BranchStream for TestStream {
    fn branch(&self, j: u32, k: u32) -> Self {
        TestStream {
            inner: self.inner.branch(j, k),
            wrong: self.wrong,
        }
    }
}

/// Each sample's contributions through the wavefront, as bits.
fn wavefront_bits<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
) -> Vec<Vec<(u32, u32, u32, u32)>> {
    let mut wf = entangled::Wavefront::default();
    let mut out = vec![SampleContributions::default(); starts.len()];
    for (c, o) in starts.chunks(256).zip(out.chunks_mut(256)) {
        entangled::trace_wavefront(scene, tracer, settings, c, &mut wf, o);
    }
    out.iter()
        .map(|c| {
            c.entries
                .iter()
                .map(|(l, v)| (*l, v.r.to_bits(), v.g.to_bits(), v.b.to_bits()))
                .collect()
        })
        .collect()
}

/// Sobol' pairs computed ahead of their vertex (`SampleStream::pair_ahead`, taken back by
/// `uniform2_ahead`) change no contribution: the wavefront with them against the same
/// samples drawing every number in turn, bit for bit, with and without branches, on
/// diffuse walls, through glass (a dielectric's own number before its pair) and on textured
/// glTF materials. And both pairs ahead are taken: with wrong light pairs, or wrong BSDF
/// pairs, over an eighth of the samples lit through a vertex change (21–100% here; none where
/// the BSDF pair is computed for the wrong slot and so never taken). Lower counts are
/// expected for light pairs with branches (a split draws its branches' light pairs at once,
/// with none ahead) and on the showcase, most of whose camera rays see the sky.
#[test]
fn sobol_pairs_drawn_ahead_change_no_contribution() {
    for (config, what) in [
        ("cornell-box/cornell-box.toml", "cornell"),
        ("glass-caustic/glass-caustic.toml", "glass"),
        ("blender-showcase/showcase.toml", "showcase"),
    ] {
        let s = renderer(config, 1, &[]);
        // SAFETY: the renderer keeps the view's data alive while `scene` is used.
        let mut scene = unsafe { Scene::from_view(s.instance.view()) };
        // SAFETY: `_table` outlives `scene`, the only scene that points at it.
        let _table = unsafe { scene.attach_constant_bsdfs() };
        let mut ut = UnitTracer::new(&s.scene, s.intersector.as_ref());
        let table = ut.table();
        let tracer = Tracer::new(&table);
        let (w, h) = (s.camera.width as f32, s.camera.height as f32);
        let defaults = PathSettings::from_params(&Params::from_slice(&[])).unwrap();
        for branches in [1, 4] {
            let settings = PathSettings {
                branches,
                ..defaults.clone()
            };
            // 16 samples in each of 128 pixels.
            let starts: Vec<(SobolSampler, Vec2)> = (0..2048u32)
                .map(|i| {
                    let pixel = u64::from(i / 16);
                    let mut rng = SobolSampler::new(Rng::hash(&[5, pixel]), i % 16);
                    let raster = rng.uniform2() * Vec2::new(w, h);
                    (rng, raster)
                })
                .collect();
            let with = |wrong: Option<u32>| -> Vec<(TestStream, Vec2)> {
                let stream = |inner: &SobolSampler| TestStream {
                    inner: inner.clone(),
                    wrong,
                };
                starts.iter().map(|(r, p)| (stream(r), *p)).collect()
            };
            let ahead = wavefront_bits(&scene, &tracer, &settings, &starts);
            let want = wavefront_bits(&scene, &tracer, &settings, &with(None));
            let what = format!("{what}, {branches} branches");
            for (i, (a, b)) in ahead.iter().zip(&want).enumerate() {
                assert_eq!(a, b, "{what}: sample {i}");
            }
            // Lit through a vertex: light of layer 1 or deeper.
            let through_vertex = |c: &Vec<(u32, u32, u32, u32)>| c.iter().any(|e| e.0 >= 1);
            let lit = want.iter().filter(|c| through_vertex(c)).count();
            assert!(
                lit > starts.len() / 20,
                "{what}: {lit} samples lit through a vertex"
            );
            for slot in [SLOT_LIGHT, SLOT_BSDF_PAIR] {
                let moved = wavefront_bits(&scene, &tracer, &settings, &with(Some(slot)));
                let changed = want
                    .iter()
                    .zip(&moved)
                    .filter(|(a, b)| through_vertex(a) && a != b)
                    .count();
                assert!(
                    changed > lit / 8,
                    "{what}: {changed} of {lit} samples lit through a vertex changed by wrong pairs ahead at slot {slot}"
                );
            }
        }
    }
}
