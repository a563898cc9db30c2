//! ERPT seeds from bidirectional path tracing: every connection strategy (s, t) of one BDPT
//! pixel sample — the light subpath and the camera subpath of [`super::light_path`] and
//! [`super::camera_path`], connections only, no merging — becomes a seed, a complete
//! eye-to-light [`Path`](flowlight_core::path::Path) with its MIS-weighted estimate, as Mitsuba 0.6's ERPT seeds its
//! chains (`src/libbidir/pathsampler.cpp`).
//!
//! A path x̄ of n + 1 vertices drawn by strategy (s, t) (s light vertices, t camera vertices,
//! the eye counted) carries
//!
//! ```text
//! X_{s,t} = w_{s,t}(x̄) · f(x̄) / p_{s,t}(x̄)
//! ```
//!
//! with f the chains' target function (`flowlight-mcmc`'s `measure.rs`: film measure for the
//! eye ray, area measure for free vertices, solid angle for a direction at infinity, the
//! discrete probability of a Dirac lobe), w_{s,t} the library's heuristic weight ([`super::mis`])
//! and p_{s,t} = p_camera(x₀ … x_{t−1}) · p_light(y₀ … y_{s−1}) the density of the strategy in
//! that measure, recorded while the subpaths are traced ([`StrategyRecorder`]):
//!
//! * camera side: 1 for the eye ray (the film measure), per step the BSDF density times the
//!   area Jacobian |n_g·ω|/d² (a Dirac step: its discrete probability) and the survival
//!   probability 1 − T of the roulette;
//! * light side: the light's choice times its area density (a point or a directional light:
//!   the choice alone, a Dirac; the environment: choice × solid-angle density of the
//!   direction), then the emitted direction's density as an area density of y₁ (for a distant
//!   light the disc's density times |n_g·ω|), then as on the camera side;
//! * s = 1: the camera prefix times what next-event estimation divides by (the area density of
//!   an area light, else the light sample's density); s = 0: the camera prefix, through the
//!   emitter hit or times the density of the escaped direction;
//! * t = 1 (light tracing): x₁ is not a free coordinate of the film measure but the raster
//!   position is; a camera ray through a raster position uniform over the W·H film reaches x₁
//!   with area density `hit_density`, so in the film measure p = p_light / (W·H · hit_density),
//!   and with N_LT = W·H light paths per sample index each light path's deposit is
//!   w·f/(N_LT·p): the seed is recorded with p_{s,1} = p_light / hit_density.
//!
//! **Light-side Dirac chains.** The target's measure makes a vertex after a Dirac vertex (eye
//! order) no free coordinate, so of a Dirac run x_a … x_b between smooth x_{a−1} and x_{b+1}
//! (or the light) it keeps x_a free, where the light subpath drew x_b (and x_{b+1}) and
//! x_{a−1} followed. With the smooth vertices as common coordinates (each run fixes its far
//! end from its near end and the first vertex of the run, Jakob & Marschner 2012), the two
//! measures differ per run by the ratio of the Jacobians of those maps, which conservation of
//! étendue along the run gives:
//!
//! ```text
//! p_eye / p_light = Π_runs G(x_{a−1}, x_a) / G(x_b, x_{b+1}) · Π_{k=a..b} ρ_k
//! ρ_k = η'_k² · |n_g·ω_L| |n_s·ω_E| / (|n_g·ω_E| |n_s·ω_L|)
//! ```
//!
//! with G(u, v) = |n_u·ω||n_v·ω|/d² (geometric normals; |n_u·ω| towards a light at infinity),
//! ω_E and ω_L the directions at x_k towards the eye and the light side, and η'_k the light
//! subpath's relative index there (a mirror: 1): Snell's law about the shading normal keeps
//! η²|n_s·ω| dσ, and dA|n_g·ω|dσ is the measure of the ray bundle on either side (the
//! caustic perturbation's Jacobian, `flowlight-mcmc`'s `specular_chain.rs`, is the same
//! étendue argument). Camera-side Dirac runs are drawn in the target's own parametrisation.
//!
//! **Why the seeds' energy density is f.** The weights of every strategy that can draw a path
//! sum to one (the library's weights are Veach's heuristic over the same densities, roulette and
//! depth caps outside them: `bidir::tests`), so over all strategies of one sample index
//!
//! ```text
//! E[Σ_{s,t} X_{s,t}] over x̄  =  Σ_{s,t} p_{s,t}(x̄) · w_{s,t}(x̄) f(x̄)/p_{s,t}(x̄)  =  f(x̄)
//! ```
//!
//! — the energy density of one path-tracer sample, which ERPT's Metropolis flow keeps (thesis
//! §5.2–5.3; the argument of [`crate::seeds`] holds unchanged). A t = 1 seed lands at its own
//! raster position, generally in another pixel than its sample's: the flow runs its chains from
//! there (the host keeps deposits outside a unit's flanged tile).
//!
//! **Node types.** Each vertex of a seed path gets its type from the step that left it towards
//! the light side of the path: a Dirac step gives a Dirac reflection or transmission (by the
//! sides of n_g its two directions lie on) of the first Dirac component with such a lobe, as
//! `measure::dirac_component` reads it; a smooth step, and a connection vertex, the type of the
//! smooth component that scatters most light between its two neighbours
//! (`crate::seeds::connection_node`). Light-side Dirac chains are stored as they are; a path
//! that does not fit a [`Path`](flowlight_core::path::Path) ([`MAX_PATH_VERTICES`]) is stored
//! without vertices, so that the flow deposits its estimate at its pixel (the chains' target
//! function gives it no energy).

use super::camera_path::CameraPaths;
use super::light_path::LightPaths;
use super::mis::{Iteration, Techniques};
use super::render::{pixel_seed, LIGHT_STREAM};
use super::vertex::LightVertex;
use super::BidirSettings;
use crate::seeds::{connection_node, Seed, SeedStore, Technique};
use crate::untangled::light_node;
use crate::walk::Step;
use crate::SampleContributions;
use flowlight_core::bsdf::Bsdf;
use flowlight_core::geometry::{Frame, SurfaceHit};
use flowlight_core::light::{EmissionSample, LightKind};
use flowlight_core::path::{NodeType, PathVertex, MAX_PATH_VERTICES};
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};
use std::cell::RefCell;

/// How a strategy's path ends on the light side.
#[derive(Clone, Copy, Debug)]
pub enum StrategyEnd {
    /// s = 0: camera vertex t − 1 lies on an emitter.
    Hit,
    /// s = 0: the camera path escaped into environment light `light` along `dir`, drawn with
    /// density `pdf` (1 for the eye ray or a Dirac step's discrete probability).
    /// `dirac` says whether that step was a Dirac step.
    Escape {
        dir: Vec3,
        light: usize,
        pdf: f64,
        dirac: bool,
    },
    /// s = 1: a light sample, its stored vertex and the density next-event estimation divides by.
    LightSample { vertex: PathVertex, pdf: f64 },
    /// s ≥ 2: the light subpath's vertex y_{s−1} (t ≥ 2 connects to it from the camera).
    LightVertex,
    /// t = 1: y_{s−1} connected to the eye at `eye`, seen at `raster`; `density` is the camera
    /// ray's area density at y_{s−1} (`Camera::hit_density`).
    Eye {
        raster: Vec2,
        eye: Vec3,
        density: f64,
    },
}

/// One weighed contribution of a pixel sample: strategy (s, t), its weight, its weighed value
/// and lighting layer, and how it ends.
#[derive(Clone, Copy, Debug)]
pub struct StrategyEvent {
    pub s: u32,
    pub t: u32,
    pub weight: f32,
    pub value: Rgb,
    pub layer: u32,
    pub end: StrategyEnd,
}

/// A subpath vertex as the recorder keeps it: the hit, whether the step that reached it was a
/// Dirac step, and the subpath's density up to it.
#[derive(Clone, Copy, Debug)]
struct Recorded {
    hit: SurfaceHit,
    dirac_in: bool,
    density: f64,
    /// The subpath's product of η'² up to here (on the light side for `StrategySeeds::light_runs_jacobian`).
    eta2: f32,
}

/// What a pixel sample's subpaths and strategies leave for the seeds: the emission sample, the
/// light and camera vertices with their running densities (module docs), and every weighed
/// contribution. The subpath tracers fill it where they are given one.
#[derive(Default)]
pub struct StrategyRecorder {
    emission: Option<EmissionSample>,
    /// y₀'s density (the light's choice and position).
    origin_density: f64,
    light: Vec<Recorded>,
    light_survival: f64,
    /// x₁ … (the eye x₀ has density 1).
    camera: Vec<Recorded>,
    /// The camera subpath's eye vertex (its lens point with a thin lens).
    camera_eye: Option<Vec3>,
    camera_survival: f64,
    pub events: Vec<StrategyEvent>,
}

/// Density of a step from `from` to `hit` drawn with solid-angle density `pdf`, in area measure.
fn area_step(pdf: f32, from: Vec3, hit: &SurfaceHit) -> f64 {
    let d = hit.p - from;
    let d2 = d.length_squared() as f64;
    pdf as f64 * (hit.ng.dot(d).abs() as f64 / (d2 * d2.sqrt()))
}

impl StrategyRecorder {
    fn clear(&mut self) {
        self.emission = None;
        self.light.clear();
        self.camera.clear();
        self.camera_eye = None;
        self.events.clear();
        self.light_survival = 1.0;
        self.camera_survival = 1.0;
    }

    /// The light subpath starts with emission sample `e`.
    pub(super) fn light_start(&mut self, e: &EmissionSample) {
        self.emission = Some(*e);
        self.origin_density = match e.kind {
            LightKind::Area => (e.pdf_choose * e.pdf_pos) as f64,
            LightKind::Positional | LightKind::Directional => e.pdf_choose as f64,
            LightKind::Environment => (e.pdf_choose * e.pdf_dir) as f64,
        };
        self.light_survival = 1.0;
    }

    /// The light subpath reaches `hit` by `step` from `from`, its product of η'² `eta2`.
    pub(super) fn light_hit(&mut self, hit: &SurfaceHit, (step, eta2): (Step, f32), from: Vec3) {
        let (before, step_density) = match (self.light.last(), self.emission) {
            (Some(prev), _) => (prev.density, Self::step_density(step, prev.hit.p, hit)),
            (None, Some(e)) => {
                let d = match e.kind {
                    LightKind::Area | LightKind::Positional => area_step(e.pdf_dir, e.p, hit),
                    LightKind::Directional | LightKind::Environment => {
                        e.pdf_pos as f64 * hit.ng.dot(e.dir).abs() as f64
                    }
                };
                (self.origin_density, d)
            }
            (None, None) => (0.0, Self::step_density(step, from, hit)),
        };
        self.light.push(Recorded {
            hit: *hit,
            dirac_in: matches!(step, Step::Dirac(_)),
            density: before * step_density * self.light_survival,
            eta2,
        });
        self.light_survival = 1.0;
    }

    /// The light subpath scatters on with survival probability `survival`.
    pub(super) fn light_scatter(&mut self, survival: f32) {
        self.light_survival = survival as f64;
    }

    /// The camera subpath starts at eye vertex `eye` (the pinhole or a lens point).
    pub(super) fn camera_start(&mut self, eye: Vec3) {
        self.camera_eye = Some(eye);
    }

    /// The camera subpath reaches `hit` by `step` from `from`.
    pub(super) fn camera_hit(&mut self, hit: &SurfaceHit, step: Step, from: Vec3) {
        let before = self.camera.last().map_or(1.0, |v| v.density);
        self.camera.push(Recorded {
            hit: *hit,
            dirac_in: matches!(step, Step::Dirac(_)),
            density: before * Self::step_density(step, from, hit) * self.camera_survival,
            eta2: 1.0,
        });
        self.camera_survival = 1.0;
    }

    /// The camera subpath scatters on with survival probability `survival`.
    pub(super) fn camera_scatter(&mut self, survival: f32) {
        self.camera_survival = survival as f64;
    }

    /// A weighed contribution.
    pub(super) fn event(&mut self, event: StrategyEvent) {
        self.events.push(event);
    }

    /// Density of a step in the target's measure (1 for the eye ray).
    fn step_density(step: Step, from: Vec3, hit: &SurfaceHit) -> f64 {
        match step {
            Step::Eye => 1.0,
            Step::Dirac(pdf) => pdf as f64,
            Step::Smooth(pdf) => area_step(pdf, from, hit),
        }
    }
}

/// The type and component of a scattering vertex at `hit` between `prev` (eye side) and the
/// direction `next` (light side): a Dirac lobe's where the step was `dirac`, else the
/// most-scattering smooth component's.
fn vertex_node(
    bsdf: &Bsdf,
    hit: &SurfaceHit,
    prev: Vec3,
    next: Vec3,
    dirac: bool,
) -> (NodeType, u8) {
    let frame = Frame::from_z(hit.ns);
    let wo_w = (prev - hit.p).normalize_or_zero();
    let (wo, wi) = (frame.to_local(wo_w), frame.to_local(next));
    if !dirac {
        return connection_node(bsdf, wo, wi);
    }
    let transmission = hit.ng.dot(wo_w) * hit.ng.dot(next) < 0.0;
    let uc = if transmission { 1.0 - 1e-7 } else { 0.0 };
    let component = bsdf
        .components()
        .position(|(c, _)| {
            c.is_delta()
                && c.sample_with(wo, uc, Vec2::splat(0.5))
                    .is_some_and(|s| s.delta && s.node.is_transmission() == transmission)
        })
        .unwrap_or(0);
    let node = if transmission {
        NodeType::SpecularTransmission
    } else {
        NodeType::SpecularReflection
    };
    (node, component as u8)
}

/// The stored vertex of the light subpath's origin `e`, next to `p_ref` (as
/// `untangled::light_vertex` stores a light sample).
fn origin_vertex(scene: &Scene, e: &EmissionSample, p_ref: Vec3) -> PathVertex {
    let (p, n, prim) = match e.kind {
        LightKind::Area => (e.p, e.n, scene.lights.emitters[e.light as usize].prim),
        LightKind::Positional => (e.p, (p_ref - e.p).normalize_or_zero(), u32::MAX),
        LightKind::Directional | LightKind::Environment => (p_ref - e.dir, -e.dir, u32::MAX),
    };
    light_node(p, e.p_error, n, prim, e.light as i32)
}

/// Seeds of BDPT pixel samples, with the buffers one thread reuses for them.
pub struct StrategySeeds<'a, 'b> {
    pub scene: &'a Scene<'b>,
    pub tracer: &'a Tracer<'a>,
    pub settings: &'a BidirSettings,
    it: Iteration,
    sphere: (Vec3, f32),
    recorder: RefCell<StrategyRecorder>,
    own: Vec<LightVertex>,
    contributions: SampleContributions,
    path: Vec<PathVertex>,
}

/// A pixel sample's deposits as the `bdpt` plugin makes them: the camera path's contributions
/// (at the sample's pixel) and the light path's splats (raster position, layer, value).
#[derive(Default)]
pub struct SampleEstimate {
    pub contributions: SampleContributions,
    pub splats: Vec<(Vec2, u32, Rgb)>,
}

impl<'a, 'b> StrategySeeds<'a, 'b> {
    /// BDPT's connection strategies (no merging) over `scene` with `settings` (its heuristic
    /// and depth caps; its layer options are ignored: seeds keep lighting layers).
    pub fn new(scene: &'a Scene<'b>, tracer: &'a Tracer<'a>, settings: &'a BidirSettings) -> Self {
        let sphere =
            flowlight_core::light::emission::scene_sphere(scene.bounds_min, scene.bounds_max);
        let film = scene.camera.width as f32 * scene.camera.height as f32;
        let it = Iteration::new(settings.heuristic, Techniques::BDPT, (film, film), 1.0, 0.0);
        StrategySeeds {
            scene,
            tracer,
            settings,
            it,
            sphere,
            recorder: RefCell::default(),
            own: Vec::new(),
            contributions: SampleContributions::default(),
            path: Vec::with_capacity(2 * MAX_PATH_VERTICES),
        }
    }

    /// Traces pixel sample (`x`, `y`, `s`) of a render seeded `seed` (the `bdpt` plugin's
    /// random streams) with or without the recorder; the camera path's contributions go to
    /// `self.contributions`, the splats to `splat`. Returns the camera ray's raster position.
    fn trace(
        &mut self,
        seed: u64,
        (x, y, s): (u32, u32, u32),
        record: bool,
        splat: &mut dyn FnMut(Vec2, u32, Rgb),
    ) -> Vec2 {
        let recorder = record.then_some(&self.recorder);
        if let Some(r) = recorder {
            r.borrow_mut().clear();
        }
        let hash = pixel_seed(seed, x, y, s);
        self.own.clear();
        let light = LightPaths {
            scene: self.scene,
            tracer: self.tracer,
            settings: self.settings,
            it: &self.it,
            sphere: self.sphere,
            recorder,
        };
        light.trace(
            Rng::new(hash, LIGHT_STREAM),
            &mut self.own,
            &mut |r: Vec2, l: u32, v: Rgb| splat(r, l, v),
        );
        let camera = CameraPaths {
            scene: self.scene,
            tracer: self.tracer,
            settings: self.settings,
            it: &self.it,
            sphere: self.sphere,
            recorder,
        };
        let mut rng = Rng::new(hash, 0);
        let raster = Vec2::new(x as f32, y as f32) + rng.uniform2();
        self.contributions.clear();
        let mut counts = Default::default();
        camera.trace(
            rng,
            raster,
            &self.own,
            None,
            &mut self.contributions,
            &mut counts,
        );
        raster
    }

    /// The deposits of pixel sample (`x`, `y`, `s`) as the `bdpt` plugin makes them (no
    /// recorder): what its seeds must add up to.
    pub fn estimate(&mut self, seed: u64, sample: (u32, u32, u32)) -> SampleEstimate {
        let mut splats = Vec::new();
        self.trace(seed, sample, false, &mut |r, l, v| splats.push((r, l, v)));
        SampleEstimate {
            contributions: self.contributions.clone(),
            splats,
        }
    }

    /// Traces pixel sample (`x`, `y`, `s`) of a render seeded `seed` and appends one seed per
    /// contribution (every strategy that carries light) to `store`.
    pub fn trace_sample(&mut self, seed: u64, sample: (u32, u32, u32), store: &mut SeedStore) {
        store.samples += 1;
        let raster = self.trace(seed, sample, true, &mut |_, _, _| {});
        // Taken out for the loop and put back after it (the buffers are kept).
        let rec = std::mem::take(&mut *self.recorder.borrow_mut());
        for event in &rec.events {
            let Some((density, raster)) = self.build_path(&rec, event, raster) else {
                continue;
            };
            let fits = self.path.len() <= MAX_PATH_VERTICES;
            let trunk = store.vertices.len();
            let (prefix, light) = if fits {
                let n = self.path.len() - 1;
                store.vertices.extend_from_slice(&self.path[..n]);
                (n, self.path[n])
            } else {
                // Too long for a path: stored without vertices (module docs).
                (0, self.path[0])
            };
            store.seeds.push(Seed {
                trunk: trunk as u32,
                prefix: prefix as u32,
                connect: None,
                light,
                raster,
                estimate: event.value,
                layer: event.layer,
                mis_weight: event.weight,
                density,
                technique: Technique::Bidirectional {
                    s: event.s,
                    t: event.t,
                },
            });
        }
        *self.recorder.borrow_mut() = rec;
    }

    /// Writes the path of `event` into `self.path` (eye first) and returns its density
    /// p_{s,t} and raster position; `None` for an event the recording cannot place.
    fn build_path(
        &mut self,
        rec: &StrategyRecorder,
        event: &StrategyEvent,
        raster: Vec2,
    ) -> Option<(f64, Vec2)> {
        let (s, t) = (event.s as usize, event.t as usize);
        let scene = self.scene;
        self.path.clear();
        let forward = scene.camera.forward;
        // Camera vertices x₁ … x_{t−1} (or up to the emitter hit / before the escape).
        let camera_count = match event.end {
            StrategyEnd::Eye { .. } => 0,
            StrategyEnd::Escape { .. } => t.checked_sub(2)?,
            _ => t.checked_sub(1)?,
        };
        if camera_count > rec.camera.len() || s.saturating_sub(1) > rec.light.len() {
            return None;
        }
        let (eye, raster) = match event.end {
            StrategyEnd::Eye { raster, eye, .. } => (eye, raster),
            _ => (
                rec.camera_eye
                    .unwrap_or_else(|| scene.camera.eye_point(raster)),
                raster,
            ),
        };
        self.path.push(PathVertex::eye(eye, forward));
        for v in &rec.camera[..camera_count] {
            self.path
                .push(PathVertex::from_hit(&v.hit, NodeType::DiffuseReflection, 0));
        }
        let camera_density = camera_count
            .checked_sub(1)
            .map_or(1.0, |k| rec.camera[k].density);
        // Light vertices y_{s−1} … y₁ (eye order), then the light.
        let light_hits = s.saturating_sub(1);
        let density = match event.end {
            StrategyEnd::Hit => {
                let last = self.path.pop()?;
                self.path.push(PathVertex {
                    node: NodeType::Light,
                    component: 0,
                    ..last
                });
                camera_density
            }
            StrategyEnd::Escape {
                dir, light, pdf, ..
            } => {
                let from = self.path.last()?.p;
                self.path.push(distant_vertex(from, dir, light));
                camera_density * pdf
            }
            StrategyEnd::LightSample { vertex, pdf } => {
                self.path.push(vertex);
                camera_density * pdf
            }
            StrategyEnd::LightVertex | StrategyEnd::Eye { .. } => {
                let e = rec.emission?;
                for y in rec.light[..light_hits].iter().rev() {
                    self.path
                        .push(PathVertex::from_hit(&y.hit, NodeType::DiffuseReflection, 0));
                }
                let p_ref = self.path.last()?.p;
                self.path.push(origin_vertex(scene, &e, p_ref));
                let light_density = light_hits
                    .checked_sub(1)
                    .map_or(rec.origin_density, |j| rec.light[j].density);
                match event.end {
                    StrategyEnd::Eye { density, .. } => light_density / density,
                    _ => camera_density * light_density,
                }
            }
        };
        self.set_nodes(rec, camera_count, light_hits, event.end);
        let light_part = matches!(
            event.end,
            StrategyEnd::LightVertex | StrategyEnd::Eye { .. }
        );
        let density = if light_part {
            density * self.light_runs_jacobian(rec, camera_count, light_hits)
        } else {
            density
        };
        Some((density, raster))
    }

    /// Sets the node type of every scattering vertex of `self.path` (module docs): camera
    /// vertex k by the step that reached camera vertex k + 1 (the escape's own step for the
    /// last), light vertex y_j by the step that reached y_{j+1}; connection vertices are
    /// smooth.
    fn set_nodes(
        &mut self,
        rec: &StrategyRecorder,
        camera_count: usize,
        light_hits: usize,
        end: StrategyEnd,
    ) {
        let n = self.path.len();
        let camera_scattering = match end {
            StrategyEnd::Hit => camera_count - 1,
            _ => camera_count,
        };
        let light_scattering = match end {
            StrategyEnd::LightVertex | StrategyEnd::Eye { .. } => light_hits,
            _ => 0,
        };
        for k in 1..=camera_scattering + light_scattering {
            let dirac = if k < camera_count {
                rec.camera[k].dirac_in
            } else if k == camera_count {
                matches!(end, StrategyEnd::Escape { dirac: true, .. })
            } else {
                // y_j, the first light vertex after the camera's being y_{light_hits}.
                let j = light_hits + camera_count + 1 - k;
                j < light_hits && rec.light[j].dirac_in
            };
            let hit = self.path[k].surface();
            let bsdf = self.scene.bsdf(&hit);
            let next = if k + 2 == n && is_distant(self.scene, &self.path[n - 1]) {
                self.path[n - 1].ng
            } else {
                (self.path[k + 1].p - self.path[k].p).normalize_or_zero()
            };
            let (node, component) = vertex_node(&bsdf, &hit, self.path[k - 1].p, next, dirac);
            self.path[k].node = node;
            self.path[k].component = component;
        }
    }
}

/// G(u, v) = |n_u·ω||n_v·ω|/d² of the segment between two stored vertices (geometric
/// normals), for a vertex at infinity `v` only |n_u·ω|: the area (or solid-angle) Jacobians of
/// the target's measure on both ends.
fn geometry(scene: &Scene, u: &PathVertex, v: &PathVertex) -> f64 {
    if is_distant(scene, v) {
        return u.ng.dot(v.ng).abs() as f64;
    }
    let d = v.p - u.p;
    let d2 = d.length_squared() as f64;
    (u.ng.dot(d).abs() as f64) * (v.ng.dot(d).abs() as f64) / (d2 * d2)
}

impl StrategySeeds<'_, '_> {
    /// p_eye / p_light of the light part of `self.path` (module docs, "Light-side Dirac
    /// chains"): the product over its Dirac runs x_a … x_b of G(x_{a−1}, x_a) / G(x_b, x_{b+1})
    /// times, per vertex k of the run, ρ_k = η'²_k · |n_g·ω_L||n_s·ω_E| / (|n_g·ω_E||n_s·ω_L|)
    /// (ω_E towards the eye side, ω_L towards the light side, η'_k the light subpath's).
    fn light_runs_jacobian(
        &self,
        rec: &StrategyRecorder,
        camera_count: usize,
        light_hits: usize,
    ) -> f64 {
        let (p, n) = (&self.path, self.path.len());
        // Path index k of the light part is light vertex y_j, j = light_hits + camera_count + 1 − k;
        // η'² of the light subpath on arriving there.
        let eta2_at = |k: usize| {
            let j = light_hits + camera_count + 1 - k;
            j.checked_sub(1).map_or(1.0, |i| rec.light[i].eta2) as f64
        };
        let direction = |k: usize, to: usize| {
            if to == n - 1 && is_distant(self.scene, &p[to]) {
                p[to].ng
            } else {
                (p[to].p - p[k].p).normalize_or_zero()
            }
        };
        let mut factor = 1.0;
        let mut run_start = None;
        for k in camera_count + 1..n - 1 {
            if !p[k].node.is_specular() {
                continue;
            }
            let a = *run_start.get_or_insert(k);
            let (w_eye, w_light) = (direction(k, k - 1), direction(k, k + 1));
            let (v, cos) = (&p[k], |n: Vec3, w: Vec3| n.dot(w).abs() as f64);
            let eta2 = eta2_at(k - 1) / eta2_at(k);
            factor *= eta2 * cos(v.ng, w_light) * cos(v.ns, w_eye)
                / (cos(v.ng, w_eye) * cos(v.ns, w_light));
            if !p[k + 1].node.is_specular() {
                factor *=
                    geometry(self.scene, &p[a - 1], &p[a]) / geometry(self.scene, &p[k], &p[k + 1]);
                run_start = None;
            }
        }
        factor
    }
}

/// Whether `v` is a light vertex at infinity (`measure::is_distant`).
fn is_distant(scene: &Scene, v: &PathVertex) -> bool {
    usize::try_from(v.emitter).is_ok_and(|i| {
        v.node == NodeType::Light && i < scene.lights.count() && scene.lights.kind(i).is_distant()
    })
}

/// A light vertex at infinity: direction `dir` from the scene towards light `light`, stored
/// one unit beyond `from` (`measure::distant_vertex`).
fn distant_vertex(from: Vec3, dir: Vec3, light: usize) -> PathVertex {
    PathVertex {
        ng: dir,
        ns: dir,
        emitter: light as i32,
        node: NodeType::Light,
        ..PathVertex::eye(from + dir, dir)
    }
}
