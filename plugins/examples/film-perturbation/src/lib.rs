//! # `film-perturbation` — a symmetric film-plane perturbation (example plugin)
//!
//! An example mutation that implements [`Mutation::propose`] and [`Mutation::density`]
//! directly, without the shared regeneration engine of `flowlight-mcmc`. It is the lens
//! perturbation of Veach's MLT in the form thesis §5.4 uses for the eye end of a path:
//!
//! 1. the raster position u of the current path x = x₀ … xₙ moves to u′ drawn uniformly
//!    from the disk of radius r around u (a move off the film is a domain miss);
//! 2. the camera ray through u′ is traced again through the Dirac (mirror, glass) vertices
//!    x₁ … x_{j−1} that follow the eye, taking at each the same kind of Dirac lobe
//!    (reflection or transmission), up to x_j, the first vertex that is not Dirac;
//! 3. if j < n, the new y_j must be smooth (diffuse or glossy) and is connected to x_{j+1}
//!    by a shadow ray; y keeps x_{j+1} … xₙ. If j = n (the eye sees a light, directly or in
//!    mirrors), y_n must lie on an area light that shines back along the chain.
//!
//! Path length and every vertex's weak type (Dirac reflection, Dirac transmission, smooth,
//! light) are kept; anything else is a domain miss (`Proposal::Miss`), and the chain stays.
//!
//! **Density.** The target function's measure is the film measure for the eye ray times the
//! area measure of each free vertex (a vertex after a Dirac vertex is not free:
//! `flowlight-mcmc`'s `measure` module). y₁ … y_j are functions of u′, and y_{j+1} … yₙ equal
//! x's, so the move is a density in u′ alone:
//!
//! ```text
//! T(x → y) = 1/(π r²)   if |u′ − u| ≤ r, u′ on the film, and y_k = x_k for k > j
//! ```
//!
//! The disk is symmetric (u′ is in u's disk exactly when u is in u′'s) and the
//! regeneration is deterministic in both directions, so T(y → x) = T(x → y): every valid
//! proposal reports the transition ratio 1. [`Mutation::density`] returns T, which an
//! integrator needs when it mixes strategies (Σ p(sᵢ) T^{sᵢ}, §5.4).
//!
//! The strategy never changes the light end of a path, so on its own it cannot make ERPT
//! ergodic over paths that differ beyond x_j; the seeds (fresh path-traced samples) supply
//! those, and ERPT stays unbiased (thesis §5.2): `tests/integration/outsider.rs` checks ERPT with this
//! mutation alone against path tracing on the Cornell box, and the conformance kit
//! (`flowlight-testkit`) checks the density, the ratio and the furnace.
//!
//! It counts its moves that leave the film (`film-perturbation.off_film` in the render's
//! statistics, beside `proposals`).
//!
//! | name | type | default | meaning |
//! |---|---|---|---|
//! | `radius` | float | 2 | radius r of the film-plane disk, in pixels |

use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::core::bsdf::Bsdf;
use flowlight_sdk::core::geometry::{Frame, Ray, SurfaceHit};
use flowlight_sdk::core::path::{NodeType, Path, PathVertex};
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::core::sampling::concentric_disk;
use flowlight_sdk::core::{Vec2, Vec3};
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::{export_mutation, param, Mutation, ParamKind, Params, Proposal, Scene, Tracer};

/// The mutation: its disk radius, the scene it regenerates paths in and its counters.
pub struct FilmPerturbation {
    scene: Scene<'static>,
    radius: f32,
    proposals: Counter,
    off_film: Counter,
}

const MISS: Proposal = Proposal::Miss;

/// Float slack (pixels) of the disk test in [`disk_density`]: a sampled point may land a
/// rounding error outside the exact disk, and must still get a positive density.
const SLACK: f32 = 1e-3;

// region: kernel
/// The moved raster position: uniform in the disk of `radius` pixels around `raster`;
/// `None` off the `width` × `height` film.
pub fn perturb(raster: Vec2, radius: f32, width: u32, height: u32, rng: &mut Rng) -> Option<Vec2> {
    let p = raster + concentric_disk(rng.uniform2()) * radius;
    on_film(p, width, height).then_some(p)
}

/// Density per unit raster area of [`perturb`] moving `from` to `to`: 1/(π r²) inside the
/// disk and on the film, else 0. Symmetric in `from` and `to` on the film.
pub fn disk_density(from: Vec2, to: Vec2, radius: f32, width: u32, height: u32) -> f64 {
    if on_film(to, width, height) && (to - from).length() <= radius + SLACK {
        1.0 / (std::f64::consts::PI * radius as f64 * radius as f64)
    } else {
        0.0
    }
}
// endregion: kernel

fn on_film(p: Vec2, width: u32, height: u32) -> bool {
    p.x >= 0.0 && p.y >= 0.0 && p.x < width as f32 && p.y < height as f32
}

/// Index j of the first vertex after the eye that is not a Dirac vertex (module docs).
fn first_free(v: &[PathVertex]) -> usize {
    let mut j = 1;
    while j + 1 < v.len() && v[j].node.is_specular() {
        j += 1;
    }
    j
}

/// The Dirac lobe of `bsdf` of the given kind (reflection or transmission) for outgoing
/// `wo` (local frame): its component index and the mirrored or refracted direction.
fn dirac_lobe(bsdf: &Bsdf, wo: Vec3, transmission: bool) -> Option<(u8, Vec3)> {
    // A dielectric picks reflection when its uniform is below R/(R+T): ask for the branch.
    let uc = if transmission { 1.0 - 1e-7 } else { 0.0 };
    bsdf.components()
        .enumerate()
        .filter(|(_, (c, _))| c.is_delta())
        .find_map(|(i, (c, _))| {
            let s = c.sample_with(wo, uc, Vec2::splat(0.5))?;
            (s.delta && s.node.is_transmission() == transmission).then_some((i as u8, s.wi))
        })
}

impl FilmPerturbation {
    /// `hit` standing in for `original` (a Dirac vertex): the vertex and the ray it sends
    /// on, or `None` when the surface has no Dirac lobe of the same kind.
    fn follow_dirac(
        &self,
        hit: &SurfaceHit,
        original: &PathVertex,
        incoming: Vec3,
    ) -> Option<(PathVertex, Ray)> {
        let frame = Frame::from_z(hit.ns);
        let wo_world = -incoming;
        let wo = frame.to_local(wo_world);
        if wo_world.dot(hit.ng) * wo.z <= 0.0 {
            return None;
        }
        let transmission = original.node == NodeType::SpecularTransmission;
        let (component, wi) = dirac_lobe(&self.scene.bsdf(hit), wo, transmission)?;
        let dir = frame.to_world(wi);
        if dir.dot(hit.ng) * wi.z <= 0.0 {
            return None;
        }
        Some((
            PathVertex::from_hit(hit, original.node, component),
            hit.spawn_ray(dir),
        ))
    }

    /// `hit` standing in for the path's light vertex: an area light seen from `from`.
    fn light_vertex(
        &self,
        hit: &SurfaceHit,
        original: &PathVertex,
        from: Vec3,
    ) -> Option<PathVertex> {
        let lights = &self.scene.lights;
        let area = |e: i32| usize::try_from(e).is_ok_and(|i| i < lights.emitters.len());
        if !area(original.emitter) || !area(hit.emitter) {
            return None; // a point light's vertex is never moved
        }
        let towards = (from - hit.p).try_normalize()?;
        (!lights
            .emitted(hit.emitter as usize, hit.p, towards)
            .is_black())
        .then(|| PathVertex::from_hit(hit, NodeType::Light, 0))
    }
}

impl Mutation for FilmPerturbation {
    const NAME: &'static str = "film-perturbation";
    const DESCRIPTION: &'static str =
        "example: symmetric film-plane perturbation of the camera vertex (disk, ratio 1)";
    const PARAMS: &'static [ParamSpec] = &[param(
        "radius",
        ParamKind::Float,
        "2",
        "radius of the film-plane disk, in pixels",
    )];

    fn create(
        params: &Params,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<Self, String> {
        let radius = params.float("radius", 2.0)?;
        if !(radius > 0.0 && radius <= 4096.0) {
            return Err(format!(
                "parameter 'radius' must be in (0, 4096] pixels, got {radius}"
            ));
        }
        Ok(FilmPerturbation {
            scene,
            radius: radius as f32,
            proposals: stats.sum("proposals"),
            off_film: stats.sum("off_film"),
        })
    }

    // region: propose
    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        x: &Path,
        y: &mut Path,
        stats: &mut Stats,
    ) -> Result<Proposal, String> {
        stats.add(self.proposals, 1.0);
        let xv = x.vertices();
        if xv.len() < 2 {
            return Ok(MISS);
        }
        let n = xv.len() - 1;
        let j = first_free(xv);
        if j < n && xv[j + 1].node.is_specular() {
            return Ok(MISS); // a shadow ray cannot end on a mirror or glass vertex
        }
        let camera = &self.scene.camera;
        let Some(raster) = perturb(x.raster, self.radius, camera.width, camera.height, rng) else {
            stats.add(self.off_film, 1.0);
            return Ok(MISS);
        };
        *y = *x;
        y.raster = raster;
        // A thin lens's point is kept: the move is on the film alone.
        let mut ray = camera.ray_from_eye(raster, xv[0].p);
        y.vertices[0] = PathVertex::eye(ray.origin, camera.forward);
        for k in 1..=j {
            let Some(hit) = tracer.intersect(&ray) else {
                return Ok(MISS);
            };
            if k < j {
                let Some((v, next)) = self.follow_dirac(&hit, &xv[k], ray.dir) else {
                    return Ok(MISS);
                };
                y.vertices[k] = v;
                ray = next;
            } else if j == n {
                let Some(v) = self.light_vertex(&hit, &xv[n], ray.origin) else {
                    return Ok(MISS);
                };
                y.vertices[n] = v;
            } else {
                if xv[j].node == NodeType::Light || !self.scene.bsdf(&hit).has_non_delta() {
                    return Ok(MISS);
                }
                let next = &xv[j + 1];
                if tracer.occluded(&hit.spawn_ray_to(next.p, next.p_error, next.ng)) {
                    return Ok(MISS);
                }
                y.vertices[j] = PathVertex::from_hit(&hit, xv[j].node, xv[j].component);
            }
        }
        // y_{j+1} … y_n are x's (copied above); the move is symmetric (module docs).
        Ok(Proposal::SYMMETRIC)
    }
    // endregion: propose

    // region: density
    fn density(&self, from: &Path, to: &Path) -> f64 {
        let (a, b) = (from.vertices(), to.vertices());
        if a.len() != b.len() || a.len() < 2 || a.iter().zip(b).any(|(u, v)| u.node != v.node) {
            return 0.0;
        }
        let j = first_free(a);
        if j + 1 < a.len() && a[j + 1].node.is_specular() {
            return 0.0;
        }
        if a[j + 1..].iter().zip(&b[j + 1..]).any(|(u, v)| u.p != v.p) {
            return 0.0; // this strategy never moves the vertices after x_j
        }
        let camera = &self.scene.camera;
        if camera.has_lens() && a[0].p != b[0].p {
            return 0.0; // nor a thin lens's point
        }
        disk_density(
            from.raster,
            to.raster,
            self.radius,
            camera.width,
            camera.height,
        )
    }
    // endregion: density
}

export_mutation!(FilmPerturbation);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_library_is_named_after_the_plugin() {
        let expected = format!("flowlight_{}", FilmPerturbation::NAME.replace('-', "_"));
        assert_eq!(env!("CARGO_CRATE_NAME"), expected);
    }

    #[test]
    fn the_disk_is_uniform_and_symmetric() {
        let mut rng = Rng::new(5, 2);
        let start = Vec2::new(30.2, 17.9);
        let (r, trials) = (3.0f32, 40_000);
        let mut inner = 0;
        for _ in 0..trials {
            let p = perturb(start, r, 64, 64, &mut rng).expect("on the film");
            let d = disk_density(start, p, r, 64, 64);
            assert!(d > 0.0, "sampled {p} but density 0");
            assert_eq!(d, disk_density(p, start, r, 64, 64), "symmetric");
            inner += ((p - start).length() < r / 2.0) as u32;
        }
        // A uniform disk has a quarter of its area within half its radius.
        let share = inner as f64 / trials as f64;
        assert!((share - 0.25).abs() < 0.01, "{share}");
        assert_eq!(
            disk_density(start, start + Vec2::new(3.1, 0.0), r, 64, 64),
            0.0
        );
        let expected = 1.0 / (std::f64::consts::PI * 9.0);
        assert!((disk_density(start, start, r, 64, 64) - expected).abs() < 1e-12);
    }

    #[test]
    fn the_free_vertex_skips_dirac_vertices() {
        let mut v = [PathVertex::eye(Vec3::ZERO, Vec3::Z); 5];
        v[1].node = NodeType::SpecularReflection;
        v[2].node = NodeType::SpecularTransmission;
        v[3].node = NodeType::DiffuseReflection;
        v[4].node = NodeType::Light;
        assert_eq!(first_free(&v), 3);
        assert_eq!(first_free(&v[..2]), 1);
        v[3].node = NodeType::SpecularReflection;
        assert_eq!(
            first_free(&v),
            4,
            "E S T S L: the light is the first free vertex"
        );
    }
}
