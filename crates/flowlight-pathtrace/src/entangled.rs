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

use crate::sampler::BranchStream;
use crate::settings::PathSettings;
use crate::shading::{
    connection_value, light_connection, light_sample, side_consistent, Connection, Shading,
};
use crate::SampleContributions;
use flowlight_core::bsdf::{volume, Bsdf, BsdfAt, OutgoingTerms};
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::area_to_solid_angle;
use flowlight_core::mesh::CompactHit;
use flowlight_core::rng::Rng;
use flowlight_core::sampler::{
    PairAhead, SampleStream, SLOT_BSDF, SLOT_BSDF_PAIR, SLOT_LIGHT, SLOT_ROULETTE,
};
use flowlight_core::sampling::power_heuristic;
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};
use std::borrow::Cow;

/// Traces one entangled path tree through raster position `raster`, adding each contribution
/// to `out` with its lighting layer. `rng` is any [`BranchStream`]: independent numbers
/// ([`Rng`]) or a pixel's stratified samples ([`flowlight_core::sobol::SobolSampler`]); the
/// path draws from a copy of it, so it is left as it was. One path at a time, one host call per ray: the same vertex
/// code as [`trace_wavefront`], with each shadow ray traced as soon as its vertex is done
/// (before the next extension ray, as the wavefront's order also gives), so the two give the
/// same contributions in the same order, bit for bit.
pub fn trace<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: &S,
    raster: Vec2,
    out: &mut SampleContributions,
) {
    let mut path = PathState::start(rng.clone(), scene.camera.generate_ray(raster));
    // The shadow-ray buffer is the thread's, so that a path allocates nothing (two
    // allocations per sample made this mode 6% slower on the Cornell box); the branches'
    // only where there are some.
    SHADOWS.with_borrow_mut(|shadows| {
        let mut branches = Vec::new();
        walk(
            scene,
            tracer,
            settings,
            &mut path,
            out,
            shadows,
            &mut branches,
        );
        // The other branches, in order, after the first: the order the wavefront merges
        // them in. A path splits once, at its first lighting vertex, so branches do not
        // split again.
        let mut none = Vec::new();
        for mut branch in branches {
            walk(
                scene,
                tracer,
                settings,
                &mut branch,
                out,
                shadows,
                &mut none,
            );
            debug_assert!(none.is_empty());
        }
    });
}

thread_local! {
    /// [`trace`]'s shadow rays and their owners between a vertex and their tests (one per
    /// connection: one, or one per branch at a split).
    static SHADOWS: std::cell::RefCell<(Vec<Ray>, Vec<ShadowOwner>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// [`trace`]'s loop for one path (or branch) until it ends.
fn walk<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    path: &mut PathState<S>,
    out: &mut SampleContributions,
    (shadow_rays, shadow_owner): &mut (Vec<Ray>, Vec<ShadowOwner>),
    branches: &mut Vec<PathState<S>>,
) {
    loop {
        let going = match tracer.intersect(&path.ray) {
            Some(hit) => {
                let shadows = (&mut *shadow_rays, &mut *shadow_owner);
                let ahead = VertexAhead::of(path);
                vertex(
                    scene, settings, path, 0, &hit, out, shadows, branches, ahead,
                )
            }
            None => {
                escape(scene, path, out);
                false
            }
        };
        // The vertex's connections (one, or one per branch at a split), in order.
        for (ray, owner) in shadow_rays.drain(..).zip(shadow_owner.drain(..)) {
            if !tracer.occluded(&ray) {
                if let Some(value) = unblocked_value(scene, &owner.pending) {
                    out.add(owner.layer, value);
                }
            }
        }
        if !going {
            return;
        }
    }
}

/// The state of one path of a [`Wavefront`] between two bounces (or of [`trace`]'s path).
#[derive(Clone, Debug)]
struct PathState<S> {
    rng: S,
    ray: Ray,
    beta: Rgb,
    /// σ_a of the absorbing volume the current ray runs through, if any.
    inside: Option<Rgb>,
    depth: u32,
    physical: u32,
    prev_delta: bool,
    prev_pdf: f32,
    prev_p: Vec3,
    /// Product of η'² over the refractions so far: undoes their 1/η'² radiance scaling in β
    /// for the throughput roulette (termination.rs), so a path inside glass is not cut more
    /// often than one outside.
    eta2: f32,
    /// The previous vertex was the path's last: emission only.
    last: bool,
}

impl<S> PathState<S> {
    fn start(rng: S, ray: Ray) -> Self {
        PathState {
            rng,
            ray,
            beta: Rgb::ONE,
            inside: None,
            depth: 0,
            physical: 0,
            prev_delta: true, // the pinhole eye is a Dirac: no MIS for the first hit
            prev_pdf: 0.0,
            prev_p: ray.origin,
            eta2: 1.0,
            last: false,
        }
    }
}

/// Reusable buffers of [`trace_wavefront`] (one per work unit, so no allocation per path).
pub struct Wavefront<S = Rng> {
    /// The wave's paths: first one per start (each start's first branch), then the other
    /// branches in the order they split off.
    paths: Vec<PathState<S>>,
    /// Indices of the paths still going.
    active: Vec<u32>,
    rays: Vec<Ray>,
    hits: Vec<CompactHit>,
    shadow_rays: Vec<Ray>,
    /// Per shadow ray: what it adds to which path when unblocked.
    shadow_owner: Vec<ShadowOwner>,
    blocked: Vec<u8>,
    /// Branches split off in the current bounce, and their starts, before they join `paths`.
    spawned: Vec<PathState<S>>,
    spawned_start: Vec<u32>,
    /// Per path past the starts' own: its start and its contributions (the first
    /// `branch_count` entries are this wave's).
    branch_start: Vec<u32>,
    branch_out: Vec<SampleContributions>,
    branch_count: usize,
}

/// The light connection behind a shadow ray of a [`Wavefront`]: the path and layer it adds
/// to, and its contribution, or what that needs where it is evaluated once the ray is known
/// to be unblocked.
#[derive(Clone, Copy, Debug)]
struct ShadowOwner {
    path: u32,
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
        /// The vertex's [`Bsdf::at`] terms, so the evaluation does not compute them again.
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

impl<S> Default for Wavefront<S> {
    fn default() -> Self {
        Wavefront {
            paths: Vec::new(),
            active: Vec::new(),
            rays: Vec::new(),
            hits: Vec::new(),
            shadow_rays: Vec::new(),
            shadow_owner: Vec::new(),
            blocked: Vec::new(),
            spawned: Vec::new(),
            spawned_start: Vec::new(),
            branch_start: Vec::new(),
            branch_out: Vec::new(),
            branch_count: 0,
        }
    }
}

/// Traces `starts.len()` entangled paths as a wavefront: the camera rays as one batch (marked
/// coherent), then per bounce one batch of extension rays and one of shadow rays, so the host
/// is called twice per bounce instead of twice per vertex. Path `i` starts from
/// `starts[i]` = (its generator, its raster position) and adds its contributions to `out[i]`
/// (cleared first).
///
/// With `settings.branches` = k > 1 a path splits into k branches at its first lighting
/// vertex (docs/mcpt.md, "Branches"); each branch is a path of its own in the wave from there on, and its
/// contributions are appended to its start's after those of the first branch, in branch
/// order.
///
/// Each path draws the same random numbers in the same order and makes the same float
/// operations as [`trace`] (its shadow ray is traced before its next extension ray, as there;
/// shading uses [`Scene::surface`] on the compact hit, the host's own surface code), so
/// `out[i]` equals what [`trace`] gives for the same start, bit for bit, and so does the
/// image whatever the batch size. A connection from a vertex whose BSDF is its material's
/// table entry is evaluated only once its shadow ray is known to be unblocked. Differences
/// that change no pixel: a connection that the BSDF's sides say is black
/// ([`flowlight_core::bsdf::Bsdf::is_zero_between`]) is not traced, and one from a vertex
/// whose BSDF is built for the hit is evaluated first and not traced where black.
pub fn trace_wavefront<S: BranchStream>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
    wf: &mut Wavefront<S>,
    out: &mut [SampleContributions],
) {
    debug_assert_eq!(starts.len(), out.len());
    let n = starts.len();
    wf.paths.clear();
    wf.active.clear();
    wf.branch_count = 0;
    for (i, (rng, raster)) in starts.iter().enumerate() {
        let ray = scene.camera.generate_ray(*raster);
        wf.paths.push(PathState::start(rng.clone(), ray));
        wf.active.push(i as u32);
        out[i].clear();
    }
    let mut coherent = true;
    while !wf.active.is_empty() {
        wf.rays.clear();
        wf.rays
            .extend(wf.active.iter().map(|&i| wf.paths[i as usize].ray));
        tracer.intersect_batch(&wf.rays, coherent, &mut wf.hits);
        coherent = false;
        wf.shadow_rays.clear();
        wf.shadow_owner.clear();
        let mut kept = 0;
        for k in 0..wf.active.len() {
            let i = wf.active[k];
            let path = &mut wf.paths[i as usize];
            let compact = wf.hits[k];
            let o = contributions_of(i as usize, n, out, &mut wf.branch_out);
            scene.prefetch_surfaces(&wf.hits, k);
            let going = if compact.is_hit() {
                let ahead = VertexAhead::of(path);
                let hit = scene.surface(&path.ray, &compact);
                let shadows = (&mut wf.shadow_rays, &mut wf.shadow_owner);
                let spawned = &mut wf.spawned;
                let going = vertex(scene, settings, path, i, &hit, o, shadows, spawned, ahead);
                // Only a start's own path splits (once), so a branch's start is `i`.
                wf.spawned_start.resize(wf.spawned.len(), i);
                going
            } else {
                escape(scene, path, o);
                false
            };
            if going {
                wf.active[kept] = i;
                kept += 1;
            }
        }
        wf.active.truncate(kept);
        // Branches split off this bounce join the wave for the next one.
        for (branch, start) in wf.spawned.drain(..).zip(wf.spawned_start.drain(..)) {
            debug_assert!((start as usize) < n);
            let b = wf.branch_count;
            wf.active.push(wf.paths.len() as u32);
            wf.paths.push(branch);
            if b < wf.branch_out.len() {
                wf.branch_out[b].clear();
                wf.branch_start[b] = start;
            } else {
                wf.branch_out.push(SampleContributions::default());
                wf.branch_start.push(start);
            }
            wf.branch_count += 1;
        }
        if !wf.shadow_rays.is_empty() {
            tracer.occluded_batch(&wf.shadow_rays, &mut wf.blocked);
            for (owner, &b) in wf.shadow_owner.iter().zip(&wf.blocked) {
                if b != 0 {
                    continue;
                }
                if let Some(value) = unblocked_value(scene, &owner.pending) {
                    contributions_of(owner.path as usize, n, out, &mut wf.branch_out)
                        .add(owner.layer, value);
                }
            }
        }
    }
    // Each start's other branches after its first, in branch order (a start's branches
    // split off together, so they are consecutive here).
    for b in 0..wf.branch_count {
        let start = wf.branch_start[b] as usize;
        out[start]
            .entries
            .extend_from_slice(&wf.branch_out[b].entries);
    }
}

/// The contributions path `p` of a wave with `n` starts adds to: its start's own for a
/// start's first branch, else the branch's until the wave ends.
#[inline(always)]
fn contributions_of<'a>(
    p: usize,
    n: usize,
    out: &'a mut [SampleContributions],
    branch_out: &'a mut [SampleContributions],
) -> &'a mut SampleContributions {
    if p < n {
        &mut out[p]
    } else {
        &mut branch_out[p - n]
    }
}

/// A vertex's light and BSDF pairs, computed before the work that leads to their use
/// ([`SampleStream::pair_ahead`]), before even the surface data of its hit: with Sobol'
/// numbers each pair is a chain of seven dependent integer multiplies and a table lookup
/// (the dimension's seeds, the index shuffle, the second dimension), which otherwise
/// starts only when the path gets to it, behind the surface, the BSDF, the light sample and
/// its connection. Where the path's draws land elsewhere (a vertex before this one drew more
/// numbers than its slots) a pair is not taken and the number is drawn as usual, and at a
/// split each branch computes its own: the numbers are the same either way (the test
/// `sobol_pairs_drawn_ahead_change_no_contribution`). Cornell box, 16 spp, 1 thread: 4%
/// less render CPU (docs/performance.md, "Twentieth session").
#[derive(Clone, Copy)]
struct VertexAhead {
    light: Option<PairAhead>,
    bsdf: Option<PairAhead>,
}

impl VertexAhead {
    /// For the vertex `path` reaches next.
    #[inline(always)]
    fn of<S: SampleStream>(path: &PathState<S>) -> VertexAhead {
        let vertex = path.physical + 1;
        VertexAhead {
            light: path.rng.pair_ahead(vertex, SLOT_LIGHT),
            bsdf: path.rng.pair_ahead(vertex, SLOT_BSDF_PAIR),
        }
    }
}

/// The escape branch: the environment, MIS-weighted against its light sample.
#[inline]
fn escape<S>(scene: &Scene, path: &PathState<S>, out: &mut SampleContributions) {
    let le = scene.lights.environment_radiance(path.ray.dir);
    if !le.is_black() {
        let w = if path.prev_delta {
            1.0
        } else {
            power_heuristic(path.prev_pdf, scene.lights.pdf_environment(path.ray.dir))
        };
        out.add(path.depth, path.beta * le * w);
    }
}

/// The work at a hit of path `index`: its emission (MIS-weighted against the light sample
/// of the vertex before), the light connection, whose shadow ray and [`ShadowOwner`] are
/// pushed onto `shadows` instead of traced (in place: a connection returned through the
/// caller's stack was reloaded wider than it was stored, a stall on every connection), the
/// termination and the BSDF sample ([`extend`]). Returns whether the path goes on (with
/// `path.ray`).
///
/// **Branches.** With `settings.branches` = k > 1, at the path's first lighting vertex
/// (depth 1, reached once) the path splits: it goes on as branch 0 and pushes branches
/// 1 … k−1 that survive their own roulette and BSDF sample onto `branches`. Each branch
/// carries β/k and draws from `path.rng.branch(j, k)` from this vertex's light sample on:
/// the camera ray, the hit, its emission and its BSDF are shared, the light connection
/// (pushed by this path for every branch, in branch order) and the rest are not. Each
/// branch is the unsplit estimator from here on with its own numbers, its connection and
/// its BSDF sample weighed against each other as in an unsplit path, so the mean of the k
/// is unbiased.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn vertex<S: BranchStream>(
    scene: &Scene,
    settings: &PathSettings,
    path: &mut PathState<S>,
    index: u32,
    hit: &SurfaceHit,
    out: &mut SampleContributions,
    (shadow_rays, shadow_owner): (&mut Vec<Ray>, &mut Vec<ShadowOwner>),
    branches: &mut Vec<PathState<S>>,
    ahead: VertexAhead,
) -> bool {
    let VertexAhead {
        light: light_ahead,
        bsdf: bsdf_ahead,
    } = ahead;
    // Beer–Lambert absorption when the segment ran inside a volumetric material.
    if let Some(sigma) = path.inside.take() {
        path.beta *= volume::transmittance(sigma, hit.t);
    }
    let wo_world = -path.ray.dir;
    if hit.emitter >= 0 {
        let le = scene.lights.emitted(hit.emitter as usize, hit.p, wo_world);
        if !le.is_black() {
            let w = if path.prev_delta {
                1.0
            } else {
                let pdf_light = area_to_solid_angle(
                    scene.lights.pdf_area(hit.emitter as usize),
                    path.prev_p,
                    hit.p,
                    hit.ng,
                );
                power_heuristic(path.prev_pdf, pdf_light)
            };
            out.add(path.depth, path.beta * le * w);
        }
    }
    if path.last {
        return false;
    }
    let bsdf = scene.bsdf(hit);
    let next_depth = if path.depth == 0 && bsdf.is_delta() {
        0
    } else {
        path.depth + 1
    };
    if next_depth > settings.path_depth {
        return false;
    }
    path.depth = next_depth;
    path.physical += 1;
    let depth = path.depth;
    let split = depth == 1 && settings.branches > 1;
    let shading = Shading::new(hit, wo_world);
    // The termination probability of the vertex, before any split here, so the same for
    // every branch of one. Past depth 1 a path has split (every path splits there when
    // k > 1), so β holds the split's 1/k, which the roulette multiplies back out: a branch
    // is cut as often as an unsplit path with the same light to carry.
    let split_weight = if depth > 1 {
        settings.branches as f32
    } else {
        1.0
    };
    let t = if depth > 0 {
        settings.termination.probability_with_throughput(
            depth,
            bsdf.albedo(),
            path.beta.max_component() * path.eta2 * split_weight,
        )
    } else {
        0.0
    };
    // The light sample below was MIS-weighted against a BSDF sample of the same vertex, so
    // that BSDF sample must be traced whenever it can be drawn, also when the path cannot
    // go on (T_k = 1 at the deepest layer, or the physical depth cap): then the extension
    // only looks for emission (which belongs to this vertex's layer, Dirac lobes included)
    // and the path ends there. A random stop (T_k < 1) is fine: survivors are divided by
    // 1 − T_k.
    path.last = t >= 1.0 || path.physical >= settings.max_ray_depth;
    // What the connections' evaluations and the BSDF samples at ω_o share, once.
    let at = bsdf.at(shading.wo);
    // The vertex's light connection with a path's (or branch's) numbers and throughput.
    let physical = path.physical;
    let mut connect_here = |u_light: Option<Vec2>, beta: Rgb| {
        let shadows = (&mut *shadow_rays, &mut *shadow_owner);
        connect(
            scene, &bsdf, &at, hit, &shading, u_light, beta, depth, index, shadows,
        );
    };
    if !split {
        // The light pair is drawn first, as ever, but the connection is made after the
        // extension: the two are independent chains of latency (the disk's division and
        // polynomials; the light sample's square root and divisions), and this way the
        // core works on the connection while the extension's chain completes. The
        // connection takes β before the roulette, as before; its shadow ray counts whether
        // or not the path goes on.
        let u_light = light_pair(&bsdf, &mut path.rng, light_ahead, physical);
        let beta = path.beta;
        let going = extend(scene, path, hit, &at, &shading, t, bsdf_ahead);
        connect_here(u_light, beta);
        return going;
    }
    // A split: k branches, each with β/k, its own numbers from here on (`trunk.branch(j,
    // k)`), its own light connection here and its own roulette and BSDF sample. Every
    // connection is pushed by this path, in branch order, so the sample's contributions
    // come in the same order from the walk and the wave.
    let k = settings.branches;
    let trunk = path.rng.clone();
    path.beta /= k as f32;
    let mut first_bsdf_ahead = None;
    for j in 0..k {
        let mut rng = trunk.branch(j, k);
        // The branch's BSDF pair ahead of its connection; its light pair is drawn at once.
        let bsdf_ahead = rng.pair_ahead(physical, SLOT_BSDF_PAIR);
        let u_light = light_pair(&bsdf, &mut rng, None, physical);
        connect_here(u_light, path.beta);
        if j == 0 {
            path.rng = rng;
            first_bsdf_ahead = bsdf_ahead;
        } else {
            let mut branch = path.clone();
            branch.rng = rng;
            if extend(scene, &mut branch, hit, &at, &shading, t, bsdf_ahead) {
                branches.push(branch);
            }
        }
    }
    extend(scene, path, hit, &at, &shading, t, first_bsdf_ahead)
}

/// The light pair of a vertex's connection, drawn (where its BSDF has a non-Dirac part).
#[inline(always)]
fn light_pair<S: SampleStream>(
    bsdf: &Bsdf,
    rng: &mut S,
    ahead: Option<PairAhead>,
    physical: u32,
) -> Option<Vec2> {
    if !bsdf.has_non_delta() {
        return None;
    }
    rng.seek(physical, SLOT_LIGHT);
    Some(rng.uniform2_ahead(ahead))
}

/// The light connection of a vertex: a light sample from its light pair `u_light` (`None`:
/// no connection, [`light_pair`]), its shadow ray and [`ShadowOwner`] pushed onto `shadows`
/// where it may carry light. `bsdf` stays a `Cow`:
/// its variant says whether it is the material's table entry (evaluated after the shadow
/// ray) or built for the hit (evaluated now); `at` is it at ω_o.
#[allow(clippy::too_many_arguments, clippy::ptr_arg)]
#[inline(always)]
fn connect(
    scene: &Scene,
    bsdf: &Cow<'_, Bsdf>,
    at: &BsdfAt,
    hit: &SurfaceHit,
    shading: &Shading,
    u_light: Option<Vec2>,
    beta: Rgb,
    depth: u32,
    index: u32,
    (shadow_rays, shadow_owner): (&mut Vec<Ray>, &mut Vec<ShadowOwner>),
) {
    let Some(u_light) = u_light else {
        return;
    };
    let Some(ls) = light_sample(scene, bsdf, hit, shading, u_light) else {
        return;
    };
    let Some((conn, shadow_ray)) = light_connection(scene, hit, shading, &ls) else {
        return;
    };
    let pending = match bsdf {
        _ if at.is_zero_between(conn.wi_local) => None,
        Cow::Borrowed(_) => Some(PendingConnection::Deferred {
            material: hit.material,
            beta,
            wo: shading.wo,
            terms: at.terms(),
            conn,
        }),
        Cow::Owned(_) => connection_value(beta, at, &conn)
            .filter(|value| !value.is_black())
            .map(PendingConnection::Value),
    };
    if let Some(pending) = pending {
        shadow_rays.push(shadow_ray.ray(hit));
        shadow_owner.push(ShadowOwner {
            path: index,
            layer: depth,
            pending,
        });
    }
}

/// The rest of a vertex for one path (or branch): the roulette with stop probability `t`
/// (none where the path is at its last vertex) and the BSDF sample, which sets the next ray.
/// Returns whether the path goes on.
#[inline(always)]
fn extend<S: SampleStream>(
    scene: &Scene,
    path: &mut PathState<S>,
    hit: &SurfaceHit,
    bsdf: &BsdfAt,
    shading: &Shading,
    t: f32,
    ahead: Option<PairAhead>,
) -> bool {
    let rng = &mut path.rng;
    if !path.last && t > 0.0 {
        rng.seek(path.physical, SLOT_ROULETTE);
        if rng.uniform() < t {
            return false;
        }
        path.beta /= 1.0 - t;
    }
    rng.seek(path.physical, SLOT_BSDF);
    let u_choice = rng.uniform();
    let Some(s) = bsdf.sample(u_choice, rng.uniform2_ahead(ahead)) else {
        return false;
    };
    let wi_world = shading.frame.to_world(s.wi);
    if !side_consistent(hit, wi_world, s.wi) {
        return false;
    }
    path.beta *= s.f * (s.wi.z.abs() / s.pdf);
    if path.beta.is_black() {
        return false;
    }
    path.eta2 *= s.eta * s.eta;
    path.prev_delta = s.delta;
    path.prev_pdf = s.pdf;
    path.prev_p = hit.p;
    path.inside = volume::entered(scene.material(hit), hit.ng, wi_world);
    path.ray = hit.spawn_ray(wi_world);
    true
}
