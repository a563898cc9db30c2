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
//! Each seed records w_t and p_t beside X_t so that `tests/integration/erpt_seeds.rs` can check
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
//! The path tree is walked by the crate's walker ([`crate::walk`]), the same step and
//! scheduler as MCPT's; this module is its seed sink. [`trace_wavefront`] walks many trees at
//! once as ray batches, each tree into buffers of its own that join the store in the order of
//! the trees: the same store, bit for bit, as path-at-a-time calls ([`trace`]) in that order.

use crate::sampler::BranchStream;
use crate::settings::PathSettings;
use crate::shading::{connection_bsdf, Shading};
use crate::untangled::{environment_vertex, light_vertex};
use crate::walk::{self, ConnectionEvent, Extension, PathSink, Step, WalkState, Wave, WaveSinks};
use crate::SampleContributions;
use flowlight_core::bsdf::Bsdf;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::LightKind;
use flowlight_core::path::{NodeType, Path, PathVertex, MAX_PATH_VERTICES};
use flowlight_core::rng::Rng;
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
    /// Strategy (s, t) of a BDPT sample: s light and t camera vertices
    /// ([`crate::bidir::strategy_seeds`]).
    Bidirectional { s: u32, t: u32 },
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
pub(crate) fn connection_node(bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> (NodeType, u8) {
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
pub fn trace<S: BranchStream>(
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
pub fn trace_split<S: BranchStream>(
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

/// A light connection's shadow ray in [`trace`]'s thread buffer.
type ShadowBuffer = (Vec<Ray>, Vec<(u32, PendingConnection)>);

thread_local! {
    /// [`trace`]'s shadow rays and their records between a vertex and their tests.
    static SHADOWS: std::cell::RefCell<ShadowBuffer> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

fn trace_with<S: BranchStream>(
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
    // Without a split nothing goes to the rest (allocates nothing).
    let (mut no_rest, mut no_count) = (SampleContributions::default(), 0);
    let (filter, rest, rest_count) = match split {
        Some(s) => (Some(s.filter), &mut *s.rest, &mut s.count),
        None => (None, &mut no_rest, &mut no_count),
    };
    let mut out = TreeOut {
        vertices: &mut store.vertices,
        seeds: &mut store.seeds,
        base: trunk,
        filter,
        rest,
        rest_count,
    };
    let trail = SeedTrail::new(raster);
    *rng = SHADOWS.with_borrow_mut(|shadows| {
        let start = rng.clone();
        walk::run_single(
            scene, tracer, settings, start, raster, trail, &mut out, shadows,
        )
    });
    // A tree without seeds keeps no trunk.
    if store.seeds.len() == seeds {
        store.vertices.truncate(trunk);
    }
}

/// Reusable buffers of [`trace_wavefront`]: the wave and the trees' own trunks, seeds and
/// split-off estimates (one set per work unit or thread, so no allocation per path).
pub struct SeedWavefront<S = Rng> {
    wave: Wave<S, SeedTrail, PendingConnection>,
    buffers: Vec<TreeBuffers>,
}

impl<S> Default for SeedWavefront<S> {
    fn default() -> Self {
        SeedWavefront {
            wave: Wave::default(),
            buffers: Vec::new(),
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
}

/// The sinks of a seed wave: tree `i` reports into `buffers[i]`.
struct TreeSinks<'a, 'f> {
    buffers: &'a mut [TreeBuffers],
    filter: Option<&'f dyn SeedFilter>,
}

impl<'f> WaveSinks for TreeSinks<'_, 'f> {
    type Trail = SeedTrail;
    type Pending = PendingConnection;
    type Sink<'b>
        = TreeOut<'b>
    where
        Self: 'b;

    #[inline(always)]
    fn sink(&mut self, tree: usize) -> TreeOut<'_> {
        let b = &mut self.buffers[tree];
        TreeOut {
            vertices: &mut b.vertices,
            seeds: &mut b.seeds,
            base: 0,
            filter: self.filter,
            rest: &mut b.rest,
            rest_count: &mut b.rest_count,
        }
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

/// [`trace`] (no `filter`) or [`trace_split`] for `starts.len()` path trees at once, as ray
/// batches ([`walk::run_wave`]). Tree `i` starts from `starts[i]` = (its generator, its raster
/// position). The seeds land in `store` tree by tree in the order of `starts`, each tree's
/// trunk followed by nothing of another tree, so the store equals what the path-at-a-time
/// calls in that order give, bit for bit; `each` is called for every tree in that order,
/// after its seeds are stored.
#[allow(clippy::too_many_arguments)]
pub fn trace_wavefront<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
    filter: Option<&dyn SeedFilter>,
    wf: &mut SeedWavefront<S>,
    store: &mut SeedStore,
    mut each: impl FnMut(TreeSeeds),
) {
    debug_assert_eq!(settings.branches, 1, "seed trees do not split");
    let n = starts.len();
    if wf.buffers.len() < n {
        wf.buffers.resize_with(n, TreeBuffers::default);
    }
    wf.buffers[..n].iter_mut().for_each(TreeBuffers::clear);
    let mut sinks = TreeSinks {
        buffers: &mut wf.buffers[..n],
        filter,
    };
    walk::run_wave(
        scene,
        tracer,
        settings,
        starts,
        SeedTrail::new,
        &mut wf.wave,
        &mut sinks,
    );
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

/// What the seed sink keeps per tree beside the walker's state.
#[derive(Clone, Debug)]
pub struct SeedTrail {
    raster: Vec2,
    /// p of the trunk so far (in the target's measure), survival included.
    density: f64,
    /// Node types of the trunk (eye first), with room for a connection vertex and a light.
    types: [NodeType; MAX_PATH_VERTICES + 1],
}

impl SeedTrail {
    fn new(raster: Vec2) -> Self {
        SeedTrail {
            raster,
            density: 1.0,
            types: [NodeType::Eye; MAX_PATH_VERTICES + 1],
        }
    }
}

/// Where a tree's trunk and seeds go: `vertices` from index `base` on holds the trunk, `seeds`
/// the stored seeds; with a `filter`, the seeds it does not keep go to `rest` (and are
/// counted in `rest_count`). The seed sink of the walker.
pub struct TreeOut<'a> {
    vertices: &'a mut Vec<PathVertex>,
    seeds: &'a mut Vec<Seed>,
    base: usize,
    filter: Option<&'a dyn SeedFilter>,
    rest: &'a mut SampleContributions,
    rest_count: &'a mut u64,
}

impl TreeOut<'_> {
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

    /// Where a seed of type `types` goes: `true` to the store, `false` to the rest (after
    /// adding its estimate there). Without a filter every seed is stored.
    fn route(&mut self, types: &[NodeType], layer: u32, estimate: Rgb) -> bool {
        match self.filter {
            None => true,
            Some(f) if f.keeps(types) => true,
            Some(_) => {
                *self.rest_count += 1;
                self.rest.add(layer, estimate);
                false
            }
        }
    }

    /// A seed of `technique` ending at the light vertex `light`.
    #[allow(clippy::too_many_arguments)]
    fn seed(
        trail: &SeedTrail,
        light: PathVertex,
        connect: Option<(NodeType, u8)>,
        estimate: Rgb,
        layer: u32,
        mis_weight: f32,
        density: f64,
        technique: Technique,
    ) -> Seed {
        Seed {
            trunk: 0,
            prefix: 0,
            connect,
            light,
            raster: trail.raster,
            estimate,
            layer,
            mis_weight,
            density,
            technique,
        }
    }
}

/// A light connection waiting for its shadow ray. Its seed, when stored, is stored at once
/// (`stored`) and taken back if the ray is blocked, so the pending record stays small.
#[derive(Clone, Copy, Debug)]
pub struct PendingConnection {
    stored: bool,
    layer: u32,
    estimate: Rgb,
}

impl PathSink for TreeOut<'_> {
    type Trail = SeedTrail;
    type Pending = PendingConnection;

    /// Stores the eye vertex.
    fn begin(&mut self, _: &mut SeedTrail, scene: &Scene, ray: &Ray) {
        self.vertices
            .push(PathVertex::eye(ray.origin, scene.camera.forward));
    }

    /// The trunk's density to the hit: the step's density (a Dirac step: the lobe's discrete
    /// probability; the eye ray: 1) times the area Jacobian |n·ω|/d² of a smooth step.
    #[inline]
    fn arrive<S>(&mut self, trail: &mut SeedTrail, state: &WalkState<S>, hit: &SurfaceHit) {
        trail.density *= match state.step {
            Step::Eye => 1.0,
            Step::Dirac(pdf) => pdf as f64,
            Step::Smooth(pdf) => {
                let d = hit.p - state.prev_p;
                let d2 = d.length_squared() as f64;
                pdf as f64 * (hit.ng.dot(d).abs() as f64 / (d2 * d2.sqrt()))
            }
        };
    }

    /// The emitter hit's seed.
    fn emitted<S>(
        &mut self,
        trail: &mut SeedTrail,
        state: &WalkState<S>,
        hit: &SurfaceHit,
        estimate: Rgb,
        w: f32,
    ) {
        let count = self.trunk_len();
        trail.types[count] = NodeType::Light;
        if estimate.is_black() || !self.route(&trail.types[..=count], state.depth, estimate) {
            return;
        }
        let light = PathVertex::from_hit(hit, NodeType::Light, 0);
        let seed = Self::seed(
            trail,
            light,
            None,
            estimate,
            state.depth,
            w,
            trail.density,
            Technique::Hit,
        );
        self.push(count, seed);
    }

    /// The environment's seed: the escaped direction as a vertex at infinity.
    fn escaped<S>(
        &mut self,
        trail: &mut SeedTrail,
        state: &WalkState<S>,
        scene: &Scene,
        estimate: Rgb,
        w: f32,
    ) {
        let Some(env) = scene.lights.environment_index() else {
            return;
        };
        let density = match state.step {
            Step::Eye => trail.density,
            Step::Dirac(pdf) | Step::Smooth(pdf) => trail.density * pdf as f64,
        };
        let count = self.trunk_len();
        trail.types[count] = NodeType::Light;
        if estimate.is_black() || !self.route(&trail.types[..=count], state.depth, estimate) {
            return;
        }
        let light = environment_vertex(&state.ray, env);
        let seed = Self::seed(
            trail,
            light,
            None,
            estimate,
            state.depth,
            w,
            density,
            Technique::Escape,
        );
        self.push(count, seed);
    }

    /// Room for the scattering vertex and a light vertex after it.
    #[inline]
    fn has_room(&self) -> bool {
        self.trunk_len() + 2 <= MAX_PATH_VERTICES
    }

    /// The trunk vertex; its node type is the BSDF sample's, set by [`PathSink::extended`].
    fn scatter(&mut self, _: &mut SeedTrail, hit: &SurfaceHit) {
        self.vertices
            .push(PathVertex::from_hit(hit, NodeType::DiffuseReflection, 0));
    }

    /// The connection's seed, stored at once (and taken back if its shadow ray is blocked)
    /// where the filter keeps it.
    fn connect(&mut self, trail: &mut SeedTrail, c: &ConnectionEvent) -> Option<PendingConnection> {
        let (f, w_over_pdf) = connection_bsdf(c.at, c.conn)?;
        let conn = c.conn;
        // The light's own density in the target's measure: area density on an area light,
        // else what next-event estimation divides by.
        let p_light = if c.light.kind == LightKind::Area {
            c.light.pdf
        } else {
            conn.pdf
        };
        let estimate = c.beta * f * conn.radiance * (conn.wi_local.z.abs() * w_over_pdf);
        // The weight itself, for the seed (≤ 1 although the product rounds).
        let w = (w_over_pdf * conn.pdf).min(1.0);
        if estimate.is_black() {
            return None;
        }
        // The scattering vertex is the trunk's last.
        let count = self.trunk_len() - 1;
        let class = connection_class(
            self.filter,
            c.bsdf,
            c.shading,
            conn.wi_local,
            &mut trail.types[..count + 2],
        );
        if let Some(connect) = class {
            let light = light_vertex(c.scene, c.light, c.hit.p);
            let density = trail.density * p_light as f64;
            let seed = Self::seed(
                trail,
                light,
                Some(connect),
                estimate,
                c.depth,
                w,
                density,
                Technique::Connection,
            );
            self.push(count + 1, seed);
        }
        Some(PendingConnection {
            stored: class.is_some(),
            layer: c.depth,
            estimate,
        })
    }

    /// The survival probability enters the trunk's density; the BSDF sample's node type and
    /// component become the trunk vertex's.
    fn extended(&mut self, trail: &mut SeedTrail, bsdf: &Bsdf, extension: &Extension) {
        if let Some(t) = extension.survived {
            trail.density *= 1.0 - t as f64;
        }
        if let Some((node, u)) = extension.sampled {
            // `Bsdf::sample` chooses the component with the pair's first number.
            let (component, _) = bsdf.choose_component(u);
            let count = self.trunk_len() - 1;
            if let Some(v) = self.vertices.last_mut() {
                v.node = node;
                v.component = component as u8;
            }
            trail.types[count] = node;
        }
    }

    /// A stored seed stays only if `visible` (it is the tree's last seed: nothing is stored
    /// between a connection and its answer); a seed for the rest goes there only if
    /// `visible`.
    fn answered(&mut self, _: &Scene, p: PendingConnection, visible: bool) {
        if p.stored {
            if !visible {
                self.seeds.pop();
            }
        } else if visible && self.filter.is_some() {
            *self.rest_count += 1;
            self.rest.add(p.layer, p.estimate);
        }
    }
}

/// The class of a light connection from the trunk's last vertex, `types[types.len() − 2]`,
/// decided before its shadow ray: `Some` with the node type and component to store the vertex
/// with ([`connection_node`]), or `None` when the filter does not keep it. The
/// most-scattering component is only looked for when the seed is stored or when the filter's
/// answer depends on which smooth component's type the vertex gets.
fn connection_class(
    filter: Option<&dyn SeedFilter>,
    bsdf: &Bsdf,
    shading: &Shading,
    wi: Vec3,
    types: &mut [NodeType],
) -> Option<(NodeType, u8)> {
    let n = types.len();
    types[n - 1] = NodeType::Light;
    if let Some(filter) = filter {
        // The filter's answer for each type a smooth component can give the vertex.
        let mut answer = None;
        let mut agree = true;
        for (c, _) in bsdf.components().filter(|(c, _)| !c.is_delta()) {
            types[n - 2] = c.node_type(shading.wo, wi);
            let keeps = filter.keeps(types);
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
            return filter.keeps(types).then_some(node);
        }
    }
    Some(connection_node(bsdf, shading.wo, wi))
}
