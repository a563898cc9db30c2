//! Film-plane migration (thesis §5.4): each mutation moves the raster position by an offset
//! drawn uniformly from a K×K window centred on it. The move is symmetric — y is in x's window
//! exactly when x is in y's — so T₀(y→x)/T₀(x→y) = 1. A move off the film is a domain miss.
//!
//! The window travels with the chain (a random walk), rather than being a fixed square: fixed
//! squares confine each chain to its seed's square and leave the squares' noise visible as a
//! block pattern. Chains therefore deposit around their seed, and the host gives ERPT's work
//! units a flange (and keeps deposits beyond it), as thesis §5.9 describes.

use flowlight_core::rng::Rng;
use glam::Vec2;

/// A uniformly random position in the K×K window around `raster`, or `None` off the film.
pub fn migrate(raster: Vec2, k: u32, width: u32, height: u32, rng: &mut Rng) -> Option<Vec2> {
    if k == 0 {
        return Some(raster);
    }
    let k = k as f32;
    let p = raster + (rng.uniform2() - Vec2::splat(0.5)) * k;
    (p.x >= 0.0 && p.y >= 0.0 && p.x < width as f32 && p.y < height as f32).then_some(p)
}

/// Density (per unit raster area) of moving from `from` to `to`: 1/K² when `to` is on the film
/// and in the window around `from`; with K = 0, 1 when the positions are equal.
pub fn density(from: Vec2, to: Vec2, k: u32, width: u32, height: u32) -> f64 {
    if k == 0 {
        return if from == to { 1.0 } else { 0.0 };
    }
    let half = k as f32 * 0.5;
    let d = (to - from).abs();
    let on_film = to.x >= 0.0 && to.y >= 0.0 && to.x < width as f32 && to.y < height as f32;
    if on_film && d.x <= half && d.y <= half {
        1.0 / (k as f64 * k as f64)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn migration_is_uniform_in_the_window_and_symmetric() {
        let mut rng = Rng::new(3, 1);
        let start = Vec2::new(13.7, 9.2);
        let mut quadrants = [0usize; 4];
        for _ in 0..40_000 {
            let p = migrate(start, 8, 64, 64, &mut rng).unwrap();
            assert!((p - start).abs().max_element() <= 4.0, "{p}");
            assert_eq!(density(start, p, 8, 64, 64), 1.0 / 64.0);
            assert_eq!(density(p, start, 8, 64, 64), 1.0 / 64.0, "symmetric");
            quadrants[((p.x > start.x) as usize) * 2 + (p.y > start.y) as usize] += 1;
        }
        for q in quadrants {
            assert!((q as f64 / 10_000.0 - 1.0).abs() < 0.05, "{quadrants:?}");
        }
        assert_eq!(density(start, Vec2::new(18.0, 9.0), 8, 64, 64), 0.0);
        assert_eq!(migrate(start, 0, 64, 64, &mut rng), Some(start));
    }

    #[test]
    fn moves_off_the_film_are_misses() {
        let mut rng = Rng::new(4, 1);
        let corner = Vec2::new(0.5, 0.5);
        let outcomes: Vec<_> = (0..1000)
            .map(|_| migrate(corner, 8, 64, 64, &mut rng))
            .collect();
        let misses = outcomes.iter().filter(|p| p.is_none()).count();
        // The window spans [-3.5, 4.5) on each axis: a share (4.5/8)² of it is on the film.
        let expected = 1.0 - (4.5f64 / 8.0).powi(2);
        assert!((misses as f64 / 1000.0 - expected).abs() < 0.05, "{misses}");
        assert_eq!(density(corner, Vec2::new(-0.5, 0.5), 8, 64, 64), 0.0);
    }
}
