//! # `ao-aov` — ambient occlusion with albedo and normal layers (example plugin)
//!
//! An example integrator built outside the workspace, as docs/writing-a-plugin.md walks
//! through it. For the first surface x a camera ray hits, with n the shading normal turned
//! towards the camera, it estimates the ambient occlusion
//!
//! ```text
//! AO(x) = (1/π) ∫_{H²(n)} V(x, ω, r) cos θ dω  ≈  (1/m) Σᵢ V(x, ωᵢ, r),  ωᵢ ~ cos θ / π
//! ```
//!
//! where V(x, ω, r) is 1 when a ray from x along ω meets nothing closer than the radius r,
//! and ωᵢ are m cosine-distributed directions (Malley's method: uniform points of the unit
//! disk lifted onto the hemisphere, `sampling::cosine_hemisphere`). A direction below the
//! geometric surface counts as occluded. An open plane has AO = 1; a point at distance d
//! from an infinite perpendicular wall has AO = 1 − (acos a − a√(1 − a²))/π with
//! a = min(d/r, 1) — the share of the unit disk beyond x = a (the test in tests/integration/outsider.rs).
//! A camera ray that hits nothing deposits nothing (0).
//!
//! With `aovs = true` the plugin also writes what denoisers take as auxiliary images, in
//! the host's lighting layers (EXR layers `layer0`, `layer1`, `layer2`):
//!
//! * `layer0` — the ambient occlusion;
//! * `layer1` — the albedo: the base colour at x (factor × texture × vertex colour);
//! * `layer2` — the world-space shading normal facing the camera, stored as (n + 1)/2 so
//!   that it is non-negative (the host discards negative deposits): decode with 2c − 1.
//!
//! **The host adds every deposit to the main image as well** (its layers are lighting
//! layers that sum to the image), so with `aovs = true` the main `R,G,B` is the sum of the
//! three and only the layers are meaningful; with `aovs = false` (default) the main image is
//! the ambient occlusion. AOV channels that bypass the main image need host support that
//! does not exist yet.
//!
//! | name | type | default | meaning |
//! |---|---|---|---|
//! | `radius` | float | 0 | occlusion radius r in scene units; 0: a tenth of the scene's bounding-box diagonal |
//! | `ao_samples` | int | 4 | occlusion rays m per pixel sample |
//! | `aovs` | bool | false | write AO, albedo and normal as layers `layer0`…`layer2` |

use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::geometry::{Frame, Ray, SurfaceHit};
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::core::sampling::cosine_hemisphere;
use flowlight_sdk::core::{Rgb, Vec2, Vec3};
use flowlight_sdk::{
    export_integrator, param, Film, Integrator, IntegratorInfo, MutationSet, ParamKind, Params,
    Scene, Stats, StatsBuilder, Tracer, WorkUnit,
};

// region: declaration
/// The integrator: its settings and the scene, read-only while the host's threads render.
pub struct AmbientOcclusion {
    scene: Scene<'static>,
    radius: f32,
    samples: u32,
    aovs: bool,
}

/// Layers written with `aovs = true`.
const AO_LAYER: u32 = 0;
const ALBEDO_LAYER: u32 = 1;
const NORMAL_LAYER: u32 = 2;

const PARAMS: &[ParamSpec] = &[
    param(
        "radius",
        ParamKind::Float,
        "0",
        "occlusion radius in scene units (0: a tenth of the scene's diagonal)",
    ),
    param(
        "ao_samples",
        ParamKind::Int,
        "4",
        "occlusion rays per pixel sample",
    ),
    param(
        "aovs",
        ParamKind::Bool,
        "false",
        "write AO, albedo and normal as layers layer0..layer2",
    ),
];
// endregion: declaration

// region: estimator
/// The AO estimate at `hit` for a camera ray leaving along `wo` (towards the camera): the
/// share of `samples` cosine-distributed rays that meet nothing within `radius`.
pub fn ambient_occlusion(
    tracer: &Tracer,
    rng: &mut Rng,
    hit: &SurfaceHit,
    wo: Vec3,
    radius: f32,
    samples: u32,
) -> f32 {
    // Two-sided: the hemisphere on the camera's side of the surface.
    let side = if hit.ng.dot(wo) < 0.0 { -1.0 } else { 1.0 };
    let (ng, ns) = (hit.ng * side, hit.ns * side);
    let frame = Frame::from_z(ns);
    let mut open = 0u32;
    for _ in 0..samples {
        let dir = frame.to_world(cosine_hemisphere(rng.uniform2()));
        if dir.dot(ng) <= 0.0 {
            continue; // below the geometric surface: blocked by the surface itself
        }
        let ray = Ray {
            t_max: radius,
            ..hit.spawn_ray(dir)
        };
        if !tracer.occluded(&ray) {
            open += 1;
        }
    }
    open as f32 / samples as f32
}
// endregion: estimator

/// The shading normal on the camera's side, encoded as (n + 1)/2.
fn encoded_normal(hit: &SurfaceHit, wo: Vec3) -> Rgb {
    let n = if hit.ng.dot(wo) < 0.0 {
        -hit.ns
    } else {
        hit.ns
    };
    let c = (n + Vec3::ONE) * 0.5;
    Rgb::from_array([c.x, c.y, c.z])
}

impl Integrator for AmbientOcclusion {
    const NAME: &'static str = "ao-aov";
    const DESCRIPTION: &'static str =
        "example: ambient occlusion, with albedo and normal layers for denoisers";
    const PARAMS: &'static [ParamSpec] = PARAMS;

    // region: create
    fn create(
        params: &Params,
        _mutations: MutationSet<'static>,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let mut radius = params.float("radius", 0.0)?;
        if !(radius >= 0.0 && radius.is_finite()) {
            return Err(format!("parameter 'radius' must be >= 0, got {radius}"));
        }
        if radius == 0.0 {
            radius = 0.2 * scene.radius() as f64; // a tenth of the diagonal
        }
        let samples = params.int("ao_samples", 4)?;
        if !(1..=4096).contains(&samples) {
            return Err(format!(
                "parameter 'ao_samples' must be in 1..=4096, got {samples}"
            ));
        }
        let aovs = params.boolean("aovs", false)?;
        let info = IntegratorInfo {
            // Three extra EXR layers with `aovs`; the main image only without.
            layer_count: if aovs { 3 } else { 0 },
            ..IntegratorInfo::simple()
        };
        let ao = AmbientOcclusion {
            scene,
            radius: radius as f32,
            samples: samples as u32,
            aovs,
        };
        Ok((ao, info))
    }
    // endregion: create

    // region: render
    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        _stats: &mut Stats,
    ) -> Result<(), String> {
        for y in unit.y0..unit.y1 {
            for x in unit.x0..unit.x1 {
                for s in unit.sample_begin..unit.sample_begin + unit.sample_count {
                    // One stream per (render seed, pixel, sample): the image is the same for
                    // any number of threads and any split into work units.
                    let key = [unit.seed, x as u64, y as u64, s as u64];
                    let mut rng = Rng::new(Rng::hash(&key), 0);
                    let raster = Vec2::new(x as f32, y as f32) + rng.uniform2();
                    let ray = self.scene.camera.sample_ray(raster, &mut rng);
                    let Some(hit) = tracer.intersect(&ray) else {
                        continue; // nothing there: 0 in every layer
                    };
                    let wo = -ray.dir;
                    let ao =
                        ambient_occlusion(tracer, &mut rng, &hit, wo, self.radius, self.samples);
                    // Box filter: every deposit goes to the centre of the sample's pixel.
                    let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
                    film.deposit(cx, cy, AO_LAYER, Rgb::splat(ao));
                    if self.aovs {
                        let albedo = self.scene.resolve(&hit).base;
                        film.deposit(cx, cy, ALBEDO_LAYER, albedo);
                        film.deposit(cx, cy, NORMAL_LAYER, encoded_normal(&hit, wo));
                    }
                }
            }
        }
        Ok(())
    }
    // endregion: render
}

// region: export
export_integrator!(AmbientOcclusion);
// endregion: export

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_library_is_named_after_the_plugin() {
        let expected = format!("flowlight_{}", AmbientOcclusion::NAME.replace('-', "_"));
        assert_eq!(env!("CARGO_CRATE_NAME"), expected);
    }

    #[test]
    fn normals_are_encoded_non_negative_and_face_the_camera() {
        let mut hit: SurfaceHit = hit_at_origin();
        hit.ng = Vec3::Z;
        hit.ns = Vec3::Z;
        assert_eq!(encoded_normal(&hit, Vec3::Z).to_array(), [0.5, 0.5, 1.0]);
        // Seen from below, the normal is turned towards the camera.
        assert_eq!(encoded_normal(&hit, -Vec3::Z).to_array(), [0.5, 0.5, 0.0]);
    }

    /// A hit at the origin (the fields the helpers read are set by the tests).
    fn hit_at_origin() -> SurfaceHit {
        SurfaceHit {
            t: 1.0,
            p: Vec3::ZERO,
            p_error: Vec3::ZERO,
            ng: Vec3::Z,
            ns: Vec3::Z,
            uv: Vec2::ZERO,
            uv1: Vec2::ZERO,
            color: [1.0; 4],
            prim: 0,
            material: 0,
            emitter: -1,
        }
    }
}
