//! The walker's schedulers: [`run_wave`], many paths as ray batches, and [`run_single`], one
//! path with one host call per ray. Both run [`super::step::vertex`] and give each path's
//! sink the same reports in the same order, bit for bit: a path's shadow rays are answered
//! before its next extension ray in both, the wave's surfaces come from the host's own
//! surface code ([`Scene::surface`] on the compact hits), and the numbers a path draws depend
//! on the path alone.

use super::sink::PathSink;
use super::step::{escape, vertex, VertexAhead};
use super::{WalkState, Walker};
use crate::sampler::BranchStream;
use crate::settings::PathSettings;
use flowlight_core::geometry::Ray;
use flowlight_core::mesh::CompactHit;
use flowlight_sdk::{Scene, Tracer};
use glam::Vec2;

/// The sinks of a wave's paths: path `i` reports to `sink(i)`. Paths `0..starts` are the
/// starts, in order; a branch split off a start joins as the next index after [`run_wave`]
/// calls [`WaveSinks::branch`] with its start.
pub trait WaveSinks {
    type Trail: Clone;
    type Pending: Copy;
    type Sink<'a>: PathSink<Trail = Self::Trail, Pending = Self::Pending>
    where
        Self: 'a;

    /// The sink of path `path`.
    fn sink(&mut self, path: usize) -> Self::Sink<'_>;

    /// A branch of start `start` joins the wave as the next path.
    fn branch(&mut self, _start: usize) {}
}

/// Reusable buffers of [`run_wave`] (kept per work unit or thread, so that a wave allocates
/// nothing per path).
pub struct Wave<S, T, P> {
    /// The wave's paths: first one per start, then the branches in the order they split off.
    paths: Vec<Walker<S, T>>,
    /// Indices of the paths still going.
    active: Vec<u32>,
    rays: Vec<Ray>,
    hits: Vec<CompactHit>,
    shadow_rays: Vec<Ray>,
    /// Per shadow ray: its path and its sink's record.
    pending: Vec<(u32, P)>,
    blocked: Vec<u8>,
    /// Branches split off in the current bounce, and their starts, before they join `paths`.
    spawned: Vec<Walker<S, T>>,
    spawned_start: Vec<u32>,
}

impl<S, T, P> Default for Wave<S, T, P> {
    fn default() -> Self {
        Wave {
            paths: Vec::new(),
            active: Vec::new(),
            rays: Vec::new(),
            hits: Vec::new(),
            shadow_rays: Vec::new(),
            pending: Vec::new(),
            blocked: Vec::new(),
            spawned: Vec::new(),
            spawned_start: Vec::new(),
        }
    }
}

/// Walks `starts.len()` camera paths as a wavefront: the camera rays as one batch (marked
/// coherent), then per bounce one batch of extension rays and one of shadow rays. Path `i`
/// starts from `starts[i]` = (its numbers, its raster position) with the trail
/// `trail(raster)`, and reports to `sinks.sink(i)`.
pub fn run_wave<S, W>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    starts: &[(S, Vec2)],
    trail: impl Fn(Vec2) -> W::Trail,
    wave: &mut Wave<S, W::Trail, W::Pending>,
    sinks: &mut W,
) where
    S: BranchStream,
    W: WaveSinks,
{
    wave.paths.clear();
    wave.active.clear();
    for (i, (rng, raster)) in starts.iter().enumerate() {
        // A lens point takes the pair after the raster position's (a pinhole draws none).
        let mut rng = rng.clone();
        let ray = scene.camera.sample_ray(*raster, &mut rng);
        let mut path = Walker {
            state: WalkState::start(rng, ray),
            trail: trail(*raster),
        };
        sinks.sink(i).begin(&mut path.trail, scene, &ray);
        wave.paths.push(path);
        wave.active.push(i as u32);
    }
    let mut coherent = true;
    while !wave.active.is_empty() {
        wave.rays.clear();
        let paths = &wave.paths;
        wave.rays
            .extend(wave.active.iter().map(|&i| paths[i as usize].state.ray));
        tracer.intersect_batch(&wave.rays, coherent, &mut wave.hits);
        coherent = false;
        bounce(scene, settings, wave, sinks);
        if !wave.shadow_rays.is_empty() {
            tracer.occluded_batch(&wave.shadow_rays, &mut wave.blocked);
            for (&(i, record), &b) in wave.pending.iter().zip(&wave.blocked) {
                sinks.sink(i as usize).answered(scene, record, b == 0);
            }
        }
    }
}

/// One bounce of [`run_wave`]: the step at every active path's hit (or its escape), the
/// paths that go on kept active, and the branches split off this bounce joined to the wave.
fn bounce<S: BranchStream, W: WaveSinks>(
    scene: &Scene,
    settings: &PathSettings,
    wave: &mut Wave<S, W::Trail, W::Pending>,
    sinks: &mut W,
) {
    wave.shadow_rays.clear();
    wave.pending.clear();
    let mut kept = 0;
    for k in 0..wave.active.len() {
        let i = wave.active[k];
        let path = &mut wave.paths[i as usize];
        let compact = wave.hits[k];
        let mut sink = sinks.sink(i as usize);
        scene.prefetch_surfaces(&wave.hits, k);
        let going = if compact.is_hit() {
            let ahead = VertexAhead::of(&path.state);
            let hit = scene.surface(&path.state.ray, &compact);
            let shadows = (&mut wave.shadow_rays, &mut wave.pending);
            let spawned = &mut wave.spawned;
            let going = vertex(
                scene, settings, path, i, &hit, &mut sink, shadows, spawned, ahead,
            );
            // Only a start's own path splits (once), so a branch's start is `i`.
            wave.spawned_start.resize(wave.spawned.len(), i);
            going
        } else {
            escape(scene, path, &mut sink);
            false
        };
        if going {
            wave.active[kept] = i;
            kept += 1;
        }
    }
    wave.active.truncate(kept);
    // Branches split off this bounce join the wave for the next one.
    for (branch, start) in wave.spawned.drain(..).zip(wave.spawned_start.drain(..)) {
        wave.active.push(wave.paths.len() as u32);
        wave.paths.push(branch);
        sinks.branch(start as usize);
    }
}

/// Walks one camera path from `rng` through `raster` with the trail `trail`, reporting to
/// `sink`, one host call per ray; each vertex's shadow rays are traced as soon as the vertex
/// is done (before the next extension ray, the order the wave also gives). Branches split off
/// the path are walked after it, in order, reporting to the same sink. `shadows` is scratch
/// space (left empty). Returns the path's numbers as the path left them.
#[allow(clippy::too_many_arguments)]
pub fn run_single<S: BranchStream, K: PathSink>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    rng: S,
    raster: Vec2,
    trail: K::Trail,
    sink: &mut K,
    shadows: &mut (Vec<Ray>, Vec<(u32, K::Pending)>),
) -> S {
    let mut rng = rng;
    let ray = scene.camera.sample_ray(raster, &mut rng);
    let mut path = Walker {
        state: WalkState::start(rng, ray),
        trail,
    };
    sink.begin(&mut path.trail, scene, &ray);
    let mut branches = Vec::new();
    walk(
        scene,
        tracer,
        settings,
        &mut path,
        sink,
        shadows,
        &mut branches,
    );
    // A path splits once, at its first lighting vertex, so branches do not split again.
    let mut none = Vec::new();
    for mut branch in branches {
        walk(
            scene,
            tracer,
            settings,
            &mut branch,
            sink,
            shadows,
            &mut none,
        );
        debug_assert!(none.is_empty());
    }
    path.state.rng
}

/// [`run_single`]'s loop for one path (or branch) until it ends.
fn walk<S: BranchStream, K: PathSink>(
    scene: &Scene,
    tracer: &Tracer,
    settings: &PathSettings,
    path: &mut Walker<S, K::Trail>,
    sink: &mut K,
    (shadow_rays, pending): &mut (Vec<Ray>, Vec<(u32, K::Pending)>),
    branches: &mut Vec<Walker<S, K::Trail>>,
) {
    loop {
        let going = match tracer.intersect(&path.state.ray) {
            Some(hit) => {
                let ahead = VertexAhead::of(&path.state);
                let shadows = (&mut *shadow_rays, &mut *pending);
                vertex(
                    scene, settings, path, 0, &hit, sink, shadows, branches, ahead,
                )
            }
            None => {
                escape(scene, path, sink);
                false
            }
        };
        for (ray, (_, record)) in shadow_rays.drain(..).zip(pending.drain(..)) {
            sink.answered(scene, record, !tracer.occluded(&ray));
        }
        if !going {
            return;
        }
    }
}
