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
//!   integrators with a flange (ERPT's chains) run units of at most [`FLANGED_TIME_TILE`]² pixels, so the units in flight
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

use crate::accumulation::{FlushCounts, Frame, Precision, Style};
use crate::plugin::PluginError;
use flowlight_sdk::AccumulationStyle;
use std::time::Duration;

mod memory;
mod pool;
mod schedule;
#[cfg(test)]
mod tests;

pub use memory::{
    available_memory, check_frame_memory, check_memory, frame_bytes, frame_bytes_with,
};
pub use pool::worker_pool;
pub use schedule::render;

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
    /// While a live preview reads the frame (`--tev`, `--preview-every`): Buffering and
    /// Caching move what a thread holds into the frame when one of its units ends this long
    /// after its last such flush, so that the preview shows it. `None`: a thread's buffer
    /// reaches the frame only when Caching needs room and at the end. The image is the same
    /// either way with exact sums.
    pub preview_flush: Option<Duration>,
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
            preview_flush: None,
        }
    }
}

/// Default of `render.accumulation_cache_mib`.
pub const DEFAULT_CACHE_MIB: u64 = 16;

/// Most bytes of private buffers [`choose_style`] gives Buffering: 1 GiB over all threads.
pub const AUTO_BUFFERING_MAX_BYTES: u64 = 1 << 30;

/// The style the host uses when the config does not force one, from the integrator's
/// `requested` style and `flange`, the bytes Buffering's whole-image buffers would take over
/// all threads (`buffering_bytes`) and whether they fit in the memory available
/// (`buffering_fits`, with the frame):
/// - **Blasting** for integrators whose deposits stay in their tile (path tracing);
/// - **Caching** for flanged ones with a flange (ERPT's chains, which random-walk from their
///   tile): their deposits stay near it, so the micro-tiles of a thread's unit stay cached,
///   and memory does not grow with threads and layers;
/// - **Buffering** for flanged ones without a flange (light tracing, BDPT, VCM, PSSMLT,
///   MMLT: deposits anywhere on the film) while `buffering_bytes` is at most
///   [`AUTO_BUFFERING_MAX_BYTES`] and fits, else Caching (so the host's choice never fails
///   for want of memory where Caching's cap would do). Deposits scattered over the film hit a
///   micro-tile cache smaller than the film at random, so it flushes half of itself every
///   few thousand deposits under the frame's locks: BDPT on the 512² Cornell box took 25%
///   more CPU at two threads than at one (944 flushes, a sixth of them waiting for the
///   lock), with whole-image buffers 1% more (docs/performance.md, "Target 4").
pub fn choose_style(
    requested: AccumulationStyle,
    flange: u32,
    buffering_bytes: u64,
    buffering_fits: bool,
) -> Style {
    match requested {
        AccumulationStyle::Tile => Style::Blasting,
        AccumulationStyle::FlangedTile if flange > 0 => Style::Caching,
        AccumulationStyle::FlangedTile
            if buffering_fits && buffering_bytes <= AUTO_BUFFERING_MAX_BYTES =>
        {
            Style::Buffering
        }
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
    /// The integrator's counters (declared on its `StatsBuilder`), then its mutations' as
    /// `NAME.counter`, merged over units, ratios resolved, in declaration order.
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
#[derive(Clone, Copy)]
pub struct Progress<'a> {
    pub pixel_samples: u64,
    /// Total planned pixel samples, or 0 for a time budget.
    pub planned: u64,
    pub elapsed: Duration,
    pub budget: Option<Duration>,
    /// The frame being rendered and whether its integrator's deposits stay in their tiles
    /// (read by [`Progress::image`]); `None` where there is no frame to show.
    pub(crate) frame: Option<(&'a crate::accumulation::SharedFrame, bool)>,
}

impl std::fmt::Debug for Progress<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("pixel_samples", &self.pixel_samples)
            .field("planned", &self.planned)
            .field("elapsed", &self.elapsed)
            .field("budget", &self.budget)
            .finish()
    }
}

impl Progress<'_> {
    /// The image as it stands, for a live preview (tev, `--preview-every`): a tile-local
    /// integrator's pixels over their own finished samples, a flanged one's (Markov chains
    /// deposit anywhere) over the mean samples per pixel so far. Deposits still in private
    /// buffers (Buffering, Caching) show when they are flushed
    /// ([`RenderOptions::preview_flush`]). Copies the frame under its lock: call it at a
    /// limited rate. `None` without a frame.
    pub fn image(&self) -> Option<Vec<flowlight_core::Rgb>> {
        let (shared, tiled) = self.frame?;
        let uniform = (!tiled).then(|| {
            let pixels = (shared.width as u64 * shared.height as u64).max(1);
            self.pixel_samples as f64 / pixels as f64
        });
        Some(shared.snapshot_image(uniform))
    }
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
