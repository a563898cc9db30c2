//! The scheduler: splits the image into tiles and passes of samples, runs the work units on
//! the host's one rayon pool, merges finished tiles, and stops cleanly when asked.
//!
//! A flanged integrator's passes run one after another (a pass's tile order and a cut
//! pass's normalisation, below, are per pass). A tile-local integrator's passes run as one
//! round ([`PASSES_PER_ROUND`] passes at most) whose units the threads take in pass order,
//! so no thread waits at a pass boundary for the pass's slowest tile (on 16 cores that wait
//! was 7–12% of an MCPT render's thread time: docs/performance.md).
//!
//! # Time budgets and partial passes
//!
//! A render with a time budget `T` starts no work unit after `T` (the clock starts before the
//! integrator's one-time `prepare`, which counts against the budget); units in flight finish,
//! so the overrun is at most one unit per thread. A unit that can run long asks the host
//! (`Tracer::should_stop`, ABI 6) whether the budget is spent or Ctrl-C was pressed, and
//! returns at once when it is (ERPT asks before each seed and every 256 chain steps): a
//! Blasting unit told so is discarded, as if it had not started; a Buffering or Caching
//! unit's deposits are already shared, so it counts as finished with the chains it ran —
//! a unit per thread of the cut pass holds less than its share of energy, the price of
//! stopping within milliseconds rather than after seconds. How the samples finished by then
//! are normalised depends on where a unit deposits:
//!
//! * tile-local integrators (MCPT): every pixel's value is the mean of its own finished
//!   samples, sum / nᵢ, so stopping between any two units leaves every pixel unbiased;
//! * flanged integrators (ERPT), whose chains deposit into neighbouring tiles: a pixel's
//!   own sample count says nothing about how much energy its neighbours' chains brought it,
//!   so the image is normalised by a **uniform** number of passes instead. Each pass visits
//!   its n tiles in a uniformly random order (Fisher–Yates, seeded by the render seed and the
//!   pass index: [`tile_order`]); the workers take tiles from that order one at a time, so
//!   when the budget (or Ctrl-C) stops the pass after m units have started, the finished
//!   tiles are the first m of a random permutation: a uniformly random m-subset. Every tile,
//!   hence every deposit a pixel would have received in a full pass, is then present with
//!   probability m/n, and for a pixel p with full-pass deposit sum D_p
//!
//!   E\[partial-pass deposits at p | m\] = (m/n)·E\[D_p\],
//!
//!   so after P whole passes of s samples each and a cut one, the image
//!
//!   I_p = (Σ whole-pass deposits + partial-pass deposits) / (s·(P + m/n))
//!
//!   has E\[I_p | m\] = E\[D_p\]/s: unbiased, with no pass dropped and no black tiles. The
//!   residual: m is not independent of the order, because it depends on how long the first
//!   tiles took (a permutation that puts the costly tiles first finishes fewer of them before
//!   the deadline), a second-order correlation between which tiles and how many; with a
//!   stop after a fixed number of units it vanishes. The cut pass is also noisier than a
//!   whole one (fewer samples, and each kept tile weighs n/m), which only matters when it is
//!   the first. The EXR says `flowlight.partial_pass = m/n` as a decimal (`0` when no pass
//!   was cut) and `flowlight.biased` only for the integrator's own bias. A tile-local
//!   integrator keeps scan order (its cut needs no correction). Under a time budget flanged
//!   integrators run units of at most [`FLANGED_TIME_TILE`]² pixels, so the units in flight
//!   at the deadline are short and a cut pass keeps many tiles.
//!
//! # Limits
//!
//! * Threads: at most [`MAX_THREADS_PER_CORE`] × the cores; more are clamped with a
//!   warning (they only add scheduling and contention).
//! * Memory: [`frame_bytes_with`] estimates the frame and output buffers, [`check_memory`]
//!   adds the accumulation style's private buffers; a render that would need more than
//!   the memory available (`MemAvailable`, the memory cgroup's limit, `RLIMIT_AS`:
//!   [`flowlight_scene::memory`]) is refused before allocating.
//!
//! # Accumulation
//!
//! Units feed the frame in one of three styles ([`crate::accumulation`]): Blasting (a buffer
//! per unit), Buffering (a whole-image buffer per thread) or Caching (capped micro-tile
//! caches per thread). Every pass, whole or cut, adds to the same frame: in exact precision
//! the sums are integers, so no pass needs a buffer of its own.

use crate::accumulation::{
    FlushCounts, Frame, MicroTileCache, Precision, SharedFrame, Style, ThreadBuffer,
    TileAccumulator,
};
use crate::intersector::{Intersector, StopSignal, UnitTracer};
use crate::plugin::{IntegratorInstance, PluginError};
use flowlight_scene::Scene;
use flowlight_sdk::{AccumulationStyle, Accumulator, WorkUnit};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How much to render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel; ignored when `time` is set.
    pub spp: u32,
    /// Index of the first sample: the render computes samples
    /// [`sample_begin`, `sample_begin` + `spp`) of every pixel (a part of a distributed
    /// render, [`crate::parts`]); 0 for a whole render.
    pub sample_begin: u32,
    /// Wall-clock budget: passes are started until it runs out.
    pub time: Option<Duration>,
    /// Threads in the pool (0: one per core).
    pub threads: usize,
    pub tile_size: u32,
    pub seed: u64,
    /// Accumulation style; `None` lets the host choose from the integrator's request
    /// ([`choose_style`]).
    pub accumulation: Option<Style>,
    /// The frame's number format.
    pub precision: Precision,
    /// Caching: bytes of all threads' micro-tile caches together.
    pub cache_bytes: u64,
    /// Blasting: the flange of each unit's buffer in pixels; `None` the integrator's
    /// (`u32::MAX` covers the screen).
    pub flange: Option<u32>,
}

impl RenderOptions {
    /// Options for `spp` samples of a `width` × `height` image with the defaults for
    /// everything else (32-pixel tiles, seed 0, all cores, the host's choice of style, exact
    /// precision, a [`DEFAULT_CACHE_MIB`] MiB cache).
    pub fn new(width: u32, height: u32, spp: u32) -> RenderOptions {
        RenderOptions {
            width,
            height,
            spp,
            sample_begin: 0,
            time: None,
            threads: 0,
            tile_size: 32,
            seed: 0,
            accumulation: None,
            precision: Precision::Exact,
            cache_bytes: DEFAULT_CACHE_MIB << 20,
            flange: None,
        }
    }
}

/// Default of `render.accumulation_cache_mib`.
pub const DEFAULT_CACHE_MIB: u64 = 16;

/// The style the host uses when the config does not force one: Blasting for integrators
/// whose deposits stay in their tile, Caching for flanged ones (Markov chains), whose
/// deposits wander and whose memory must not grow with threads and layers.
pub fn choose_style(requested: AccumulationStyle) -> Style {
    match requested {
        AccumulationStyle::Tile => Style::Blasting,
        AccumulationStyle::FlangedTile => Style::Caching,
    }
}

/// What a render's accumulation did and cost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AccumulationReport {
    pub style: Style,
    pub precision: Precision,
    /// Bytes of the frame (framebuffers and sample counts).
    pub frame_bytes: u64,
    /// Most bytes of private buffers held at once: for Caching and Buffering what the
    /// threads allocated, for Blasting the largest unit buffer times the threads.
    pub private_bytes: u64,
    pub counts: FlushCounts,
}

/// Counters of a finished (or stopped) render.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub wall: Duration,
    pub threads: usize,
    /// Completed camera samples (pixel × sample).
    pub pixel_samples: u64,
    pub closest_rays: u64,
    pub shadow_rays: u64,
    /// NaN/Inf/negative deposits: counted, never written.
    pub invalid_deposits: u64,
    pub stray_deposits: u64,
    pub units: u64,
    /// True when the render stopped before its budget (Ctrl-C or a plugin error).
    pub interrupted: bool,
    /// Passes every tile finished.
    pub full_passes: u32,
    /// A flanged integrator's pass that the budget or Ctrl-C cut: kept, and the image
    /// normalised by `full_passes + finished/tiles` passes (module documentation).
    pub partial_pass: Option<PartialPass>,
    /// When the last work unit started, measured from the start of the render (the clock
    /// the budget runs on): never after the budget.
    pub last_unit_start: Option<Duration>,
    /// The integrator's own counters (declared on its `StatsBuilder`), merged over units,
    /// ratios resolved, in declaration order.
    pub integrator: Vec<(String, f64)>,
    /// The accumulation style, its memory and its flushes (`None` before any render).
    pub accumulation: Option<AccumulationReport>,
}

/// The finished part of a cut pass: the first `finished` of its `tiles` tiles in their
/// random order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartialPass {
    pub finished: u32,
    pub tiles: u32,
}

impl PartialPass {
    /// m/n: the probability with which each tile's deposits are in the image.
    pub fn fraction(&self) -> f64 {
        self.finished as f64 / self.tiles.max(1) as f64
    }
}

impl RenderStats {
    pub fn rays(&self) -> u64 {
        self.closest_rays + self.shadow_rays
    }
}

/// Progress reported after each finished unit.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub pixel_samples: u64,
    /// Total planned pixel samples, or 0 for a time budget.
    pub planned: u64,
    pub elapsed: Duration,
    pub budget: Option<Duration>,
}

/// What a render produced; `error` is set when a plugin failed, in which case `frame` still
/// holds every unit finished before it.
pub struct RenderOutcome {
    pub frame: Frame,
    pub stats: RenderStats,
    pub error: Option<PluginError>,
}

/// Threads per core beyond which `threads` is clamped.
pub const MAX_THREADS_PER_CORE: usize = 4;

/// Side of the tiles of a flanged integrator under a time budget. Small, so that the units in
/// flight at the deadline finish soon (a unit's chains cost about M mutations per camera sample
/// with the per-tile quantum); not smaller, because each unit has a fixed cost (its quantum, its
/// flow's buffers and statistics, its micro-tile cache traffic). Measured while other jobs
/// loaded the machine, ERPT reached 6% (narrow gap) and 15% (Cornell box) more samples in 4 s
/// with 8×8 units than with 4×4 ones; a later fixed-spp check found no measurable difference
/// between 8×8 and 64×64 units, so the gain over 4×4 is unconfirmed.
pub const FLANGED_TIME_TILE: u32 = 8;

/// Passes a tile-local integrator's round holds under a time budget: units past the
/// deadline are skipped, so a round only bounds how many unit slots a stopped render walks
/// through.
pub const TIMED_PASSES_PER_ROUND: usize = 16;

/// Passes a tile-local integrator's round holds without a time budget: every pass of any
/// usual render (1024 passes are over 16k samples per pixel), while a huge `spp` does not
/// make the round's per-pass counters huge (one barrier per 1024 passes costs nothing).
pub const PASSES_PER_ROUND: usize = 1024;

/// The passes of one round, as (first sample, samples), from sample `begin` towards `end`:
/// at most `most` of them, the first of `pass_spp` samples. Returns them with the sample and
/// the pass size the next round starts from.
///
/// Short passes first for a quick first look at every tile, then longer ones to amortise
/// scheduling: a tile-local integrator's passes double up to 16 samples. Deposits of a
/// flanged unit land in its neighbours too: a pass stopped half-way would leave them
/// normalised by their own (smaller) sample counts, so such integrators (`tiled` false) keep
/// one-sample passes and a stop costs at most that imbalance.
fn round_passes(
    mut begin: u32,
    end: u32,
    mut pass_spp: u32,
    most: usize,
    tiled: bool,
) -> (Vec<(u32, u32)>, u32, u32) {
    let mut passes = Vec::new();
    while begin < end && passes.len() < most {
        let count = pass_spp.min(end - begin);
        passes.push((begin, count));
        begin += count;
        if tiled {
            pass_spp = (pass_spp * 2).min(16);
        }
    }
    (passes, begin, pass_spp)
}

/// The pool size for `requested` threads (0: one per core), clamped to
/// [`MAX_THREADS_PER_CORE`] × the cores with a warning.
///
/// `FLOWLIGHT_OVERSUBSCRIBE=1` in the environment lifts the clamp, for benchmarks that
/// measure what many threads cost (memory per accumulation style) on a smaller machine.
pub fn effective_threads(requested: usize) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let max = MAX_THREADS_PER_CORE * cores;
    if requested > max && std::env::var_os("FLOWLIGHT_OVERSUBSCRIBE").is_some_and(|v| v == "1") {
        tracing::warn!("{requested} threads on {cores} cores (FLOWLIGHT_OVERSUBSCRIBE=1)");
        return requested;
    }
    if requested > max {
        tracing::warn!(
            "{requested} threads requested on {cores} cores: clamped to {max} ({MAX_THREADS_PER_CORE} per core); more only add overhead"
        );
        max
    } else {
        requested
    }
}

/// Bytes an exact-precision `width` × `height` render with `layers` lighting layers needs
/// for its image buffers ([`frame_bytes_with`]).
pub fn frame_bytes(width: u32, height: u32, layers: u32) -> Option<u64> {
    frame_bytes_with(width, height, layers, Precision::Exact)
}

/// Bytes a `width` × `height` render with `layers` lighting layers needs for its image
/// buffers, or `None` beyond 2⁶⁴: per pixel, the frame (per framebuffer 48 B of fixed-point
/// RGB sums, or 12 B of f32, plus a u32 sample count) and at write time the resolved f32
/// images, the EXR channel copies and encoded data (12 B each per framebuffer) and 3 B of
/// PNG: (c + 36)·(1 + L) + 7 bytes for c bytes per frame cell. Private buffers (Buffering's
/// thread buffers, Caching's cap) come on top ([`check_memory`]).
pub fn frame_bytes_with(width: u32, height: u32, layers: u32, precision: Precision) -> Option<u64> {
    let planes = (layers as u64).checked_add(1)?;
    let per_pixel = (precision.frame_cell_bytes() + 36)
        .checked_mul(planes)?
        .checked_add(7)?;
    (width as u64)
        .checked_mul(height as u64)?
        .checked_mul(per_pixel)
}

/// The bytes this process may still allocate: the least of the host's `MemAvailable`, the
/// room under its memory cgroup's limit (v2 `memory.max`, v1 `memory.limit_in_bytes`) and
/// the address space left under `RLIMIT_AS` ([`flowlight_scene::memory`]).
pub fn available_memory() -> Option<u64> {
    flowlight_scene::memory::available_memory()
}

fn human_bytes(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b as f64;
    let mut i = 0;
    while v >= 1024.0 && i + 1 < units.len() {
        v /= 1024.0;
        i += 1;
    }
    format!("{v:.1} {}", units[i])
}

/// Refuses an exact-precision render whose image buffers ([`frame_bytes`]) exceed the
/// available memory (or the address space), before anything is allocated.
pub fn check_frame_memory(width: u32, height: u32, layers: u32) -> Result<(), String> {
    check_memory(width, height, layers, Precision::Exact, 0)
}

/// Refuses a render whose image buffers ([`frame_bytes_with`]) and `private` bytes of
/// accumulation buffers exceed the available memory (or the address space).
pub fn check_memory(
    width: u32,
    height: u32,
    layers: u32,
    precision: Precision,
    private: u64,
) -> Result<(), String> {
    let what = format!("a {width}x{height} image with {layers} lighting layers");
    let Some(need) = frame_bytes_with(width, height, layers, precision)
        .and_then(|b| b.checked_add(private))
        .filter(|&b| b <= isize::MAX as u64)
    else {
        return Err(format!(
            "{what} needs more than {} bytes of buffers, beyond this machine's address space; lower render.width/render.height",
            isize::MAX
        ));
    };
    if let Some(avail) = available_memory() {
        if need > avail {
            let hint = if private > need / 2 {
                "; use render.accumulation = \"caching\" or fewer threads"
            } else if precision == Precision::Exact {
                "; lower render.width/render.height, or set render.precision = \"f32\" (a quarter of the frame)"
            } else {
                "; lower render.width/render.height"
            };
            return Err(format!(
                "{what} needs about {} ({need} bytes) of buffers but {} is available{hint}",
                human_bytes(need),
                human_bytes(avail)
            ));
        }
    }
    Ok(())
}

/// Uniform integer in [0, `bound`) (Lemire's multiply-shift with rejection: exact).
fn below(rng: &mut flowlight_core::rng::Rng, bound: u32) -> u32 {
    let threshold = bound.wrapping_neg() % bound;
    loop {
        let m = rng.next_u32() as u64 * bound as u64;
        if (m as u32) >= threshold {
            return (m >> 32) as u32;
        }
    }
}

/// The order in which pass `pass` of a render seeded `seed` visits its `n` tiles: a
/// uniformly random permutation (Fisher–Yates), the same for the same seed and pass.
pub fn tile_order(n: usize, seed: u64, pass: u32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let mut rng = flowlight_core::rng::Rng::new(
        flowlight_core::rng::Rng::hash(&[seed, pass as u64, 0x7469_6c65]),
        0x6f72_6465,
    );
    for i in (1..n).rev() {
        let j = below(&mut rng, i as u32 + 1) as usize;
        order.swap(i, j);
    }
    order
}

fn tiles(width: u32, height: u32, size: u32) -> Vec<(u32, u32, u32, u32)> {
    let size = size.max(1);
    let mut out = Vec::new();
    for y0 in (0..height).step_by(size as usize) {
        for x0 in (0..width).step_by(size as usize) {
            out.push((x0, y0, (x0 + size).min(width), (y0 + size).min(height)));
        }
    }
    out
}

/// A worker thread's private accumulator for Buffering or Caching, made at its first unit.
enum ThreadAccumulator<'a> {
    Buffer(ThreadBuffer),
    Cache(MicroTileCache<'a>),
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
    let style = opts
        .accumulation
        .unwrap_or_else(|| choose_style(instance.info.accumulation));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(effective_threads(opts.threads))
        .thread_name(|i| format!("flowlight-worker-{i}"))
        .build()
        .map_err(|e| format!("cannot start the thread pool: {e}"))?;
    let threads = pool.current_num_threads();
    let planes = layer_count as u64 + 1;
    let private_plan = match style {
        Style::Blasting => 0,
        Style::Buffering => (width as u64 * height as u64)
            .saturating_mul(planes * precision.partial_cell_bytes())
            .saturating_mul(threads as u64),
        Style::Caching => opts.cache_bytes,
    };
    check_memory(width, height, layer_count, precision, private_plan)?;
    let tiled = instance.info.accumulation == AccumulationStyle::Tile;
    let shared = SharedFrame::new(width, height, layer_count, precision);
    let cache_slots = MicroTileCache::slots_for(opts.cache_bytes / threads as u64, &shared);
    if style == Style::Caching && cache_slots == 0 {
        let need = MicroTileCache::slot_bytes(shared.plane_count(), precision) * threads as u64;
        return Err(format!(
            "render.accumulation_cache_mib = {:.3} MiB holds no micro-tile for {threads} threads ({} framebuffers): give it at least {:.3} MiB",
            opts.cache_bytes as f64 / 1048576.0,
            shared.plane_count(),
            need as f64 / 1048576.0
        ));
    }
    let private: Vec<Mutex<Option<ThreadAccumulator>>> =
        (0..threads).map(|_| Mutex::new(None)).collect();
    let mut tile_size = opts.tile_size.max(1);
    if opts.time.is_some() && instance.info.accumulation == AccumulationStyle::FlangedTile {
        tile_size = tile_size.min(FLANGED_TIME_TILE);
    }
    let flange = opts.flange.unwrap_or(match instance.info.accumulation {
        AccumulationStyle::Tile => 0,
        AccumulationStyle::FlangedTile => instance.info.flange,
    });
    let tiles = tiles(width, height, tile_size);
    let start = Instant::now();
    let specs = instance.stat_specs();
    let (closest_prepare_rays, shadow_prepare_rays);
    let merged_stats = Mutex::new(vec![0.0f64; specs.len()]);
    {
        let mut tracer = UnitTracer::new(scene, intersector);
        if let Err(e) = instance.prepare_once(&tracer.table()) {
            return Ok(RenderOutcome {
                frame: Frame::with_precision(width, height, layer_count, precision),
                stats: RenderStats {
                    interrupted: true,
                    ..Default::default()
                },
                error: Some(e),
            });
        }
        closest_prepare_rays = tracer.counts.closest;
        shadow_prepare_rays = tracer.counts.shadow;
    }
    let deadline = opts.time.map(|t| start + t);
    let planned = if opts.time.is_some() {
        0
    } else {
        opts.spp as u64 * width as u64 * height as u64
    };

    let done = AtomicU64::new(0);
    let closest = AtomicU64::new(0);
    let shadow = AtomicU64::new(0);
    let invalid = AtomicU64::new(0);
    let stray = AtomicU64::new(0);
    let units = AtomicU64::new(0);
    let blast_bytes = AtomicU64::new(0);
    let error: Mutex<Option<PluginError>> = Mutex::new(None);
    let halted = AtomicBool::new(false);
    let out_of_time = || deadline.is_some_and(|d| Instant::now() >= d);
    // Nanoseconds after `start` at which the last unit started (+1, so 0 means none did).
    let last_start = AtomicU64::new(0);

    let mut sample_begin = opts.sample_begin;
    let sample_end = opts.sample_begin.saturating_add(opts.spp);
    let mut pass_spp = 1u32;
    let mut passes_done = 0u32;
    let mut partial_pass = None;
    // Samples per pixel the flanged image is normalised by: s per whole pass, s·m/n for a
    // cut one.
    let mut uniform_spp = 0.0f64;
    pool.install(|| loop {
        let remaining = if opts.time.is_some() {
            u32::MAX
        } else {
            sample_end - sample_begin
        };
        if remaining == 0
            || stop.load(Ordering::Relaxed)
            || halted.load(Ordering::Relaxed)
            || out_of_time()
        {
            break;
        }
        // The passes of this round, as (first sample, samples): one for a flanged integrator,
        // a run of them for a tile-local one (module documentation).
        let passes_per_round = if !tiled {
            1
        } else if opts.time.is_some() {
            TIMED_PASSES_PER_ROUND
        } else {
            PASSES_PER_ROUND
        };
        let round_end = sample_begin.saturating_add(remaining);
        let passes;
        (passes, sample_begin, pass_spp) =
            round_passes(sample_begin, round_end, pass_spp, passes_per_round, tiled);
        let skipped = AtomicBool::new(false);
        let round_done = AtomicU64::new(0);
        let pass_units: Vec<AtomicU64> = passes.iter().map(|_| AtomicU64::new(0)).collect();
        // Flanged passes take their tiles in a random order, so that a cut keeps a uniformly
        // random subset (module documentation); tile-local ones in scan order.
        let order = if tiled {
            (0..tiles.len()).collect()
        } else {
            tile_order(tiles.len(), opts.seed, passes_done)
        };
        let next = AtomicUsize::new(0);
        let round_units = tiles.len() * passes.len();
        (0..round_units).into_par_iter().for_each(|_| {
            // The budget and Ctrl-C stop every integrator between units: no unit starts after
            // the deadline; the units in flight finish.
            let now = Instant::now();
            if stop.load(Ordering::Relaxed)
                || halted.load(Ordering::Relaxed)
                || deadline.is_some_and(|d| now >= d)
            {
                skipped.store(true, Ordering::Relaxed);
                return;
            }
            // One fetch per closure call and as many calls as units: always in range. The
            // units that start are the first ones of the round, pass by pass in `order`.
            let k = next.fetch_add(1, Ordering::Relaxed);
            let pass = k / tiles.len();
            let (sample_begin, count) = passes[pass];
            let (x0, y0, x1, y1) = tiles[order[k % tiles.len()]];
            last_start.fetch_max(
                (now - start).as_nanos().min(u64::MAX as u128 - 1) as u64 + 1,
                Ordering::Relaxed,
            );
            let unit = WorkUnit {
                x0,
                y0,
                x1,
                y1,
                sample_begin,
                sample_count: count,
                seed: opts.seed,
            };
            // The plugin may ask whether to stop inside a long unit (ERPT's chains): a
            // Blasting unit then ends early and its tile is discarded, as if it had not
            // started; a Buffering or Caching unit's deposits are already shared, so it is
            // kept as a finished unit with the chains it ran.
            let mut tracer = UnitTracer::new(scene, intersector).with_stop(StopSignal {
                interrupt: stop,
                deadline,
            });
            let mut unit_stats = vec![0.0f64; specs.len()];
            let (result, counts) = if style == Style::Blasting {
                let mut tile = TileAccumulator::with_precision(
                    (x0, y0, x1, y1),
                    flange,
                    (width, height),
                    layer_count,
                    precision,
                );
                blast_bytes.fetch_max(tile.bytes(), Ordering::Relaxed);
                let result =
                    instance.render(&unit, &tracer.table(), &tile.table(), &mut unit_stats);
                if result.is_ok() && !tracer.stop_answered {
                    shared.merge_tile(&tile, count);
                }
                (result, tile.counts)
            } else {
                // The pool's threads are 0..threads; each owns its slot, so the lock is
                // never contended.
                let me = rayon::current_thread_index().unwrap_or(0) % threads;
                let mut slot = private[me].lock().unwrap_or_else(|e| e.into_inner());
                let acc = slot.get_or_insert_with(|| match style {
                    Style::Buffering => ThreadAccumulator::Buffer(ThreadBuffer::new(
                        width,
                        height,
                        layer_count,
                        precision,
                    )),
                    _ => ThreadAccumulator::Cache(MicroTileCache::new(&shared, cache_slots)),
                });
                let (result, counts) = match acc {
                    ThreadAccumulator::Buffer(b) => {
                        let r =
                            instance.render(&unit, &tracer.table(), &b.table(), &mut unit_stats);
                        (r, std::mem::take(&mut b.counts))
                    }
                    ThreadAccumulator::Cache(c) => {
                        let r =
                            instance.render(&unit, &tracer.table(), &c.table(), &mut unit_stats);
                        (r, std::mem::take(&mut c.counts))
                    }
                };
                if result.is_ok() {
                    shared.add_samples((x0, y0, x1, y1), count);
                }
                (result, counts)
            };
            closest.fetch_add(tracer.counts.closest, Ordering::Relaxed);
            shadow.fetch_add(tracer.counts.shadow, Ordering::Relaxed);
            invalid.fetch_add(counts.invalid, Ordering::Relaxed);
            stray.fetch_add(counts.stray, Ordering::Relaxed);
            if let Err(e) = result {
                halted.store(true, Ordering::Relaxed);
                skipped.store(true, Ordering::Relaxed);
                error.lock().unwrap().get_or_insert(e);
                return;
            }
            if tracer.stop_answered && style == Style::Blasting {
                // Abandoned and discarded: the pass is cut before this unit.
                skipped.store(true, Ordering::Relaxed);
                return;
            }
            if !specs.is_empty() {
                flowlight_sdk::stats::merge(specs, &mut merged_stats.lock().unwrap(), &unit_stats);
            }
            units.fetch_add(1, Ordering::Relaxed);
            pass_units[pass].fetch_add(1, Ordering::Relaxed);
            let pixels = (x1 - x0) as u64 * (y1 - y0) as u64;
            let d = pixels * count as u64;
            let p = round_done.fetch_add(d, Ordering::Relaxed) + d;
            progress(&Progress {
                pixel_samples: done.load(Ordering::Relaxed) + p,
                planned,
                elapsed: start.elapsed(),
                budget: opts.time,
            });
        });
        let whole = !skipped.load(Ordering::Relaxed);
        if !tiled {
            // Whole or cut, the pass is in the image; a cut one counts m/n of its samples.
            let count = passes[0].1;
            if whole {
                uniform_spp += count as f64;
            } else {
                let cut = PartialPass {
                    finished: pass_units[0].load(Ordering::Relaxed) as u32,
                    tiles: tiles.len() as u32,
                };
                uniform_spp += count as f64 * cut.fraction();
                partial_pass = Some(cut);
            }
        }
        done.fetch_add(round_done.load(Ordering::Relaxed), Ordering::Relaxed);
        // A pass is whole when every one of its units finished (units start in order, so a
        // stop cuts one pass and leaves the later ones empty).
        passes_done += pass_units
            .iter()
            .filter(|u| u.load(Ordering::Relaxed) == tiles.len() as u64)
            .count() as u32;
    });

    // Buffering and Caching flush what the threads still hold (a failed unit's partial
    // deposits too: a render a plugin failed is reported, never written).
    let mut private_bytes = blast_bytes.load(Ordering::Relaxed) * threads as u64;
    for slot in private {
        match slot.into_inner().unwrap_or_else(|e| e.into_inner()) {
            Some(ThreadAccumulator::Buffer(b)) => {
                private_bytes += b.bytes();
                b.flush_into(&shared);
            }
            Some(ThreadAccumulator::Cache(mut c)) => {
                private_bytes += c.bytes();
                c.flush();
            }
            None => {}
        }
    }
    let error = error.into_inner().unwrap();
    let pixel_samples = done.load(Ordering::Relaxed);
    let interrupted = error.is_some()
        || (opts.time.is_none() && pixel_samples < planned)
        || (opts.time.is_some() && stop.load(Ordering::Relaxed));
    let flush_counts = shared.counts();
    let mut frame = shared.into_frame();
    if !tiled {
        frame.set_uniform_spp(uniform_spp);
    }
    if pixel_samples == 0 && error.is_none() && !stop.load(Ordering::Relaxed) {
        tracing::warn!(
            "no work unit started inside the time budget (the integrator's preparation used it up): the image is black; give it more time"
        );
    }
    let last_start = last_start.load(Ordering::Relaxed);
    let stats = RenderStats {
        wall: start.elapsed(),
        threads,
        pixel_samples,
        closest_rays: closest.load(Ordering::Relaxed) + closest_prepare_rays,
        shadow_rays: shadow.load(Ordering::Relaxed) + shadow_prepare_rays,
        invalid_deposits: invalid.load(Ordering::Relaxed),
        stray_deposits: stray.load(Ordering::Relaxed),
        units: units.load(Ordering::Relaxed),
        interrupted,
        full_passes: passes_done,
        partial_pass,
        last_unit_start: (last_start > 0).then(|| Duration::from_nanos(last_start - 1)),
        // SAFETY: the specs' names are the instance's, which outlives this call.
        integrator: unsafe {
            flowlight_sdk::stats::resolve(specs, &merged_stats.into_inner().unwrap())
        },
        accumulation: Some(AccumulationReport {
            style,
            precision,
            frame_bytes: frame.bytes(),
            private_bytes,
            counts: flush_counts,
        }),
    };
    Ok(RenderOutcome {
        frame,
        stats,
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 17,000 samples of a tile-local integrator are passes of 1, 2, 4, 8, then 16 samples
    /// and a last one of 9: 1066 passes, so two rounds of at most [`PASSES_PER_ROUND`]. A
    /// flanged integrator's passes stay at one sample each; an empty range has no pass.
    #[test]
    fn rounds_split_the_passes_and_continue_where_the_last_stopped() {
        let (first, next, spp) = round_passes(0, 17_000, 1, PASSES_PER_ROUND, true);
        assert_eq!(first.len(), PASSES_PER_ROUND);
        assert_eq!(first[..5], [(0, 1), (1, 2), (3, 4), (7, 8), (15, 16)]);
        assert_eq!((next, spp), (15 + 16 * 1020, 16));
        let (second, end, _) = round_passes(next, 17_000, spp, PASSES_PER_ROUND, true);
        assert_eq!(second.len(), 1066 - PASSES_PER_ROUND);
        assert_eq!(second.first(), Some(&(next, 16)));
        assert_eq!(second.last(), Some(&(16_991, 9)));
        assert_eq!(end, 17_000);
        // Contiguous and complete: every sample once.
        let all: Vec<_> = first.iter().chain(&second).collect();
        assert!(all.windows(2).all(|w| w[0].0 + w[0].1 == w[1].0));
        assert_eq!(all.iter().map(|p| p.1).sum::<u32>(), 17_000);

        let (flanged, next, spp) = round_passes(5, 8, 1, 16, false);
        assert_eq!((flanged, next, spp), (vec![(5, 1), (6, 1), (7, 1)], 8, 1));
        let (one, _, _) = round_passes(0, 100, 1, 1, false);
        assert_eq!(one, [(0, 1)]);
        assert!(round_passes(9, 9, 4, 16, true).0.is_empty());
    }

    #[test]
    fn frame_bytes_counts_frame_and_output_buffers_without_overflow() {
        // Per pixel: (48 + 36)·(1 + L) + 4 + 3 = 91 + 84L (exact), (12 + 36)·(1 + L) + 7 (f32).
        assert_eq!(frame_bytes(1, 1, 0), Some(91));
        assert_eq!(frame_bytes(512, 512, 9), Some(512 * 512 * (91 + 84 * 9)));
        assert_eq!(
            frame_bytes_with(512, 512, 9, Precision::F32),
            Some(512 * 512 * (55 + 48 * 9))
        );
        assert_eq!(frame_bytes(100_000, 100_000, 0), Some(910_000_000_000));
        assert_eq!(frame_bytes(u32::MAX, u32::MAX, 0), None);
        // 4294967295 · (91 + 84·4294967295) > 2⁶⁴.
        assert_eq!(frame_bytes(u32::MAX, 1, u32::MAX), None);
        assert_eq!(
            frame_bytes(u32::MAX, 1, 1000),
            Some(4_294_967_295 * (84 * 1001 + 7))
        );
        let e = check_frame_memory(u32::MAX, u32::MAX, 3).unwrap_err();
        assert!(
            e.contains("4294967295x4294967295") && e.contains("3 lighting layers"),
            "{e}"
        );
        assert!(check_frame_memory(64, 64, 2).is_ok());
        // Private buffers count: a Buffering plan beyond the machine names the way out.
        let e = check_memory(64, 64, 2, Precision::F32, u64::MAX / 4).unwrap_err();
        assert!(e.contains("render.accumulation = \"caching\""), "{e}");
        let e = check_memory(64, 64, 2, Precision::F32, u64::MAX).unwrap_err();
        assert!(e.contains("address space"), "{e}");
    }

    #[test]
    fn threads_are_clamped_to_four_per_core() {
        let cores = std::thread::available_parallelism().unwrap().get();
        assert_eq!(effective_threads(0), 0);
        assert_eq!(effective_threads(cores), cores);
        assert_eq!(effective_threads(4 * cores), 4 * cores);
        assert_eq!(effective_threads(4 * cores + 1), 4 * cores);
        assert_eq!(effective_threads(usize::MAX), 4 * cores);
    }

    #[test]
    fn tile_orders_are_uniform_permutations_fixed_by_seed_and_pass() {
        let n = 4;
        assert_eq!(tile_order(n, 1, 0), tile_order(n, 1, 0));
        assert_ne!(tile_order(64, 1, 0), tile_order(64, 1, 1));
        assert_ne!(tile_order(64, 1, 0), tile_order(64, 2, 0));
        // Each tile is in each position with probability 1/n, so a cut after m tiles keeps
        // each tile with probability m/n: count over many passes.
        let trials = 24_000u32;
        let mut at = [[0u32; 4]; 4];
        for pass in 0..trials {
            let o = tile_order(n, 7, pass);
            let mut sorted = o.clone();
            sorted.sort();
            assert_eq!(sorted, (0..n).collect::<Vec<_>>());
            for (pos, &t) in o.iter().enumerate() {
                at[t][pos] += 1;
            }
        }
        let expected = trials as f64 / n as f64;
        // Binomial standard deviation sqrt(N p (1 − p)) = 67; allow 5 of them.
        for row in at {
            for c in row {
                assert!((c as f64 - expected).abs() < 5.0 * 67.1, "{at:?}");
            }
        }
        // Lemire's bounded draw is uniform even for a bound that does not divide 2³².
        let mut rng = flowlight_core::rng::Rng::new(3, 3);
        let mut hist = [0u32; 3];
        for _ in 0..30_000 {
            hist[below(&mut rng, 3) as usize] += 1;
        }
        assert!(
            hist.iter()
                .all(|&h| (h as f64 - 10_000.0).abs() < 5.0 * 81.7),
            "{hist:?}"
        );
    }

    #[test]
    fn tiles_cover_the_image_once() {
        let t = tiles(70, 33, 32);
        assert_eq!(t.len(), 3 * 2);
        let area: u32 = t
            .iter()
            .map(|&(x0, y0, x1, y1)| (x1 - x0) * (y1 - y0))
            .sum();
        assert_eq!(area, 70 * 33);
    }
}
