//! Entangled MCPT (thesis §3.7): at every vertex a light connection (next-event estimation)
//! and a BSDF-sampled extension, whose emitter hits (and escapes to the environment) are
//! combined with the connections by the power heuristic (Veach 1997). Delta lights (point,
//! spot, directional) are reached only by the connection, with weight 1. The termination
//! distribution (depth-based, or the throughput roulette from `rr_depth` on) decides after
//! each vertex's light connection whether the path goes on; survivors are divided by 1 − T_k.
//!
//! Where the path cannot go on (T_k = 1 at the path-space depth N, or the physical depth cap)
//! the vertex's BSDF sample is still traced, for emission only: its light connection was
//! weighted against that sample, so without it layer N would lose the BSDF-sampled share
//! (in the white furnace of albedo ½ at N = 1: 1.245 instead of 1.5).
//!
//! With `branches` = k > 1 (MCPT's parameter; [`PathSettings::branches`]) a camera path
//! splits at its first lighting vertex into k branches of weight 1/k, each with its own
//! light connection there and its own BSDF sample: docs/mcpt.md, "Branches".
//!
//! The estimator's step and scheduler are the crate's walker ([`crate::walk`]); this module is
//! its radiance sink: each report is added to the sample's contributions with its lighting
//! layer.

use crate::sampler::BranchStream;
use crate::settings::PathSettings;
use crate::shading::{connection_value, Connection};
use crate::walk::{self, ConnectionEvent, PathSink, WalkState, Wave, WaveSinks};
use crate::SampleContributions;
use flowlight_core::bsdf::OutgoingTerms;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};
use std::borrow::Cow;

/// Traces one entangled path tree through raster position `raster`, adding each contribution
/// to `out` with its lighting layer. `rng` is any [`BranchStream`]: independent numbers
/// ([`flowlight_core::rng::Rng`]) or a pixel's stratified samples
/// ([`flowlight_core::sobol::SobolSampler`]); the path draws from a copy of it, so it is left
/// as it was. One path at a time, one host call per ray ([`walk::run_single`]): the same
/// contributions in the same order as [`trace_wavefront`], bit for bit.
pub fn trace<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &S,
    raster: Vec2,
    out: &mut SampleContributions,
) {
    // The shadow-ray buffer is the thread's, so that a path allocates nothing (two
    // allocations per sample made this mode 6% slower on the Cornell box).
    SHADOWS.with_borrow_mut(|shadows| {
        let mut sink = Radiance { out };
        walk::run_single(
            scene,
            tracer,
            settings,
            rng.clone(),
            raster,
            (),
            &mut sink,
            shadows,
        );
    });
}

/// A shadow ray's record in [`trace`]'s thread buffer.
type ShadowBuffer = (Vec<Ray>, Vec<(u32, ShadowOwner)>);

thread_local! {
    /// [`trace`]'s shadow rays and their records between a vertex and their tests.
    static SHADOWS: std::cell::RefCell<ShadowBuffer> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// MCPT's sink for one path: its contributions.
pub struct Radiance<'a> {
    pub out: &'a mut SampleContributions,
}

/// The light connection behind a shadow ray: the layer it adds to, and its contribution or
/// what that needs where it is evaluated once the ray is known to be unblocked.
#[derive(Clone, Copy, Debug)]
pub struct ShadowOwner {
    layer: u32,
    pending: PendingConnection,
}

#[derive(Clone, Copy, Debug)]
enum PendingConnection {
    /// Evaluated at the vertex: its BSDF was built for the hit (textures, vertex colour) and
    /// is not kept.
    Value(Rgb),
    /// The vertex's BSDF is its material's entry in the scene's table
    /// ([`Scene::constant_bsdf`]): evaluated after the shadow ray, and only if unblocked.
    /// Half of the dragon's shadow rays are blocked (`dragon.toml`), and on it the BSDF
    /// value and density cost about half a BSDF sample (callgrind: 340 instructions per
    /// `Bsdf::eval_pdf` against 650 per `Bsdf::sample`).
    Deferred {
        material: u32,
        beta: Rgb,
        wo: Vec3,
        /// The vertex's [`flowlight_core::bsdf::Bsdf::at`] terms, so the evaluation does not
        /// compute them again.
        terms: OutgoingTerms,
        conn: Connection,
    },
}

/// The contribution of a connection whose shadow ray is unblocked (`None` where black).
#[inline]
fn unblocked_value(scene: &Scene, pending: &PendingConnection) -> Option<Rgb> {
    match *pending {
        PendingConnection::Value(value) => Some(value),
        PendingConnection::Deferred {
            material,
            beta,
            wo,
            terms,
            conn,
        } => {
            // The table entry `scene.bsdf` borrowed at the vertex.
            let bsdf = scene.constant_bsdf(material, [1.0; 4]);
            bsdf.and_then(|b| connection_value(beta, &b.at_with(wo, terms), &conn))
                .filter(|value| !value.is_black())
        }
    }
}

impl PathSink for Radiance<'_> {
    type Trail = ();
    type Pending = ShadowOwner;

    #[inline(always)]
    fn emitted<S>(&mut self, _: &mut (), state: &WalkState<S>, _: &SurfaceHit, e: Rgb, _: f32) {
        self.out.add(state.depth, e);
    }

    #[inline(always)]
    fn escaped<S>(&mut self, _: &mut (), state: &WalkState<S>, _: &Scene, e: Rgb, _: f32) {
        self.out.add(state.depth, e);
    }

    /// A connection that the BSDF's sides say is black
    /// ([`flowlight_core::bsdf::Bsdf::is_zero_between`]) is not traced; one from a vertex
    /// whose BSDF is built for the hit is evaluated now and not traced where black; one from
    /// a vertex whose BSDF is its material's table entry is evaluated only once its shadow
    /// ray is known to be unblocked. None of these changes a pixel.
    #[inline(always)]
    fn connect(&mut self, _: &mut (), c: &ConnectionEvent) -> Option<ShadowOwner> {
        let pending = match c.bsdf {
            _ if c.at.is_zero_between(c.conn.wi_local) => None,
            Cow::Borrowed(_) => Some(PendingConnection::Deferred {
                material: c.hit.material,
                beta: c.beta,
                wo: c.shading.wo,
                terms: c.at.terms(),
                conn: *c.conn,
            }),
            Cow::Owned(_) => connection_value(c.beta, c.at, c.conn)
                .filter(|value| !value.is_black())
                .map(PendingConnection::Value),
        };
        pending.map(|pending| ShadowOwner {
            layer: c.depth,
            pending,
        })
    }

    #[inline(always)]
    fn answered(&mut self, scene: &Scene, owner: ShadowOwner, visible: bool) {
        if visible {
            if let Some(value) = unblocked_value(scene, &owner.pending) {
                self.out.add(owner.layer, value);
            }
        }
    }
}

/// Reusable buffers of [`trace_wavefront`] (one per work unit or thread, so no allocation per
/// path).
pub struct Wavefront<S = flowlight_core::rng::Rng> {
    wave: Wave<S, (), ShadowOwner>,
    /// Per path past the starts' own: its start and its contributions (the first
    /// `branch_count` entries are this wave's).
    branch_start: Vec<u32>,
    branch_out: Vec<SampleContributions>,
}

impl<S> Default for Wavefront<S> {
    fn default() -> Self {
        Wavefront {
            wave: Wave::default(),
            branch_start: Vec::new(),
            branch_out: Vec::new(),
        }
    }
}

/// The contributions of a wave's paths: a start's own for a start's first branch, else the
/// branch's until the wave ends.
struct WaveContributions<'a> {
    out: &'a mut [SampleContributions],
    branch_start: &'a mut Vec<u32>,
    branch_out: &'a mut Vec<SampleContributions>,
    branch_count: usize,
}

impl WaveSinks for WaveContributions<'_> {
    type Trail = ();
    type Pending = ShadowOwner;
    type Sink<'b>
        = Radiance<'b>
    where
        Self: 'b;

    #[inline(always)]
    fn sink(&mut self, p: usize) -> Radiance<'_> {
        let n = self.out.len();
        let out = if p < n {
            &mut self.out[p]
        } else {
            &mut self.branch_out[p - n]
        };
        Radiance { out }
    }

    fn branch(&mut self, start: usize) {
        let b = self.branch_count;
        if b < self.branch_out.len() {
            self.branch_out[b].clear();
            self.branch_start[b] = start as u32;
        } else {
            self.branch_out.push(SampleContributions::default());
            self.branch_start.push(start as u32);
        }
        self.branch_count += 1;
    }
}

/// Traces `starts.len()` entangled paths as a wavefront ([`walk::run_wave`]): the camera
/// rays as one batch (marked coherent), then per bounce one batch of extension rays and one
/// of shadow rays, so the host is called twice per bounce instead of twice per vertex. Path
/// `i` starts from `starts[i]` = (its generator, its raster position) and adds its
/// contributions to `out[i]` (cleared first).
///
/// With `settings.branches` = k > 1 a path splits into k branches at its first lighting
/// vertex (docs/mcpt.md, "Branches"); each branch is a path of its own in the wave from there
/// on, and its contributions are appended to its start's after those of the first branch, in
/// branch order. `out[i]` equals what [`trace`] gives for the same start, bit for bit, and so
/// does the image whatever the batch size.
pub fn trace_wavefront<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
    wf: &mut Wavefront<S>,
    out: &mut [SampleContributions],
) {
    debug_assert_eq!(starts.len(), out.len());
    out.iter_mut().for_each(SampleContributions::clear);
    let mut sinks = WaveContributions {
        out,
        branch_start: &mut wf.branch_start,
        branch_out: &mut wf.branch_out,
        branch_count: 0,
    };
    walk::run_wave(
        scene,
        tracer,
        settings,
        starts,
        |_| (),
        &mut wf.wave,
        &mut sinks,
    );
    // Each start's other branches after its first, in branch order (a start's branches
    // split off together, so they are consecutive here).
    let WaveContributions {
        out,
        branch_start,
        branch_out,
        branch_count,
    } = sinks;
    for b in 0..branch_count {
        let start = branch_start[b] as usize;
        out[start].entries.extend_from_slice(&branch_out[b].entries);
    }
}
