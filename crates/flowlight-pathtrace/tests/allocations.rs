//! The bidirectional library allocates nothing per sample, and the light vertices it keeps
//! stay within their bound (`flowlight_pathtrace::bidir::render`'s module docs).
//!
//! The plugins are cdylibs with their own allocator, so a counting allocator in the host
//! would not see them: this binary installs one and calls
//! [`render_unit`] itself, over real scenes loaded and intersected by the host's code
//! (config, glTF loader, lights, Embree or the BVH), with deposits summed by an accumulator
//! of the test's. The counter is per thread: `render_unit` runs on the calling thread, and
//! the test harness's other threads (other tests) must not count.
//!
//! Per scene and technique set, on a thread of its own: one unit warms the thread's arena,
//! units of the same tile with further samples (other sample indices, so other paths) are
//! measured, fewer than one allocation per sample (a buffer may still double once), and
//! the same units rendered again must allocate nothing, with 4 samples as with 16. The
//! figures are printed (`cargo test -p flowlight-pathtrace --test
//! allocations -- --nocapture`).

mod loaded;

use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_pathtrace::bidir::params::settings_from_params;
use flowlight_pathtrace::bidir::render::{render_unit, UnitCounts};
use flowlight_pathtrace::bidir::vertex::LightVertex;
use flowlight_pathtrace::bidir::{BidirSettings, Techniques};
use flowlight_sdk::abi::{Deposit, ParamValue, StrRef};
use flowlight_sdk::{Accumulator, Film, ParamKind, Params, Scene, Tracer, WorkUnit};
use loaded::{load, LoadedScene};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting the allocations (and reallocations) of each thread.
struct CountingAllocator;

thread_local! {
    /// Allocations of this thread so far (const-initialised and without a destructor, so
    /// the allocator may read it at any time).
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count_one() {
    // During the thread's teardown the slot may be gone: those allocations are not counted.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

/// This thread's allocations so far.
fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_one();
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// Sums what is deposited (the test reads that the units rendered something).
#[derive(Default)]
struct DepositSum {
    deposits: u64,
    total: f64,
}

impl Accumulator for DepositSum {
    fn deposit(&mut self, deposits: &[Deposit]) {
        for d in deposits {
            self.deposits += 1;
            let Rgb { r, g, b } = d.value;
            self.total += f64::from(r) + f64::from(g) + f64::from(b);
        }
    }
}

/// The plugin's settings for `techniques` with the config's path depth, else the defaults.
fn settings(loaded: &LoadedScene, techniques: Techniques) -> BidirSettings {
    let depth: Vec<ParamValue> = loaded
        .path_depth
        .map(|d| ParamValue {
            name: StrRef::new("path_depth"),
            kind: ParamKind::Int,
            int: d,
            float: 0.0,
            boolean: 0,
            string: StrRef::EMPTY,
        })
        .into_iter()
        .collect();
    settings_from_params(&Params::from_slice(&depth), techniques, false).unwrap()
}

/// What one measured unit did.
struct Measured {
    allocations: u64,
    counts: UnitCounts,
    deposits: DepositSum,
}

/// Side of the measured tile, in pixels.
const TILE: u32 = 32;

/// Renders samples `begin .. begin + count` of the tile at the centre of the image on this
/// thread, counting this thread's allocations during `render_unit` alone.
fn render(loaded: &LoadedScene, settings: &BidirSettings, begin: u32, count: u32) -> Measured {
    // SAFETY: `loaded` owns what the view points into and outlives `scene`.
    let scene = unsafe { Scene::from_view(&loaded.view) };
    let mut unit_tracer = UnitTracer::new(&loaded.scene, loaded.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let (x0, y0) = ((w - TILE) / 2, (h - TILE) / 2);
    let unit = WorkUnit {
        x0,
        y0,
        x1: x0 + TILE,
        y1: y0 + TILE,
        sample_begin: begin,
        sample_count: count,
        seed: 1,
    };
    let mut deposits = DepositSum::default();
    let film_table = deposits.table();
    let mut counts = UnitCounts::default();
    let allocations = {
        let mut film = Film::new(&film_table);
        let before = allocations();
        render_unit(&scene, &tracer, settings, &unit, &mut film, &mut counts);
        let after = allocations();
        film.flush();
        after - before
    };
    Measured {
        allocations,
        counts,
        deposits,
    }
}

/// Samples of the warm-up unit.
const WARM_UP: u32 = 4;

/// The measured units: (first sample, samples), after the warm-up's.
const UNITS: [(u32, u32); 2] = [(WARM_UP, 4), (WARM_UP + 4, 16)];

/// On a thread of its own (a fresh arena and counter): warms the arena with a unit of
/// [`WARM_UP`] samples, renders [`UNITS`] (fresh sample indices: their paths may need more
/// room than the warm-up's, and a buffer then doubles), then renders the same units again,
/// which must allocate nothing at all: rendering is deterministic, so no buffer needs more
/// room than it already has, and any allocation is work done per sample or per unit. No
/// iteration may keep more than (tile pixels) × path_depth light vertices.
fn check(config: &'static str, label: &'static str, techniques: Techniques) {
    let outcome = std::thread::spawn(move || {
        let loaded = load(config);
        let settings = settings(&loaded, techniques);
        let warm = render(&loaded, &settings, 0, WARM_UP);
        let bound = u64::from(TILE * TILE) * u64::from(settings.path.path_depth);
        let fresh = UNITS.map(|(begin, count)| render(&loaded, &settings, begin, count));
        let again = UNITS.map(|(begin, count)| render(&loaded, &settings, begin, count));
        for (((begin, count), fresh), again) in UNITS.into_iter().zip(&fresh).zip(&again) {
            let what = format!("{config} {label}, samples {begin}..{}", begin + count);
            report(&what, &warm, fresh, again, count, bound);
            assert!(
                again.deposits.deposits > 0 && again.deposits.total > 0.0,
                "{what}: the unit deposited nothing"
            );
            assert_eq!(
                again.counts.light_paths,
                u64::from(TILE * TILE * count),
                "{what}: one light path per pixel sample"
            );
            assert!(
                again.counts.max_light_vertices <= bound,
                "{what}: {} light vertices in one iteration, bound {bound}",
                again.counts.max_light_vertices
            );
            if techniques.connect || techniques.merge {
                assert!(
                    again.counts.max_light_vertices > 0,
                    "{what}: no light vertex kept"
                );
            }
            assert!(
                fresh.allocations < u64::from(count),
                "{what}: {} allocations, not fewer than one per sample, after the warm-up",
                fresh.allocations
            );
            assert_eq!(
                again.allocations, 0,
                "{what}: rendered a second time, the unit allocated (per-sample or per-unit work)"
            );
        }
    })
    .join();
    if let Err(panic) = outcome {
        std::panic::resume_unwind(panic);
    }
}

/// Prints the figures of a unit rendered fresh and again.
fn report(what: &str, warm: &Measured, fresh: &Measured, again: &Measured, count: u32, bound: u64) {
    let vertex_bytes = std::mem::size_of::<LightVertex>() as u64;
    let c = &again.counts;
    println!(
        "{what} ({TILE}x{TILE} tile; warm-up unit of {WARM_UP} samples: {} allocations): \
         fresh {} allocations ({:.3} per sample), again {} ({:.3} per sample); light \
         vertices kept {} (max per iteration {} = {} KiB, bound {bound} = {} KiB); {} \
         deposits, {} connections, {} merges",
        warm.allocations,
        fresh.allocations,
        fresh.allocations as f64 / f64::from(count),
        again.allocations,
        again.allocations as f64 / f64::from(count),
        c.light_vertices,
        c.max_light_vertices,
        c.max_light_vertices * vertex_bytes / 1024,
        bound * vertex_bytes / 1024,
        again.deposits.deposits,
        c.connections,
        c.merges,
    );
}

const CORNELL: &str = "scenes/cornell-box/cornell-box.toml";
const CAUSTIC: &str = "scenes/glass-caustic/glass-caustic.toml";

#[test]
fn light_tracing_allocates_nothing_per_sample() {
    check(CORNELL, "lighttrace", Techniques::LIGHT_TRACE);
    check(CAUSTIC, "lighttrace", Techniques::LIGHT_TRACE);
}

#[test]
fn bdpt_allocates_nothing_per_sample() {
    check(CORNELL, "bdpt", Techniques::BDPT);
    check(CAUSTIC, "bdpt", Techniques::BDPT);
}

#[test]
fn vcm_allocates_nothing_per_sample() {
    check(CORNELL, "vcm", Techniques::VCM);
    check(CAUSTIC, "vcm", Techniques::VCM);
}
