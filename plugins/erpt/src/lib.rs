//! # `erpt` — Energy Redistribution Path Tracing
//!
//! Cline, Talbot & Egbert 2005, as corrected and extended in thesis ch. 5. Initial Monte Carlo
//! samples (seeds) come from the MCPT plugin's own samplers (`flowlight-pathtrace`): untangled
//! paths, one light connection each (`seeds = "untangled"`, the thesis'), or entangled paths
//! split into their techniques (`seeds = "entangled"`: every light connection, emitter hit
//! and environment escape is a seed with its MIS-weighted estimate; `flowlight_pathtrace::seeds`
//! has the argument why their energy density is f), or BDPT samples split into their
//! connection strategies (`seeds = "bdpt"`, `flowlight_pathtrace::bidir::strategy_seeds`; a
//! light-tracing seed runs its chains from its own raster position, wherever it lies, and a
//! seed whose path the target function gives no energy goes to its pixel). Each seed spawns chains that redistribute
//! its energy over nearby paths with the mutation strategies listed in the config, each its own
//! plugin:
//!
//! ```toml
//! [integrator]
//! plugin = "erpt"
//! mutations_per_sample = 64
//! chain_length = 16
//! [[integrator.mutations]]
//! plugin = "drill"
//! width = "narrow"
//! weight = 0.3
//! [[integrator.mutations]]
//! plugin = "blow"
//! weight = 0.7
//! ```
//!
//! Per work unit (a tile × a range of samples per pixel) the seeds are traced once (entangled
//! ones as wavefronts of ray batches) and stored;
//! the deposition quantum e_d = lum(Σ X) / (samples · M) is estimated from them (or once for
//! the image, `quantum = "image"`), with M the expected number of mutations per camera sample
//! (§5.2; an entangled camera sample gives several seeds); then every seed runs the corrected
//! Equal Deposition Flow (`flow.rs`) from the stored path. With a split (`direct`,
//! `chains_for`; `part.rs`) only the seeds of the chains' part of path space run chains, and
//! only their energy enters e_d; every other seed's estimate goes to its pixel, as path
//! tracing would deposit it, and a proposal that leaves the part is a counted domain miss. Chains random-walk on
//! the film in a `film_window`² window around their current position, so their deposits land
//! around the seed's tile: units use flanged tiles (§5.9).
//!
//! Without a mutation list the host hands over every installed strategy and `preset =
//! "auto"` (`auto.rs`, `pilot.rs`) picks the split, the chain budget and the weights from a
//! pilot's norms in `prepare`.
//!
//! The parameters are declared once, in `settings.rs`; the table generated from the
//! declarations is in docs/erpt.md ("Parameters"), and `flowlight plugins --markdown` prints it.
//!
//! Seeds whose estimate is NaN, infinite or negative, or whose path the target function gives
//! no energy, are skipped and counted; proposals with invalid densities or contributions are
//! rejected and counted, never deposited. The quality norms of §5.5 (strength and streaks of
//! acceptance, rejection, domain hit and miss, per strategy and in total), chains per seed and
//! deposits per pixel are reported to the host, which prints them and writes them as JSON,
//! with the costs: time proposing and density calls per strategy, target-function calls,
//! seed-tracing and flow time (`stats.rs`).

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

mod auto;
mod automaton;
mod flow;
mod gain;
mod part;
mod pilot;
mod settings;
mod stats;

use flow::Flow;
use flowlight_core::path::{NodeType, Path};
use flowlight_core::rng::Rng;
use flowlight_core::sobol::SobolSampler;
use flowlight_core::Rgb;
use flowlight_pathtrace::bidir::strategy_seeds::StrategySeeds;
use flowlight_pathtrace::bidir::{BidirSettings, Heuristic, Techniques};
use flowlight_pathtrace::sampler::{sample_start, PixelSampler, SamplerKind};
use flowlight_pathtrace::seeds::{self, SeedFilter, SeedStore, SeedWavefront};
use flowlight_pathtrace::walk::units;
use flowlight_pathtrace::{entangled, untangled, PathSettings, SampleContributions};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{
    export_integrator, AccumulationStyle, Film, Integrator, IntegratorInfo, MutationSet, Params,
    Scene, Stats, StatsBuilder, Tracer, WorkUnit, MAX_MUTATIONS,
};
use settings::{ErptSettings, QuantumScope, SeedKind};
use std::cell::RefCell;
use std::time::Instant;

pub struct Erpt {
    scene: Scene<'static>,
    mutations: MutationSet<'static>,
    settings: ErptSettings,
    /// e_d from the whole-image pre-pass (`quantum = "image"`).
    image_quantum: Option<f64>,
    /// Handles of the counters declared in `create`.
    counters: stats::Counters,
    /// No path of this scene can be in the chains' part ([`scene_letters`]): entangled seeds
    /// are then path tracing, and are traced and deposited as MCPT does.
    chains_part_empty: bool,
    /// The settings of a unit [`Self::render_without_chains`] path-traces: the seeds' with
    /// MCPT's default branches (seeds never branch: a branch would split a seed's path before
    /// the flow, but no seed of such a unit reaches a flow). Set again after the pilot.
    path_tracing: PathSettings,
    /// Selection probability per strategy: the host's normalised weights, or `auto`'s.
    weights: Vec<f64>,
    /// `preset = "auto"`: its counters, and after `prepare` its choices (`auto.rs`).
    auto: Option<(auto::Counters, Option<auto::Report>)>,
}

/// The Heckbert letters (`part::letter_bit_of`) the scene's surfaces can give a vertex: per
/// material the letters of its BSDF's components (`D` diffuse, `G` glossy, `S` Dirac), read
/// from the per-material BSDF table; every letter for a material whose BSDF depends on its
/// textures (or without a table).
fn scene_letters(scene: &Scene) -> u8 {
    let all = part::letter_bit_of(NodeType::DiffuseReflection)
        | part::letter_bit_of(NodeType::GlossyReflection)
        | part::letter_bit_of(NodeType::SpecularReflection);
    (0..scene.materials.len()).fold(0, |mask, i| {
        mask | match scene.material_bsdfs.get(i) {
            Some(Some(bsdf)) => bsdf.components().fold(0, |m, (c, _)| {
                m | part::letter_bit_of(if c.is_delta() {
                    NodeType::SpecularReflection
                } else if c.is_diffuse() {
                    NodeType::DiffuseReflection
                } else {
                    NodeType::GlossyReflection
                })
            }),
            _ => all,
        }
    })
}

/// Deposits seed estimates outside the chains (per lighting layer) at the centre of their
/// sample's pixel (x, y), as path tracing deposits a sample (a box filter: the jittered raster
/// position could round into the next pixel), counting the valid ones in `deposits` and
/// skipping and counting the others in `skipped`.
fn deposit_at_pixel(
    film: &mut Film,
    x: u32,
    y: u32,
    estimates: &SampleContributions,
    deposits: &mut u64,
    skipped: &mut u64,
) {
    for &(layer, value) in &estimates.entries {
        if value.is_valid_radiance() {
            *deposits += 1;
            film.deposit(x as f32 + 0.5, y as f32 + 0.5, layer, value);
        } else {
            *skipped += 1;
        }
    }
}

/// A pixel sampler with each worker thread's wavefront buffers for it, kept across units so
/// that a unit allocates nothing for its trees and paths.
trait WaveSampler: PixelSampler + 'static {
    fn with_seed_wave<R>(f: impl FnOnce(&mut SeedWavefront<Self>) -> R) -> R;
    fn with_mcpt_wave<R>(
        f: impl FnOnce(&mut (entangled::Wavefront<Self>, Vec<SampleContributions>)) -> R,
    ) -> R;
}

macro_rules! wave_sampler {
    ($sampler:ty) => {
        impl WaveSampler for $sampler {
            fn with_seed_wave<R>(f: impl FnOnce(&mut SeedWavefront<Self>) -> R) -> R {
                thread_local! {
                    static WAVE: RefCell<SeedWavefront<$sampler>> =
                        RefCell::new(SeedWavefront::default());
                }
                WAVE.with_borrow_mut(f)
            }
            fn with_mcpt_wave<R>(
                f: impl FnOnce(&mut (entangled::Wavefront<Self>, Vec<SampleContributions>)) -> R,
            ) -> R {
                thread_local! {
                    static WAVE: RefCell<(entangled::Wavefront<$sampler>, Vec<SampleContributions>)> =
                        RefCell::new((entangled::Wavefront::default(), Vec::new()));
                }
                WAVE.with_borrow_mut(f)
            }
        }
    };
}
wave_sampler!(Rng);
wave_sampler!(SobolSampler);

/// The chains' random stream of camera sample (`x`, `y`, `s`): stream 1 of the hash whose
/// stream 0 is the independent seed path's (`PixelSampler for Rng`).
fn chain_rng(seed: u64, x: u32, y: u32, s: u32) -> Rng {
    Rng::new(Rng::hash(&[seed, x as u64, y as u64, s as u64]), 1)
}

/// A unit's tile with its flange, in raster coordinates: where its chains are expected to
/// deposit (the host keeps deposits elsewhere too).
struct FlangedTile {
    x0: f32,
    y0: f32,
    x1: f32,
    y1: f32,
}

impl FlangedTile {
    fn of(unit: &WorkUnit, flange: u32) -> Self {
        let f = flange as f32;
        FlangedTile {
            x0: unit.x0 as f32 - f,
            y0: unit.y0 as f32 - f,
            x1: unit.x1 as f32 + f,
            y1: unit.y1 as f32 + f,
        }
    }

    fn contains(&self, raster: glam::Vec2) -> bool {
        (self.x0..self.x1).contains(&raster.x) && (self.y0..self.y1).contains(&raster.y)
    }
}

/// A camera sample of a unit and the first of its seeds in the unit's store.
struct SampleKey {
    x: u32,
    y: u32,
    s: u32,
    first: usize,
}

/// The seeds of a work unit, traced once: the store, each sample's first seed, and whether
/// each seed lies in the chains' part of path space.
#[derive(Default)]
struct UnitSeeds {
    store: SeedStore,
    keys: Vec<SampleKey>,
    in_part: Vec<bool>,
}

/// Camera samples whose entangled seeds are traced together as one wavefront (ray batches of
/// the camera, extension and shadow rays, as MCPT's `wavefront`): large enough to amortise the
/// host call, small enough that the trees' state stays in cache.
const SEED_WAVE: usize = 256;

impl Erpt {
    /// Whether entangled seeds are split while traced (only the chains' part is stored).
    fn splits_while_tracing(&self) -> bool {
        self.settings.seed_kind == SeedKind::Entangled && !self.settings.part.is_everything()
    }

    /// Traces every seed of `pixels` × `samples` once (random streams from `seed`): untangled
    /// paths one at a time, entangled path trees as wavefronts of [`SEED_WAVE`] camera samples.
    /// With entangled seeds and a split, only the seeds of the chains' part are stored; the
    /// others are handed to `rest` per sample (its pixel, their estimates, their number).
    #[allow(clippy::too_many_arguments)]
    fn trace_unit(
        &self,
        tracer: &Tracer,
        seed: u64,
        pixels: impl Iterator<Item = (u32, u32)>,
        samples: std::ops::Range<u32>,
        out: &mut UnitSeeds,
        path: &mut Path,
        rest: &mut dyn FnMut(u32, u32, &SampleContributions, u64),
    ) {
        match self.settings.seed_kind {
            SeedKind::Untangled => {
                for (x, y) in pixels {
                    for s in samples.clone() {
                        out.keys.push(SampleKey {
                            x,
                            y,
                            s,
                            first: out.store.seeds.len(),
                        });
                        let (mut rng, raster) = sample_start::<Rng>(seed, x, y, s);
                        untangled::trace(
                            &self.scene,
                            tracer,
                            &self.settings.seeds,
                            &mut rng,
                            raster,
                            Some(path),
                        );
                        out.store.push_path(path);
                    }
                }
            }
            SeedKind::Bdpt => self.trace_bdpt(tracer, seed, pixels, samples, out),
            SeedKind::Entangled => match self.settings.sampler {
                SamplerKind::Independent => {
                    self.trace_entangled::<Rng>(tracer, seed, pixels, samples, out, rest)
                }
                SamplerKind::Sobol => {
                    self.trace_entangled::<SobolSampler>(tracer, seed, pixels, samples, out, rest)
                }
            },
        }
        let part = &self.settings.part;
        // Split while traced: every stored seed is in the part.
        let everything = part.is_everything() || self.splits_while_tracing();
        out.in_part = (0..out.store.seeds.len())
            .map(|i| {
                everything || {
                    out.store.path(i, path);
                    part.contains(path)
                }
            })
            .collect();
    }

    /// [`Self::trace_unit`]'s BDPT seeds: per pixel sample the `bdpt` plugin's light and camera
    /// subpaths (its random streams; the chains draw from stream 1 of the same hash), every
    /// connection strategy a seed (`flowlight_pathtrace::bidir::strategy_seeds`).
    fn trace_bdpt(
        &self,
        tracer: &Tracer,
        seed: u64,
        pixels: impl Iterator<Item = (u32, u32)>,
        samples: std::ops::Range<u32>,
        out: &mut UnitSeeds,
    ) {
        let settings = BidirSettings {
            path: self.settings.seeds.clone(),
            heuristic: Heuristic::Power,
            techniques: Techniques::BDPT,
            lighting_layers: false,
            strategy_layers: false,
            radius: 0.0,
            radius_alpha: 1.0,
            only_strategy: None,
        };
        let mut sampler = StrategySeeds::new(&self.scene, tracer, &settings);
        for (x, y) in pixels {
            for s in samples.clone() {
                out.keys.push(SampleKey {
                    x,
                    y,
                    s,
                    first: out.store.seeds.len(),
                });
                sampler.trace_sample(seed, (x, y, s), &mut out.store);
            }
        }
    }

    /// [`Self::trace_unit`]'s entangled seeds, drawn with the pixel sampler `S`.
    fn trace_entangled<S: WaveSampler>(
        &self,
        tracer: &Tracer,
        seed: u64,
        pixels: impl Iterator<Item = (u32, u32)>,
        samples: std::ops::Range<u32>,
        out: &mut UnitSeeds,
        rest: &mut dyn FnMut(u32, u32, &SampleContributions, u64),
    ) {
        S::with_seed_wave(|wf| {
            let filter: Option<&dyn SeedFilter> = self
                .splits_while_tracing()
                .then_some(&self.settings.part as &dyn SeedFilter);
            units::for_each_wave::<S>(seed, pixels, samples, SEED_WAVE, |starts, wave| {
                let (store, keys) = (&mut out.store, &mut out.keys);
                seeds::trace_wavefront(
                    &self.scene,
                    tracer,
                    &self.settings.seeds,
                    starts,
                    filter,
                    wf,
                    store,
                    |tree| {
                        let units::SampleKey { x, y, s } = wave[tree.index];
                        keys.push(SampleKey {
                            x,
                            y,
                            s,
                            first: tree.first_seed,
                        });
                        if tree.rest_count > 0 {
                            rest(x, y, tree.rest, tree.rest_count);
                        }
                    },
                );
            });
        })
    }

    /// A unit of a scene whose chains' part is empty: every entangled seed would go to its
    /// pixel, so the unit is path tracing. It is traced as MCPT's wavefront
    /// (`entangled::trace_wavefront`, whose estimate per sample and layer is the sum of the
    /// sample's seeds, `flowlight_pathtrace::seeds`) with MCPT's default branches, from the
    /// seeds' own random streams, and each valid contribution is deposited at the sample's
    /// pixel, as the split deposits seeds.
    fn render_without_chains(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut Stats,
    ) {
        match self.settings.sampler {
            SamplerKind::Independent => self.mcpt_unit::<Rng>(unit, tracer, film, stats),
            SamplerKind::Sobol => self.mcpt_unit::<SobolSampler>(unit, tracer, film, stats),
        }
    }

    /// [`Self::render_without_chains`] with the pixel sampler `S`.
    fn mcpt_unit<S: WaveSampler>(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut Stats,
    ) {
        let start = Instant::now();
        let (mut samples, mut deposits, mut skipped) = (0u64, 0u64, 0u64);
        S::with_mcpt_wave(|(wf, out)| {
            out.resize_with(SEED_WAVE, SampleContributions::default);
            let sample_range = unit.sample_begin..unit.sample_begin + unit.sample_count;
            let pixels = units::unit_pixels(unit);
            units::for_each_wave::<S>(
                unit.seed,
                pixels,
                sample_range,
                SEED_WAVE,
                |starts, keys| {
                    let out = &mut out[..starts.len()];
                    entangled::trace_wavefront(
                        &self.scene,
                        tracer,
                        &self.path_tracing,
                        starts,
                        wf,
                        out,
                    );
                    for (key, c) in keys.iter().zip(out.iter()) {
                        deposit_at_pixel(film, key.x, key.y, c, &mut deposits, &mut skipped);
                    }
                    samples += starts.len() as u64;
                },
            );
        });
        let c = &self.counters;
        stats.add(c.seed_seconds, start.elapsed().as_secs_f64());
        stats.add(c.camera_samples, samples as f64);
        stats.add(c.seeds, (deposits + skipped) as f64);
        stats.add(c.mcpt_part_seeds, deposits as f64);
        stats.add(c.seeds_skipped, skipped as f64);
        stats.add(c.units, 1.0);
        stats.add(c.units_without_chains, 1.0);
        stats.add(
            c.image_pixels,
            (self.scene.camera.width as f64) * (self.scene.camera.height as f64),
        );
    }

    /// Algorithm 1: e_d = lum(Σ X) / (samples · M), the sum over the valid estimates of the
    /// seeds in the chains' part, `samples` the camera samples traced (each one entangled
    /// path, or one untangled path): M mutations per camera sample in expectation.
    fn quantum(&self, sum: Rgb, samples: u64) -> f64 {
        if samples == 0 {
            return 0.0;
        }
        sum.luminance() as f64 / (samples as f64 * self.settings.mutations_per_sample)
    }

    /// Σ of the valid estimates of a unit's seeds in the chains' part.
    fn part_energy(seeds: &UnitSeeds) -> Rgb {
        seeds
            .store
            .seeds
            .iter()
            .zip(&seeds.in_part)
            .filter(|(s, &inside)| inside && s.estimate.is_valid_radiance())
            .fold(Rgb::ZERO, |a, (s, _)| a + s.estimate)
    }
}

/// The settings a unit without chains path-traces with: `seeds`' with MCPT's default branches.
fn path_tracing_settings(seeds: &PathSettings) -> PathSettings {
    PathSettings {
        branches: flowlight_pathtrace::settings::DEFAULT_BRANCHES,
        ..seeds.clone()
    }
}

impl Integrator for Erpt {
    const NAME: &'static str = "erpt";
    const DESCRIPTION: &'static str =
        "Energy Redistribution Path Tracing with pluggable mutation strategies";
    const PARAMS: &'static [ParamSpec] = &settings::PARAMS;

    fn create(
        params: &Params,
        mutations: MutationSet<'static>,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let mut settings = ErptSettings::from_params(params)?;
        if settings.auto.is_some_and(|free| free.film_window) {
            // Fixed here, not by the pilot: the flange below depends on it. The pilot's report
            // records it with its other choices (`auto::Report::decided_params`).
            settings.film_window = auto::film_window(scene.camera.width, scene.camera.height);
        }
        if mutations.is_empty() {
            return Err("erpt needs at least one [[integrator.mutations]] entry".into());
        }
        // The host refuses longer lists; kept for hosts that do not.
        if mutations.len() > MAX_MUTATIONS {
            return Err(format!(
                "erpt takes at most {MAX_MUTATIONS} mutation strategies, got {}",
                mutations.len()
            ));
        }
        let names: Vec<String> = (0..mutations.len())
            .map(|i| {
                let n = mutations.name(i);
                let dup = (0..i).filter(|&j| mutations.name(j) == n).count();
                if dup == 0 {
                    n.to_string()
                } else {
                    format!("{n}#{}", dup + 1)
                }
            })
            .collect();
        let counters = stats::Counters::declare(stats, &names);
        let auto = settings.auto.map(|_| {
            let layers = settings.seeds.path_depth as usize + 2;
            (auto::Counters::declare(stats, &names, layers), None)
        });
        let chains_part_empty = settings.seed_kind == SeedKind::Entangled
            && settings.part.is_empty_for(scene_letters(&scene));
        let info = IntegratorInfo {
            layer_count: if settings.layers {
                settings.seeds.path_depth + 1
            } else {
                0
            },
            biased: (settings.max_consecutive > 0) as u32,
            // Chains random-walk on the film by at most K/2 per step; a flange of 2K keeps most
            // of their deposits in the unit's buffer (the host keeps the rest). Without chains
            // every deposit is at its sample's pixel, as in path tracing: plain tiles, whose
            // buffers are a quarter the size of 32-pixel tiles with a 16-pixel flange.
            accumulation: if chains_part_empty {
                AccumulationStyle::Tile
            } else {
                AccumulationStyle::FlangedTile
            },
            flange: if chains_part_empty {
                0
            } else {
                2 * settings.film_window
            },
        };
        let path_tracing = path_tracing_settings(&settings.seeds);
        Ok((
            Erpt {
                scene,
                mutations,
                settings,
                image_quantum: None,
                counters,
                chains_part_empty,
                path_tracing,
                weights: (0..mutations.len()).map(|i| mutations.weight(i)).collect(),
                auto,
            },
            info,
        ))
    }

    fn prepare(&mut self, tracer: &Tracer) -> Result<(), String> {
        if self.auto.is_some() {
            self.run_auto_pilot(tracer)?;
            self.path_tracing = path_tracing_settings(&self.settings.seeds);
        }
        if self.settings.quantum != QuantumScope::Image
            || self.chains_part_empty
            || self.image_quantum.is_some()
        {
            return Ok(());
        }
        // Algorithm 1 over the whole image: one camera sample per pixel, a row at a time.
        let (w, h) = (self.scene.camera.width, self.scene.camera.height);
        let (mut sum, mut samples) = (Rgb::ZERO, 0u64);
        let mut row = UnitSeeds::default();
        let mut path = Box::new(Path::empty());
        for y in 0..h {
            row = UnitSeeds {
                store: std::mem::take(&mut row.store),
                ..UnitSeeds::default()
            };
            row.store.clear();
            // Only the part's energy enters e_d: the rest is not deposited here.
            self.trace_unit(
                tracer,
                0x5eed_f1a6,
                (0..w).map(|x| (x, y)),
                0..1,
                &mut row,
                &mut path,
                &mut |_, _, _, _| {},
            );
            sum += Self::part_energy(&row);
            samples += row.store.samples;
        }
        self.image_quantum = Some(self.quantum(sum, samples));
        if let Some((_, Some(report))) = &mut self.auto {
            report.quantum = self.image_quantum;
        }
        Ok(())
    }

    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut Stats,
    ) -> Result<(), String> {
        if let Some((counters, Some(report))) = &self.auto {
            counters.add(stats, report);
        }
        if self.chains_part_empty {
            self.render_without_chains(unit, tracer, film, stats);
            return Ok(());
        }
        let mut path = Box::new(Path::empty());
        let samples = unit.sample_begin..unit.sample_begin + unit.sample_count;
        let pixels = (unit.y0..unit.y1).flat_map(move |y| (unit.x0..unit.x1).map(move |x| (x, y)));
        // Every seed of the unit is traced once, here; the quantum and the flow use the store.
        let start = Instant::now();
        let mut seeds = UnitSeeds::default();
        let c = &self.counters;
        // Seeds split off while traced go to their pixel now, as path tracing deposits them
        // (the same deposits as the loop below makes for stored seeds outside the part).
        let (mut rest_seeds, mut rest_deposits, mut rest_skipped) = (0u64, 0u64, 0u64);
        self.trace_unit(
            tracer,
            unit.seed,
            pixels,
            samples,
            &mut seeds,
            &mut path,
            &mut |x, y, rest, count| {
                rest_seeds += count;
                deposit_at_pixel(film, x, y, rest, &mut rest_deposits, &mut rest_skipped);
            },
        );
        stats.add(c.seeds, rest_seeds as f64);
        stats.add(c.mcpt_part_seeds, rest_deposits as f64);
        stats.add(c.seeds_skipped, rest_skipped as f64);
        stats.add(c.seed_seconds, start.elapsed().as_secs_f64());
        stats.add(c.camera_samples, seeds.store.samples as f64);
        let quantum = match self.image_quantum {
            Some(q) => q,
            None => self.quantum(Self::part_energy(&seeds), seeds.store.samples),
        };
        stats.add(c.quantum_sum, quantum);
        stats.add(c.units, 1.0);
        stats.add(
            c.image_pixels,
            (self.scene.camera.width as f64) * (self.scene.camera.height as f64),
        );
        let start = Instant::now();
        let mut flow = Flow::new(
            &self.scene,
            tracer,
            &self.settings,
            &self.mutations,
            &self.weights,
            c,
        );
        // BDPT seeds include paths the target function cannot hold (a Dirac light seen through
        // a Dirac chain): they go to their pixel, as a split's MCPT part does.
        flow.deposit_unmeasured = self.settings.seed_kind == SeedKind::Bdpt;
        let flanged = FlangedTile::of(unit, 2 * self.settings.film_window);
        let count = seeds.store.seeds.len();
        for (k, key) in seeds.keys.iter().enumerate() {
            let end = seeds.keys.get(k + 1).map_or(count, |n| n.first);
            // The chains of all seeds of one camera sample draw from its chain stream.
            let mut chain_rng = chain_rng(unit.seed, key.x, key.y, key.s);
            for i in key.first..end {
                seeds.store.path(i, &mut path);
                path.film_window = self.settings.film_window;
                let estimate = seeds.store.seeds[i].estimate;
                if !flanged.contains(path.raster) {
                    // A light-tracing seed of another tile: its chains run from where it is
                    // and the host keeps their deposits (docs/erpt.md, "Seed kinds").
                    stats.add(c.seeds_outside_flange, 1.0);
                }
                if seeds.in_part[i] {
                    flow.run_seed(&path, estimate, quantum, &mut chain_rng, film, stats)?;
                    continue;
                }
                // Outside the chains' part: the seed's estimate goes to its pixel, as path
                // tracing deposits it.
                stats.add(c.seeds, 1.0);
                if estimate.is_black() {
                    // An untangled sample that found no light.
                } else if estimate.is_valid_radiance() {
                    stats.add(c.mcpt_part_seeds, 1.0);
                    film.deposit(
                        path.raster.x.floor() + 0.5,
                        path.raster.y.floor() + 0.5,
                        path.layer,
                        estimate,
                    );
                } else {
                    stats.add(c.seeds_skipped, 1.0);
                }
            }
        }
        stats.add(c.flow_seconds, start.elapsed().as_secs_f64());
        flow.report(stats);
        Ok(())
    }

    fn decided_params(&self) -> Vec<(String, String)> {
        match &self.auto {
            Some((_, Some(report))) => report.decided_params(),
            _ => Vec::new(),
        }
    }
}

export_integrator!(Erpt);
