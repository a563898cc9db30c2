//! The three styles against each other on synthetic chain-like deposit streams: bitwise
//! equal in exact precision (any style, any number of threads, any cache size), within
//! rounding in f32 precision, and nothing lost.

use super::*;
use flowlight_core::rng::Rng;
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;

const W: u32 = 37;
const H: u32 = 29;
const TILE: u32 = 8;

fn tiles() -> Vec<(u32, u32, u32, u32)> {
    let mut t = Vec::new();
    for y0 in (0..H).step_by(TILE as usize) {
        for x0 in (0..W).step_by(TILE as usize) {
            t.push((x0, y0, (x0 + TILE).min(W), (y0 + TILE).min(H)));
        }
    }
    t
}

/// A unit's deposits: chains that start in the tile and random-walk a few pixels per step
/// (some far beyond any flange), values over six decades, layers 0..=layers (one beyond
/// the last layer: main image only), and a few invalid and off-film ones.
fn unit_deposits(unit: usize, tile: (u32, u32, u32, u32), layers: u32) -> Vec<Deposit> {
    let mut rng = Rng::new(Rng::hash(&[unit as u64, 77]), 5);
    let mut out = Vec::new();
    for _chain in 0..6 {
        let mut x = tile.0 as f32 + rng.uniform() * (tile.2 - tile.0) as f32;
        let mut y = tile.1 as f32 + rng.uniform() * (tile.3 - tile.1) as f32;
        for _step in 0..40 {
            let jump = if rng.uniform() < 0.05 { 30.0 } else { 3.0 };
            x = (x + (rng.uniform() - 0.5) * 2.0 * jump).clamp(0.0, W as f32 - 0.01);
            y = (y + (rng.uniform() - 0.5) * 2.0 * jump).clamp(0.0, H as f32 - 0.01);
            let v = 10f32.powf(rng.uniform() * 6.0 - 3.0);
            out.push(Deposit {
                x,
                y,
                layer: (rng.next_u32() % (layers + 2)).min(layers + 1),
                value: Rgb::new(v, 0.5 * v, 2.0 * v),
            });
        }
    }
    out.push(Deposit {
        x: 1.0,
        y: 1.0,
        layer: 0,
        value: Rgb::new(f32::NAN, 0.0, 0.0),
    });
    out.push(Deposit {
        x: -3.0,
        y: 1.0,
        layer: 0,
        value: Rgb::ONE,
    });
    out
}

/// Renders the synthetic units with `style` over `threads` threads (units dealt round
/// robin), each thread depositing in batches of 7 as a plugin's film would.
fn run(
    style: Style,
    precision: Precision,
    layers: u32,
    threads: usize,
    cache: u64,
) -> (Frame, FlushCounts, u64) {
    let shared = SharedFrame::new(W, H, layers, precision);
    let tiles = tiles();
    let peak = std::sync::atomic::AtomicU64::new(0);
    std::thread::scope(|s| {
        for t in 0..threads {
            let (shared, tiles, peak) = (&shared, &tiles, &peak);
            s.spawn(move || {
                let mut buffer = None;
                let mut cache_acc = None;
                for (u, &tile) in tiles.iter().enumerate().skip(t).step_by(threads) {
                    let deposits = unit_deposits(u, tile, layers);
                    match style {
                        Style::Blasting => {
                            let mut acc =
                                TileAccumulator::with_precision(tile, 2, (W, H), layers, precision);
                            for batch in deposits.chunks(7) {
                                acc.deposit(batch);
                            }
                            shared.merge_tile(&acc, 1);
                        }
                        Style::Buffering => {
                            let acc = buffer
                                .get_or_insert_with(|| ThreadBuffer::new(W, H, layers, precision));
                            for batch in deposits.chunks(7) {
                                acc.deposit(batch);
                            }
                            shared.add_samples(tile, 1);
                        }
                        Style::Caching => {
                            let slots = MicroTileCache::slots_for(cache, shared);
                            let acc =
                                cache_acc.get_or_insert_with(|| MicroTileCache::new(shared, slots));
                            for batch in deposits.chunks(7) {
                                acc.deposit(batch);
                                peak.fetch_max(acc.bytes(), std::sync::atomic::Ordering::Relaxed);
                            }
                            assert!(acc.bytes() <= cache, "{} > {cache}", acc.bytes());
                            shared.add_samples(tile, 1);
                        }
                    }
                }
                if let Some(b) = buffer {
                    b.flush_into(shared);
                }
                if let Some(mut c) = cache_acc {
                    c.flush();
                }
            });
        }
    });
    let counts = shared.counts();
    (shared.into_frame(), counts, peak.into_inner())
}

fn all_sums(f: &Frame) -> Vec<Vec<[u128; 3]>> {
    std::iter::once(f.main_sums().to_vec())
        .chain((0..f.layer_count as usize).map(|k| f.layer_sums(k).to_vec()))
        .collect()
}

/// The exact sum of every valid on-film deposit, channel R, main image.
fn expected_total(layers: u32) -> f64 {
    tiles()
        .iter()
        .enumerate()
        .flat_map(|(u, &t)| unit_deposits(u, t, layers))
        .filter(|d| d.value.is_valid_radiance() && d.x >= 0.0)
        .map(|d| d.value.r as f64)
        .sum()
}

#[test]
fn exact_styles_give_the_same_bits_for_any_threads_and_cache() {
    for layers in [0, 3] {
        let (reference, _, _) = run(Style::Blasting, Precision::Exact, layers, 1, 0);
        let want = all_sums(&reference);
        // Nothing lost: the main image holds every valid deposit (to 2⁻⁶⁴ each).
        let total: f64 = reference.main_sums().iter().map(|s| from_fixed(s[0])).sum();
        assert!(
            (total / expected_total(layers) - 1.0).abs() < 1e-12,
            "{total}"
        );
        for (style, threads, cache) in [
            (Style::Blasting, 3, 0),
            (Style::Buffering, 1, 0),
            (Style::Buffering, 4, 0),
            (Style::Caching, 1, 1 << 20),
            (Style::Caching, 4, 1 << 20),
            // One or two slots per thread: a flush at nearly every deposit.
            (
                Style::Caching,
                3,
                MicroTileCache::slot_bytes(layers as usize + 1, Precision::Exact),
            ),
            (
                Style::Caching,
                2,
                2 * MicroTileCache::slot_bytes(layers as usize + 1, Precision::Exact),
            ),
        ] {
            let (frame, counts, _) = run(style, Precision::Exact, layers, threads, cache);
            assert!(
                all_sums(&frame) == want,
                "{style:?} with {threads} threads, cache {cache}, {layers} layers"
            );
            assert_eq!(frame.samples(), reference.samples());
            assert!(counts.flushes > 0 && counts.locks >= counts.flushes);
        }
    }
}

#[test]
fn f32_styles_agree_with_the_exact_sums_to_rounding() {
    let layers = 2;
    let (exact, _, _) = run(Style::Blasting, Precision::Exact, layers, 1, 0);
    let want = exact.image();
    for (style, threads, cache) in [
        (Style::Blasting, 2, 0),
        (Style::Buffering, 3, 0),
        (
            Style::Caching,
            3,
            3 * MicroTileCache::slot_bytes(layers as usize + 1, Precision::F32),
        ),
    ] {
        let (frame, _, _) = run(style, Precision::F32, layers, threads, cache);
        assert_eq!(frame.precision(), Precision::F32);
        for (k, (a, b)) in frame.image().iter().zip(&want).enumerate() {
            for (x, y) in a.to_array().into_iter().zip(b.to_array()) {
                assert!(
                    (x - y).abs() <= 1e-5 * y.abs() + 1e-30,
                    "{style:?} pixel {k}: {x} vs {y}"
                );
            }
        }
        let l = frame.layer(1);
        let le = exact.layer(1);
        let (s, se): (f64, f64) = (
            l.iter().map(|p| p.g as f64).sum(),
            le.iter().map(|p| p.g as f64).sum(),
        );
        assert!(
            (s / se - 1.0).abs() < 1e-6,
            "{style:?} layer 1: {s} vs {se}"
        );
    }
}

#[test]
fn caching_holds_at_most_its_cap_and_flushes_in_batches() {
    let layers = 8;
    let slot = MicroTileCache::slot_bytes(layers as usize + 1, Precision::Exact);
    let cap = 5 * slot + slot / 2;
    let (_, counts, peak) = run(Style::Caching, Precision::Exact, layers, 2, cap);
    assert!(peak > 0 && peak <= cap, "{peak} > {cap}");
    assert_eq!(peak, 5 * slot);
    // Each batch takes one lock per framebuffer.
    assert_eq!(counts.locks % (layers as u64 + 1), 0);
    assert!(counts.flushes > 10, "{counts:?}");
}

#[test]
fn an_f32_frame_keeps_a_million_small_deposits_that_an_f32_sum_would_lose() {
    // A bright first deposit, then 10⁶ deposits each below 2⁻²⁵ of it: an f32 running sum
    // stays at 1e4 (stagnation), the f64 partial sums of the cache do not.
    let shared = SharedFrame::new(1, 1, 0, Precision::F32);
    let mut cache = MicroTileCache::new(&shared, 1);
    let d = |v: f32| Deposit {
        x: 0.5,
        y: 0.5,
        layer: 0,
        value: Rgb::splat(v),
    };
    cache.deposit(&[d(1.0e4)]);
    let mut naive = 1.0e4f32;
    for _ in 0..1_000_000 {
        cache.deposit(&[d(2.0e-4)]);
        naive += 2.0e-4;
    }
    cache.flush();
    let frame = shared.into_frame();
    let exact = 1.0e4 + 1.0e6 * 2.0e-4f32 as f64;
    let got = frame.sum(0, 0)[0];
    assert!((got / exact - 1.0).abs() < 1e-7, "{got} vs {exact}");
    assert!(
        (naive as f64 / exact - 1.0).abs() > 0.01,
        "the naive f32 sum lost {naive}"
    );
}

#[test]
fn locks_found_held_are_counted() {
    let shared = SharedFrame::new(4, 4, 1, Precision::Exact);
    let guard = shared.lock_plane(1);
    std::thread::scope(|s| {
        s.spawn(|| {
            let _g = shared.lock_plane(0);
            // Framebuffer 1 is held by the main thread until it sees this thread waiting.
            let counts = shared.counts();
            assert_eq!(counts.contended, 0);
        });
    });
    std::thread::scope(|s| {
        let h = s.spawn(|| drop(shared.lock_plane(1)));
        while shared.counts().contended == 0 {
            std::thread::yield_now();
        }
        drop(guard);
        h.join().unwrap();
    });
    let c = shared.counts();
    assert_eq!((c.locks, c.contended), (3, 1));
}

/// A deposit's pixel is ⌊x⌋, ⌊y⌋ on the film; anything else (negative, NaN, at or past the
/// edge, infinite) is stray. Checked against `floor` on the edge cases.
#[test]
fn classify_takes_the_floor_and_drops_what_is_off_the_film() {
    let xs = [
        -1.0,
        -f32::MIN_POSITIVE,
        -0.0,
        0.0,
        0.5,
        1.0 - f32::EPSILON / 2.0,
        36.0,
        37.0 - 4.0 * f32::EPSILON,
        37.0,
        37.5,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];
    for &x in &xs {
        for &y in &xs {
            let d = Deposit {
                x,
                y,
                layer: 0,
                value: flowlight_core::Rgb::ONE,
            };
            let mut counts = DepositCounts::default();
            let got = classify(&d, W, W, &mut counts);
            let (fx, fy) = (x.floor(), y.floor());
            let on = fx >= 0.0 && fy >= 0.0 && fx < W as f32 && fy < W as f32;
            let want = on.then_some((fx as u32, fy as u32));
            assert_eq!(got, want, "({x}, {y})");
            assert_eq!(counts.stray, u64::from(!on), "({x}, {y})");
        }
    }
}
