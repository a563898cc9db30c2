//! The caustic perturbation (Veach 1997 §11.4.4): move a path's specular chain from its light
//! side, with its transition density in the target function's measure.
//!
//! **Which chain.** A path x₀ (eye) … xₙ has a *caustic chain* (d, m) when x_d is smooth,
//! x_{d+1} … x_{m−1} are Dirac vertices (at least one), x_m is a smooth vertex or a point on an
//! area light, and x_{d−1} is the eye or smooth (so that x_d can be connected to it). Of
//! several, the one nearest the light (largest m) is taken; the choice depends on the weak
//! path type alone, which every proposal keeps, so x and y always agree on it. E D S+ L paths
//! (d = 1, m = n) are the caustics of Veach's name; E D D S L (d = 2) and E D S D L (m < n) are
//! moved the same way.
//!
//! **The move.** Keep x_m … xₙ and x₀ … x_{d−1}. Draw a new direction ω' at x_m from the
//! exponential cone around ω = (x_{m−1} − x_m)/|·| ([`ExpCone`]: θ log-uniform in [θ₁, θ₂]
//! with a uniform core inside θ₁, Veach's θ₁ = 10⁻⁴, θ₂ = 0.1 rad), trace it through the Dirac vertices (same lobe kind at
//! each, else a domain miss) to a smooth y_d, and connect y_d to x_{d−1} with a shadow ray.
//! With d = 1 the new raster position is the projection of y₁; it must lie in the chain's
//! K×K film window around x's (the convention of [`crate::migration`], symmetric; with K = 0
//! such proposals are domain misses).
//!
//! **The measure.** The target function f is a density in μ = film measure (eye ray) × area
//! measure of every free vertex, and a vertex after a Dirac vertex is not free
//! ([`crate::measure`]). The move keeps x_m, whose position is *not* a free coordinate of μ
//! (it follows x_{m−1}, a Dirac vertex): in μ the proposals lie on the leaf {y_m = x_m}, a set
//! of μ-measure zero, so T has no density in μ. Detailed balance is kept leaf by leaf: write
//! μ near the path in the coordinates (x_m ∈ area, ω_m ∈ solid angle, the rest) as
//! dμ = J · dA(x_m) dσ(ω_m) · (the rest), then the target restricted to a leaf has density
//! f·J in σ(ω_m), the cone density q is symmetric in ω ↔ ω', and Metropolis–Hastings on the
//! leaf accepts with f(y)J(y) / (f(x)J(x)). The strategy reports this as a density "in μ"
//! with the leaf's Dirac factor left implicit:
//!
//! ```text
//! T(x → y) = q(ω → ω') / J(y),      T(y → x) / T(x → y) = J(y) / J(x)
//! ```
//!
//! (times the window indicator when d = 1). Other strategies give such a y no density: a
//! point traced after a moved Dirac vertex lands on x_m with probability 0, and
//! [`crate::regenerate::density`] returns 0 for it, so the mixture density stays consistent.
//!
//! **The Jacobian J = dμ / (dA(x_m) dσ(ω_m))**, in closed form from the stored vertices,
//! with ng the geometric and ns the shading normal. Follow the ray bundle from x_m towards
//! the eye. Straight flight conserves the étendue dA |ng·ω| dσ between the two ends of a
//! segment. At a Dirac vertex k, in the coordinates (position on the surface, direction), the
//! map (x, ω_in) ↦ (x, ω_out) has a block-triangular Jacobian (the outgoing direction depends
//! on x through the shading normal, but x is unchanged), so dA dσ_out = s_k dA dσ_in with the
//! direction Jacobian at fixed x: s_k = 1 for a mirror, and Snell's
//! s_k = (η_in/η_out)² |ns·ω_in| / |ns·ω_out| for a refraction (η of the medium on each
//! side: 1 on the side ns points to, the material's ior on the other). So
//!
//! ```text
//! dA(x_{d+1}) dσ(ω_{d+1→d}) = C · dA(x_m) dσ(ω_m),
//! C = |ng_m·ω_m| · Π_{k=d+2}^{m−1} s_k |ng_k·ω_out,k| / |ng_k·ω_in,k| · s_{d+1} / |ng_{d+1}·ω_in,d+1|
//! ```
//!
//! and dσ(ω_{d+1→d}) = |ng_d·ω| / |x_d − x_{d+1}|² dA(x_d), so
//!
//! ```text
//! J = C · |x_d − x_{d+1}|² / |ng_d·ω_{d+1→d}|   (· du/dA(x₁) when d = 1)
//! ```
//!
//! with the film Jacobian du/dA(x₁) = (W·H / (4 e_x e_y)) · |ng₁·ω| / (cos³θ_c |x₁ − x₀|²) for a
//! pinhole (e the tangents of the half fields of view, θ_c the angle to the optical axis) and
//! (W·H / (4 e_x e_y)) · |ng₁·forward| for an orthographic camera (e its half extents). For a
//! curved mirror with ns = ng, C reduces to |cos θ_m| / |cos θ_{d+1}|: the conservation of
//! étendue Veach's generalized geometry terms (§11.4–11.5, §8.3.2) express.

use crate::measure::{dirac_scatter, light_index, side_consistent, vertex_bsdf, WeakNode};
use crate::perturbation::ExpCone;
use crate::regenerate::trace_vertex;
use flowlight_core::camera::Projection;
use flowlight_core::geometry::{offset_ray_origin, Frame};
use flowlight_core::path::{Path, PathVertex};
use flowlight_core::rng::Rng;
use flowlight_sdk::{Proposal, Scene, Tracer};
use glam::{DVec3, Vec3};

const MISS: Proposal = Proposal::Miss;

/// Whether `v` is a point on an area light.
fn on_area_light(scene: &Scene, v: &PathVertex) -> bool {
    light_index(scene, v).is_some_and(|i| i < scene.lights.emitters.len())
}

/// The caustic chain (d, m) of a path (module docs), or `None`.
pub fn caustic_chain(scene: &Scene, v: &[PathVertex]) -> Option<(usize, usize)> {
    let n = v.len().checked_sub(1)?;
    for m in (3..=n).rev() {
        let end = WeakNode::of(&v[m]);
        let end_ok =
            end == WeakNode::Smooth || (end == WeakNode::Light && on_area_light(scene, &v[m]));
        if !end_ok || !WeakNode::of(&v[m - 1]).is_dirac() {
            continue;
        }
        let mut d = m - 1;
        while d > 0 && WeakNode::of(&v[d]).is_dirac() {
            d -= 1;
        }
        if d == 0 || WeakNode::of(&v[d]) != WeakNode::Smooth {
            continue;
        }
        if matches!(WeakNode::of(&v[d - 1]), WeakNode::Eye | WeakNode::Smooth) {
            return Some((d, m));
        }
    }
    None
}

fn dv(v: Vec3) -> DVec3 {
    v.as_dvec3()
}

/// Index of refraction of the medium on the side of `v`'s shading normal that `w` points to.
fn medium_ior(scene: &Scene, v: &PathVertex, w: DVec3) -> f64 {
    if dv(v.ns).dot(w) > 0.0 {
        1.0
    } else {
        scene
            .materials
            .get(v.material as usize)
            .map_or(1.0, |m| m.ior as f64)
    }
}

/// du/dA(x₁): raster area per unit area at the first vertex (module docs).
pub fn film_jacobian(scene: &Scene, eye: &PathVertex, x1: &PathVertex) -> f64 {
    let cam = &scene.camera;
    let (ey, ortho) = match cam.kind() {
        Projection::Perspective => (cam.tan_half_fov_y as f64, false),
        Projection::Orthographic => (cam.ortho_half_height as f64, true),
    };
    let ex = ey * cam.aspect() as f64;
    let scale = cam.width as f64 * cam.height as f64 / (4.0 * ex * ey);
    let fwd = dv(cam.forward).normalize();
    let ng = dv(x1.ng).normalize();
    if ortho {
        return scale * ng.dot(fwd).abs();
    }
    let d = dv(x1.p) - dv(eye.p);
    let d2 = d.length_squared();
    let w = d / d2.sqrt();
    let c = fwd.dot(w);
    if c <= 0.0 || d2 <= 0.0 {
        return 0.0;
    }
    scale * ng.dot(w).abs() / (c * c * c * d2)
}

/// J = dμ / (dA(x_m) dσ(ω_m)) of the caustic chain (d, m) of `v` (module docs). 0 for a
/// degenerate configuration.
pub fn leaf_jacobian(scene: &Scene, v: &[PathVertex], d: usize, m: usize) -> f64 {
    let p = |k: usize| dv(v[k].p);
    let ng = |k: usize| dv(v[k].ng).normalize();
    let dir = |a: usize, b: usize| (p(b) - p(a)).normalize();
    let mut c = ng(m).dot(dir(m, m - 1)).abs();
    for k in (d + 1..m).rev() {
        let (w_in, w_out) = (dir(k, k + 1), dir(k, k - 1));
        let cos_in = ng(k).dot(w_in).abs();
        if cos_in <= 0.0 {
            return 0.0;
        }
        let s = if WeakNode::of(&v[k]) == WeakNode::DiracTransmission {
            let ns = dv(v[k].ns).normalize();
            let (ci, co) = (ns.dot(w_in).abs(), ns.dot(w_out).abs());
            if co <= 0.0 {
                return 0.0;
            }
            let eta = medium_ior(scene, &v[k], w_in) / medium_ior(scene, &v[k], w_out);
            eta * eta * ci / co
        } else {
            1.0
        };
        c *= s / cos_in;
        if k > d + 1 {
            c *= ng(k).dot(w_out).abs();
        }
    }
    let seg = p(d) - p(d + 1);
    let d2 = seg.length_squared();
    let cos_d = ng(d).dot(seg / d2.sqrt()).abs();
    if cos_d <= 0.0 {
        return 0.0;
    }
    let mut j = c * d2 / cos_d;
    if d == 1 {
        j *= film_jacobian(scene, &v[0], &v[1]);
    }
    if j.is_finite() {
        j
    } else {
        0.0
    }
}

/// Whether `a` and `b` are within half the K×K window of each other (K > 0).
fn in_window(a: glam::Vec2, b: glam::Vec2, k: u32) -> bool {
    let half = k as f32 * 0.5;
    let d = (a - b).abs();
    k > 0 && d.x <= half && d.y <= half
}

/// Proposes y from x by the caustic perturbation (module docs).
pub fn propose(
    scene: &Scene,
    tracer: &Tracer,
    rng: &mut Rng,
    cone: &ExpCone,
    x: &Path,
    y: &mut Path,
) -> Proposal {
    let xv = x.vertices();
    let Some((d, m)) = caustic_chain(scene, xv) else {
        return MISS;
    };
    if d == 1 && x.film_window == 0 {
        return MISS;
    }
    *y = *x;
    if trace_chain(scene, tracer, rng, cone, x, y, d, m).is_none() {
        return MISS;
    }
    let forward = density(scene, cone, x, y);
    let reverse = density(scene, cone, y, x);
    let ratio = reverse / forward;
    Proposal::Move {
        transition_ratio: if ratio.is_finite() && ratio >= 0.0 {
            ratio as f32
        } else {
            f32::NAN
        },
    }
}

/// Traces the perturbed chain from x_m to y_d and connects y_d to x_{d−1}; `y` starts as a
/// copy of `x`.
#[allow(clippy::too_many_arguments)]
fn trace_chain(
    scene: &Scene,
    tracer: &Tracer,
    rng: &mut Rng,
    cone: &ExpCone,
    x: &Path,
    y: &mut Path,
    d: usize,
    m: usize,
) -> Option<()> {
    let xv = x.vertices();
    let xm = xv[m];
    let axis = (xv[m - 1].p - xm.p).try_normalize()?;
    let mut w = cone.sample(axis, rng);
    if !side_consistent(xm.ng, w, Frame::from_z(xm.ns).to_local(w)) {
        return None;
    }
    let mut prev = xm;
    for k in (d..m).rev() {
        let ray = prev.surface().spawn_ray(w);
        let v = trace_vertex(scene, tracer, &ray, prev.p, &xv[k])?;
        y.vertices[k] = v;
        if k == d {
            break;
        }
        // Follow the Dirac lobe of v from the light side towards the eye.
        let frame = Frame::from_z(v.ns);
        let wo_w = (prev.p - v.p).try_normalize()?;
        let wo = frame.to_local(wo_w);
        if !side_consistent(v.ng, wo_w, wo) {
            return None;
        }
        let bsdf = vertex_bsdf(scene, &v)?;
        let (c, _) = bsdf.components().nth(v.component as usize)?;
        let transmission = WeakNode::of(&v) == WeakNode::DiracTransmission;
        let (wi, _) = dirac_scatter(&c, wo, transmission)?;
        w = frame.to_world(wi);
        if !side_consistent(v.ng, w, wi) {
            return None;
        }
        prev = v;
    }
    let yd = y.vertices[d];
    if d == 1 {
        // Seen from x's eye vertex: a lens point is kept (`flowlight_core::thin_lens`).
        let raster = scene.camera.project_from_eye(xv[0].p, yd.p)?;
        if !in_window(raster, x.raster, x.film_window) {
            return None;
        }
        let eye_ray = scene.camera.ray_from_eye(raster, xv[0].p);
        let eye = PathVertex::eye(eye_ray.origin, scene.camera.forward);
        let shadow = yd.surface().spawn_ray_to(eye.p, Vec3::ZERO, eye.ng);
        if tracer.occluded(&shadow) {
            return None;
        }
        y.vertices[0] = eye;
        y.raster = raster;
    } else {
        let t = &xv[d - 1];
        let shadow = yd.surface().spawn_ray_to(t.p, t.p_error, t.ng);
        if tracer.occluded(&shadow) {
            return None;
        }
    }
    Some(())
}

/// Transition density T(x → y) of the caustic perturbation (module docs): q(ω → ω')/J(y),
/// 0 when the move cannot turn x into y.
pub fn density(scene: &Scene, cone: &ExpCone, x: &Path, y: &Path) -> f64 {
    let (xv, yv) = (x.vertices(), y.vertices());
    if xv.len() != yv.len() || xv.len() < 4 || x.film_window != y.film_window {
        return 0.0;
    }
    if xv
        .iter()
        .zip(yv)
        .any(|(a, b)| WeakNode::of(a) != WeakNode::of(b))
    {
        return 0.0;
    }
    let Some((d, m)) = caustic_chain(scene, xv) else {
        return 0.0;
    };
    // The light side is kept, the eye side up to x_{d−1} too.
    if xv[m..].iter().zip(&yv[m..]).any(|(a, b)| a.p != b.p) {
        return 0.0;
    }
    if xv[1..d].iter().zip(&yv[1..d]).any(|(a, b)| a.p != b.p) {
        return 0.0;
    }
    // A lens point is kept (`flowlight_core::thin_lens`, "Markov chains").
    if scene.camera.has_lens() && xv[0].p != yv[0].p {
        return 0.0;
    }
    if d == 1 {
        if !in_window(y.raster, x.raster, x.film_window) {
            return 0.0;
        }
    } else if x.raster != y.raster {
        return 0.0;
    }
    if xv[m - 1].p == yv[m - 1].p {
        return 0.0;
    }
    // The axis from the positions (as the proposal took it), the new direction from the
    // offset origin its ray left from (module docs of crate::perturbation).
    let Some(wx) = (xv[m - 1].p - xv[m].p).try_normalize() else {
        return 0.0;
    };
    let o = offset_ray_origin(yv[m].p, yv[m].p_error, yv[m].ng, yv[m - 1].p - yv[m].p);
    let Some(wy) = (yv[m - 1].p - o).try_normalize() else {
        return 0.0;
    };
    let q = cone.pdf(wx, wy);
    if q == 0.0 {
        return 0.0;
    }
    let j = leaf_jacobian(scene, yv, d, m);
    if j > 0.0 {
        q / j
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    //! The leaf Jacobian against a finite-difference Jacobian of the traced chain: planar
    //! mirrors and refracting planes in f64, the lamp point and direction moved in local
    //! coordinates (area, solid angle), the raster position and the first Dirac vertex read
    //! back (film, area): J = |det ∂(u, x_{d+1}) / ∂(x_m, ω_m)|.
    use super::*;
    use crate::testscene::*;
    use flowlight_core::path::NodeType;

    #[derive(Clone, Copy)]
    enum Kind {
        Mirror,
        Glass,
    }

    /// A plane through `p` with unit normal `n` (for glass: pointing out of the glass).
    #[derive(Clone, Copy)]
    struct Plane {
        p: DVec3,
        n: DVec3,
        kind: Kind,
    }

    fn plane(p: [f64; 3], n: [f64; 3], kind: Kind) -> Plane {
        Plane {
            p: DVec3::from(p),
            n: DVec3::from(n).normalize(),
            kind,
        }
    }

    fn hit(o: DVec3, d: DVec3, pl: &Plane) -> Option<DVec3> {
        let t = (pl.p - o).dot(pl.n) / d.dot(pl.n);
        (t > 1e-9).then(|| o + d * t)
    }

    /// The direction after the Dirac surface, travelling along `d`.
    fn scatter(d: DVec3, pl: &Plane) -> Option<DVec3> {
        match pl.kind {
            Kind::Mirror => Some(d - 2.0 * d.dot(pl.n) * pl.n),
            Kind::Glass => {
                let (n, eta) = if d.dot(pl.n) < 0.0 {
                    (pl.n, 1.0 / 1.5)
                } else {
                    (-pl.n, 1.5)
                };
                let c = -d.dot(n);
                let k = 1.0 - eta * eta * (1.0 - c * c);
                (k >= 0.0).then(|| eta * d + (eta * c - k.sqrt()) * n)
            }
        }
    }

    /// Traces from `o` along `d` through `surfaces` onto `end`: the hit points.
    fn trace(o: DVec3, mut d: DVec3, surfaces: &[Plane], end: &Plane) -> Option<Vec<DVec3>> {
        let mut pts = Vec::new();
        let mut o = o;
        for s in surfaces {
            o = hit(o, d, s)?;
            d = scatter(d, s)?;
            pts.push(o);
        }
        pts.push(hit(o, d, end)?);
        Some(pts)
    }

    fn tangents(n: DVec3) -> (DVec3, DVec3) {
        let a = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let t1 = n.cross(a).normalize();
        (t1, n.cross(t1))
    }

    fn raster(scene: &Scene, p: DVec3) -> [f64; 2] {
        let cam = &scene.camera;
        let d = p - dv(cam.position);
        let z = d.dot(dv(cam.forward));
        let ey = cam.tan_half_fov_y as f64;
        let ex = ey * cam.aspect() as f64;
        let (sx, sy) = (
            d.dot(dv(cam.right)) / (z * ex),
            d.dot(dv(cam.up)) / (z * ey),
        );
        [
            (sx + 1.0) * 0.5 * cam.width as f64,
            (1.0 - sy) * 0.5 * cam.height as f64,
        ]
    }

    fn det4(m: [[f64; 4]; 4]) -> f64 {
        let mut a = m;
        let mut det = 1.0;
        for c in 0..4 {
            let p = (c..4)
                .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
                .unwrap();
            if p != c {
                a.swap(p, c);
                det = -det;
            }
            det *= a[c][c];
            let pivot = a[c];
            for row in a.iter_mut().skip(c + 1) {
                let f = row[c] / pivot[c];
                for (v, p) in row.iter_mut().zip(pivot).skip(c) {
                    *v -= f * p;
                }
            }
        }
        det
    }

    /// Checks the leaf Jacobian of the chain from floor point `x1` leaving along `dir`
    /// through `surfaces` (eye side first) to the lamp.
    fn check(x1: [f64; 3], dir: [f64; 3], surfaces: &[Plane]) {
        let scene = scene();
        let floor_plane = plane([0.0; 3], [0.0, 1.0, 0.0], Kind::Mirror);
        let lamp_plane = plane([0.0, 2.0, 0.0], [0.0, -1.0, 0.0], Kind::Mirror);
        let x1 = DVec3::from(x1);
        let pts = trace(x1, DVec3::from(dir).normalize(), surfaces, &lamp_plane)
            .unwrap_or_else(|| panic!("{} surfaces: the nominal chain misses", surfaces.len()));
        let xm = *pts.last().unwrap();
        let w0 = (pts[pts.len() - 2] - xm).normalize();
        // The map (lamp point, direction) → (raster, first Dirac vertex), from the light.
        let reversed: Vec<Plane> = surfaces.iter().rev().copied().collect();
        let (e1, e2) = tangents(lamp_plane.n);
        let (f1, f2) = tangents(w0);
        let (g1, g2) = tangents(surfaces[0].n);
        let map = |a: [f64; 4]| -> [f64; 4] {
            let o = xm + e1 * a[0] + e2 * a[1];
            let w = (w0 + f1 * a[2] + f2 * a[3]).normalize();
            let back = trace(o, w, &reversed, &floor_plane).unwrap();
            let (y1, y2) = (back[back.len() - 1], back[back.len() - 2]);
            let u = raster(&scene, y1);
            let q = y2 - pts[0];
            [u[0], u[1], q.dot(g1), q.dot(g2)]
        };
        let h = 1e-6;
        let mut jac = [[0.0; 4]; 4];
        for c in 0..4 {
            let (mut ap, mut am) = ([0.0; 4], [0.0; 4]);
            ap[c] = h;
            am[c] = -h;
            let (fp, fm) = (map(ap), map(am));
            for r in 0..4 {
                jac[r][c] = (fp[r] - fm[r]) / (2.0 * h);
            }
        }
        let want = det4(jac).abs();
        // The stored path: eye, floor, Dirac vertices, lamp.
        let mut verts = vec![eye(), floor(x1.as_vec3())];
        for (s, p) in surfaces.iter().zip(&pts) {
            let mut v = mirror(p.as_vec3(), s.n.as_vec3());
            if let Kind::Glass = s.kind {
                v.node = NodeType::SpecularTransmission;
                v.material = 0; // ior 1.5 (the material default)
            }
            verts.push(v);
        }
        verts.push(lamp(xm.as_vec3()));
        let m = verts.len() - 1;
        assert_eq!(caustic_chain(&scene, &verts), Some((1, m)));
        let got = leaf_jacobian(&scene, &verts, 1, m);
        assert!(
            (got / want - 1.0).abs() < 2e-3,
            "{} Dirac vertices: closed form {got}, finite differences {want}",
            surfaces.len()
        );
    }

    #[test]
    fn the_leaf_jacobian_matches_finite_differences_of_the_traced_chain() {
        // One tilted mirror.
        let m1 = plane([0.6, 1.0, -1.2], [-1.0, 0.1, 0.3], Kind::Mirror);
        check([0.05, 0.0, -1.0], [0.5, 0.6, -0.1], &[m1]);
        // Two mirrors facing each other (a corridor).
        let m2 = plane([-0.5, 0.0, -1.0], [1.0, 0.0, 0.1], Kind::Mirror);
        let m3 = plane([0.5, 0.0, -1.0], [-1.0, 0.05, 0.0], Kind::Mirror);
        check([0.1, 0.0, -1.1], [-0.6, 0.3, 0.05], &[m2, m3]);
        // A glass slab: in through its bottom face, out through its tilted top face.
        let bottom = plane([0.0, 0.8, 0.0], [0.0, -1.0, 0.0], Kind::Glass);
        let top = plane([0.0, 1.1, 0.0], [0.15, 1.0, -0.1], Kind::Glass);
        check([0.0, 0.0, -1.0], [0.7, 1.0, 0.2], &[bottom, top]);
        // Two slabs: four refractions in a row.
        let b2 = plane([0.0, 1.4, 0.0], [0.1, -1.0, 0.0], Kind::Glass);
        let t2 = plane([0.0, 1.6, 0.0], [0.0, 1.0, 0.2], Kind::Glass);
        check([0.0, 0.0, -1.0], [0.6, 1.0, -0.3], &[bottom, top, b2, t2]);
    }
}
