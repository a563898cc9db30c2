//! The AOV pass: arbitrary output variables (albedo, normal, depth, position, material and
//! object ids) that the host estimates itself, for every integrator alike.
//!
//! # Design
//!
//! The host owns the intersector, the camera and the scene, so it traces its own camera rays
//! in a pass after the beauty: the integrators' random streams and deposits are untouched
//! (the beauty is bit for bit the same with or without AOVs), and MCPT, ERPT, BDPT, VCM,
//! PSSMLT and MMLT all get the same AOVs without a line of plugin code. The cost is one
//! coherent camera-ray batch and one material lookup per AOV sample (plus a ray per Dirac
//! bounce), nothing per path vertex.
//!
//! # What each AOV holds
//!
//! Every sample follows its camera ray through **Dirac** surfaces (smooth mirrors and glass:
//! a material whose BSDF is all Dirac lobes), choosing a lobe as the BSDF's sampling does, to
//! the **first non-Dirac hit**, at most [`MAX_DIRAC_BOUNCES`] of them — what Open Image
//! Denoise expects, so that a mirror shows the albedo and normals of what it reflects. At
//! that surface:
//!
//! * `albedo`: the chain's throughput (f |cos θ_i| / p of each Dirac bounce, the radiance
//!   scaling of refraction undone: a white mirror or clear glass passes 1) times the
//!   material's reflectance at the viewing angle ([`albedo::reflectance`]: the BSDF's
//!   directional albedo, base colour × (1 − metallic) weighted by what the specular layer
//!   leaves, plus the specular layer's own albedo and the coat's);
//! * `normal`: the world-space shading normal (normal maps applied), turned to the side the
//!   ray arrives from (by the geometric normal);
//! * `depth`: the length of the path from the camera (the eye point, or the film plane of an
//!   orthographic camera) to the surface, summed over the Dirac bounces: for a pinhole camera
//!   the Euclidean distance along the ray, not the z of camera space; written in all three
//!   channels;
//! * `position`: the world-space point;
//! * `material_id`, `object_id`: the material's index in the scene's material table and the
//!   object's (a glTF mesh placement: `flowlight_scene::Scene::object_first_virtual`), in all
//!   three channels; −1 where the ray leaves the scene.
//!
//! A ray that leaves the scene gives zero albedo, normal, depth and position.
//!
//! # Filtering
//!
//! The beauty's pixel filter is the box over the pixel (the film's pixel value is the mean
//! radiance over its raster area: `flowlight_core::camera`), so the AOVs are box filtered
//! too: pixel (x, y) holds the mean over `aov_spp` raster positions in [x, x + 1) × [y, y + 1),
//! the 2-D golden-ratio (R2) sequence started at the pixel centre, (½ + i g₁, ½ + i g₂) mod 1
//! with g₁ = 0.7548776662, g₂ = 0.5698402910 (Roberts 2018): well spread for any count. Ids
//! cannot be averaged, so they are **not filtered**: they are the value seen by the first
//! sample, the ray through the pixel centre. Under a thin lens each sample's lens point is
//! uniform on the lens (hashed from the seed, pixel and sample), so the AOVs are defocused as
//! the beauty is.

pub mod albedo;

use crate::intersector::{Intersector, UnitTracer};
use flowlight_core::bsdf::Bsdf;
use flowlight_core::camera::Camera;
use flowlight_core::geometry::{Frame, Ray};
use flowlight_core::mesh::CompactHit;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_scene::config::Aov;
use flowlight_scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Most Dirac bounces a sample follows before it takes the surface it is on.
pub const MAX_DIRAC_BOUNCES: u32 = 8;

/// The R2 sequence's increments: 1/φ₂ and 1/φ₂², φ₂ the plastic number.
const R2: [f64; 2] = [0.754_877_666_246_692_7, 0.569_840_290_998_053_2];

/// What the pass computes and with how many samples.
#[derive(Clone, Debug)]
pub struct AovRequest {
    pub aovs: Vec<Aov>,
    /// Camera samples per pixel (at least 1).
    pub spp: u32,
    /// Seeds the lobe choices at Dirac surfaces (glass: reflect or refract).
    pub seed: u64,
    /// Threads (0: one per core).
    pub threads: usize,
}

/// The AOV layers of a render, planar (`r`, `g`, `b`, row-major, top row first).
#[derive(Clone, Debug)]
pub struct AovImages {
    pub width: u32,
    pub height: u32,
    pub layers: Vec<(Aov, [Vec<f32>; 3])>,
    /// Camera samples per pixel.
    pub spp: u32,
    /// Wall time of the pass.
    pub wall: Duration,
    /// True when Ctrl-C stopped the pass: rows not reached are zero.
    pub interrupted: bool,
}

impl AovImages {
    /// The channels of `aov`, when the pass computed it.
    pub fn layer(&self, aov: Aov) -> Option<&[Vec<f32>; 3]> {
        self.layers.iter().find(|(a, _)| *a == aov).map(|(_, c)| c)
    }

    /// The pixels of `aov` as RGB values.
    pub fn pixels(&self, aov: Aov) -> Option<Vec<Rgb>> {
        let [r, g, b] = self.layer(aov)?;
        Some((0..r.len()).map(|i| Rgb::new(r[i], g[i], b[i])).collect())
    }

    /// The layers as the EXR writer takes them, named by [`Aov::name`].
    pub fn into_planar(self) -> Vec<crate::output::PlanarLayer> {
        self.layers
            .into_iter()
            .map(|(a, channels)| crate::output::PlanarLayer {
                name: a.name().to_string(),
                channels,
            })
            .collect()
    }
}

/// One sample's values at its first non-Dirac surface.
#[derive(Clone, Copy, Debug, Default)]
struct SampleAov {
    albedo: Rgb,
    normal: Vec3,
    depth: f32,
    position: Vec3,
    material: f32,
    object: f32,
}

impl SampleAov {
    const MISS: SampleAov = SampleAov {
        albedo: Rgb::ZERO,
        normal: Vec3::ZERO,
        depth: 0.0,
        position: Vec3::ZERO,
        material: -1.0,
        object: -1.0,
    };
}

/// Raster offset within the pixel of sample `i`: the R2 sequence from the centre.
fn sample_offset(i: u32) -> Vec2 {
    let f = |k: usize| (0.5 + i as f64 * R2[k]).fract() as f32;
    Vec2::new(f(0), f(1))
}

/// The lens pair of sample `i` of `pixel` under a thin lens: hashed from the seed, so it is
/// independent of the raster offset; nothing is drawn for a pinhole.
fn lens_sample(camera: &Camera, seed: u64, pixel: u32, i: u32) -> Vec2 {
    if !camera.has_lens() {
        return Vec2::ZERO;
    }
    Rng::new(Rng::hash(&[seed, pixel as u64, i as u64, 0x6c65_6e73]), 0).uniform2()
}

/// Runs the AOV pass over the whole image (module docs), on the host's worker pool.
pub fn render_aovs(
    scene: &Scene,
    intersector: &dyn Intersector,
    camera: &Camera,
    req: &AovRequest,
    stop: &AtomicBool,
) -> Result<AovImages, String> {
    let start = Instant::now();
    let (w, h) = (camera.width, camera.height);
    let pool = crate::render::worker_pool(req.threads)?;
    let spp = req.spp.max(1);
    let rows: Vec<Option<Vec<SampleAov>>> = pool.install(|| {
        (0..h)
            .into_par_iter()
            .map(|y| {
                if stop.load(Ordering::Relaxed) {
                    return None;
                }
                Some(row(scene, intersector, camera, y, spp, req.seed))
            })
            .collect()
    });
    let interrupted = rows.iter().any(Option::is_none);
    let n = (w * h) as usize;
    let mut layers: Vec<(Aov, [Vec<f32>; 3])> = req
        .aovs
        .iter()
        .map(|&a| (a, std::array::from_fn(|_| vec![0.0f32; n])))
        .collect();
    for (y, r) in rows.iter().enumerate() {
        let Some(r) = r else { continue };
        for (x, s) in r.iter().enumerate() {
            let i = y * w as usize + x;
            for (aov, ch) in layers.iter_mut() {
                let v = match aov {
                    Aov::Albedo => s.albedo.to_array(),
                    Aov::Normal => s.normal.to_array(),
                    Aov::Depth => [s.depth; 3],
                    Aov::Position => s.position.to_array(),
                    Aov::MaterialId => [s.material; 3],
                    Aov::ObjectId => [s.object; 3],
                };
                for c in 0..3 {
                    ch[c][i] = v[c];
                }
            }
        }
    }
    Ok(AovImages {
        width: w,
        height: h,
        layers,
        spp,
        wall: start.elapsed(),
        interrupted,
    })
}

/// The filtered values of row `y`: its camera rays in one coherent batch, then each sample
/// followed through Dirac surfaces and averaged per pixel (ids from sample 0).
fn row(
    scene: &Scene,
    intersector: &dyn Intersector,
    camera: &Camera,
    y: u32,
    spp: u32,
    seed: u64,
) -> Vec<SampleAov> {
    let w = camera.width;
    let mut tracer = UnitTracer::new(scene, intersector);
    let rays: Vec<Ray> = (0..w)
        .flat_map(|x| {
            (0..spp).map(move |i| {
                let raster = Vec2::new(x as f32, y as f32) + sample_offset(i);
                camera.generate_ray_lens(raster, lens_sample(camera, seed, y * w + x, i))
            })
        })
        .collect();
    let mut hits = vec![CompactHit::MISS; rays.len()];
    tracer.intersect_batch(&rays, true, &mut hits);
    let weight = 1.0 / spp as f32;
    (0..w)
        .map(|x| {
            let mut acc = SampleAov::default();
            for i in 0..spp {
                let k = (x * spp + i) as usize;
                let pixel = y as u64 * w as u64 + x as u64;
                let mut rng = Rng::new(Rng::hash(&[seed, pixel, i as u64, 0x0061_6f76]), 0);
                let s = follow(scene, &tracer, &rays[k], hits[k], &mut rng);
                if i == 0 {
                    (acc.material, acc.object) = (s.material, s.object);
                }
                acc.albedo += s.albedo * weight;
                acc.normal += s.normal * weight;
                acc.depth += s.depth * weight;
                acc.position += s.position * weight;
            }
            acc
        })
        .collect()
}

/// One sample from its camera ray's first hit `hit`: through Dirac surfaces to the first
/// non-Dirac one (module docs).
fn follow(
    scene: &Scene,
    tracer: &UnitTracer,
    camera_ray: &Ray,
    hit: CompactHit,
    rng: &mut Rng,
) -> SampleAov {
    let mut ray = *camera_ray;
    let mut hit = hit;
    let mut throughput = Rgb::ONE;
    let mut depth = 0.0f32;
    let mesh = scene.mesh();
    for bounce in 0..=MAX_DIRAC_BOUNCES {
        if !hit.is_hit() {
            return SampleAov::MISS;
        }
        let surface = mesh.surface_hit(&ray, &hit);
        depth += surface.t * ray.dir.length();
        let mut r = scene.materials[surface.material as usize].resolve(
            surface.uvs(),
            surface.color,
            &scene.texture_table,
        );
        let arriving = if surface.ng.dot(ray.dir) > 0.0 {
            -1.0
        } else {
            1.0
        };
        let frame = Frame::from_z(surface.ns);
        let wo = frame.to_local(-ray.dir.normalize());
        r.material
            .layers
            .orient_anisotropy(&mesh, surface.prim, surface.p, surface.ns);
        let bsdf = Bsdf::from_material(&r.material, r.base);
        if !bsdf.is_delta() || bounce == MAX_DIRAC_BOUNCES {
            return SampleAov {
                albedo: throughput * albedo::reflectance(&r.material, r.base, wo),
                normal: surface.ns * arriving,
                depth,
                position: surface.p,
                material: surface.material as f32,
                object: scene.object_of(surface.prim) as f32,
            };
        }
        let Some(s) = bsdf.sample(wo, rng.uniform(), rng.uniform2()) else {
            return SampleAov::MISS;
        };
        // Undo refraction's radiance scaling (1/η'²): the albedo counts light, and a chain
        // into and out of glass would scale it back anyway.
        throughput *= s.f * (s.wi.z.abs() / s.pdf * s.eta * s.eta);
        ray = surface.spawn_ray(frame.to_world(s.wi).normalize());
        hit = tracer
            .closest(&ray)
            .map_or(CompactHit::MISS, CompactHit::from);
    }
    SampleAov::MISS
}

#[cfg(test)]
mod tests;
