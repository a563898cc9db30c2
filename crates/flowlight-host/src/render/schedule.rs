//! The render loop: the pool and the accumulation plan, the integrator's one-time
//! preparation, the rounds of passes whose units the threads take in order (module
//! documentation of [`crate::render`]), one work unit into its accumulator, and the final
//! flush into the frame with the render's counters.

use super::check_memory;
use super::{
    choose_style, round_passes, tile_order, tiles, AccumulationReport, PartialPass, Progress,
    RenderOptions, RenderOutcome, RenderStats, FLANGED_TIME_TILE, PASSES_PER_ROUND,
    TIMED_PASSES_PER_ROUND,
};
use crate::accumulation::{
    DepositCounts, Frame, MicroTileCache, Precision, SharedFrame, Style, ThreadBuffer,
    TileAccumulator,
};
use crate::intersector::{Intersector, StopSignal, UnitTracer};
use crate::plugin::{IntegratorInstance, PluginError};
use flowlight_scene::Scene;
use flowlight_sdk::abi::{IntegratorInfo, StatSpec};
use flowlight_sdk::{AccumulationStyle, Accumulator, WorkUnit};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// A worker thread's private accumulator for Buffering or Caching, made at its first unit.
enum ThreadAccumulator<'a> {
    Buffer(ThreadBuffer),
    Cache(MicroTileCache<'a>),
}

/// What a worker thread keeps between its units (Buffering, Caching): its accumulator, and
/// when after the render's start it last moved it into the frame for a live preview
/// ([`RenderOptions::preview_flush`]).
#[derive(Default)]
struct ThreadSlot<'a> {
    acc: Option<ThreadAccumulator<'a>>,
    preview_flushed: Duration,
}

/// The counters the units add to, shared by every thread.
struct Counters {
    /// Pixel samples of the finished rounds.
    done: AtomicU64,
    closest: AtomicU64,
    shadow: AtomicU64,
    invalid: AtomicU64,
    stray: AtomicU64,
    units: AtomicU64,
    /// Largest Blasting unit buffer.
    blast_bytes: AtomicU64,
    /// Nanoseconds after `start` at which the last unit started (+1, so 0 means none did).
    last_start: AtomicU64,
    /// The first plugin error; set together with `halted`.
    error: Mutex<Option<PluginError>>,
    halted: AtomicBool,
    /// The integrator's counters, merged over units.
    merged_stats: Mutex<Vec<f64>>,
}

/// How far the passes went: what the image is normalised by.
struct PassTally {
    /// Passes every tile finished.
    passes_done: u32,
    /// A flanged integrator's cut pass.
    partial_pass: Option<PartialPass>,
    /// Samples per pixel the flanged image is normalised by: s per whole pass, s·m/n for a
    /// cut one.
    uniform_spp: f64,
}

/// Everything the units of one render share; `'f` is the borrow of the frame that the
/// threads' micro-tile caches hold.
struct Run<'a, 'f> {
    instance: &'a IntegratorInstance,
    scene: &'a Scene,
    intersector: &'a dyn Intersector,
    opts: &'a RenderOptions,
    stop: &'a AtomicBool,
    progress: &'a (dyn Fn(&Progress) + Sync),
    specs: &'a [StatSpec],
    style: Style,
    layer_count: u32,
    precision: Precision,
    threads: usize,
    /// Whether the integrator's deposits stay in their tile (its passes run as rounds).
    tiled: bool,
    flange: u32,
    cache_slots: usize,
    tiles: Vec<(u32, u32, u32, u32)>,
    start: Instant,
    deadline: Option<Instant>,
    /// Pixel samples of the whole render, or 0 for a time budget.
    planned: u64,
    shared: &'f SharedFrame,
    private: &'a [Mutex<ThreadSlot<'f>>],
    counters: &'a Counters,
}

/// Renders with `instance` until the budget is spent or `stop` is set.
pub fn render(
    instance: &IntegratorInstance,
    scene: &Scene,
    intersector: &dyn Intersector,
    opts: &RenderOptions,
    stop: &AtomicBool,
    progress: &(dyn Fn(&Progress) + Sync),
) -> Result<RenderOutcome, String> {
    let (width, height) = (opts.width, opts.height);
    let layer_count = instance.info.layer_count;
    let precision = opts.precision;
    let (pool, style, shared, cache_slots) = accumulation_plan(&instance.info, opts)?;
    let threads = pool.current_num_threads();
    let private: Vec<Mutex<ThreadSlot>> = (0..threads).map(|_| Mutex::default()).collect();
    let (tiles, flange) = unit_tiles(instance, opts);
    let start = Instant::now();
    let specs = instance.stat_specs();
    // The integrator's one-time preparation counts against a time budget.
    let prepare_rays = match prepare(instance, scene, intersector) {
        Ok(rays) => rays,
        Err(e) => {
            return Ok(RenderOutcome {
                frame: Frame::with_precision(width, height, layer_count, precision),
                stats: RenderStats {
                    interrupted: true,
                    ..Default::default()
                },
                error: Some(e),
            })
        }
    };
    let counters = Counters::new(specs.len());
    let run = Run {
        instance,
        scene,
        intersector,
        opts,
        stop,
        progress,
        specs,
        style,
        layer_count,
        precision,
        threads,
        tiled: instance.info.accumulation == AccumulationStyle::Tile,
        flange,
        cache_slots,
        tiles,
        start,
        deadline: opts.time.map(|t| start + t),
        planned: if opts.time.is_some() {
            0
        } else {
            opts.spp as u64 * width as u64 * height as u64
        },
        shared: &shared,
        private: &private,
        counters: &counters,
    };
    let tally = pool.install(|| run.passes());
    let (tiled, planned) = (run.tiled, run.planned);
    drop(run);

    let private_bytes = flush_private(
        private,
        &shared,
        counters.blast_bytes.load(Ordering::Relaxed),
        threads,
    );
    let flush_counts = shared.counts();
    let mut frame = shared.into_frame();
    if !tiled {
        frame.set_uniform_spp(tally.uniform_spp);
    }
    let report = AccumulationReport {
        style,
        precision,
        frame_bytes: frame.bytes(),
        private_bytes,
        counts: flush_counts,
    };
    let (stats, error) = finish_stats(
        opts,
        stop,
        specs,
        counters,
        tally,
        (start, threads, planned),
        prepare_rays,
        report,
    );
    Ok(RenderOutcome {
        frame,
        stats,
        error,
    })
}

/// The work units' tiles and the flange of their buffers: a flanged integrator with a
/// flange (chains that random-walk from their tile, ERPT) under a time budget runs units of
/// at most [`FLANGED_TIME_TILE`]² pixels (module documentation). One without (light
/// tracing, BDPT, VCM: deposits anywhere, no chains) keeps the configured tiles: its units
/// cost what a path-tracing unit costs, and a unit's light paths are its merging set.
fn unit_tiles(
    instance: &IntegratorInstance,
    opts: &RenderOptions,
) -> (Vec<(u32, u32, u32, u32)>, u32) {
    let mut tile_size = opts.tile_size.max(1);
    if opts.time.is_some()
        && instance.info.accumulation == AccumulationStyle::FlangedTile
        && instance.info.flange > 0
    {
        tile_size = tile_size.min(FLANGED_TIME_TILE);
    }
    let flange = opts.flange.unwrap_or(match instance.info.accumulation {
        AccumulationStyle::Tile => 0,
        AccumulationStyle::FlangedTile => instance.info.flange,
    });
    (tiles(opts.width, opts.height, tile_size), flange)
}

/// The integrator's one-time preparation; the (closest, shadow) rays it traced.
fn prepare(
    instance: &IntegratorInstance,
    scene: &Scene,
    intersector: &dyn Intersector,
) -> Result<(u64, u64), PluginError> {
    let mut tracer = UnitTracer::new(scene, intersector);
    instance.prepare_once(&tracer.table())?;
    Ok((tracer.counts.closest, tracer.counts.shadow))
}

/// The render's thread pool, its accumulation style (the config's, else the host's choice for
/// the integrator `info` and the pool's threads), its frame and the micro-tiles per thread's
/// cache, once the memory they and the style's private buffers need is known to be available.
fn accumulation_plan(
    info: &IntegratorInfo,
    opts: &RenderOptions,
) -> Result<(std::sync::Arc<rayon::ThreadPool>, Style, SharedFrame, usize), String> {
    let pool = super::worker_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let layer_count = info.layer_count;
    let (width, height, precision) = (opts.width, opts.height, opts.precision);
    let style = opts.accumulation.unwrap_or_else(|| {
        let buffering = private_plan(Style::Buffering, opts, layer_count, threads);
        let fits = check_memory(width, height, layer_count, precision, buffering).is_ok();
        choose_style(info.accumulation, info.flange, buffering, fits)
    });
    let private = private_plan(style, opts, layer_count, threads);
    check_memory(width, height, layer_count, precision, private)?;
    let shared = SharedFrame::new(width, height, layer_count, precision);
    let cache_slots = cache_slots(style, opts, &shared, threads)?;
    Ok((pool, style, shared, cache_slots))
}

/// Bytes of private accumulation buffers the style will hold at most: Buffering's whole-image
/// buffer per thread, Caching's cap (Blasting's unit buffers are small and counted after).
fn private_plan(style: Style, opts: &RenderOptions, layer_count: u32, threads: usize) -> u64 {
    let planes = layer_count as u64 + 1;
    match style {
        Style::Blasting => 0,
        Style::Buffering => (opts.width as u64 * opts.height as u64)
            .saturating_mul(planes * opts.precision.partial_cell_bytes())
            .saturating_mul(threads as u64),
        Style::Caching => opts.cache_bytes,
    }
}

/// Micro-tiles each thread's cache holds within its share of the cap; an error when Caching
/// would get none.
fn cache_slots(
    style: Style,
    opts: &RenderOptions,
    shared: &SharedFrame,
    threads: usize,
) -> Result<usize, String> {
    let cache_slots = MicroTileCache::slots_for(opts.cache_bytes / threads as u64, shared);
    if style == Style::Caching && cache_slots == 0 {
        let need =
            MicroTileCache::slot_bytes(shared.plane_count(), opts.precision) * threads as u64;
        return Err(format!(
            "render.accumulation_cache_mib = {:.3} MiB holds no micro-tile for {threads} threads ({} framebuffers): give it at least {:.3} MiB",
            opts.cache_bytes as f64 / 1048576.0,
            shared.plane_count(),
            need as f64 / 1048576.0
        ));
    }
    Ok(cache_slots)
}

/// Buffering and Caching flush what the threads still hold (a failed unit's partial
/// deposits too: a render a plugin failed is reported, never written). Returns the most
/// bytes of private buffers held: the threads' accumulators, or for Blasting the largest
/// unit buffer (`blast_bytes`) times the threads.
fn flush_private(
    private: Vec<Mutex<ThreadSlot>>,
    shared: &SharedFrame,
    blast_bytes: u64,
    threads: usize,
) -> u64 {
    let mut private_bytes = blast_bytes * threads as u64;
    for slot in private {
        match slot.into_inner().unwrap_or_else(|e| e.into_inner()).acc {
            Some(ThreadAccumulator::Buffer(b)) => {
                private_bytes += b.bytes();
                b.flush_into(shared);
            }
            Some(ThreadAccumulator::Cache(mut c)) => {
                private_bytes += c.bytes();
                c.flush();
            }
            None => {}
        }
    }
    private_bytes
}

impl Counters {
    fn new(stat_count: usize) -> Counters {
        Counters {
            done: AtomicU64::new(0),
            closest: AtomicU64::new(0),
            shadow: AtomicU64::new(0),
            invalid: AtomicU64::new(0),
            stray: AtomicU64::new(0),
            units: AtomicU64::new(0),
            blast_bytes: AtomicU64::new(0),
            last_start: AtomicU64::new(0),
            error: Mutex::new(None),
            halted: AtomicBool::new(false),
            merged_stats: Mutex::new(vec![0.0f64; stat_count]),
        }
    }
}

/// The render's counters once every unit has finished, and the plugin error if one failed.
#[allow(clippy::too_many_arguments)]
fn finish_stats(
    opts: &RenderOptions,
    stop: &AtomicBool,
    specs: &[StatSpec],
    counters: Counters,
    tally: PassTally,
    (start, threads, planned): (Instant, usize, u64),
    (closest_prepare_rays, shadow_prepare_rays): (u64, u64),
    accumulation: AccumulationReport,
) -> (RenderStats, Option<PluginError>) {
    let error = counters.error.into_inner().unwrap();
    let pixel_samples = counters.done.load(Ordering::Relaxed);
    let interrupted = error.is_some()
        || (opts.time.is_none() && pixel_samples < planned)
        || (opts.time.is_some() && stop.load(Ordering::Relaxed));
    if pixel_samples == 0 && error.is_none() && !stop.load(Ordering::Relaxed) {
        tracing::warn!(
            "no work unit started inside the time budget (the integrator's preparation used it up): the image is black; give it more time"
        );
    }
    let last_start = counters.last_start.load(Ordering::Relaxed);
    let stats = RenderStats {
        wall: start.elapsed(),
        threads,
        pixel_samples,
        closest_rays: counters.closest.load(Ordering::Relaxed) + closest_prepare_rays,
        shadow_rays: counters.shadow.load(Ordering::Relaxed) + shadow_prepare_rays,
        invalid_deposits: counters.invalid.load(Ordering::Relaxed),
        stray_deposits: counters.stray.load(Ordering::Relaxed),
        units: counters.units.load(Ordering::Relaxed),
        interrupted,
        full_passes: tally.passes_done,
        partial_pass: tally.partial_pass,
        last_unit_start: (last_start > 0).then(|| Duration::from_nanos(last_start - 1)),
        // SAFETY: the specs' names are the instance's, which outlives this call.
        integrator: unsafe {
            flowlight_sdk::stats::resolve(specs, &counters.merged_stats.into_inner().unwrap())
        },
        accumulation: Some(accumulation),
    };
    (stats, error)
}

impl Run<'_, '_> {
    /// Whether the render must start no further unit: Ctrl-C, a failed unit, or the deadline.
    fn must_stop(&self, now: Instant) -> bool {
        self.stop.load(Ordering::Relaxed)
            || self.counters.halted.load(Ordering::Relaxed)
            || self.deadline.is_some_and(|d| now >= d)
    }

    /// Runs rounds of passes until the samples are done or the render must stop.
    fn passes(&self) -> PassTally {
        let opts = self.opts;
        let mut sample_begin = opts.sample_begin;
        let sample_end = opts.sample_begin.saturating_add(opts.spp);
        let mut pass_spp = 1u32;
        let mut tally = PassTally {
            passes_done: 0,
            partial_pass: None,
            uniform_spp: 0.0,
        };
        loop {
            let remaining = if opts.time.is_some() {
                u32::MAX
            } else {
                sample_end - sample_begin
            };
            if remaining == 0 || self.must_stop(Instant::now()) {
                break;
            }
            // The passes of this round, as (first sample, samples): one for a flanged
            // integrator, a run of them for a tile-local one (module documentation).
            let passes_per_round = if !self.tiled {
                1
            } else if opts.time.is_some() {
                TIMED_PASSES_PER_ROUND
            } else {
                PASSES_PER_ROUND
            };
            let round_end = sample_begin.saturating_add(remaining);
            let passes;
            (passes, sample_begin, pass_spp) = round_passes(
                sample_begin,
                round_end,
                pass_spp,
                passes_per_round,
                self.tiled,
            );
            self.round(&passes, &mut tally);
        }
        tally
    }

    /// Runs the units of one round (every tile of every pass in `passes`) on the pool and
    /// adds what finished to `tally`.
    fn round(&self, passes: &[(u32, u32)], tally: &mut PassTally) {
        let tiles = &self.tiles;
        let skipped = AtomicBool::new(false);
        let round_done = AtomicU64::new(0);
        let pass_units: Vec<AtomicU64> = passes.iter().map(|_| AtomicU64::new(0)).collect();
        // Flanged passes take their tiles in a random order, so that a cut keeps a uniformly
        // random subset (module documentation); tile-local ones in scan order.
        let order = if self.tiled {
            (0..tiles.len()).collect()
        } else {
            tile_order(tiles.len(), self.opts.seed, tally.passes_done)
        };
        let next = AtomicUsize::new(0);
        let round_units = tiles.len() * passes.len();
        (0..round_units).into_par_iter().for_each(|_| {
            // The budget and Ctrl-C stop every integrator between units: no unit starts after
            // the deadline; the units in flight finish.
            let now = Instant::now();
            if self.must_stop(now) {
                skipped.store(true, Ordering::Relaxed);
                return;
            }
            // One fetch per closure call and as many calls as units: always in range. The
            // units that start are the first ones of the round, pass by pass in `order`.
            let k = next.fetch_add(1, Ordering::Relaxed);
            let pass = k / tiles.len();
            let (sample_begin, count) = passes[pass];
            let tile = tiles[order[k % tiles.len()]];
            self.counters.last_start.fetch_max(
                (now - self.start).as_nanos().min(u64::MAX as u128 - 1) as u64 + 1,
                Ordering::Relaxed,
            );
            if !self.unit(tile, sample_begin, count) {
                skipped.store(true, Ordering::Relaxed);
                return;
            }
            pass_units[pass].fetch_add(1, Ordering::Relaxed);
            let (x0, y0, x1, y1) = tile;
            let pixels = (x1 - x0) as u64 * (y1 - y0) as u64;
            let d = pixels * count as u64;
            let p = round_done.fetch_add(d, Ordering::Relaxed) + d;
            (self.progress)(&Progress {
                pixel_samples: self.counters.done.load(Ordering::Relaxed) + p,
                planned: self.planned,
                elapsed: self.start.elapsed(),
                budget: self.opts.time,
                frame: Some((self.shared, self.tiled)),
            });
        });
        let whole = !skipped.load(Ordering::Relaxed);
        if !self.tiled {
            // Whole or cut, the pass is in the image; a cut one counts m/n of its samples.
            let count = passes[0].1;
            if whole {
                tally.uniform_spp += count as f64;
            } else {
                let cut = PartialPass {
                    finished: pass_units[0].load(Ordering::Relaxed) as u32,
                    tiles: tiles.len() as u32,
                };
                tally.uniform_spp += count as f64 * cut.fraction();
                tally.partial_pass = Some(cut);
            }
        }
        let counters = &self.counters;
        counters
            .done
            .fetch_add(round_done.load(Ordering::Relaxed), Ordering::Relaxed);
        // A pass is whole when every one of its units finished (units start in order, so a
        // stop cuts one pass and leaves the later ones empty).
        tally.passes_done += pass_units
            .iter()
            .filter(|u| u.load(Ordering::Relaxed) == tiles.len() as u64)
            .count() as u32;
    }

    /// Renders samples `[sample_begin, sample_begin + count)` of `tile` into the style's
    /// accumulator and adds its counters; false when nothing of it counts: the plugin failed
    /// (the render halts), or a Blasting unit stopped early and was discarded.
    fn unit(&self, tile: (u32, u32, u32, u32), sample_begin: u32, count: u32) -> bool {
        let (x0, y0, x1, y1) = tile;
        let unit = WorkUnit {
            x0,
            y0,
            x1,
            y1,
            sample_begin,
            sample_count: count,
            seed: self.opts.seed,
        };
        // The plugin may ask whether to stop inside a long unit (ERPT's chains): a Blasting
        // unit then ends early and its tile is discarded, as if it had not started; a
        // Buffering or Caching unit's deposits are already shared, so it is kept as a
        // finished unit with the chains it ran (module documentation).
        let mut tracer = UnitTracer::new(self.scene, self.intersector).with_stop(StopSignal {
            interrupt: self.stop,
            deadline: self.deadline,
        });
        let mut unit_stats = vec![0.0f64; self.specs.len()];
        let (result, counts) = if self.style == Style::Blasting {
            self.blast(&unit, &mut tracer, &mut unit_stats)
        } else {
            self.deposit_privately(&unit, &mut tracer, &mut unit_stats)
        };
        let counters = &self.counters;
        counters
            .closest
            .fetch_add(tracer.counts.closest, Ordering::Relaxed);
        counters
            .shadow
            .fetch_add(tracer.counts.shadow, Ordering::Relaxed);
        counters
            .invalid
            .fetch_add(counts.invalid, Ordering::Relaxed);
        counters.stray.fetch_add(counts.stray, Ordering::Relaxed);
        if let Err(e) = result {
            counters.halted.store(true, Ordering::Relaxed);
            counters.error.lock().unwrap().get_or_insert(e);
            return false;
        }
        if tracer.stop_answered && self.style == Style::Blasting {
            return false;
        }
        if !self.specs.is_empty() {
            flowlight_sdk::stats::merge(
                self.specs,
                &mut counters.merged_stats.lock().unwrap(),
                &unit_stats,
            );
        }
        counters.units.fetch_add(1, Ordering::Relaxed);
        true
    }

    /// Blasting: the unit deposits into a buffer of its own (its tile and the flange), merged
    /// into the frame when it succeeded.
    fn blast(
        &self,
        unit: &WorkUnit,
        tracer: &mut UnitTracer,
        unit_stats: &mut [f64],
    ) -> (Result<(), PluginError>, DepositCounts) {
        let tile = (unit.x0, unit.y0, unit.x1, unit.y1);
        let shared = self.shared;
        let mut acc = TileAccumulator::with_precision(
            tile,
            self.flange,
            (self.opts.width, self.opts.height),
            self.layer_count,
            self.precision,
        );
        self.counters
            .blast_bytes
            .fetch_max(acc.bytes(), Ordering::Relaxed);
        let result = self
            .instance
            .render(unit, &tracer.table(), &acc.table(), unit_stats);
        if result.is_ok() && !tracer.stop_answered {
            shared.merge_tile(&acc, unit.sample_count);
        }
        (result, acc.counts)
    }

    /// Buffering and Caching: the unit deposits into its thread's private accumulator (made
    /// at the thread's first unit); the frame counts the unit's samples when it succeeded.
    fn deposit_privately(
        &self,
        unit: &WorkUnit,
        tracer: &mut UnitTracer,
        unit_stats: &mut [f64],
    ) -> (Result<(), PluginError>, DepositCounts) {
        let shared = self.shared;
        // The pool's threads are 0..threads; each owns its slot, so the lock is never
        // contended.
        let me = rayon::current_thread_index().unwrap_or(0) % self.threads;
        let mut slot = self.private[me].lock().unwrap_or_else(|e| e.into_inner());
        let slot = &mut *slot;
        let acc = slot.acc.get_or_insert_with(|| match self.style {
            Style::Buffering => ThreadAccumulator::Buffer(ThreadBuffer::new(
                self.opts.width,
                self.opts.height,
                self.layer_count,
                self.precision,
            )),
            _ => ThreadAccumulator::Cache(MicroTileCache::new(shared, self.cache_slots)),
        });
        let (result, counts) = match acc {
            ThreadAccumulator::Buffer(b) => {
                let r = self
                    .instance
                    .render(unit, &tracer.table(), &b.table(), unit_stats);
                (r, std::mem::take(&mut b.counts))
            }
            ThreadAccumulator::Cache(c) => {
                let r = self
                    .instance
                    .render(unit, &tracer.table(), &c.table(), unit_stats);
                (r, std::mem::take(&mut c.counts))
            }
        };
        if result.is_ok() {
            shared.add_samples((unit.x0, unit.y0, unit.x1, unit.y1), unit.sample_count);
        }
        if let Some(every) = self.opts.preview_flush {
            let now = self.start.elapsed();
            if now.saturating_sub(slot.preview_flushed) >= every {
                slot.preview_flushed = now;
                match acc {
                    ThreadAccumulator::Buffer(b) => b.flush_and_clear(shared),
                    ThreadAccumulator::Cache(c) => c.flush(),
                }
            }
        }
        (result, counts)
    }
}
