//! One work unit of a bidirectional render: per sample index, one light subpath per pixel of
//! the unit (splatting where light tracing is on), the merging grid over their vertices,
//! then one camera subpath per pixel ([`super`] for the iteration's structure).
//!
//! Memory: the light vertices, the grid and the contributions live in a per-thread arena
//! that the thread's units reuse. Its buffers grow by doubling to the largest iteration the
//! thread has rendered, so nothing is allocated per sample: a thread allocates only when an
//! iteration needs more room than any before (`tests/allocations.rs` counts it). A unit
//! keeps the vertices of one sample index at a time: at most (unit pixels) × `path_depth`
//! of them, as a light subpath keeps at most `path_depth` ([`super::light_path`]), reported
//! as `max light vertices`.

use super::camera_path::{CameraCounts, CameraPaths, MergeSet};
use super::grid::HashGrid;
use super::light_path::LightPaths;
use super::mis::Iteration;
use super::mis::Techniques;
use super::params::settings_from_params;
use super::vertex::LightVertex;
use super::BidirSettings;
use crate::walk::units::unit_pixels;
use crate::SampleContributions;
use flowlight_core::light::emission::scene_sphere;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::{
    AccumulationStyle, Film, Integrator, IntegratorInfo, MutationSet, Params, Scene, Tracer,
    WorkUnit,
};
use glam::Vec2;
use std::cell::RefCell;
use std::marker::PhantomData;

/// The PCG stream of a pixel sample's light subpath (its camera subpath draws from stream 0
/// of the same seed, as MCPT's samples do; ERPT's chains use stream 1).
pub(crate) const LIGHT_STREAM: u64 = 2;

/// A thread's buffers (module docs).
#[derive(Default)]
struct Arena {
    vertices: Vec<LightVertex>,
    /// Per pixel of the unit, where its light subpath's vertices start in `vertices`.
    starts: Vec<usize>,
    grid: HashGrid,
    contributions: SampleContributions,
}

thread_local! {
    static ARENA: RefCell<Arena> = RefCell::new(Arena::default());
}

/// What a unit counted.
#[derive(Clone, Copy, Debug, Default)]
pub struct UnitCounts {
    pub light_paths: u64,
    pub light_vertices: u64,
    /// The most light vertices one iteration of the unit kept.
    pub max_light_vertices: u64,
    pub connections: u64,
    pub merges: u64,
}

/// Renders `unit` into `film`.
pub fn render_unit(
    scene: &Scene,
    tracer: &Tracer,
    settings: &BidirSettings,
    unit: &WorkUnit,
    film: &mut Film,
    counts: &mut UnitCounts,
) {
    ARENA.with(|arena| {
        let arena = &mut *arena.borrow_mut();
        let sphere = scene_sphere(scene.bounds_min, scene.bounds_max);
        let camera = &scene.camera;
        let film_paths = camera.width as f32 * camera.height as f32;
        let unit_paths = unit_pixels(unit).count() as f32;
        for s in unit.sample_begin..unit.sample_begin + unit.sample_count {
            let radius = settings.radius_at(s, sphere.1);
            let it = Iteration::new(
                settings.heuristic,
                settings.techniques,
                (film_paths, film_paths),
                unit_paths,
                radius,
            );
            let light = LightPaths {
                scene,
                tracer,
                settings,
                it: &it,
                sphere,
                recorder: None,
            };
            arena.vertices.clear();
            arena.starts.clear();
            let mut splat = |raster: Vec2, layer: u32, value: Rgb| {
                film.deposit(raster.x, raster.y, layer, value)
            };
            for (x, y) in unit_pixels(unit) {
                arena.starts.push(arena.vertices.len());
                let rng = Rng::new(pixel_seed(unit.seed, x, y, s), LIGHT_STREAM);
                light.trace(rng, &mut arena.vertices, &mut splat);
            }
            arena.starts.push(arena.vertices.len());
            counts.light_paths += unit_paths as u64;
            counts.light_vertices += arena.vertices.len() as u64;
            counts.max_light_vertices = counts.max_light_vertices.max(arena.vertices.len() as u64);
            if !it.techniques.camera_paths() {
                continue;
            }
            if it.techniques.merge {
                let points = arena.vertices.iter().map(|v| v.hit.p);
                arena.grid.build(points, it.radius);
            }
            let camera_paths = CameraPaths {
                scene,
                tracer,
                settings,
                it: &it,
                sphere,
                recorder: None,
            };
            let merges = it.techniques.merge.then_some(MergeSet {
                grid: &arena.grid,
                vertices: &arena.vertices,
            });
            let mut camera_counts = CameraCounts::default();
            for (k, (x, y)) in unit_pixels(unit).enumerate() {
                let mut rng = Rng::new(pixel_seed(unit.seed, x, y, s), 0);
                let raster = Vec2::new(x as f32, y as f32) + rng.uniform2();
                let own = if it.techniques.connect {
                    &arena.vertices[arena.starts[k]..arena.starts[k + 1]]
                } else {
                    &[]
                };
                let out = &mut arena.contributions;
                out.clear();
                camera_paths.trace(rng, raster, own, merges, out, &mut camera_counts);
                out.deposit(film, x, y, settings.layers());
            }
            counts.connections += camera_counts.connections;
            counts.merges += camera_counts.merges;
        }
    });
}

/// The seed of pixel sample (`x`, `y`, `s`) of a render with seed `seed`.
pub(crate) fn pixel_seed(seed: u64, x: u32, y: u32, s: u32) -> u64 {
    Rng::hash(&[seed, x as u64, y as u64, s as u64])
}

/// The counters a bidirectional plugin reports.
#[derive(Clone, Copy, Debug)]
pub struct Counters {
    light_paths: Counter,
    light_vertices: Counter,
    max_light_vertices: Counter,
    connections: Counter,
    merges: Counter,
}

impl Counters {
    /// Declares the counters.
    pub fn declare(stats: &mut StatsBuilder) -> Counters {
        Counters {
            light_paths: stats.sum("light paths"),
            light_vertices: stats.sum("light vertices kept"),
            max_light_vertices: stats.max("max light vertices"),
            connections: stats.sum("connections"),
            merges: stats.sum("merges"),
        }
    }

    /// Reports a unit's counts.
    pub fn report(&self, stats: &mut Stats, c: &UnitCounts) {
        stats.add(self.light_paths, c.light_paths as f64);
        stats.add(self.light_vertices, c.light_vertices as f64);
        stats.add(self.max_light_vertices, c.max_light_vertices as f64);
        stats.add(self.connections, c.connections as f64);
        stats.add(self.merges, c.merges as f64);
    }
}

/// What distinguishes the `lighttrace`, `bdpt` and `vcm` plugins: their names, parameters
/// and strategies. Each plugin is [`BidirIntegrator`] of its own kind.
pub trait BidirKind: Send + Sync + 'static {
    const NAME: &'static str;
    const DESCRIPTION: &'static str;
    const PARAMS: &'static [ParamSpec];
    /// The strategies it combines (`vcm`'s `mode` may narrow them to photon mapping).
    const TECHNIQUES: Techniques;
    /// Whether it takes `strategies` (per-strategy layers).
    const STRATEGY_LAYERS: bool = false;
}

/// A bidirectional integrator: the scene, its settings and counters.
pub struct BidirIntegrator<K> {
    scene: Scene<'static>,
    settings: BidirSettings,
    counters: Counters,
    kind: PhantomData<K>,
}

impl<K: BidirKind> Integrator for BidirIntegrator<K> {
    const NAME: &'static str = K::NAME;
    const DESCRIPTION: &'static str = K::DESCRIPTION;
    const PARAMS: &'static [ParamSpec] = K::PARAMS;

    /// Deposits land anywhere on the film (flanged tiles without a flange: every deposit
    /// kept); `biased` where merging is on; one layer per lighting layer or strategy.
    fn create(
        params: &Params,
        _mutations: MutationSet<'static>,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let settings = settings_from_params(params, K::TECHNIQUES, K::STRATEGY_LAYERS)?;
        let depth = settings.path.path_depth;
        let layer_count = if settings.strategy_layers {
            super::strategy_layer_count(depth)
        } else if settings.lighting_layers {
            depth + 1
        } else {
            0
        };
        let info = IntegratorInfo {
            layer_count,
            accumulation: AccumulationStyle::FlangedTile,
            flange: 0,
            biased: u32::from(settings.techniques.merge),
        };
        let counters = Counters::declare(stats);
        let integrator = BidirIntegrator {
            scene,
            settings,
            counters,
            kind: PhantomData,
        };
        Ok((integrator, info))
    }

    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut Stats,
    ) -> Result<(), String> {
        let mut counts = UnitCounts::default();
        render_unit(&self.scene, tracer, &self.settings, unit, film, &mut counts);
        self.counters.report(stats, &counts);
        Ok(())
    }
}
