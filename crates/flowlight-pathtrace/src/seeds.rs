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
//!
//! [`trace_wavefront`] traces many trees at once as ray batches (camera, then per bounce
//! extension and shadow rays), each tree into buffers of its own that join the store in the
//! order of the trees: the same store, bit for bit, as path-at-a-time calls in that order.
//! Both run the same per-vertex step (`Tree::vertex`), which returns a light connection's
//! shadow ray instead of tracing it.

use crate::settings::PathSettings;
use crate::shading::{connection_bsdf, light_connection, light_sample, side_consistent, Shading};
use crate::untangled::{environment_vertex, light_vertex};
use crate::SampleContributions;
use flowlight_core::bsdf::{volume, Bsdf};
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::{area_to_solid_angle, LightKind};
use flowlight_core::mesh::CompactHit;
use flowlight_core::path::{NodeType, Path, PathVertex, MAX_PATH_VERTICES};
use flowlight_core::rng::Rng;
use flowlight_core::sampler::{SampleStream, SLOT_BSDF, SLOT_LIGHT, SLOT_ROULETTE};
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
#[derive(Clone, Copy, Debug, PartialEq)]
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
pub fn trace<S: SampleStream + Clone>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut S,
    raster: Vec2,
    store: &mut SeedStore,
) {
    trace_with(scene, tracer, settings, rng, raster, store, None);
}

/// [`trace`] that stores only the seeds `split.filter` keeps; the others' estimates are added
/// to `split.rest` (not cleared first). The same random numbers are drawn as by [`trace`], and
/// a seed is stored here exactly when [`trace`] stores it and the filter keeps its path.
pub fn trace_split<S: SampleStream + Clone>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut S,
    raster: Vec2,
    store: &mut SeedStore,
    split: &mut SeedSplit,
) {
    trace_with(scene, tracer, settings, rng, raster, store, Some(split));
}

fn trace_with<S: SampleStream + Clone>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &mut S,
    raster: Vec2,
    store: &mut SeedStore,
    split: Option<&mut SeedSplit>,
) {
    store.samples += 1;
    let (trunk, seeds) = (store.vertices.len(), store.seeds.len());
    let mut tree = Tree::start(scene, rng.clone(), raster);
    let mut out = TreeOut {
        vertices: &mut store.vertices,
        seeds: &mut store.seeds,
        base: trunk,
        split,
    };
    tree.begin(scene, &mut out);
    loop {
        let Some(hit) = tracer.intersect(&tree.ray) else {
            tree.escape(scene, &mut out);
            break;
        };
        let (going, pending) = tree.vertex(scene, settings, &hit, &mut out);
        if let Some(p) = pending {
            out.connect(p, !tracer.occluded(&p.ray));
        }
        if !going {
            break;
        }
    }
    *rng = tree.rng;
    // A tree without seeds keeps no trunk.
    if store.seeds.len() == seeds {
        store.vertices.truncate(trunk);
    }
}

/// Reusable buffers of [`trace_wavefront`]: the trees of one wave and their own trunks, seeds
/// and split-off estimates (one set per work unit, so no allocation per path).
pub struct SeedWavefront<S = Rng> {
    trees: Vec<Tree<S>>,
    buffers: Vec<TreeBuffers>,
    active: Vec<u32>,
    rays: Vec<Ray>,
    hits: Vec<CompactHit>,
    shadow_rays: Vec<Ray>,
    pending: Vec<(u32, PendingConnection)>,
    blocked: Vec<u8>,
}

impl<S> Default for SeedWavefront<S> {
    fn default() -> Self {
        SeedWavefront {
            trees: Vec::new(),
            buffers: Vec::new(),
            active: Vec::new(),
            rays: Vec::new(),
            hits: Vec::new(),
            shadow_rays: Vec::new(),
            pending: Vec::new(),
            blocked: Vec::new(),
        }
    }
}

/// One tree's own trunk, seeds and split-off estimates in a [`SeedWavefront`].
#[derive(Default)]
struct TreeBuffers {
    vertices: Vec<PathVertex>,
    seeds: Vec<Seed>,
    rest: SampleContributions,
    rest_count: u64,
}

impl TreeBuffers {
    fn clear(&mut self) {
        self.vertices.clear();
        self.seeds.clear();
        self.rest.clear();
        self.rest_count = 0;
    }

    /// Runs `f` with this tree's [`TreeOut`], then counts the seeds it split off.
    fn with_out<R>(
        &mut self,
        filter: Option<&dyn SeedFilter>,
        f: impl FnOnce(&mut TreeOut) -> R,
    ) -> R {
        let mut split = filter.map(|filter| SeedSplit {
            filter,
            rest: &mut self.rest,
            count: 0,
        });
        let mut out = TreeOut {
            vertices: &mut self.vertices,
            seeds: &mut self.seeds,
            base: 0,
            split: split.as_mut(),
        };
        let r = f(&mut out);
        self.rest_count += split.map_or(0, |s| s.count);
        r
    }
}

/// What [`trace_wavefront`] hands back per tree, in the order of `starts`: the index of the
/// tree, the index in `store.seeds` of its first seed, and, with a filter, the estimates and
/// the number of its seeds the filter did not keep.
pub struct TreeSeeds<'a> {
    pub index: usize,
    pub first_seed: usize,
    pub rest: &'a SampleContributions,
    pub rest_count: u64,
}

/// [`trace`] (no `filter`) or [`trace_split`] for `starts.len()` path trees at once: the
/// camera rays as one batch (marked coherent), then per bounce one batch of extension rays and
/// one of shadow rays, as [`crate::entangled::trace_wavefront`] does, with the shading built
/// from the compact hits by [`Scene::surface`] (the host's own surface code). Tree `i` starts
/// from `starts[i]` = (its generator, its raster position). The seeds land in `store` tree by
/// tree in the order of `starts`, each tree's trunk followed by nothing of another tree, so the
/// store equals what the path-at-a-time calls in that order give, bit for bit; `each` is
/// called for every tree in that order, after its seeds are stored.
#[allow(clippy::too_many_arguments)]
pub fn trace_wavefront<S: SampleStream + Clone>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
    filter: Option<&dyn SeedFilter>,
    wf: &mut SeedWavefront<S>,
    store: &mut SeedStore,
    mut each: impl FnMut(TreeSeeds),
) {
    let n = starts.len();
    if wf.buffers.len() < n {
        wf.buffers.resize_with(n, TreeBuffers::default);
    }
    wf.trees.clear();
    wf.active.clear();
    for (i, (rng, raster)) in starts.iter().enumerate() {
        let tree = Tree::start(scene, rng.clone(), *raster);
        let buffers = &mut wf.buffers[i];
        buffers.clear();
        buffers.with_out(filter, |out| tree.begin(scene, out));
        wf.trees.push(tree);
        wf.active.push(i as u32);
    }
    let mut coherent = true;
    while !wf.active.is_empty() {
        wf.rays.clear();
        wf.rays
            .extend(wf.active.iter().map(|&i| wf.trees[i as usize].ray));
        tracer.intersect_batch(&wf.rays, coherent, &mut wf.hits);
        coherent = false;
        wf.shadow_rays.clear();
        wf.pending.clear();
        let mut kept = 0;
        for k in 0..wf.active.len() {
            let i = wf.active[k] as usize;
            let tree = &mut wf.trees[i];
            let compact = wf.hits[k];
            scene.prefetch_surfaces(&wf.hits, k);
            let going = wf.buffers[i].with_out(filter, |out| {
                if !compact.is_hit() {
                    tree.escape(scene, out);
                    return false;
                }
                let hit = scene.surface(&tree.ray, &compact);
                let (going, pending) = tree.vertex(scene, settings, &hit, out);
                if let Some(p) = pending {
                    wf.shadow_rays.push(p.ray);
                    wf.pending.push((i as u32, p));
                }
                going
            });
            if going {
                wf.active[kept] = i as u32;
                kept += 1;
            }
        }
        wf.active.truncate(kept);
        if !wf.shadow_rays.is_empty() {
            tracer.occluded_batch(&wf.shadow_rays, &mut wf.blocked);
            for (&(i, p), &b) in wf.pending.iter().zip(&wf.blocked) {
                wf.buffers[i as usize].with_out(filter, |out| out.connect(p, b == 0));
            }
        }
    }
    for (i, buffers) in wf.buffers[..n].iter().enumerate() {
        store.samples += 1;
        let first_seed = store.seeds.len();
        if !buffers.seeds.is_empty() {
            let base = store.vertices.len() as u32;
            store.vertices.extend_from_slice(&buffers.vertices);
            store.seeds.extend(buffers.seeds.iter().map(|s| Seed {
                trunk: s.trunk + base,
                ..*s
            }));
        }
        each(TreeSeeds {
            index: i,
            first_seed,
            rest: &buffers.rest,
            rest_count: buffers.rest_count,
        });
    }
}

/// Where a tree's trunk and seeds go: `vertices` from index `base` on holds the trunk, `seeds`
/// the stored seeds, and `split` (if any) takes the seeds its filter does not keep.
struct TreeOut<'a, 'b> {
    vertices: &'a mut Vec<PathVertex>,
    seeds: &'a mut Vec<Seed>,
    base: usize,
    split: Option<&'a mut SeedSplit<'b>>,
}

impl TreeOut<'_, '_> {
    /// Trunk vertices so far (eye included).
    fn trunk_len(&self) -> usize {
        self.vertices.len() - self.base
    }

    /// Stores `seed` with the first `prefix` trunk vertices.
    fn push(&mut self, prefix: usize, seed: Seed) {
        self.seeds.push(Seed {
            trunk: self.base as u32,
            prefix: prefix as u32,
            ..seed
        });
    }

    /// Where a seed of type `types` goes: `true` to the store, `false` to the split's rest
    /// (after adding its estimate there). Without a split every seed is stored.
    fn route(&mut self, types: &[NodeType], layer: u32, estimate: Rgb) -> bool {
        match &mut self.split {
            None => true,
            Some(s) if s.filter.keeps(types) => true,
            Some(s) => {
                s.count += 1;
                s.rest.add(layer, estimate);
                false
            }
        }
    }

    /// A light connection's shadow ray answered: a stored seed stays only if `visible` (it is
    /// the tree's last seed: nothing is stored between a connection and its answer); a seed
    /// for the split's rest goes there only if `visible`.
    fn connect(&mut self, p: PendingConnection, visible: bool) {
        if p.stored {
            if !visible {
                self.seeds.pop();
            }
        } else if visible {
            if let Some(s) = &mut self.split {
                s.count += 1;
                s.rest.add(p.layer, p.estimate);
            }
        }
    }
}

/// A light connection waiting for its shadow ray. Its seed, when stored, is stored at once
/// (`stored`) and taken back if the ray is blocked, so the pending record stays small.
#[derive(Clone, Copy, Debug)]
struct PendingConnection {
    ray: Ray,
    stored: bool,
    layer: u32,
    estimate: Rgb,
}

/// The class of a light connection from the trunk's last vertex, `types[types.len() − 2]`,
/// decided before its shadow ray: `Some` with the node type and component to store the vertex
/// with ([`connection_node`]), or `None` when the split's filter does not keep it. The
/// most-scattering component is only looked for when the seed is stored or when the filter's
/// answer depends on which smooth component's type the vertex gets.
fn connection_class(
    split: Option<&SeedSplit>,
    bsdf: &Bsdf,
    shading: &Shading,
    wi: Vec3,
    types: &mut [NodeType],
) -> Option<(NodeType, u8)> {
    let n = types.len();
    types[n - 1] = NodeType::Light;
    if let Some(s) = split {
        // The filter's answer for each type a smooth component can give the vertex.
        let mut answer = None;
        let mut agree = true;
        for (c, _) in bsdf.components().filter(|(c, _)| !c.is_delta()) {
            types[n - 2] = c.node_type(shading.wo, wi);
            let keeps = s.filter.keeps(types);
            agree &= answer.is_none_or(|a| a == keeps);
            answer = Some(keeps);
        }
        if agree {
            if answer == Some(false) {
                return None;
            }
        } else {
            let node = connection_node(bsdf, shading.wo, wi);
            types[n - 2] = node.0;
            return s.filter.keeps(types).then_some(node);
        }
    }
    Some(connection_node(bsdf, shading.wo, wi))
}

/// One entangled path tree being split into seeds: the locals of the sampler between two
/// bounces.
#[derive(Clone, Debug)]
struct Tree<S> {
    rng: S,
    raster: Vec2,
    ray: Ray,
    beta: Rgb,
    /// p of the trunk so far, survival included.
    density: f64,
    inside: Option<Rgb>,
    depth: u32,
    physical: u32,
    step: Step,
    prev_p: Vec3,
    /// Product of η'² over the refractions so far (as `entangled::trace`).
    eta2: f32,
    last: bool,
    /// Node types of the trunk (eye first), with room for a connection vertex and a light.
    types: [NodeType; MAX_PATH_VERTICES + 1],
}

impl<S: SampleStream> Tree<S> {
    fn start(scene: &Scene, rng: S, raster: Vec2) -> Self {
        let ray = scene.camera.generate_ray(raster);
        Tree {
            rng,
            raster,
            ray,
            beta: Rgb::ONE,
            density: 1.0,
            inside: None,
            depth: 0,
            physical: 0,
            step: Step::Eye,
            prev_p: ray.origin,
            eta2: 1.0,
            last: false,
            types: [NodeType::Eye; MAX_PATH_VERTICES + 1],
        }
    }

    /// Stores the eye vertex.
    fn begin(&self, scene: &Scene, out: &mut TreeOut) {
        out.vertices
            .push(PathVertex::eye(self.ray.origin, scene.camera.forward));
    }

    /// The ray escaped: the environment's seed, MIS-weighted against its light sample.
    fn escape(&mut self, scene: &Scene, out: &mut TreeOut) {
        let ray = self.ray;
        let le = scene.lights.environment_radiance(ray.dir);
        let Some(env) = scene.lights.environment_index() else {
            return;
        };
        if le.is_black() {
            return;
        }
        let (w, p) = match self.step {
            Step::Eye => (1.0, self.density),
            Step::Dirac(pdf) => (1.0, self.density * pdf as f64),
            Step::Smooth(pdf) => (
                power_heuristic(pdf, scene.lights.pdf_environment(ray.dir)),
                self.density * pdf as f64,
            ),
        };
        let estimate = self.beta * le * w;
        let count = out.trunk_len();
        self.types[count] = NodeType::Light;
        if estimate.is_black() || !out.route(&self.types[..=count], self.depth, estimate) {
            return;
        }
        let light = environment_vertex(&ray, env);
        let seed = Seed {
            trunk: 0,
            prefix: 0,
            connect: None,
            light,
            raster: self.raster,
            estimate,
            layer: self.depth,
            mis_weight: w,
            density: p,
            technique: Technique::Escape,
        };
        out.push(count, seed);
    }

    /// The sampler's step at `hit`: its emission seed, its light connection (returned with the
    /// shadow ray that decides it, not traced here) and its BSDF sample. Returns whether the
    /// tree goes on (with `self.ray`).
    fn vertex(
        &mut self,
        scene: &Scene,
        settings: &PathSettings,
        hit: &SurfaceHit,
        out: &mut TreeOut,
    ) -> (bool, Option<PendingConnection>) {
        let count = out.trunk_len();
        if let Some(sigma) = self.inside.take() {
            self.beta *= volume::transmittance(sigma, hit.t);
        }
        let wo_world = -self.ray.dir;
        self.density *= match self.step {
            Step::Eye => 1.0,
            Step::Dirac(pdf) => pdf as f64,
            Step::Smooth(pdf) => {
                let d = hit.p - self.prev_p;
                let d2 = d.length_squared() as f64;
                pdf as f64 * (hit.ng.dot(d).abs() as f64 / (d2 * d2.sqrt()))
            }
        };

        if hit.emitter >= 0 {
            let le = scene.lights.emitted(hit.emitter as usize, hit.p, wo_world);
            if !le.is_black() {
                let w = match self.step {
                    Step::Eye | Step::Dirac(_) => 1.0,
                    Step::Smooth(pdf) => {
                        let pdf_light = area_to_solid_angle(
                            scene.lights.pdf_area(hit.emitter as usize),
                            self.prev_p,
                            hit.p,
                            hit.ng,
                        );
                        power_heuristic(pdf, pdf_light)
                    }
                };
                let estimate = self.beta * le * w;
                self.types[count] = NodeType::Light;
                if !estimate.is_black() && out.route(&self.types[..=count], self.depth, estimate) {
                    let seed = Seed {
                        trunk: 0,
                        prefix: 0,
                        connect: None,
                        light: PathVertex::from_hit(hit, NodeType::Light, 0),
                        raster: self.raster,
                        estimate,
                        layer: self.depth,
                        mis_weight: w,
                        density: self.density,
                        technique: Technique::Hit,
                    };
                    out.push(count, seed);
                }
            }
        }
        if self.last {
            return (false, None);
        }

        let bsdf = scene.bsdf(hit);
        let next_depth = if self.depth == 0 && bsdf.is_delta() {
            0
        } else {
            self.depth + 1
        };
        // Room for this vertex and a light vertex after it.
        if next_depth > settings.path_depth || count + 2 > MAX_PATH_VERTICES {
            return (false, None);
        }
        self.depth = next_depth;
        self.physical += 1;
        let shading = Shading::new(hit, wo_world);
        // Its node type is the BSDF sample's, set below.
        out.vertices
            .push(PathVertex::from_hit(hit, NodeType::DiffuseReflection, 0));

        let rng = &mut self.rng;
        let mut pending = None;
        if bsdf.has_non_delta() {
            rng.seek(self.physical, SLOT_LIGHT);
            let u_light = rng.uniform2();
            if let Some(ls) = light_sample(scene, &bsdf, hit, &shading, u_light) {
                if let Some((conn, shadow)) = light_connection(scene, hit, &shading, &ls) {
                    if let Some((f, w_over_pdf)) = connection_bsdf(&bsdf.at(shading.wo), &conn) {
                        // The light's own density in the target's measure: area density on an
                        // area light, else what next-event estimation divides by.
                        let p_light = if ls.kind == LightKind::Area {
                            ls.pdf
                        } else {
                            conn.pdf
                        };
                        let estimate =
                            self.beta * f * conn.radiance * (conn.wi_local.z.abs() * w_over_pdf);
                        // The weight itself, for the seed (≤ 1 although the product rounds).
                        let w = (w_over_pdf * conn.pdf).min(1.0);
                        if !estimate.is_black() {
                            let class = connection_class(
                                out.split.as_deref(),
                                &bsdf,
                                &shading,
                                conn.wi_local,
                                &mut self.types[..count + 2],
                            );
                            if let Some(connect) = class {
                                let seed = Seed {
                                    trunk: 0,
                                    prefix: 0,
                                    connect: Some(connect),
                                    light: light_vertex(scene, &ls, hit.p),
                                    raster: self.raster,
                                    estimate,
                                    layer: self.depth,
                                    mis_weight: w,
                                    density: self.density * p_light as f64,
                                    technique: Technique::Connection,
                                };
                                out.push(count + 1, seed);
                            }
                            pending = Some(PendingConnection {
                                ray: shadow.ray(hit),
                                stored: class.is_some(),
                                layer: self.depth,
                                estimate,
                            });
                        }
                    }
                }
            }
        }

        // As in the entangled sampler: the BSDF sample is traced for emission also where the
        // path cannot go on.
        let t = if self.depth > 0 {
            // The same decision as `entangled::trace` (same random stream, same throughput).
            settings.termination.probability_with_throughput(
                self.depth,
                bsdf.albedo(),
                self.beta.max_component() * self.eta2,
            )
        } else {
            0.0
        };
        self.last = t >= 1.0 || self.physical >= settings.max_ray_depth;
        if !self.last && t > 0.0 {
            rng.seek(self.physical, SLOT_ROULETTE);
            if rng.uniform() < t {
                return (false, pending);
            }
            self.beta /= 1.0 - t;
            self.density *= 1.0 - t as f64;
        }

        rng.seek(self.physical, SLOT_BSDF);
        let u_lobe = rng.uniform();
        let u = rng.uniform2();
        let Some(s) = bsdf.sample(shading.wo, u_lobe, u) else {
            return (false, pending);
        };
        // `Bsdf::sample` chooses the component with the pair's first number.
        let (component, _) = bsdf.choose_component(u.x);
        if let Some(v) = out.vertices.last_mut() {
            v.node = s.node;
            v.component = component as u8;
        }
        self.types[count] = s.node;
        let wi_world = shading.frame.to_world(s.wi);
        if !side_consistent(hit, wi_world, s.wi) {
            return (false, pending);
        }
        self.beta *= s.f * (s.wi.z.abs() / s.pdf);
        if self.beta.is_black() {
            return (false, pending);
        }
        self.eta2 *= s.eta * s.eta;
        self.step = if s.delta {
            Step::Dirac(s.pdf)
        } else {
            Step::Smooth(s.pdf)
        };
        self.prev_p = hit.p;
        self.inside = volume::entered(scene.material(hit), hit.ng, wi_world);
        self.ray = hit.spawn_ray(wi_world);
        (true, pending)
    }
}
