//! The vertex of [`super::scalar`] for eight paths at a time: the geometry and shading in
//! eight lanes ([`super::lanes`]); the emission, the random numbers, the light's choice and
//! the roulette path by path, by the scalar vertex's own steps. The same operations in the
//! same order as the scalar vertex, so the image is the same bits (the tests below compare
//! the lane functions with the scalar ones; `scripts/lean-path.sh` the images).

// Lane `i` of several arrays at once is the point of these loops.
#![allow(clippy::needless_range_loop)]

use super::lanes::{F, L, M, V3};
use super::scalar::Surf;
use super::{Lean, Path, Shadow};
use flowlight_core::geometry::Frame;
use flowlight_core::geometry::{gamma, Ray};
use flowlight_core::mesh::CompactHit;
use flowlight_core::Rgb;
use std::f32::consts::{FRAC_1_PI, PI};

/// `Frame::from_z` and its two maps, lane by lane.
struct Frame8 {
    x: V3,
    y: V3,
    z: V3,
}

impl Frame8 {
    #[inline(always)]
    fn from_z(n: V3) -> Frame8 {
        let one = F::splat(1.0);
        let sign = n.z.sign();
        let a = -one / (sign + n.z);
        let b = n.x * n.y * a;
        Frame8 {
            x: V3 {
                x: one + sign * n.x * n.x * a,
                y: sign * b,
                z: -sign * n.x,
            },
            y: V3 {
                x: b,
                y: sign + n.y * n.y * a,
                z: -n.y,
            },
            z: n,
        }
    }
    #[inline(always)]
    fn to_local(&self, v: V3) -> V3 {
        V3 {
            x: v.dot(self.x),
            y: v.dot(self.y),
            z: v.dot(self.z),
        }
    }
    #[inline(always)]
    fn to_world(&self, v: V3) -> V3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }
}

#[inline(always)]
fn barycentric_error(b: [F; 3], p0: V3, p1: V3, p2: V3) -> V3 {
    ((p0 * b[0]).abs() + (p1 * b[1]).abs() + (p2 * b[2]).abs()) * F::splat(gamma(7))
}

/// `offset_ray_origin`, lane by lane.
#[inline(always)]
fn offset_ray_origin(p: V3, p_error: V3, ng: V3, w: V3) -> V3 {
    let d = ng.abs().dot(p_error);
    let n = w.dot(ng).lt(F::splat(0.0)).select3(-ng, ng);
    let po = p + n * d;
    V3 {
        x: away_along(po.x, n.x),
        y: away_along(po.y, n.y),
        z: away_along(po.z, n.z),
    }
}

/// `away_along` in integer lane operations without branches: the same results.
#[inline(always)]
fn away_along(v: F, n: F) -> F {
    let mut out = F::default();
    for i in 0..L {
        let (v, n) = (v.0[i], n.0[i]);
        let (bits, nb) = (v.to_bits(), n.to_bits());
        // Same sign: away from zero (bits + 1); opposite: towards zero (bits − 1).
        let away = ((bits ^ nb) >> 31).wrapping_sub(1); // all ones where the signs agree
        let moved = bits.wrapping_add((away & 2).wrapping_sub(1));
        let from_zero = 1 | (nb & 0x8000_0000);
        let infinite = ((bits & 0x7fff_ffff) == 0x7f80_0000) as u32;
        let keep = (n == 0.0) as u32 | n.is_nan() as u32 | (infinite & away & 1);
        let zero = (bits & 0x7fff_ffff == 0) as u32;
        let keep = keep.wrapping_neg();
        let zero = zero.wrapping_neg();
        let r = (bits & keep) | !keep & ((from_zero & zero) | (moved & !zero));
        out.0[i] = f32::from_bits(r);
    }
    out
}

#[inline(always)]
fn sin_cos_quarter(x: F) -> (F, F) {
    let c = F::splat;
    let x2 = x * x;
    let s = x
        * (c(1.0)
            + x2 * (c(-1.0 / 6.0)
                + x2 * (c(1.0 / 120.0) + x2 * (c(-1.0 / 5040.0) + x2 * c(1.0 / 362_880.0)))));
    let co = c(1.0)
        + x2 * (c(-0.5) + x2 * (c(1.0 / 24.0) + x2 * (c(-1.0 / 720.0) + x2 * c(1.0 / 40_320.0))));
    (s, co)
}

/// `cosine_hemisphere` of the pairs (`ux`, `uy`).
#[inline(always)]
fn cosine_hemisphere(ux: F, uy: F) -> V3 {
    let two = F::splat(2.0);
    let one = F::splat(1.0);
    let zero = F::splat(0.0);
    let ox = two * ux - one;
    let oy = two * uy - one;
    let centre = ox.eq(zero).and(oy.eq(zero));
    let wide = ox.abs().gt(oy.abs());
    let num = wide.select(oy, ox);
    let den = wide.select(ox, oy);
    let (s, c) = sin_cos_quarter(F::splat(PI / 4.0) * (num / den));
    let dx = centre.select(zero, den * wide.select(c, s));
    let dy = centre.select(zero, den * wide.select(s, c));
    let z = (one - (dx * dx + dy * dy)).max(zero).sqrt();
    V3 { x: dx, y: dy, z }
}

#[inline(always)]
fn power_heuristic_over(pa: F, pb: F) -> F {
    let mut out = F::default();
    for i in 0..L {
        let (pa, pb) = (pa.0[i], pb.0[i]);
        let a = pa * pa;
        let b = pb * pb;
        out.0[i] = if a.is_infinite() {
            1.0 / pa
        } else if a + b == 0.0 {
            0.0
        } else {
            pa / (a + b)
        };
    }
    out
}

fn rgb(v: &V3, i: usize) -> Rgb {
    Rgb::new(v.x.0[i], v.y.0[i], v.z.0[i])
}

fn set_rgb(v: &mut V3, i: usize, c: Rgb) {
    v.x.0[i] = c.r;
    v.y.0[i] = c.g;
    v.z.0[i] = c.b;
}

/// What the three steps of an eight-lane vertex share: the surfaces in lanes, and which
/// lanes' paths scatter there.
pub struct Surf8 {
    live: [bool; L],
    p: V3,
    p_error: V3,
    ng: V3,
    frame: Frame8,
    wo: V3,
    albedo: V3,
}

impl Surf8 {
    /// Up to eight of the scalar vertex's surfaces in lanes, the lanes past them dead.
    pub fn gather(surfs: &[Surf]) -> Surf8 {
        let mut s = Surf8 {
            live: [false; L],
            p: V3::default(),
            p_error: V3::default(),
            ng: V3::default(),
            frame: Frame8 {
                x: V3::default(),
                y: V3::default(),
                z: V3::default(),
            },
            wo: V3::default(),
            albedo: V3::default(),
        };
        for (i, surf) in surfs.iter().enumerate() {
            s.live[i] = true;
            s.p.set(i, surf.p);
            s.p_error.set(i, surf.p_error);
            s.ng.set(i, surf.ng);
            s.frame.x.set(i, surf.frame.x);
            s.frame.y.set(i, surf.frame.y);
            s.frame.z.set(i, surf.frame.z);
            s.wo.set(i, surf.wo);
            set_rgb(&mut s.albedo, i, surf.albedo);
        }
        s
    }

    /// Lane `i` as the scalar vertex's [`Surf`], where its path scatters.
    pub fn lane(&self, i: usize) -> Option<Surf> {
        let f = &self.frame;
        let frame = Frame {
            x: f.x.get(i),
            y: f.y.get(i),
            z: f.z.get(i),
        };
        let (p, p_error, ng, wo) = (
            self.p.get(i),
            self.p_error.get(i),
            self.ng.get(i),
            self.wo.get(i),
        );
        self.live[i].then(|| Surf::new(p, p_error, ng, frame, wo, rgb(&self.albedo, i)))
    }
}

/// The vertex of up to eight `paths` at their `hits`; `going[i]`: path `i` goes on.
#[inline(always)]
pub fn vertex8(
    lean: &Lean,
    paths: &mut [Path],
    hits: &[CompactHit],
    image: &mut [Rgb],
    shadows: &mut Vec<Shadow>,
    going: &mut [bool; L],
) {
    let mut s = surface8(lean, paths, hits, image);
    connect8(lean, paths, &s, shadows);
    extend8(lean, paths, &mut s, going);
}

/// The surfaces of up to eight `paths` at their `hits` in lanes, and their emission.
#[inline(always)]
pub fn surface8(lean: &Lean, paths: &mut [Path], hits: &[CompactHit], image: &mut [Rgb]) -> Surf8 {
    let scene = lean.scene;
    let n = paths.len();
    let mut live = [false; L];
    let (mut p0, mut p1, mut p2) = (V3::default(), V3::default(), V3::default());
    let (mut n0, mut n1, mut n2) = (V3::default(), V3::default(), V3::default());
    let (mut b1, mut b2) = (F::default(), F::default());
    let mut dir = V3::default();
    let mut albedo = V3::default();
    let mut tris = [0usize; L];
    let smooth = !scene.normals.is_empty();
    for i in 0..n {
        let hit = &hits[i];
        if hit.prim == u32::MAX {
            continue;
        }
        live[i] = true;
        let tri = hit.prim as usize;
        tris[i] = tri;
        let idx = scene.triangles[tri].map(|k| k as usize);
        p0.set(i, scene.positions[idx[0]]);
        p1.set(i, scene.positions[idx[1]]);
        p2.set(i, scene.positions[idx[2]]);
        if smooth {
            n0.set(i, scene.normals[idx[0]]);
            n1.set(i, scene.normals[idx[1]]);
            n2.set(i, scene.normals[idx[2]]);
        }
        b1.0[i] = hit.b1;
        b2.0[i] = hit.b2;
        dir.set(i, paths[i].ray.dir);
        set_rgb(
            &mut albedo,
            i,
            lean.albedo[scene.triangle_material[tri] as usize],
        );
    }
    // The surface.
    let (zero, one) = (F::splat(0.0), F::splat(1.0));
    let b0 = one - b1 - b2;
    let p = p0 * b0 + p1 * b1 + p2 * b2;
    let p_error = barycentric_error([b0, b1, b2], p0, p1, p2);
    let ng = (p1 - p0).cross(p2 - p0).normalize();
    let ns = if smooth {
        (n0 * b0 + n1 * b1 + n2 * b2).normalize_or_zero()
    } else {
        V3::default()
    };
    let flat = ns.x.eq(zero).and(ns.y.eq(zero)).and(ns.z.eq(zero));
    let flip = ns.dot(ng).lt(zero);
    let ns = flat.select3(ng, flip.select3(-ns, ns));
    let wo_world = -dir;
    // Emission and the depth, path by path.
    for i in 0..n {
        live[i] = live[i]
            && lean.emission_and_depth(&mut paths[i], tris[i], p.get(i), wo_world.get(i), image);
    }
    let frame = Frame8::from_z(ns);
    let wo = frame.to_local(wo_world);
    Surf8 {
        live,
        p,
        p_error,
        ng,
        frame,
        wo,
        albedo,
    }
}

/// The light connections of the live lanes of `s`.
#[inline(always)]
pub fn connect8(lean: &Lean, paths: &mut [Path], s: &Surf8, shadows: &mut Vec<Shadow>) {
    let scene = lean.scene;
    let n = paths.len();
    let (live, p, p_error, ng, frame, wo, albedo) =
        (s.live, s.p, s.p_error, s.ng, &s.frame, s.wo, s.albedo);
    let (zero, one) = (F::splat(0.0), F::splat(1.0));
    // The light sample: its numbers and the light's choice lane by lane, its geometry in lanes.
    let (mut ux, mut uy, mut p_choose, mut area) =
        (F::default(), F::default(), F::splat(1.0), F::splat(1.0));
    let (mut e0, mut e1, mut e2, mut en) =
        (V3::default(), V3::default(), V3::default(), V3::default());
    let (mut radiance, mut beta) = (V3::default(), V3::default());
    let mut two_sided = M::default();
    for i in 0..n {
        if !live[i] {
            continue;
        }
        let choice = lean.light_choice(&mut paths[i]);
        let em = &scene.emitters[choice.emitter];
        ux.0[i] = choice.u.x;
        uy.0[i] = choice.u.y;
        p_choose.0[i] = choice.p_choose;
        area.0[i] = em.area;
        e0.set(i, em.p0);
        e1.set(i, em.p1);
        e2.set(i, em.p2);
        en.set(i, em.n);
        set_rgb(&mut radiance, i, em.radiance);
        set_rgb(&mut beta, i, paths[i].beta);
        two_sided.0[i] = if em.double_sided == 1 { u32::MAX } else { 0 };
    }
    let below = ux.lt(uy);
    let half = F::splat(2.0);
    let (b0_lo, b1_hi) = (ux / half, uy / half);
    let l0 = below.select(b0_lo, ux - b1_hi);
    let l1 = below.select(uy - b0_lo, b1_hi);
    let l2 = one - l0 - l1;
    let q = e0 * l0 + e1 * l1 + e2 * l2;
    let to = q - p;
    let d2 = to.dot(to);
    let wi = to / d2.sqrt();
    let cos_l = -wi.dot(en);
    let facing = cos_l
        .gt(zero)
        .or(two_sided.and(cos_l.ne(zero)))
        .and(d2.gt(zero));
    let pdf_l = p_choose / area * d2 / cos_l.abs();
    let wi_local = frame.to_local(wi);
    let sides = (wo.z * wi_local.z)
        .gt(zero)
        .and((wi.dot(ng) * wi_local.z).gt(zero));
    let pdf_b = wi_local.z.abs() * F::splat(FRAC_1_PI);
    let f = albedo * F::splat(FRAC_1_PI);
    let c = beta * f * radiance * (wi_local.z.abs() * power_heuristic_over(pdf_l, pdf_b));
    let q_error = barycentric_error([l0, l1, l2], e0, e1, e2);
    let o = offset_ray_origin(p, p_error, ng, to);
    let t = offset_ray_origin(q, q_error, en, o - q);
    let span = t - o;
    let ok = facing.and(sides);
    for i in 0..n {
        if live[i] && ok.at(i) {
            let ray = Ray::new(o.get(i), span.get(i), 1.0 - 1e-4);
            shadows.push((ray, paths[i].pixel, rgb(&c, i)));
        }
    }
}

/// The roulette and BSDF samples of the live lanes of `s`; `going[i]`: path `i` goes on.
#[inline(always)]
pub fn extend8(lean: &Lean, paths: &mut [Path], s: &mut Surf8, going: &mut [bool; L]) {
    let n = paths.len();
    let (p, p_error, ng, frame, wo, albedo) = (s.p, s.p_error, s.ng, &s.frame, s.wo, s.albedo);
    let live = &mut s.live;
    let zero = F::splat(0.0);
    let (mut ux, mut uy) = (F::default(), F::default());
    // The roulette and the BSDF's numbers path by path, its sample in lanes.
    for i in 0..n {
        if !live[i] {
            continue;
        }
        match lean.bsdf_numbers(&mut paths[i], rgb(&albedo, i)) {
            Some(u) => {
                ux.0[i] = u.x;
                uy.0[i] = u.y;
            }
            None => live[i] = false,
        }
    }
    let mut wi = cosine_hemisphere(ux, uy);
    wi.z = wo.z.lt(zero).select(-wi.z, wi.z);
    let wi_world = frame.to_world(wi);
    let ok = wi.z.ne(zero).and((wi_world.dot(ng) * wi.z).le(zero).not());
    let pdf = wi.z.abs() * F::splat(FRAC_1_PI);
    let origin = offset_ray_origin(p, p_error, ng, wi_world);
    for i in 0..n {
        going[i] = live[i]
            && ok.at(i)
            && lean.scatter(
                &mut paths[i],
                rgb(&albedo, i),
                pdf.0[i],
                p.get(i),
                origin.get(i),
                wi_world.get(i),
            );
    }
}

/// [`vertex8`] with only the surface in lanes ([`surface8`]); the connection and the
/// extension path by path as the scalar vertex runs them: what the surface alone gains.
#[inline(always)]
pub fn surface8_then_scalar(
    lean: &Lean,
    paths: &mut [Path],
    hits: &[CompactHit],
    image: &mut [Rgb],
    shadows: &mut Vec<Shadow>,
    going: &mut [bool; L],
) {
    let s = surface8(lean, paths, hits, image);
    let surfs: [Option<Surf>; L] = std::array::from_fn(|i| s.lane(i));
    for (path, surf) in paths.iter_mut().zip(&surfs) {
        if let Some(surf) = surf {
            lean.connect(path, surf, shadows);
        }
    }
    for (i, path) in paths.iter_mut().enumerate() {
        going[i] = surfs[i]
            .as_ref()
            .is_some_and(|surf| lean.extend(path, surf));
    }
}

/// The light connections and extensions of up to eight branches at the vertex where their
/// camera paths split, `surfs[i]` the surface of `paths[i]`'s split vertex, in lanes: the
/// same connections and extensions as [`Lean::split_vertex`] makes path by path.
#[inline(always)]
pub fn branches8(
    lean: &Lean,
    paths: &mut [Path],
    surfs: &[Surf],
    shadows: &mut Vec<Shadow>,
    going: &mut [bool; L],
) {
    let mut s = Surf8::gather(surfs);
    connect8(lean, paths, &s, shadows);
    extend8(lean, paths, &mut s, going);
}

/// `$avx2`: `$step` compiled for AVX2, eight lanes per instruction (`$step` and what it
/// calls are inlined into it).
macro_rules! avx2_version {
    ($avx2:ident = $step:ident($($arg:ident: $ty:ty),* $(,)?)) => {
        #[doc = concat!("[`", stringify!($step), "`] compiled for AVX2.")]
        ///
        /// # Safety
        /// The CPU must have AVX2 (`is_x86_feature_detected!("avx2")`).
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        pub unsafe fn $avx2($($arg: $ty),*) {
            $step($($arg),*)
        }
    };
}

/// The arguments of a vertex's step in lanes: the paths at their hits.
macro_rules! vertex_step_avx2 {
    ($avx2:ident = $step:ident) => {
        avx2_version!($avx2 = $step(
            lean: &Lean,
            paths: &mut [Path],
            hits: &[CompactHit],
            image: &mut [Rgb],
            shadows: &mut Vec<Shadow>,
            going: &mut [bool; L],
        ));
    };
}
vertex_step_avx2!(vertex8_avx2 = vertex8);
vertex_step_avx2!(surface8_then_scalar_avx2 = surface8_then_scalar);
avx2_version!(branches8_avx2 = branches8(
    lean: &Lean,
    paths: &mut [Path],
    surfs: &[Surf],
    shadows: &mut Vec<Shadow>,
    going: &mut [bool; L],
));

#[cfg(test)]
mod tests {
    //! Each lane function against the scalar function it stands for, bit for bit, on
    //! random inputs and the edge cases the scalar code handles (zeros, signs, the disk's
    //! centre).
    use super::*;
    use flowlight_core::geometry::{
        barycentric_error as bary1, offset_ray_origin as offset1, Frame,
    };
    use flowlight_core::rng::Rng;
    use flowlight_core::sampling::{
        cosine_hemisphere as cosine1, power_heuristic_over as heuristic1,
    };
    use glam::{Vec2, Vec3};

    fn same(a: Vec3, b: Vec3) -> bool {
        a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
    }

    /// Eight random vectors with components in ±2^[−10, 10], some of them zero.
    fn vectors(r: &mut Rng) -> [Vec3; L] {
        let c = |r: &mut Rng| {
            if r.uniform() < 0.1 {
                0.0
            } else {
                let m = (r.uniform() * 20.0 - 10.0).exp2();
                if r.uniform() < 0.5 {
                    -m
                } else {
                    m
                }
            }
        };
        std::array::from_fn(|_| Vec3::new(c(r), c(r), c(r)))
    }

    fn lanes3(v: &[Vec3; L]) -> V3 {
        let mut out = V3::default();
        for (i, &x) in v.iter().enumerate() {
            out.set(i, x);
        }
        out
    }

    #[test]
    fn offsets_frames_and_errors_match_the_scalar_ones() {
        let mut r = Rng::new(7, 0);
        for _ in 0..2_000 {
            let (p, e, w) = (vectors(&mut r), vectors(&mut r), vectors(&mut r));
            let ng = vectors(&mut r).map(|n| n.try_normalize().unwrap_or(Vec3::Z));
            let b: [f32; 3] = std::array::from_fn(|_| r.uniform());
            let got = offset_ray_origin(lanes3(&p), lanes3(&e), lanes3(&ng), lanes3(&w));
            let frame = Frame8::from_z(lanes3(&ng));
            let (local, world) = (frame.to_local(lanes3(&w)), frame.to_world(lanes3(&w)));
            let err = barycentric_error(b.map(F::splat), lanes3(&p), lanes3(&e), lanes3(&w));
            for i in 0..L {
                assert!(
                    same(got.get(i), offset1(p[i], e[i], ng[i], w[i])),
                    "offset {i}: {p:?} {ng:?}"
                );
                let f = Frame::from_z(ng[i]);
                assert!(
                    same(local.get(i), f.to_local(w[i])) && same(world.get(i), f.to_world(w[i]))
                );
                assert!(same(err.get(i), bary1(b, p[i], e[i], w[i])));
            }
        }
    }

    #[test]
    fn normals_match_glam() {
        let mut r = Rng::new(8, 0);
        for _ in 0..2_000 {
            let v = vectors(&mut r);
            let (n, z) = (lanes3(&v).normalize(), lanes3(&v).normalize_or_zero());
            for i in 0..L {
                if v[i] != Vec3::ZERO {
                    assert!(same(n.get(i), v[i].normalize()));
                }
                assert!(same(z.get(i), v[i].normalize_or_zero()));
            }
        }
    }

    #[test]
    fn cosine_samples_and_weights_match_the_scalar_ones() {
        let mut r = Rng::new(9, 0);
        for round in 0..4_000 {
            let mut u: [Vec2; L] = std::array::from_fn(|_| Vec2::new(r.uniform(), r.uniform()));
            if round == 0 {
                u[0] = Vec2::splat(0.5); // the disk's centre
                u[1] = Vec2::new(0.5, 0.25);
                u[2] = Vec2::new(0.25, 0.5);
                u[3] = Vec2::ZERO;
            }
            let got = cosine_hemisphere(F(u.map(|u| u.x)), F(u.map(|u| u.y)));
            let pa: [f32; L] =
                std::array::from_fn(|i| if i == 0 { 0.0 } else { r.uniform() * 10.0 });
            let pb: [f32; L] =
                std::array::from_fn(|i| if i < 2 { 0.0 } else { r.uniform() * 10.0 });
            let w = power_heuristic_over(F(pa), F(pb));
            for i in 0..L {
                assert!(same(got.get(i), cosine1(u[i])), "{:?}", u[i]);
                assert_eq!(w.0[i].to_bits(), heuristic1(pa[i], pb[i]).to_bits());
            }
        }
    }
}
