//! A bound, not a renderer: the least a wavefront path tracer over Flowlight's own scene,
//! Embree and sampler has to do on a Lambertian scene lit by emissive triangles, to size
//! what MCPT's walker spends beyond it (docs/performance.md, "What a lean path costs").
//!
//! The same estimator as MCPT with the `throughput` roulette: paths from
//! the camera, next-event estimation at every vertex weighted by the power heuristic
//! against the cosine-sampled BSDF direction, the same Sobol' numbers slot by slot, the same
//! robust ray offsets, the same batches of 256 paths through the host's intersector and the
//! same cache hints for a large mesh's surface data (`MeshView::prefetch_surfaces`). What
//! it leaves out is everything a general scene needs: textures, the glTF BSDF, punctual and
//! environment lights, instancing, volumes, lighting layers, sinks. It refuses a scene that
//! needs any of these, so its image must match MCPT's in expectation.
//!
//! `LEAN_BRANCHES=k` (default 1) splits each camera path into k branches at its first
//! vertex, as MCPT's `branches = k`: the surface once, then per branch its own numbers
//! (`rng.branch(j, k)`), light connection and extension with β/k; the branches join the wave.
//! The split vertex's surface runs path by path in every mode; its branches' connections and
//! extensions path by path in `scalar`, `phased` and `surface8` ([`Lean::split_vertex`]) and
//! eight at a time in lanes in `lanes` and `avx2` ([`vertex8::branches8`]); the vertices
//! after it as the mode runs them.
//!
//!     cargo run --release -p flowlight-bench --example lean_path -- CONFIG.toml SPP OUT.exr
//!
//! One thread; prints the render's wall time per camera sample. `LEAN_MODE` picks how a
//! bounce's vertices are run:
//!
//! - `scalar` (default): one path at a time ([`scalar`]);
//! - `phased`: each of the vertex's three phases for every path of the wave before the next
//!   (whether short loops let the core overlap paths' chains of dependent operations);
//! - `lanes`: eight paths at a time, the geometry and shading in eight lanes ([`vertex8`]),
//!   as compiled for the default target (SSE);
//! - `avx2`: the same compiled for AVX2, eight lanes per instruction;
//! - `surface8`: only the surface in AVX2 lanes, the light connection and the extension path
//!   by path (what a phase in lanes between per-path code gains).
//!
//! Every mode gives the same image, bit for bit.

use flowlight_core::geometry::Ray;
use flowlight_core::light::Lights;
use flowlight_core::mesh::{CompactHit, MeshView};
use flowlight_core::sobol::SobolSampler;
use flowlight_core::Rgb;
use flowlight_host::intersector::Intersector;
use flowlight_host::output::exr::{write_exr, ExrMetadata, ImageLayer};
use flowlight_host::renderer::LoadedScene;
use flowlight_pathtrace::sampler::sample_start;
use flowlight_scene::config::load_config;
use glam::Vec3;
use std::path::Path as FilePath;
use std::time::Instant;

mod lanes;
mod scalar;
mod vertex8;

/// Paths per wave, as MCPT's.
const WAVE: usize = 256;
/// The first lighting depth the roulette plays at (MCPT's default `rr_depth`).
const RR_DEPTH: u32 = 5;
// The roulette divides out the split's 1/k, so it must start past the split vertex.
const _: () = assert!(RR_DEPTH > 1);

/// A shadow ray, the pixel it lights and the contribution it carries if unblocked.
type Shadow = (Ray, u32, Rgb);

/// One camera path between two vertices.
#[derive(Clone)]
struct Path {
    rng: SobolSampler,
    ray: Ray,
    beta: Rgb,
    pixel: u32,
    /// Lighting depth of the vertex the ray leaves.
    depth: u32,
    /// Solid-angle density of the BSDF sample that made `ray`; 0 for the camera ray.
    pdf: f32,
    prev_p: Vec3,
    /// The vertex the ray leaves was the path's last: it is traced for emission only.
    last: bool,
}

/// The scene as the lean path reads it.
struct Lean<'a> {
    scene: &'a flowlight_scene::Scene,
    /// Its mesh, for the cache hints of a wave's hits.
    mesh: MeshView<'a>,
    /// The scene's emitters and power CDF, for the emitters' densities.
    lights: Lights<'a>,
    /// Per material: its Lambertian albedo.
    albedo: Vec<Rgb>,
    path_depth: u32,
    /// Branches per camera path from its first vertex on (MCPT's `branches`).
    branches: u32,
}

#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Scalar,
    Phased,
    Lanes,
    Avx2,
    Surface8,
}

fn fail(msg: String) -> ! {
    eprintln!("lean_path: {msg}");
    std::process::exit(2)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [config, spp, out] = &args[..] else {
        fail("usage: lean_path CONFIG.toml SPP OUT.exr".into())
    };
    let spp: u32 = spp
        .parse()
        .unwrap_or_else(|_| fail(format!("SPP {spp:?}: not a whole number")));
    let mode = match std::env::var("LEAN_MODE").as_deref() {
        Err(_) | Ok("scalar") => Mode::Scalar,
        Ok("phased") => Mode::Phased,
        Ok("lanes") => Mode::Lanes,
        Ok("avx2") if avx2_available() => Mode::Avx2,
        Ok("surface8") if avx2_available() => Mode::Surface8,
        Ok(m @ ("avx2" | "surface8")) => fail(format!("LEAN_MODE={m}: this CPU has no AVX2")),
        Ok(other) => fail(format!(
            "LEAN_MODE={other:?}: scalar, phased, lanes, avx2 or surface8"
        )),
    };
    let config = load_config(FilePath::new(config)).unwrap_or_else(|e| fail(e.to_string()));
    let (width, height, seed) = (config.width, config.height, config.seed);
    let path_depth = config
        .integrator_params
        .iter()
        .find(|(k, _)| k == "path_depth")
        .map_or(Some(32), |(_, v)| v.as_integer())
        .unwrap_or_else(|| fail("path_depth: not a whole number".into()))
        as u32;
    let branches = match std::env::var("LEAN_BRANCHES") {
        Err(_) => 1,
        Ok(k) => match k.parse::<u32>() {
            Ok(k @ 1..=64) => k,
            _ => fail(format!("LEAN_BRANCHES={k:?}: a whole number in 1..=64")),
        },
    };
    let loaded = LoadedScene::load(config).unwrap_or_else(|e| fail(e.to_string()));
    let mut lean = Lean::new(&loaded.scene, path_depth).unwrap_or_else(|e| fail(e));
    lean.branches = branches;
    let t0 = Instant::now();
    let mut image = lean.render(&loaded, mode, spp, seed, width, height);
    let elapsed = t0.elapsed().as_secs_f64();
    let samples = width as f64 * height as f64 * spp as f64;
    println!(
        "lean_path: {elapsed:.3} s, {:.3} µs per camera sample",
        elapsed / samples * 1e6
    );
    for p in &mut image {
        *p *= 1.0 / spp as f32;
    }
    let layer = ImageLayer {
        name: String::new(),
        pixels: &image,
    };
    let meta = ExrMetadata::default();
    write_exr(
        FilePath::new(out),
        width as usize,
        height as usize,
        &[layer],
        &meta,
    )
    .unwrap_or_else(|e| fail(e.to_string()));
}

fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

impl<'a> Lean<'a> {
    /// The scene's tables, or why the lean path cannot render it.
    fn new(scene: &'a flowlight_scene::Scene, path_depth: u32) -> Result<Lean<'a>, String> {
        use flowlight_core::material::DiffuseModel;
        if scene.is_instanced() || !scene.punctual_lights.is_empty() || scene.emitters.is_empty() {
            return Err("a scene without instancing, lit by emissive triangles only".into());
        }
        let mut albedo = Vec::new();
        for (m, name) in scene.materials.iter().zip(&scene.material_names) {
            let lambertian = m.base_color_texture.index < 0
                && m.metallic == 0.0
                && m.transmission == 0.0
                && m.specular == 0.0
                && m.clearcoat == 0.0
                && m.normal_texture.index < 0
                && m.diffuse_model == DiffuseModel::Lambert;
            if !lambertian {
                return Err(format!(
                    "material '{name}': Lambertian materials without textures only"
                ));
            }
            albedo.push(m.base_color);
        }
        Ok(Lean {
            scene,
            mesh: scene.mesh(),
            lights: Lights::area_only(&scene.emitters, &scene.emitter_power_cdf),
            albedo,
            path_depth,
            branches: 1,
        })
    }

    /// Every pixel's `spp` samples, in waves of [`WAVE`] paths: the sum per pixel.
    fn render(
        &self,
        loaded: &LoadedScene,
        mode: Mode,
        spp: u32,
        seed: u64,
        width: u32,
        height: u32,
    ) -> Vec<Rgb> {
        let isect = &*loaded.intersector;
        let mut image = vec![Rgb::ZERO; (width * height) as usize];
        let mut paths: Vec<Path> = Vec::with_capacity(WAVE);
        let mut wave = Buffers::default();
        let total = width as u64 * height as u64 * spp as u64;
        for first in (0..total).step_by(WAVE) {
            paths.clear();
            for n in first..(first + WAVE as u64).min(total) {
                let (pixel, s) = ((n / spp as u64) as u32, (n % spp as u64) as u32);
                let (x, y) = (pixel % width, pixel / width);
                let (mut rng, raster) = sample_start::<SobolSampler>(seed, x, y, s);
                let ray = loaded.camera.sample_ray(raster, &mut rng);
                paths.push(Path {
                    rng,
                    ray,
                    beta: Rgb::ONE,
                    pixel,
                    depth: 0,
                    pdf: 0.0,
                    prev_p: ray.origin,
                    last: false,
                });
            }
            let mut coherent = true;
            while !paths.is_empty() {
                wave.trace(isect, &paths, coherent);
                coherent = false;
                self.bounce(mode, &mut paths, &mut wave, &mut image);
                wave.shadows_traced(isect, &mut image);
            }
        }
        image
    }

    /// The vertices of every path of the wave at its hit, as `mode` runs them; the paths
    /// that go on are kept, in order, and the branches split off this bounce join after them.
    fn bounce(&self, mode: Mode, paths: &mut Vec<Path>, wave: &mut Buffers, image: &mut [Rgb]) {
        let n = paths.len();
        wave.going.resize(n.max(wave.going.len()), false);
        let (hits, going) = (&wave.hits[..n], &mut wave.going[..n]);
        let shadows = &mut wave.shadows;
        shadows.clear();
        let spawned = &mut wave.spawned;
        spawned.clear();
        // Every path of a wave reaches its first vertex in the first bounce.
        let splits = self.branches > 1 && paths.first().is_some_and(|p| p.depth == 0);
        if splits {
            let lanes_split = matches!(mode, Mode::Lanes | Mode::Avx2);
            if lanes_split {
                let (b, avx2) = (&mut wave.branches, mode == Mode::Avx2);
                self.split_in_lanes(avx2, &mut paths[..n], hits, image, shadows, going, b);
                spawned.append(&mut b.paths);
            } else {
                for k in 0..n {
                    self.mesh.prefetch_surfaces(hits, k);
                    going[k] = self.split_vertex(&mut paths[k], &hits[k], image, shadows, spawned);
                }
            }
        }
        match mode {
            _ if splits => {}
            Mode::Scalar => {
                for k in 0..n {
                    self.mesh.prefetch_surfaces(hits, k);
                    going[k] = self.vertex(&mut paths[k], &hits[k], image, shadows);
                }
            }
            Mode::Phased => {
                let surfs = &mut wave.surfs;
                surfs.clear();
                surfs.extend((0..n).map(|k| {
                    self.mesh.prefetch_surfaces(hits, k);
                    self.surface(&mut paths[k], &hits[k], image)
                }));
                for (path, s) in paths.iter_mut().zip(surfs.iter()) {
                    if let Some(s) = s {
                        self.connect(path, s, shadows);
                    }
                }
                for (k, s) in surfs.iter().enumerate() {
                    going[k] = s.as_ref().is_some_and(|s| self.extend(&mut paths[k], s));
                }
            }
            Mode::Lanes | Mode::Avx2 | Mode::Surface8 => {
                for c in (0..n).step_by(lanes::L) {
                    let end = (c + lanes::L).min(n);
                    (c..end).for_each(|k| self.mesh.prefetch_surfaces(hits, k));
                    let mut g = [false; lanes::L];
                    let (ps, hs) = (&mut paths[c..end], &hits[c..end]);
                    let g = &mut g;
                    match mode {
                        // SAFETY (both): the AVX2 modes are chosen only where the CPU has AVX2.
                        #[cfg(target_arch = "x86_64")]
                        Mode::Avx2 => unsafe {
                            vertex8::vertex8_avx2(self, ps, hs, image, shadows, g)
                        },
                        #[cfg(target_arch = "x86_64")]
                        Mode::Surface8 => unsafe {
                            vertex8::surface8_then_scalar_avx2(self, ps, hs, image, shadows, g)
                        },
                        _ => vertex8::vertex8(self, ps, hs, image, shadows, g),
                    }
                    going[c..end].copy_from_slice(&g[..end - c]);
                }
            }
        }
        let mut kept = 0;
        for (k, &g) in going.iter().enumerate() {
            if g {
                paths.swap(kept, k);
                kept += 1;
            }
        }
        paths.truncate(kept);
        paths.append(spawned);
    }
}

impl Lean<'_> {
    /// [`Lean::split_vertex`] for every path of the wave, the branches' connections and
    /// extensions eight at a time in lanes ([`vertex8::branches8`]): the surfaces first, path
    /// by path, then the branches in (path, branch) order, so the shadow rays come in the same
    /// order as the scalar split's. Branch 0 of each path takes its place (`going` says
    /// whether it goes on); the other branches that go on are left in `b.paths`, in order.
    #[allow(clippy::too_many_arguments)]
    fn split_in_lanes(
        &self,
        avx2: bool,
        paths: &mut [Path],
        hits: &[CompactHit],
        image: &mut [Rgb],
        shadows: &mut Vec<Shadow>,
        going: &mut [bool],
        b: &mut BranchBuffers,
    ) {
        let k = self.branches;
        b.paths.clear();
        b.surfs.clear();
        b.owner.clear();
        for (t, path) in paths.iter_mut().enumerate() {
            going[t] = false;
            self.mesh.prefetch_surfaces(hits, t);
            let Some(s) = self.surface(path, &hits[t], image) else {
                continue;
            };
            let trunk = path.rng.clone();
            path.beta /= k as f32;
            for j in 0..k {
                let mut branch = path.clone();
                branch.rng = trunk.branch(j, k);
                b.paths.push(branch);
                b.surfs.push(s.clone());
                b.owner.push((t as u32, j));
            }
        }
        let count = b.paths.len();
        b.going.clear();
        b.going.resize(count, false);
        for c in (0..count).step_by(lanes::L) {
            let end = (c + lanes::L).min(count);
            let mut g = [false; lanes::L];
            let (ps, ss) = (&mut b.paths[c..end], &b.surfs[c..end]);
            match avx2 {
                // SAFETY: the AVX2 mode is chosen only where the CPU has AVX2.
                #[cfg(target_arch = "x86_64")]
                true => unsafe { vertex8::branches8_avx2(self, ps, ss, shadows, &mut g) },
                _ => vertex8::branches8(self, ps, ss, shadows, &mut g),
            }
            b.going[c..end].copy_from_slice(&g[..end - c]);
        }
        let mut kept = 0;
        for i in 0..count {
            let (t, j) = b.owner[i];
            if j == 0 {
                going[t as usize] = b.going[i];
                std::mem::swap(&mut paths[t as usize], &mut b.paths[i]);
            } else if b.going[i] {
                b.paths.swap(kept, i);
                kept += 1;
            }
        }
        b.paths.truncate(kept);
    }
}

/// The branches of a wave's split in lanes: each with its surface and its (path, branch).
#[derive(Default)]
struct BranchBuffers {
    paths: Vec<Path>,
    surfs: Vec<scalar::Surf>,
    owner: Vec<(u32, u32)>,
    going: Vec<bool>,
}

/// A wave's ray batches.
struct Buffers {
    rays: Vec<Ray>,
    hits: Vec<CompactHit>,
    going: Vec<bool>,
    shadows: Vec<Shadow>,
    shadow_rays: Vec<Ray>,
    blocked: Vec<u8>,
    /// The `phased` mode's surfaces, one per path, between its phases.
    surfs: Vec<Option<scalar::Surf>>,
    /// Branches split off in a bounce, before they join the wave.
    spawned: Vec<Path>,
    branches: BranchBuffers,
}

impl Default for Buffers {
    fn default() -> Self {
        let miss = CompactHit {
            t: 0.0,
            prim: u32::MAX,
            b1: 0.0,
            b2: 0.0,
            instance: u32::MAX,
        };
        Buffers {
            rays: Vec::with_capacity(WAVE),
            hits: vec![miss; WAVE],
            going: vec![false; WAVE],
            shadows: Vec::with_capacity(WAVE),
            shadow_rays: Vec::with_capacity(WAVE),
            blocked: vec![0; WAVE],
            surfs: Vec::with_capacity(WAVE),
            spawned: Vec::new(),
            branches: BranchBuffers::default(),
        }
    }
}

impl Buffers {
    /// The closest hits of the paths' rays (the camera rays as one coherent batch).
    fn trace(&mut self, isect: &dyn Intersector, paths: &[Path], coherent: bool) {
        self.rays.clear();
        self.rays.extend(paths.iter().map(|p| p.ray));
        if self.hits.len() < paths.len() {
            self.hits.resize(paths.len(), self.hits[0]);
        }
        let hits = &mut self.hits[..paths.len()];
        if coherent {
            isect.intersect_coherent_batch(&self.rays, hits);
        } else {
            isect.intersect_batch(&self.rays, hits);
        }
    }

    /// The bounce's shadow rays traced, the unblocked ones' contributions added.
    fn shadows_traced(&mut self, isect: &dyn Intersector, image: &mut [Rgb]) {
        if self.shadows.is_empty() {
            return;
        }
        self.shadow_rays.clear();
        self.shadow_rays.extend(self.shadows.iter().map(|s| s.0));
        self.blocked
            .resize(self.shadow_rays.len().max(self.blocked.len()), 0);
        let blocked = &mut self.blocked[..self.shadow_rays.len()];
        isect.occluded_batch(&self.shadow_rays, blocked);
        for (&(_, pixel, c), &b) in self.shadows.iter().zip(blocked.iter()) {
            if b == 0 {
                image[pixel as usize] += c;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: u32 = 24;

    /// The repository's Cornell box (Lambertian, lit by its emissive lamp) at SIZE².
    fn cornell_box() -> LoadedScene {
        let repo = FilePath::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut config = load_config(&repo.join("scenes/cornell-box/cornell-box.toml")).unwrap();
        (config.width, config.height) = (SIZE, SIZE);
        LoadedScene::load(config).unwrap()
    }

    fn bits(image: &[Rgb]) -> Vec<[u32; 3]> {
        image
            .iter()
            .map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()])
            .collect()
    }

    fn mean_luminance(image: &[Rgb], spp: u32) -> f64 {
        let sum: f64 = image.iter().map(|c| c.luminance() as f64).sum();
        sum / (image.len() as f64 * spp as f64)
    }

    /// What `lean-path.sh`'s timings rest on: every mode renders the scalar mode's image bit
    /// for bit, with and without a split at the first vertex (the split in lanes included).
    #[test]
    fn every_mode_renders_the_scalar_image() {
        let loaded = cornell_box();
        let mut modes = vec![Mode::Phased, Mode::Lanes];
        if avx2_available() {
            modes.extend([Mode::Avx2, Mode::Surface8]);
        }
        for branches in [1, 3] {
            let mut lean = Lean::new(&loaded.scene, 8).unwrap();
            lean.branches = branches;
            let scalar = bits(&lean.render(&loaded, Mode::Scalar, 4, 1, SIZE, SIZE));
            for &mode in &modes {
                let image = bits(&lean.render(&loaded, mode, 4, 1, SIZE, SIZE));
                let differ = image.iter().zip(&scalar).filter(|(a, b)| a != b).count();
                assert_eq!(differ, 0, "branches {branches}: {differ} pixels differ");
            }
        }
    }

    /// Splitting keeps the estimator unbiased: the image's mean at three branches agrees
    /// with one branch's within the noise of so few samples.
    #[test]
    fn a_split_changes_the_mean_only_by_noise() {
        let loaded = cornell_box();
        let spp = 16;
        let mean = |branches| {
            let mut lean = Lean::new(&loaded.scene, 8).unwrap();
            lean.branches = branches;
            mean_luminance(&lean.render(&loaded, Mode::Scalar, spp, 7, SIZE, SIZE), spp)
        };
        let (one, three) = (mean(1), mean(3));
        assert!(one > 0.0, "the lamp lights the box");
        assert!(
            (three / one - 1.0).abs() < 0.03,
            "mean luminance {three} at three branches against {one} at one"
        );
    }
}
