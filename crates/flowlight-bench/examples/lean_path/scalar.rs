//! The vertex one path at a time, in three phases (the surface and its emission, the light
//! connection, the roulette and BSDF sample), and the per-path steps the eight-lane vertex
//! ([`super::vertex8`]) shares with it: the emission, the light's numbers and choice, the
//! roulette and the BSDF's numbers.

use super::{Lean, Path, Shadow, RR_DEPTH};
use flowlight_core::geometry::{barycentric_error, offset_ray_origin, Frame, Ray};
use flowlight_core::mesh::CompactHit;
use flowlight_core::sampler::{SampleStream, SLOT_BSDF, SLOT_BSDF_PAIR, SLOT_LIGHT, SLOT_ROULETTE};
use flowlight_core::sampling::{
    cosine_hemisphere, power_heuristic, power_heuristic_over, sample_cdf_remapped, uniform_triangle,
};
use flowlight_core::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// What the phases of a vertex share.
#[derive(Clone)]
pub struct Surf {
    pub p: Vec3,
    pub p_error: Vec3,
    pub ng: Vec3,
    pub frame: Frame,
    pub wo: Vec3,
    pub albedo: Rgb,
}

impl Surf {
    pub fn new(p: Vec3, p_error: Vec3, ng: Vec3, frame: Frame, wo: Vec3, albedo: Rgb) -> Surf {
        Surf {
            p,
            p_error,
            ng,
            frame,
            wo,
            albedo,
        }
    }
}

/// A light sample's choice: the emitter, its probability and the pair for the point on it.
pub struct LightChoice {
    pub emitter: usize,
    pub p_choose: f32,
    pub u: Vec2,
}

impl Lean<'_> {
    /// The work at one hit, the three phases in turn; whether the path goes on.
    #[inline(always)]
    pub fn vertex(
        &self,
        path: &mut Path,
        hit: &CompactHit,
        image: &mut [Rgb],
        shadows: &mut Vec<Shadow>,
    ) -> bool {
        let Some(s) = self.surface(path, hit, image) else {
            return false;
        };
        self.connect(path, &s, shadows);
        self.extend(path, &s)
    }

    /// The vertex where a camera path splits into [`Lean::branches`] branches (its first, as
    /// MCPT's): the surface and its emission once; then per branch j, with the numbers
    /// `rng.branch(j, k)` and β/k, its own light connection and extension, in MCPT's order
    /// (the connections in branch order, each branch j ≥ 1 extended at once and pushed onto
    /// `spawned` where it goes on, branch 0 extended last and going on as the path itself).
    /// Whether the path goes on.
    pub fn split_vertex(
        &self,
        path: &mut Path,
        hit: &CompactHit,
        image: &mut [Rgb],
        shadows: &mut Vec<Shadow>,
        spawned: &mut Vec<Path>,
    ) -> bool {
        let Some(s) = self.surface(path, hit, image) else {
            return false;
        };
        let k = self.branches;
        let trunk = path.rng.clone();
        path.beta /= k as f32;
        let mut first = None;
        for j in 0..k {
            let mut branch = path.clone();
            branch.rng = trunk.branch(j, k);
            self.connect(&mut branch, &s, shadows);
            if j == 0 {
                first = Some(branch);
            } else if self.extend(&mut branch, &s) {
                spawned.push(branch);
            }
        }
        *path = first.expect("at least one branch");
        self.extend(path, &s)
    }

    /// Phase 1: the surface at the hit and its emission; `None` where the path ends here.
    #[inline(always)]
    pub fn surface(&self, path: &mut Path, hit: &CompactHit, image: &mut [Rgb]) -> Option<Surf> {
        if hit.prim == u32::MAX {
            return None;
        }
        let scene = self.scene;
        let tri = hit.prim as usize;
        let idx = scene.triangles[tri].map(|i| i as usize);
        let [p0, p1, p2] = idx.map(|i| scene.positions[i]);
        let b = [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2];
        let p = p0 * b[0] + p1 * b[1] + p2 * b[2];
        let p_error = barycentric_error(b, p0, p1, p2);
        let ng = (p1 - p0).cross(p2 - p0).normalize();
        let mut ns = if scene.normals.is_empty() {
            Vec3::ZERO
        } else {
            let n = idx.map(|i| scene.normals[i]);
            (n[0] * b[0] + n[1] * b[1] + n[2] * b[2]).normalize_or_zero()
        };
        if ns == Vec3::ZERO {
            ns = ng;
        } else if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        let wo_world = -path.ray.dir;
        if !self.emission_and_depth(path, tri, p, wo_world, image) {
            return None;
        }
        let frame = Frame::from_z(ns);
        Some(Surf {
            p,
            p_error,
            ng,
            wo: frame.to_local(wo_world),
            frame,
            albedo: self.albedo[scene.triangle_material[tri] as usize],
        })
    }

    /// Phase 2: the light connection, its shadow ray pushed onto `shadows`.
    #[inline(always)]
    pub fn connect(&self, path: &mut Path, s: &Surf, shadows: &mut Vec<Shadow>) {
        let (p, frame, wo, ng) = (s.p, &s.frame, s.wo, s.ng);
        let choice = self.light_choice(path);
        let em = &self.scene.emitters[choice.emitter];
        let bl = uniform_triangle(choice.u);
        let q = em.p0 * bl[0] + em.p1 * bl[1] + em.p2 * bl[2];
        let to = q - p;
        let d2 = to.length_squared();
        let wi = to / d2.sqrt();
        let cos_l = -wi.dot(em.n);
        if !((cos_l > 0.0 || em.double_sided == 1 && cos_l != 0.0) && d2 > 0.0) {
            return;
        }
        let pdf_l = choice.p_choose / em.area * d2 / cos_l.abs();
        let wi_local = frame.to_local(wi);
        if !(wo.z * wi_local.z > 0.0 && wi.dot(ng) * wi_local.z > 0.0) {
            return;
        }
        let pdf_b = wi_local.z.abs() * FRAC_1_PI;
        let f = s.albedo * FRAC_1_PI;
        let c =
            path.beta * f * em.radiance * (wi_local.z.abs() * power_heuristic_over(pdf_l, pdf_b));
        let q_error = barycentric_error(bl, em.p0, em.p1, em.p2);
        let o = offset_ray_origin(p, s.p_error, ng, to);
        let t = offset_ray_origin(q, q_error, em.n, o - q);
        shadows.push((Ray::new(o, t - o, 1.0 - 1e-4), path.pixel, c));
    }

    /// Phase 3: the roulette and the BSDF sample; whether the path goes on.
    #[inline(always)]
    pub fn extend(&self, path: &mut Path, s: &Surf) -> bool {
        let (frame, wo, ng) = (&s.frame, s.wo, s.ng);
        let Some(u) = self.bsdf_numbers(path, s.albedo) else {
            return false;
        };
        let mut wi = cosine_hemisphere(u);
        if wo.z < 0.0 {
            wi.z = -wi.z;
        }
        if wi.z == 0.0 {
            return false;
        }
        let wi_world = frame.to_world(wi);
        if wi_world.dot(ng) * wi.z <= 0.0 {
            return false;
        }
        let origin = offset_ray_origin(s.p, s.p_error, ng, wi_world);
        self.scatter(
            path,
            s.albedo,
            wi.z.abs() * FRAC_1_PI,
            s.p,
            origin,
            wi_world,
        )
    }

    /// The emission of emitter triangle `tri` at `p` towards `wo` (weighted against the light
    /// sample of the vertex before), added to the path's pixel; then the lighting depth.
    /// Whether the path scatters here.
    #[inline(always)]
    pub fn emission_and_depth(
        &self,
        path: &mut Path,
        tri: usize,
        p: Vec3,
        wo: Vec3,
        image: &mut [Rgb],
    ) -> bool {
        let e = self.scene.triangle_emitter[tri];
        if e >= 0 {
            let em = &self.scene.emitters[e as usize];
            if em.double_sided == 1 || wo.dot(em.n) > 0.0 {
                let w = if path.pdf > 0.0 {
                    let d = p - path.prev_p;
                    let cos = (em.n.dot(d) / d.length()).abs();
                    let pdf_light = self.lights.pdf_area(e as usize) * d.length_squared() / cos;
                    power_heuristic(path.pdf, pdf_light)
                } else {
                    1.0
                };
                image[path.pixel as usize] += path.beta * em.radiance * w;
            }
        }
        if path.last || path.depth + 1 > self.path_depth {
            return false;
        }
        path.depth += 1;
        true
    }

    /// The light pair of the path's vertex and the emitter it chooses (by power).
    #[inline(always)]
    pub fn light_choice(&self, path: &mut Path) -> LightChoice {
        path.rng.seek(path.depth, SLOT_LIGHT);
        let u = path.rng.uniform2();
        let (emitter, p_choose, ux) = sample_cdf_remapped(&self.scene.emitter_power_cdf, u.x);
        LightChoice {
            emitter,
            p_choose,
            u: Vec2::new(ux, u.y),
        }
    }

    /// The roulette on the throughput (from [`RR_DEPTH`] on, survivors divided by their
    /// probability; a branch's throughput without its split's 1/k), then the BSDF's
    /// numbers: its one number (drawn for the slot, unused by a Lambertian surface) and the
    /// pair of its direction. `None` where the path stops.
    #[inline(always)]
    pub fn bsdf_numbers(&self, path: &mut Path, albedo: Rgb) -> Option<Vec2> {
        let vertex = path.depth;
        let last = vertex >= self.path_depth;
        if !last && vertex >= RR_DEPTH {
            // The roulette starts past the split (the first vertex; RR_DEPTH > 1, checked
            // where it is defined), so a branch's β holds its 1/k, which the roulette
            // multiplies back out, as MCPT's does (×1 without branches: the same bits).
            let throughput = path.beta.max_component() * self.branches as f32;
            let survive = (throughput * albedo.max_component()).min(0.95);
            path.rng.seek(vertex, SLOT_ROULETTE);
            if path.rng.uniform() >= survive {
                return None;
            }
            path.beta *= 1.0 / survive;
        }
        path.last = last;
        path.rng.seek(vertex, SLOT_BSDF);
        let _ = path.rng.uniform();
        path.rng.seek(vertex, SLOT_BSDF_PAIR);
        Some(path.rng.uniform2())
    }

    /// The path scatters off `p` into the cosine-sampled `dir` (density `pdf`) with the ray
    /// from `origin`; whether it still carries light.
    #[inline(always)]
    pub fn scatter(
        &self,
        path: &mut Path,
        albedo: Rgb,
        pdf: f32,
        p: Vec3,
        origin: Vec3,
        dir: Vec3,
    ) -> bool {
        path.beta *= albedo;
        if path.beta.is_black() {
            return false;
        }
        path.pdf = pdf;
        path.prev_p = p;
        path.ray = Ray::new(origin, dir, f32::INFINITY);
        true
    }
}
