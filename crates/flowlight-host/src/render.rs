//! The scheduler: splits the image into tiles and passes of samples, runs the work units on
//! the host's one rayon pool, merges finished tiles, and stops cleanly when asked.

use crate::film::{Frame, TileAccumulator};
use crate::intersector::{Intersector, UnitTracer};
use crate::plugin::{IntegratorInstance, PluginError};
use flowlight_scene::Scene;
use flowlight_sdk::integrator::STAT_SLOTS;
use flowlight_sdk::{AccumulationStyle, Accumulator, StatMerge, StatSpec, WorkUnit};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How much to render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel; ignored when `time` is set.
    pub spp: u32,
    /// Wall-clock budget: passes are started until it runs out.
    pub time: Option<Duration>,
    /// Threads in the pool (0: one per core).
    pub threads: usize,
    pub tile_size: u32,
    pub seed: u64,
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
    /// The integrator's own counters (declared in its `IntegratorInfo`), merged over units,
    /// ratios resolved, in declaration order.
    pub integrator: Vec<(String, f64)>,
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
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .thread_name(|i| format!("flowlight-worker-{i}"))
        .build()
        .map_err(|e| format!("cannot start the thread pool: {e}"))?;
    let threads = pool.current_num_threads();
    let layer_count = instance.info.layer_count;
    let frame = Mutex::new(Frame::new(width, height, layer_count));
    // Integrators whose deposits stay in fixed K×K squares ask for tiles aligned to K.
    let multiple = instance.info.tile_multiple.max(1);
    let tile_size = opts.tile_size.max(1).div_ceil(multiple) * multiple;
    let tiles = tiles(width, height, tile_size);
    let specs = instance.stat_specs();
    let (closest_prepare_rays, shadow_prepare_rays);
    let merged_stats = Mutex::new(vec![0.0f64; specs.len()]);
    {
        let mut tracer = UnitTracer::new(scene, intersector);
        if let Err(e) = instance.prepare_once(&tracer.table()) {
            return Ok(RenderOutcome {
                frame: Frame::new(width, height, instance.info.layer_count),
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
    let start = Instant::now();
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
    let error: Mutex<Option<PluginError>> = Mutex::new(None);
    let halted = AtomicBool::new(false);
    let out_of_time = || deadline.is_some_and(|d| Instant::now() >= d);

    let tiled = instance.info.accumulation == AccumulationStyle::Tile;
    let mut sample_begin = 0u32;
    let mut pass_spp = 1u32;
    pool.install(|| loop {
        let remaining = if opts.time.is_some() {
            u32::MAX
        } else {
            opts.spp - sample_begin
        };
        if remaining == 0
            || stop.load(Ordering::Relaxed)
            || halted.load(Ordering::Relaxed)
            || out_of_time()
        {
            break;
        }
        let count = pass_spp.min(remaining);
        tiles.par_iter().for_each(|&(x0, y0, x1, y1)| {
            // A time budget stops a tile-local integrator at any unit; a flanged one (whose units
            // deposit into their neighbours) finishes the pass, so every pixel's neighbourhood
            // has the same number of samples. Ctrl-C stops both at once.
            let budget_over = tiled && out_of_time();
            if stop.load(Ordering::Relaxed) || halted.load(Ordering::Relaxed) || budget_over {
                return;
            }
            let unit = WorkUnit {
                x0,
                y0,
                x1,
                y1,
                sample_begin,
                sample_count: count,
                seed: opts.seed,
            };
            let flange = match instance.info.accumulation {
                AccumulationStyle::Tile => 0,
                AccumulationStyle::FlangedTile => instance.info.flange,
                AccumulationStyle::FullFrame => width.max(height),
            };
            let mut tile = TileAccumulator::new(x0, y0, x1, y1, flange, width, height, layer_count);
            let mut tracer = UnitTracer::new(scene, intersector);
            let mut unit_stats = [0.0f64; STAT_SLOTS];
            let result = instance.render(&unit, &tracer.table(), &tile.table(), &mut unit_stats);
            closest.fetch_add(tracer.counts.closest, Ordering::Relaxed);
            shadow.fetch_add(tracer.counts.shadow, Ordering::Relaxed);
            if let Err(e) = result {
                halted.store(true, Ordering::Relaxed);
                error.lock().unwrap().get_or_insert(e);
                return;
            }
            invalid.fetch_add(tile.counts.invalid, Ordering::Relaxed);
            stray.fetch_add(tile.counts.stray, Ordering::Relaxed);
            frame.lock().unwrap().merge(&tile, count);
            if !specs.is_empty() {
                merge_stats(specs, &mut merged_stats.lock().unwrap(), &unit_stats);
            }
            units.fetch_add(1, Ordering::Relaxed);
            let pixels = ((x1 - x0) * (y1 - y0)) as u64;
            let d =
                done.fetch_add(pixels * count as u64, Ordering::Relaxed) + pixels * count as u64;
            progress(&Progress {
                pixel_samples: d,
                planned,
                elapsed: start.elapsed(),
                budget: opts.time,
            });
        });
        sample_begin += count;
        // Short passes first for a quick preview, then longer ones to amortise scheduling.
        // Deposits of a flanged unit land in its neighbours too: a pass stopped half-way
        // would leave them normalised by their own (smaller) sample counts, so such
        // integrators keep one-sample passes and a stop costs at most that imbalance.
        if tiled {
            pass_spp = (pass_spp * 2).min(16);
        }
    });

    let error = error.into_inner().unwrap();
    let pixel_samples = done.load(Ordering::Relaxed);
    let interrupted = error.is_some() || (opts.time.is_none() && pixel_samples < planned);
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
        integrator: resolve_stats(specs, &merged_stats.into_inner().unwrap()),
    };
    Ok(RenderOutcome {
        frame: frame.into_inner().unwrap(),
        stats,
        error,
    })
}

/// Adds one unit's counters into the running totals.
fn merge_stats(specs: &[StatSpec], total: &mut [f64], unit: &[f64]) {
    for (i, s) in specs.iter().enumerate() {
        match s.merge {
            StatMerge::Sum => total[i] += unit[i],
            StatMerge::Max => total[i] = total[i].max(unit[i]),
            StatMerge::Ratio => {}
        }
    }
}

/// Names and values of the counters, ratios computed (0 where the denominator is 0).
fn resolve_stats(specs: &[StatSpec], total: &[f64]) -> Vec<(String, f64)> {
    specs
        .iter()
        .enumerate()
        .map(|(i, s)| {
            // SAFETY: static strings of the loaded plugin.
            let name = unsafe { s.name.as_str() }.to_string();
            let value = match s.merge {
                StatMerge::Ratio => {
                    let num = total.get(s.numerator as usize).copied().unwrap_or(0.0);
                    let den = total.get(s.denominator as usize).copied().unwrap_or(0.0);
                    if den != 0.0 {
                        num / den
                    } else {
                        0.0
                    }
                }
                _ => total[i],
            };
            (name, value)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_merge_by_kind_and_ratios_resolve() {
        let specs = [
            flowlight_sdk::stat("events", StatMerge::Sum),
            flowlight_sdk::stat("longest", StatMerge::Max),
            flowlight_sdk::stat_ratio("mean", 1, 0),
        ];
        let mut total = vec![0.0; 3];
        merge_stats(&specs, &mut total, &[2.0, 5.0, 99.0]);
        merge_stats(&specs, &mut total, &[3.0, 4.0, 99.0]);
        let r = resolve_stats(&specs, &total);
        assert_eq!(r[0], ("events".to_string(), 5.0));
        assert_eq!(r[1].1, 5.0);
        assert_eq!(r[2].1, 1.0);
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
