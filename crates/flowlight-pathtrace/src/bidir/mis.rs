//! The multiple-importance weights of the bidirectional strategies, computed from three
//! running quantities per subpath instead of from all the path's densities at once
//! (Georgiev et al. 2012, "Light transport simulation with vertex connection and merging",
//! and its technical report "Implementing vertex connection and merging"; Veach 1997 §10.2
//! for the plain connections).
//!
//! A full path x̄ = y₀ … y_{s−1} x_{t−1} … x₀ of k + 1 vertices (y₀ on a light, x₀ the eye)
//! can be made by every split (s, t), s + t = k + 1: a light subpath of s vertices joined to
//! a camera subpath of t vertices by a connection (s ≥ 1, t ≥ 1), a camera subpath that hits
//! the light (s = 0), or, for vertex merging, a light and a camera subpath that end at the
//! same interior vertex, joined by a density estimate of radius r. With p_i the density of
//! strategy i (area measure over the path's vertices, N_LT and η factors below included),
//! the heuristic weight of strategy i is
//!
//! ```text
//! w_i = m(p_i) / Σ_j m(p_j),      m(x) = x (balance heuristic) or x² (power heuristic)
//! ```
//!
//! Dividing by m(p_i) leaves ratios of neighbouring strategies, products of one forward and
//! one reverse density per vertex, which each subpath accumulates as it grows:
//!
//! * `dvcm`: m(1 / p⃗) of the last vertex — the ratio that turns this strategy into the one
//!   whose other subpath made the last vertex;
//! * `dvc`: the sum, over the connection strategies that move the join further towards
//!   this subpath's origin, of their ratios;
//! * `dvm`: the same for the merging strategies.
//!
//! A segment of squared length d² arriving at a vertex with |cos θ| (shading normal) turns
//! the last solid-angle density into an area density: dvcm·m(d²) (not for the first segment
//! from a light at infinity), then all three divided by m(|cos θ|). A BSDF sample with
//! forward density p⃗ and reverse density p⃖ (solid angle), leaving with |cos θ_o|:
//!
//! ```text
//! dvc  ← m(|cos θ_o| / p⃗) · (dvc · m(p⃖) + dvcm + m(η_VCM))
//! dvm  ← m(|cos θ_o| / p⃗) · (dvm · m(p⃖) + dvcm · m(1/η_VCM) + 1)
//! dvcm ← m(1 / p⃗)
//! ```
//!
//! and a Dirac sample (p⃗ = p⃖ cancel, and no strategy can join at the vertex):
//! dvcm ← 0, dvc ← dvc · m(|cos θ_o|), dvm ← dvm · m(|cos θ_o|).
//!
//! η_VCM = N_VM π r² compares merging with connecting: a merge uses all N_VM light paths of
//! the iteration within the disc of radius r (its density is the connection's times
//! N_VM π r²). The m(η_VCM) term exists only where merging is on, the m(1/η_VCM) term only
//! where connecting is on. N_LT, the number of light paths that splat to the film per
//! camera sample, enters where a light vertex connects to the eye: light tracing has N_LT
//! tries at every pixel sample.
//!
//! Starts. A light subpath from emission densities p_e = p_choose·p_pos·p_dir and the
//! density p_d with which a light sample at a camera vertex picks the same point (area, or
//! solid angle for the environment, or the choice alone for a Dirac light):
//! dvcm = m(p_d / p_e), dvc = m(cos / p_e) (0 for a Dirac light; cos = 1 for lights at
//! infinity), dvm = dvc · m(1/η_VCM). A camera subpath at its first hit x₁:
//! dvcm = m(N_LT / p_cam(x₁)) with p_cam the area density of x₁ under the camera,
//! dvc = dvm = 0.
//!
//! Russian roulette and the depth caps stay outside the weights: every strategy of a path
//! that the caps allow is weighed by the same function of the path, so the weights of a path
//! still sum to 1 (the test `bidir::tests`), and the estimator stays unbiased.

use flowlight_core::Rgb;

/// The heuristic that turns densities into weights.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heuristic {
    /// m(x) = x (Veach 1997 §9.2.2).
    Balance,
    /// m(x) = x² (β = 2 of Veach's power heuristic).
    Power,
}

impl Heuristic {
    /// m(x).
    #[inline(always)]
    pub fn m(self, x: f32) -> f32 {
        match self {
            Heuristic::Balance => x,
            Heuristic::Power => x * x,
        }
    }

    /// From the `heuristic` parameter's value.
    pub fn parse(name: &str) -> Option<Heuristic> {
        match name {
            "balance" => Some(Heuristic::Balance),
            "power" => Some(Heuristic::Power),
            _ => None,
        }
    }
}

/// Which strategies a render combines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Techniques {
    /// Camera subpaths that hit lights, sample lights and connect to light vertices.
    pub connect: bool,
    /// Light vertices connected to the eye (t = 1) and splatted.
    pub light_trace: bool,
    /// Camera vertices merged with the light vertices within the radius.
    pub merge: bool,
}

impl Techniques {
    /// Particle tracing alone: every light vertex connects to the eye.
    pub const LIGHT_TRACE: Techniques = Techniques {
        connect: false,
        light_trace: true,
        merge: false,
    };
    /// Bidirectional path tracing: every (s, t) connection strategy.
    pub const BDPT: Techniques = Techniques {
        connect: true,
        light_trace: true,
        merge: false,
    };
    /// Vertex connection and merging.
    pub const VCM: Techniques = Techniques {
        connect: true,
        light_trace: true,
        merge: true,
    };
    /// Progressive photon mapping: merging alone, at a camera path's first non-Dirac event.
    pub const PPM: Techniques = Techniques {
        connect: false,
        light_trace: false,
        merge: true,
    };

    /// Whether camera subpaths are traced at all.
    pub fn camera_paths(self) -> bool {
        self.connect || self.merge
    }

    /// Whether a path's strategies are weighed against each other (more than one
    /// strategy samples it); light tracing and photon mapping alone give every path one.
    pub fn weighs(self) -> bool {
        self.connect
    }
}

/// What the weights of one iteration share: the heuristic, the strategies, the number of
/// light paths and the merging radius.
#[derive(Clone, Copy, Debug)]
pub struct Iteration {
    pub heuristic: Heuristic,
    pub techniques: Techniques,
    /// N_LT: light paths splatting to the film per camera sample.
    pub light_paths: f32,
    /// W·H: a pixel sample's camera ray starts uniformly in its pixel, so its density is
    /// W·H times `Camera::hit_density` (a density over the whole film).
    pub film_pixels: f32,
    /// Merging radius r of this iteration (0 without merging).
    pub radius: f32,
    /// m(η_VCM) where merging is on, else 0.
    pub vm_factor: f32,
    /// m(1/η_VCM) where connecting and merging are both on, else 0.
    pub vc_factor: f32,
    /// 1 / η_VCM = 1 / (N_VM π r²): what a merge's sum is multiplied by.
    pub vm_normalisation: f32,
}

impl Iteration {
    /// An iteration with `light_paths` = N_LT splatting light paths per camera sample and
    /// `merge_paths` = N_VM light paths in the merging set, merging within `radius`.
    pub fn new(
        heuristic: Heuristic,
        techniques: Techniques,
        (light_paths, film_pixels): (f32, f32),
        merge_paths: f32,
        radius: f32,
    ) -> Iteration {
        let eta = merge_paths * std::f32::consts::PI * radius * radius;
        let merging = techniques.merge && eta > 0.0;
        Iteration {
            heuristic,
            techniques,
            light_paths,
            film_pixels,
            radius: if merging { radius } else { 0.0 },
            vm_factor: if merging { heuristic.m(eta) } else { 0.0 },
            vc_factor: if merging && techniques.connect {
                heuristic.m(1.0 / eta)
            } else {
                0.0
            },
            vm_normalisation: if merging { 1.0 / eta } else { 0.0 },
        }
    }

    #[inline(always)]
    fn m(&self, x: f32) -> f32 {
        self.heuristic.m(x)
    }
}

/// The three running quantities of a subpath (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Partial {
    pub dvcm: f32,
    pub dvc: f32,
    pub dvm: f32,
}

impl Partial {
    /// A light subpath leaving a light: `direct` = p_d, `emission` = p_e (module docs),
    /// `cos` at the light (1 at infinity), `dirac` for a point, spot or directional light.
    pub fn light_start(it: &Iteration, direct: f32, emission: f32, cos: f32, dirac: bool) -> Self {
        let dvc = if dirac { 0.0 } else { it.m(cos / emission) };
        Partial {
            dvcm: it.m(direct / emission),
            dvc,
            dvm: dvc * it.vc_factor,
        }
    }

    /// A camera subpath at its first hit, which the pixel sample's camera ray reaches with
    /// area density `camera_density` (W·H · `Camera::hit_density`).
    pub fn camera_start(it: &Iteration, camera_density: f32) -> Self {
        Partial {
            dvcm: it.m(it.light_paths / camera_density),
            dvc: 0.0,
            dvm: 0.0,
        }
    }

    /// A segment of squared length `d2` reached a vertex at |cos θ| = `cos`; `distance`
    /// false for the first segment from a light at infinity.
    #[inline]
    pub fn arrive(&mut self, it: &Iteration, d2: f32, cos: f32, distance: bool) {
        if distance {
            self.dvcm *= it.m(d2);
        }
        let inv = 1.0 / it.m(cos);
        self.dvcm *= inv;
        self.dvc *= inv;
        self.dvm *= inv;
    }

    /// A BSDF sample left the vertex at |cos θ_o| = `cos_out` with forward and reverse
    /// densities `forward`, `reverse` (solid angle); `dirac` for a Dirac lobe.
    #[inline]
    pub fn scatter(
        &mut self,
        it: &Iteration,
        cos_out: f32,
        forward: f32,
        reverse: f32,
        dirac: bool,
    ) {
        if dirac {
            let c = it.m(cos_out);
            self.dvcm = 0.0;
            self.dvc *= c;
            self.dvm *= c;
            return;
        }
        let g = it.m(cos_out / forward);
        let (dvcm, dvc, dvm) = (self.dvcm, self.dvc, self.dvm);
        self.dvc = g * (dvc * it.m(reverse) + dvcm + it.vm_factor);
        self.dvm = g * (dvm * it.m(reverse) + dvcm * it.vc_factor + 1.0);
        self.dvcm = it.m(1.0 / forward);
    }

    /// The sum of the other strategies' ratios seen from this subpath's end, for a
    /// connection whose other end reaches this end with area density `other_forward` and
    /// whose reverse density at this end is `reverse`: m(other_forward) · (m(η_VCM) + dvcm
    /// + dvc · m(reverse)).
    #[inline]
    fn connection_ratio(&self, it: &Iteration, other_forward: f32, reverse: f32) -> f32 {
        it.m(other_forward) * (it.vm_factor + self.dvcm + self.dvc * it.m(reverse))
    }
}

/// Weight of a camera subpath that hit an emitter (s = 0), which a light sample picks with
/// density `direct` (area, or solid angle for the environment) and light tracing emits with
/// density `emission` (p_e).
#[inline]
pub fn emitter_hit(it: &Iteration, camera: &Partial, direct: f32, emission: f32) -> f32 {
    1.0 / (1.0 + it.m(direct) * camera.dvcm + it.m(emission) * camera.dvc)
}

/// Weight of a light sample at a camera vertex (s = 1): `bsdf_forward` the density with
/// which the vertex's BSDF samples the light's direction (0 for a Dirac light),
/// `bsdf_reverse` the reverse one, `direct` the light sample's solid-angle density (the
/// choice alone for a Dirac light), and `emission_ratio` = p_e · |cos θ_x| / (direct ·
/// cos θ_light): the density with which a light subpath reaches the vertex over `direct`.
#[inline]
pub fn light_sample(
    it: &Iteration,
    camera: &Partial,
    bsdf_forward: f32,
    bsdf_reverse: f32,
    direct: f32,
    emission_ratio: f32,
) -> f32 {
    let to_bsdf = it.m(bsdf_forward / direct);
    let to_light = camera.connection_ratio(it, emission_ratio, bsdf_reverse);
    1.0 / (to_bsdf + 1.0 + to_light)
}

/// Weight of a light vertex connected to the eye (t = 1): `camera_density` the area density
/// with which a pixel sample's camera ray reaches it (W·H · `Camera::hit_density`), `reverse` the density with which its BSDF, seen from the
/// eye, samples the direction back to the light subpath.
#[inline]
pub fn eye_connection(it: &Iteration, light: &Partial, camera_density: f32, reverse: f32) -> f32 {
    let to_camera = light.connection_ratio(it, camera_density / it.light_paths, reverse);
    1.0 / (1.0 + to_camera)
}

/// The two ends' densities of a connection between a camera and a light vertex.
#[derive(Clone, Copy, Debug)]
pub struct ConnectionDensities {
    /// The camera vertex's BSDF towards the light vertex, as an area density there.
    pub camera_forward: f32,
    /// The camera vertex's BSDF from the light vertex's direction back to the camera
    /// subpath (solid angle).
    pub camera_reverse: f32,
    /// The light vertex's BSDF towards the camera vertex, as an area density there.
    pub light_forward: f32,
    /// The light vertex's BSDF from the camera vertex's direction back along the light
    /// subpath (solid angle).
    pub light_reverse: f32,
}

/// Weight of a connection between a camera vertex and a light vertex (s, t ≥ 2).
#[inline]
pub fn connection(
    it: &Iteration,
    camera: &Partial,
    light: &Partial,
    d: &ConnectionDensities,
) -> f32 {
    let to_light = light.connection_ratio(it, d.camera_forward, d.light_reverse);
    let to_camera = camera.connection_ratio(it, d.light_forward, d.camera_reverse);
    1.0 / (to_light + 1.0 + to_camera)
}

/// Weight of a merge of a camera vertex with a light vertex: `forward` the camera BSDF's
/// density towards the light subpath's last direction, `reverse` its density back.
#[inline]
pub fn merge(it: &Iteration, camera: &Partial, light: &Partial, forward: f32, reverse: f32) -> f32 {
    let to_light = light.dvcm * it.vc_factor + light.dvm * it.m(forward);
    let to_camera = camera.dvcm * it.vc_factor + camera.dvm * it.m(reverse);
    1.0 / (to_light + 1.0 + to_camera)
}

/// A contribution with a weight, `None` where it is black or not finite-weighted.
#[inline]
pub fn weighted(value: Rgb, weight: f32) -> Option<Rgb> {
    let v = value * weight;
    (!v.is_black()).then_some(v)
}
