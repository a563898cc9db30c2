//! Caching never holds more than its cap (docs/config.md, "Accumulation"): a counting global
//! allocator watches every byte this test binary allocates while four threads deposit
//! chain-like streams over a whole 1080p-wide film with eight lighting layers, touching far
//! more micro-tiles than the cap holds. One test per binary, so no other test's allocations are
//! counted.

use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::accumulation::{MicroTileCache, Precision, SharedFrame, MICRO_TILE};
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;

static LIVE: AtomicU64 = AtomicU64::new(0);
static PEAK: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live =
                LIVE.fetch_add(layout.size() as u64, Ordering::SeqCst) + layout.size() as u64;
            PEAK.fetch_max(live, Ordering::SeqCst);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        LIVE.fetch_sub(layout.size() as u64, Ordering::SeqCst);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn caching_never_holds_more_than_its_cap_whatever_the_threads() {
    let (w, h, layers) = (1920u32, 240u32, 8u32);
    let threads = 4u64;
    let cap: u64 = 2 << 20;
    for precision in [Precision::F32, Precision::Exact] {
        let shared = SharedFrame::new(w, h, layers, precision);
        let slots = MicroTileCache::slots_for(cap / threads, &shared);
        let slot_bytes = MicroTileCache::slot_bytes(layers as usize + 1, precision);
        assert!(slots >= 1);
        // Everything allocated from here on but the frame is the caches' (and a few
        // hundred bytes of thread handles and each thread's one batch of deposits).
        let base = LIVE.load(Ordering::SeqCst);
        PEAK.store(base, Ordering::SeqCst);
        let touched = AtomicU64::new(0);
        std::thread::scope(|s| {
            for t in 0..threads {
                let (shared, touched) = (&shared, &touched);
                s.spawn(move || {
                    let mut cache = MicroTileCache::new(shared, slots);
                    let mut rng = Rng::new(Rng::hash(&[t, 9]), 1);
                    let mut batch = Vec::with_capacity(256);
                    let mut seen = 0u64;
                    for chain in 0..400 {
                        // Chains start anywhere and random-walk: 400 chains of 200 steps.
                        let mut x = rng.uniform() * w as f32;
                        let mut y = rng.uniform() * h as f32;
                        for _ in 0..200 {
                            x = (x + (rng.uniform() - 0.5) * 12.0).clamp(0.0, w as f32 - 0.5);
                            y = (y + (rng.uniform() - 0.5) * 12.0).clamp(0.0, h as f32 - 0.5);
                            batch.push(Deposit {
                                x,
                                y,
                                layer: chain % (layers + 1),
                                value: Rgb::splat(0.01),
                            });
                            if batch.len() == 256 {
                                cache.deposit(&batch);
                                batch.clear();
                            }
                        }
                        seen += 1;
                    }
                    cache.deposit(&batch);
                    assert!(cache.bytes() <= cap / threads);
                    cache.flush();
                    touched.fetch_add(seen, Ordering::Relaxed);
                });
            }
        });
        let peak = PEAK.load(Ordering::SeqCst) - base;
        // Thread handles and the deposit batches (256 × 20 B per thread): 64 KiB at most.
        let slack = 64 << 10;
        assert!(
            peak <= cap + slack,
            "{precision:?}: the caches peaked at {peak} B over a cap of {cap} B"
        );
        // The cap binds: the chains visit many times the micro-tiles it holds.
        let tiles = (w / MICRO_TILE) as u64 * (h / MICRO_TILE) as u64;
        assert!(tiles * slot_bytes > 8 * cap, "{tiles} micro-tiles");
        assert!(
            peak > cap / 2,
            "{precision:?}: {peak} B: the caches were not even filled"
        );
        // And nothing was lost: 4 threads × 400 chains × 200 deposits of 0.01 in the main image.
        let frame = shared.into_frame();
        let total: f64 = (0..(w * h) as usize).map(|i| frame.sum(0, i)[0]).sum();
        let want = (threads * 400 * 200) as f64 * 0.01f32 as f64;
        assert!((total / want - 1.0).abs() < 1e-6, "{total} vs {want}");
        assert_eq!(touched.load(Ordering::Relaxed), threads * 400);
    }
}
