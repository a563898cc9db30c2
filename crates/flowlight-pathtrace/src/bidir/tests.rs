//! The weights of every strategy that can sample a path sum to 1, per path and heuristic,
//! with the production recursion ([`super::mis`]) driven along fixed random paths: the
//! camera side from the eye, the light side from the light, each strategy's weight from the
//! two partial states at its join.

use super::mis::{self, ConnectionDensities, Heuristic, Iteration, Partial, Techniques};
use flowlight_core::camera::Camera;
use flowlight_core::rng::Rng;
use glam::Vec3;
use std::f32::consts::PI;

/// A test vertex: position, unit normal, whether its BSDF is a Dirac lobe.
#[derive(Clone, Copy)]
struct V {
    p: Vec3,
    n: Vec3,
    dirac: bool,
}

/// A deliberately non-reciprocal density of sampling `to` given `from` at `v` (unit
/// directions away from the vertex): half a cosine lobe, half a lobe around `from`'s mirror
/// direction.
fn pdf(v: &V, from: Vec3, to: Vec3) -> f32 {
    let cos = to.dot(v.n).abs();
    let mirror = 2.0 * from.dot(v.n) * v.n - from;
    let lobe = mirror.dot(to).max(0.0).powi(8) * 10.0 / (2.0 * PI);
    0.5 * cos / PI + 0.5 * lobe
}

fn dir(a: Vec3, b: Vec3) -> Vec3 {
    (b - a).normalize()
}

fn cos_at(v: &V, w: Vec3) -> f32 {
    v.n.dot(w).abs()
}

/// The lamp: a one-sided area light of area `AREA` chosen with probability `CHOOSE`.
const AREA: f32 = 0.3;
const CHOOSE: f32 = 0.7;

/// A random path eye → x₁ … x_{k−1} → light (k + 1 vertices), in front of the camera.
fn random_path(rng: &mut Rng, k: usize, dirac_at: Option<usize>) -> (Camera, Vec<V>) {
    let camera = Camera::look_along(Vec3::ZERO, Vec3::Z, Vec3::Y, 50.0, 64, 48);
    let mut path = vec![V {
        p: Vec3::ZERO,
        n: Vec3::Z,
        dirac: false,
    }];
    for i in 1..=k {
        let p = Vec3::new(
            rng.uniform() * 2.0 - 1.0,
            rng.uniform() * 2.0 - 1.0,
            2.0 + rng.uniform() * 3.0,
        );
        let n = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5).normalize();
        path.push(V {
            p,
            n,
            dirac: dirac_at == Some(i),
        });
    }
    // The first vertex must be on the film.
    path[1].p = Vec3::new(0.1, -0.2, 3.0);
    (camera, path)
}

/// The camera side's partial state at each vertex x₁ … x_k (index j: arrived at x_j).
fn camera_partials(it: &Iteration, camera: &Camera, path: &[V]) -> Vec<Partial> {
    let mut out = vec![Partial::default()];
    let d1 = path[1].p - path[0].p;
    let w1 = d1.normalize();
    let density = camera.hit_density(w1, d1.length(), cos_at(&path[1], w1));
    let mut partial = Partial::camera_start(it, density * it.film_pixels);
    out.push(partial);
    for j in 1..path.len() - 1 {
        let (back, next) = (dir(path[j].p, path[j - 1].p), dir(path[j].p, path[j + 1].p));
        let v = &path[j];
        partial.scatter(
            it,
            cos_at(v, next),
            pdf(v, back, next),
            pdf(v, next, back),
            v.dirac,
        );
        let d = path[j + 1].p - path[j].p;
        partial.arrive(
            it,
            d.length_squared(),
            cos_at(&path[j + 1], d.normalize()),
            true,
        );
        out.push(partial);
    }
    out
}

/// The light side's partial state at each vertex (index j: arrived at x_j, coming from the
/// light x_k), and the lamp's emission densities towards x_{k−1}.
fn light_partials(it: &Iteration, path: &[V]) -> Vec<Partial> {
    let k = path.len() - 1;
    let mut out = vec![Partial::default(); path.len()];
    let light = &path[k];
    let w = dir(light.p, path[k - 1].p);
    let cos = cos_at(light, w);
    let direct = CHOOSE / AREA;
    let mut partial = Partial::light_start(it, direct, direct * cos / PI, cos, false);
    out[k] = partial;
    for j in (1..k).rev() {
        let d = path[j].p - path[j + 1].p;
        partial.arrive(
            it,
            d.length_squared(),
            cos_at(&path[j], d.normalize()),
            true,
        );
        out[j] = partial;
        if j > 1 {
            let v = &path[j];
            let (back, next) = (dir(v.p, path[j + 1].p), dir(v.p, path[j - 1].p));
            partial.scatter(
                it,
                cos_at(v, next),
                pdf(v, back, next),
                pdf(v, next, back),
                v.dirac,
            );
        }
    }
    out
}

/// The weights of every strategy the path allows, in the production formulas.
fn weights(it: &Iteration, camera: &Camera, path: &[V]) -> Vec<f32> {
    let k = path.len() - 1;
    let cam = camera_partials(it, camera, path);
    let light = light_partials(it, path);
    let lamp = &path[k];
    let mut w = Vec::new();
    // s = 0: the camera path hits the lamp.
    let back = dir(lamp.p, path[k - 1].p);
    let emission = CHOOSE / AREA * cos_at(lamp, back) / PI;
    w.push(mis::emitter_hit(it, &cam[k], CHOOSE / AREA, emission));
    // s = 1: a light sample at x_{k−1}.
    let x = &path[k - 1];
    if k >= 2 && !x.dirac {
        let (back, to_light) = (dir(x.p, path[k - 2].p), dir(x.p, lamp.p));
        let d2 = (lamp.p - x.p).length_squared();
        let cos_light = cos_at(lamp, -to_light);
        let direct = CHOOSE / AREA * d2 / cos_light;
        let ratio = cos_light / PI * cos_at(x, to_light) / d2;
        let (forward, reverse) = (pdf(x, back, to_light), pdf(x, to_light, back));
        w.push(mis::light_sample(
            it,
            &cam[k - 1],
            forward,
            reverse,
            direct,
            ratio,
        ));
    }
    // 2 ≤ s ≤ k − 1: camera vertex x_c connected to light vertex x_{c+1}.
    for c in 1..k.saturating_sub(1) {
        let (xc, y) = (&path[c], &path[c + 1]);
        if xc.dirac || y.dirac {
            continue;
        }
        let d = y.p - xc.p;
        let (d2, to_y) = (d.length_squared(), d.normalize());
        let (cam_back, light_back) = (dir(xc.p, path[c - 1].p), dir(y.p, path[c + 2].p));
        let densities = ConnectionDensities {
            camera_forward: pdf(xc, cam_back, to_y) * cos_at(y, to_y) / d2,
            camera_reverse: pdf(xc, to_y, cam_back),
            light_forward: pdf(y, light_back, -to_y) * cos_at(xc, to_y) / d2,
            light_reverse: pdf(y, -to_y, light_back),
        };
        w.push(mis::connection(it, &cam[c], &light[c + 1], &densities));
    }
    // t = 1: x₁ connected to the eye.
    let x1 = &path[1];
    if k >= 2 && !x1.dirac {
        let to_eye = dir(x1.p, path[0].p);
        let dist = (x1.p - path[0].p).length();
        let density = camera.hit_density(-to_eye, dist, cos_at(x1, to_eye)) * it.film_pixels;
        let back = dir(x1.p, path[2].p);
        w.push(mis::eye_connection(
            it,
            &light[1],
            density,
            pdf(x1, to_eye, back),
        ));
    }
    // Merges at every interior non-Dirac vertex.
    if it.techniques.merge {
        for j in 1..k {
            let x = &path[j];
            if x.dirac {
                continue;
            }
            let (back, to_light) = (dir(x.p, path[j - 1].p), dir(x.p, path[j + 1].p));
            let (forward, reverse) = (pdf(x, back, to_light), pdf(x, to_light, back));
            w.push(mis::merge(it, &cam[j], &light[j], forward, reverse));
        }
    }
    w
}

fn iteration(heuristic: Heuristic, techniques: Techniques) -> Iteration {
    Iteration::new(
        heuristic,
        techniques,
        (64.0 * 48.0, 64.0 * 48.0),
        1000.0,
        0.02,
    )
}

#[test]
fn the_weights_of_every_strategy_of_a_path_sum_to_one() {
    let mut rng = Rng::new(11, 0);
    for techniques in [Techniques::BDPT, Techniques::VCM] {
        for heuristic in [Heuristic::Balance, Heuristic::Power] {
            let it = iteration(heuristic, techniques);
            for k in 2..=7 {
                for dirac in [None, Some(1), Some(k / 2 + 1).filter(|&j| j < k)] {
                    for _ in 0..20 {
                        let (camera, path) = random_path(&mut rng, k, dirac);
                        let w = weights(&it, &camera, &path);
                        let sum: f32 = w.iter().sum();
                        assert!(
                            (sum - 1.0).abs() < 2e-3,
                            "{techniques:?} {heuristic:?}, {k} segments, Dirac at {dirac:?}: weights {w:?} sum to {sum}"
                        );
                        assert!(w.iter().all(|&x| (0.0..=1.0).contains(&x)));
                    }
                }
            }
        }
    }
}

#[test]
fn a_wrong_forward_density_breaks_the_sum() {
    // The test above can fail: the same sums with one forward density off by 5% stray
    // from 1 by far more than its tolerance on some path.
    let it = iteration(Heuristic::Power, Techniques::BDPT);
    let mut rng = Rng::new(3, 0);
    let mut worst = 0.0f32;
    for _ in 0..200 {
        let (camera, path) = random_path(&mut rng, 3, None);
        let good: f32 = weights(&it, &camera, &path).iter().sum();
        assert!((good - 1.0).abs() < 2e-3);
        let cam = camera_partials(&it, &camera, &path);
        let light = light_partials(&it, &path);
        let (xc, y) = (&path[1], &path[2]);
        let d = y.p - xc.p;
        let (d2, to_y) = (d.length_squared(), d.normalize());
        let (cam_back, light_back) = (dir(xc.p, path[0].p), dir(y.p, path[3].p));
        let mut densities = ConnectionDensities {
            camera_forward: pdf(xc, cam_back, to_y) * cos_at(y, to_y) / d2,
            camera_reverse: pdf(xc, to_y, cam_back),
            light_forward: pdf(y, light_back, -to_y) * cos_at(xc, to_y) / d2,
            light_reverse: pdf(y, -to_y, light_back),
        };
        let right = mis::connection(&it, &cam[1], &light[2], &densities);
        densities.camera_forward *= 1.05;
        let wrong = mis::connection(&it, &cam[1], &light[2], &densities);
        worst = worst.max((good - right + wrong - 1.0).abs());
    }
    assert!(worst > 1e-2, "a 5% error moved the sum by {worst} at most");
}
