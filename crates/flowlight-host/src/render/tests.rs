//! Unit tests of the scheduler's pass rounds, memory estimate, thread clamp and tile order.

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

/// The host's style: Blasting for tile-local deposits, Caching for chains with a flange,
/// Buffering for deposits anywhere up to [`AUTO_BUFFERING_MAX_BYTES`] of whole-image buffers
/// over all threads where they fit in memory, Caching otherwise.
#[test]
fn the_style_follows_where_the_deposits_land_and_what_buffers_cost() {
    use flowlight_sdk::AccumulationStyle::{FlangedTile, Tile};
    assert_eq!(choose_style(Tile, 0, 0, true), Style::Blasting);
    assert_eq!(choose_style(FlangedTile, 16, 0, true), Style::Caching);
    assert_eq!(
        choose_style(FlangedTile, 0, 24 << 20, true),
        Style::Buffering
    );
    let max = AUTO_BUFFERING_MAX_BYTES;
    assert_eq!(choose_style(FlangedTile, 0, max, true), Style::Buffering);
    assert_eq!(choose_style(FlangedTile, 0, max + 1, true), Style::Caching);
    assert_eq!(
        choose_style(FlangedTile, 16, 24 << 20, true),
        Style::Caching
    );
    // Buffers the machine cannot hold: Caching, whose cap it can.
    assert_eq!(
        choose_style(FlangedTile, 0, 24 << 20, false),
        Style::Caching
    );
}
