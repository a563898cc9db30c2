//! Entangled seeds for ERPT: one entangled MCPT path (next-event estimation at every smooth
//! vertex, BSDF sampling, the power heuristic between them; [`crate::entangled`]) split into
//! its techniques, each a complete eye-to-light path with its own estimate.
//!
//! An entangled path tree through raster position u has one *trunk* x₀ (eye) x₁ … x_m, the
//! BSDF-sampled camera path, and contributes along three techniques:
//!
//! ```text
//! connection at x_k:  x₀ … x_k y       y sampled on a light      X = w_c · f(x̄)/p_c(x̄)
//! hit at x_{k+1}:     x₀ … x_k x_{k+1}  x_{k+1} on an emitter     X = w_h · f(x̄)/p_h(x̄)
//! escape after x_k:   x₀ … x_k ω        ω into the environment    X = w_h · f(x̄)/p_h(x̄)
//! ```
//!
//! with f the target function of `flowlight-mcmc` (`measure.rs`: film measure for the eye ray,
//! area measure for free vertices, solid angle for a direction at infinity, the discrete
//! probability of a Dirac lobe) and p_t the density of drawing x̄ with technique t in that
//! measure: the product, over the trunk's steps, of the BSDF density times the area Jacobian
//! |n·ω|/d² (a Dirac step: the lobe's discrete probability; the eye ray: 1) and of the
//! survival probabilities 1 − T_k; times, for a connection, the light's area density (its
//! selection probability included) or, for a Dirac or distant light, what next-event
//! estimation divides by. The weights are the power heuristic of the entangled sampler,
//! w_c = p_c²/(p_c² + p_h²) and w_h = 1 − w_c, evaluated on the same last step (Veach 1997
//! §9.2; a Dirac light or a step after a Dirac vertex has one technique, weight 1). Since the
//! weights of the techniques that can draw a path sum to one,
//!
//! ```text
//! E[Σ_t X_t] = Σ_t ∫ p_t · w_t f / p_t = ∫ f
//! ```
//!
//! so the seeds' energy density over path space is f: the energy distribution that ERPT's
//! Metropolis flow (stationary density ∝ lum f) keeps (thesis §5.2–5.3). Mitsuba 0.6's ERPT
//! draws its seeds from bidirectional path tracing in the same way, each connection strategy
//! with its MIS weight (`src/integrators/erpt/`).
//!
//! Each seed records w_t and p_t beside X_t so that `tests/erpt_seeds.rs` can check
//! X_t = w_t · f(x̄)/p_t for every seed with `measure.rs`'s f. A trunk vertex keeps the node type
//! and BSDF component the BSDF sample chose; the vertex a light is connected from gets the type
//! of the smooth component that scatters most light along the connection (only Dirac versus
//! smooth matters for the target function, the letter for the Heckbert type).
//!
//! Seeds of one work unit are stored in a [`SeedStore`]: every trunk once, and per seed its
//! trunk prefix and light vertex, so that the unit's seeds are traced once and serve both the
//! deposition quantum and the flow.
//!
//! With a [`SeedSplit`] ([`trace_split`]) only the seeds whose path type the caller's
//! [`SeedFilter`] keeps are stored; the others only add their estimates to the split's
//! [`SampleContributions`], for the caller to deposit at the sample's pixel as path tracing
//! would. The type is known as the trunk grows (each vertex's node type, then the light), so a
//! seed outside the filter costs no record, no copy of its path and no second
//! classification. A connection vertex's stored type is that of the smooth component that
//! scatters most light (above); it is only computed when the filter's answer depends on it.

use crate::settings::PathSettings;
use crate::shading::{connect_light, side_consistent, Shading};
use crate::untangled::light_vertex;
use crate::SampleContributions;
use flowlight_core::bsdf::{volume, Bsdf};
use flowlight_core::light::{area_to_solid_angle, LightKind};
use flowlight_core::path::{NodeType, Path, PathVertex, MAX_PATH_VERTICES};
use flowlight_core::rng::Rng;
use flowlight_core::sampling::power_heuristic;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};

/// The technique that produced a seed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// Next-event estimation from the trunk's last vertex.
    Connection,
    /// A BSDF-sampled (or camera) ray hit an emitter.
    Hit,
    /// A BSDF-sampled (or camera) ray escaped into the environment.
    Escape,
    /// A whole untangled path ([`SeedStore::push_path`]).
    Untangled,
}

/// One seed: a path (a trunk prefix and a light vertex) with its estimate.
#[derive(Clone, Copy, Debug)]
pub struct Seed {
    /// Offset of the seed's trunk in [`SeedStore::vertices`].
    pub trunk: u32,
    /// Trunk vertices before the light vertex (eye included).
    pub prefix: u32,
    /// Node type and component of the last trunk vertex for a connection (the trunk holds
    /// the BSDF sample's).
    pub connect: Option<(NodeType, u8)>,
    pub light: PathVertex,
    pub raster: Vec2,
    /// X_t, MIS weight included.
    pub estimate: Rgb,
    pub layer: u32,
    /// The technique's MIS weight w_t (1 for untangled seeds).
    pub mis_weight: f32,
    /// p_t(x̄) in the measure of the target function (NaN for untangled seeds: not tracked).
    pub density: f64,
    pub technique: Technique,
}

/// The seeds of a work unit, traced once.
#[derive(Clone, Debug, Default)]
pub struct SeedStore {
    pub vertices: Vec<PathVertex>,
    pub seeds: Vec<Seed>,
    /// Camera samples traced into the store (each gives zero or more seeds).
    pub samples: u64,
}

impl SeedStore {
    pub fn clear(&mut self) {
        self.vertices.clear();
        self.seeds.clear();
        self.samples = 0;
    }

    /// Writes seed `i` into `out` (its vertices, raster position, layer and estimate; the film
    /// window is left as it is).
    pub fn path(&self, i: usize, out: &mut Path) {
        let s = &self.seeds[i];
        let t = s.trunk as usize;
        let n = s.prefix as usize;
        out.vertices[..n].copy_from_slice(&self.vertices[t..t + n]);
        if let (Some((node, component)), Some(v)) = (s.connect, n.checked_sub(1)) {
            out.vertices[v].node = node;
            out.vertices[v].component = component;
        }
        out.vertices[n] = s.light;
        out.vertex_count = n as u32 + 1;
        out.raster = s.raster;
        out.layer = s.layer;
        out.contribution = s.estimate;
    }

    /// Stores a whole path (an untangled seed, `path.contribution` its estimate). Every camera
    /// sample is one untangled seed, so a path that carries no light is stored too, without
    /// vertices (one record, so that the seeds count the samples as the thesis' do); a path
    /// without a light vertex but with a non-zero estimate is stored with a NaN estimate, so
    /// that the flow counts it as invalid.
    pub fn push_path(&mut self, path: &Path) {
        self.samples += 1;
        let n = path.vertex_count as usize;
        let estimate = path.contribution;
        let record = |trunk: usize, prefix: usize, estimate: Rgb| Seed {
            trunk: trunk as u32,
            prefix: prefix as u32,
            connect: None,
            light: path.vertices[n.saturating_sub(1)],
            raster: path.raster,
            estimate,
            layer: path.layer,
            mis_weight: 1.0,
            density: f64::NAN,
            technique: Technique::Untangled,
        };
        let trunk = self.vertices.len();
        if estimate.is_black() {
            self.seeds.push(record(trunk, 0, Rgb::ZERO));
        } else if n < 2 {
            self.seeds.push(record(trunk, 0, Rgb::splat(f32::NAN)));
        } else {
            self.vertices.extend_from_slice(&path.vertices[..n - 1]);
            self.seeds.push(record(trunk, n - 1, estimate));
        }
    }
}

/// Node type and component index of the smooth component of `bsdf` that scatters most light
/// from `wi` to `wo` (local frame): the type a connection vertex is stored with.
fn connection_node(bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> (NodeType, u8) {
    let mut best = (NodeType::DiffuseReflection, 0u8, -1.0f32);
    for (i, (c, w)) in bsdf.components().enumerate() {
        if c.is_delta() {
            continue;
        }
        let l = (c.eval(wo, wi) * w).luminance();
        if l > best.2 {
            best = (c.node_type(wo, wi), i as u8, l);
        }
    }
    (best.0, best.1)
}

/// How the trunk's last step was drawn, for the density of the vertex it reaches.
#[derive(Clone, Copy, PartialEq)]
enum Step {
    /// The camera ray: density 1 in the film measure.
    Eye,
    /// A Dirac lobe: its discrete probability.
    Dirac(f32),
    /// A smooth BSDF sample: solid-angle density, times the area Jacobian at a surface.
    Smooth(f32),
}

/// Which seeds [`trace_split`] stores with their paths.
pub trait SeedFilter {
    /// Whether a seed whose path has the node types `types` (eye first, light last) is kept.
    fn keeps(&self, types: &[NodeType]) -> bool;
}

/// The seeds a [`SeedFilter`] does not keep: their estimates go to `rest` (lighting layer,
/// estimate), and `count` counts them.
pub struct SeedSplit<'a> {
    pub filter: &'a dyn SeedFilter,
    pub rest: &'a mut SampleContributions,
    pub count: u64,
}

/// Traces one entangled path tree through `raster` and appends its seeds (every light
/// connection, emitter hit and environment escape that carries light) to `store`. The
/// estimates sum to the entangled sampler's estimate of the same path tree
/// ([`crate::entangled::trace`], same random-number order).
pub fn trace(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut Rng,
    raster: Vec2,
    store: &mut SeedStore,
) {
    trace_with(scene, tracer, settings, rng, raster, store, None);
}

/// [`trace`] that stores only the seeds `split.filter` keeps; the others' estimates are added
/// to `split.rest` (not cleared first). The same random numbers are drawn as by [`trace`], and
/// a seed is stored here exactly when [`trace`] stores it and the filter keeps its path.
pub fn trace_split(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut Rng,
    raster: Vec2,
    store: &mut SeedStore,
    split: &mut SeedSplit,
) {
    trace_with(scene, tracer, settings, rng, raster, store, Some(split));
}

fn trace_with(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut Rng,
    raster: Vec2,
    store: &mut SeedStore,
    split: Option<&mut SeedSplit>,
) {
    store.samples += 1;
    let (trunk, seeds) = (store.vertices.len(), store.seeds.len());
    trace_tree(scene, tracer, settings, rng, raster, store, split);
    // A tree without seeds keeps no trunk.
    if store.seeds.len() == seeds {
        store.vertices.truncate(trunk);
    }
}

/// Where a seed of type `types` goes: `true` to the store, `false` to the split's rest (after
/// adding its estimate there). Without a split every seed is stored.
#[inline]
fn route(
    split: &mut Option<&mut SeedSplit>,
    types: &[NodeType],
    layer: u32,
    estimate: Rgb,
) -> bool {
    match split {
        None => true,
        Some(s) if s.filter.keeps(types) => true,
        Some(s) => {
            s.count += 1;
            s.rest.add(layer, estimate);
            false
        }
    }
}

/// [`route`] for a light connection from the trunk's last vertex, `types[types.len() − 2]`:
/// the vertex's type is that of [`connection_node`], computed only when the seed is stored or
/// when the filter's answer depends on which smooth component's type it is. Returns the node
/// type and component to store, or `None` when the seed went to the split's rest.
fn connection_route(
    split: &mut Option<&mut SeedSplit>,
    bsdf: &Bsdf,
    shading: &Shading,
    wi: Vec3,
    types: &mut [NodeType],
    layer: u32,
    estimate: Rgb,
) -> Option<(NodeType, u8)> {
    let n = types.len();
    types[n - 1] = NodeType::Light;
    if let Some(s) = split.as_deref_mut() {
        // The filter's answer for each type a smooth component can give the vertex: when they
        // agree, the most-scattering component need not be found.
        let mut answer = None;
        let mut agree = true;
        for (c, _) in bsdf.components().filter(|(c, _)| !c.is_delta()) {
            types[n - 2] = c.node_type(shading.wo, wi);
            let keeps = s.filter.keeps(types);
            agree &= answer.is_none_or(|a| a == keeps);
            answer = Some(keeps);
        }
        if agree && answer == Some(false) {
            s.count += 1;
            s.rest.add(layer, estimate);
            return None;
        }
        if !agree {
            let node = connection_node(bsdf, shading.wo, wi);
            types[n - 2] = node.0;
            if !route(split, types, layer, estimate) {
                return None;
            }
            return Some(node);
        }
    }
    Some(connection_node(bsdf, shading.wo, wi))
}

fn trace_tree(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut Rng,
    raster: Vec2,
    store: &mut SeedStore,
    mut split: Option<&mut SeedSplit>,
) {
    let trunk = store.vertices.len();
    let mut ray = scene.camera.generate_ray(raster);
    store
        .vertices
        .push(PathVertex::eye(ray.origin, scene.camera.forward));
    // Node types of the trunk (eye first) and room for a connection vertex and a light.
    let mut types = [NodeType::Eye; MAX_PATH_VERTICES + 1];
    let mut beta = Rgb::ONE;
    let mut density = 1.0f64; // p of the trunk so far, survival included
    let mut inside: Option<Rgb> = None;
    let mut depth = 0u32;
    let mut physical = 0u32;
    let mut step = Step::Eye;
    let mut prev_p = ray.origin;
    let mut last = false;
    let emit = |store: &mut SeedStore, prefix: usize, seed: Seed| {
        store.seeds.push(Seed {
            trunk: trunk as u32,
            prefix: prefix as u32,
            ..seed
        });
    };
    loop {
        let count = store.vertices.len() - trunk;
        let Some(hit) = tracer.intersect(&ray) else {
            let le = scene.lights.environment_radiance(ray.dir);
            let Some(env) = scene.lights.environment_index() else {
                return;
            };
            if le.is_black() {
                return;
            }
            let (w, p) = match step {
                Step::Eye => (1.0, density),
                Step::Dirac(pdf) => (1.0, density * pdf as f64),
                Step::Smooth(pdf) => (
                    power_heuristic(pdf, scene.lights.pdf_environment(ray.dir)),
                    density * pdf as f64,
                ),
            };
            let estimate = beta * le * w;
            types[count] = NodeType::Light;
            if estimate.is_black() || !route(&mut split, &types[..=count], depth, estimate) {
                return;
            }
            let light = PathVertex {
                p: ray.origin + ray.dir,
                p_error: Vec3::ZERO,
                ng: ray.dir,
                ns: ray.dir,
                uv: Vec2::ZERO,
                uv1: Vec2::ZERO,
                color: [1.0; 4],
                prim: u32::MAX,
                material: u32::MAX,
                emitter: env as i32,
                node: NodeType::Light,
                component: 0,
            };
            let seed = Seed {
                trunk: 0,
                prefix: 0,
                connect: None,
                light,
                raster,
                estimate,
                layer: depth,
                mis_weight: w,
                density: p,
                technique: Technique::Escape,
            };
            emit(store, count, seed);
            return;
        };
        if let Some(sigma) = inside.take() {
            beta *= volume::transmittance(sigma, hit.t);
        }
        let wo_world = -ray.dir;
        density *= match step {
            Step::Eye => 1.0,
            Step::Dirac(pdf) => pdf as f64,
            Step::Smooth(pdf) => {
                let d = hit.p - prev_p;
                let d2 = d.length_squared() as f64;
                pdf as f64 * (hit.ng.dot(d).abs() as f64 / (d2 * d2.sqrt()))
            }
        };

        if hit.emitter >= 0 {
            let le = scene.lights.emitted(hit.emitter as usize, hit.p, wo_world);
            if !le.is_black() {
                let w = match step {
                    Step::Eye | Step::Dirac(_) => 1.0,
                    Step::Smooth(pdf) => {
                        let pdf_light = area_to_solid_angle(
                            scene.lights.pdf_area(hit.emitter as usize),
                            prev_p,
                            hit.p,
                            hit.ng,
                        );
                        power_heuristic(pdf, pdf_light)
                    }
                };
                let estimate = beta * le * w;
                types[count] = NodeType::Light;
                if !estimate.is_black() && route(&mut split, &types[..=count], depth, estimate) {
                    let seed = Seed {
                        trunk: 0,
                        prefix: 0,
                        connect: None,
                        light: PathVertex::from_hit(&hit, NodeType::Light, 0),
                        raster,
                        estimate,
                        layer: depth,
                        mis_weight: w,
                        density,
                        technique: Technique::Hit,
                    };
                    emit(store, count, seed);
                }
            }
        }
        if last {
            return;
        }

        let bsdf = scene.bsdf(&hit);
        let next_depth = if depth == 0 && bsdf.is_delta() {
            0
        } else {
            depth + 1
        };
        // Room for this vertex and a light vertex after it.
        if next_depth > settings.path_depth || count + 2 > MAX_PATH_VERTICES {
            return;
        }
        depth = next_depth;
        physical += 1;
        let shading = Shading::new(&hit, wo_world);
        // Its node type is the BSDF sample's, set below.
        store
            .vertices
            .push(PathVertex::from_hit(&hit, NodeType::DiffuseReflection, 0));

        if bsdf.has_non_delta() {
            if let Some(ls) = scene.lights.sample(rng.uniform(), rng.uniform2()) {
                if let Some(conn) = connect_light(scene, tracer, &hit, &shading, &ls) {
                    let f = bsdf.eval(shading.wo, conn.wi_local);
                    if !f.is_black() {
                        let w = if conn.delta {
                            1.0
                        } else {
                            power_heuristic(conn.pdf, bsdf.pdf(shading.wo, conn.wi_local))
                        };
                        // The light's own density in the target's measure: area density on an
                        // area light, else what next-event estimation divides by.
                        let p_light = if ls.kind == LightKind::Area {
                            ls.pdf
                        } else {
                            conn.pdf
                        };
                        let estimate =
                            beta * f * conn.radiance * (conn.wi_local.z.abs() * w / conn.pdf);
                        let connect = (!estimate.is_black())
                            .then(|| {
                                connection_route(
                                    &mut split,
                                    &bsdf,
                                    &shading,
                                    conn.wi_local,
                                    &mut types[..count + 2],
                                    depth,
                                    estimate,
                                )
                            })
                            .flatten();
                        if let Some(connect) = connect {
                            let seed = Seed {
                                trunk: 0,
                                prefix: 0,
                                connect: Some(connect),
                                light: light_vertex(scene, &ls, hit.p),
                                raster,
                                estimate,
                                layer: depth,
                                mis_weight: w,
                                density: density * p_light as f64,
                                technique: Technique::Connection,
                            };
                            emit(store, count + 1, seed);
                        }
                    }
                }
            }
        }

        // As in the entangled sampler: the BSDF sample is traced for emission also where the
        // path cannot go on.
        let t = if depth > 0 {
            // The same decision as `entangled::trace` (same random stream, same throughput).
            settings.termination.probability_with_throughput(
                depth,
                bsdf.albedo(),
                beta.max_component(),
            )
        } else {
            0.0
        };
        last = t >= 1.0 || physical >= settings.max_ray_depth;
        if !last && t > 0.0 {
            if rng.uniform() < t {
                return;
            }
            beta /= 1.0 - t;
            density *= 1.0 - t as f64;
        }

        let u_component = rng.uniform();
        let Some(s) = bsdf.sample(shading.wo, u_component, rng.uniform2()) else {
            return;
        };
        let (component, _) = bsdf.choose_component(u_component);
        if let Some(v) = store.vertices.last_mut() {
            v.node = s.node;
            v.component = component as u8;
        }
        types[count] = s.node;
        let wi_world = shading.frame.to_world(s.wi);
        if !side_consistent(&hit, wi_world, s.wi) {
            return;
        }
        beta *= s.f * (s.wi.z.abs() / s.pdf);
        if beta.is_black() {
            return;
        }
        step = if s.delta {
            Step::Dirac(s.pdf)
        } else {
            Step::Smooth(s.pdf)
        };
        prev_p = hit.p;
        inside = volume::entered(scene.material(&hit), hit.ng, wi_world);
        ray = hit.spawn_ray(wi_world);
    }
}
