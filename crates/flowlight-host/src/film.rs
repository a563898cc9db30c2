//! Accumulators: the whole-image frame and the per-unit tile buffers merged into it.

use flowlight_core::Rgb;
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;

/// The image being rendered: sums of deposits (main image and lighting layers) and, per
/// pixel, how many camera samples have been completed. f64 sums keep long renders exact.
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub layer_count: u32,
    main: Vec<[f64; 3]>,
    layers: Vec<Vec<[f64; 3]>>,
    samples: Vec<u32>,
}

impl Frame {
    pub fn new(width: u32, height: u32, layer_count: u32) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width,
            height,
            layer_count,
            main: vec![[0.0; 3]; n],
            layers: (0..layer_count).map(|_| vec![[0.0; 3]; n]).collect(),
            samples: vec![0; n],
        }
    }

    /// Adds a finished tile: its sums and `samples` more samples for each of its pixels.
    pub fn merge(&mut self, tile: &TileAccumulator, samples: u32) {
        let tw = (tile.x1 - tile.x0) as usize;
        for y in tile.y0..tile.y1 {
            for x in tile.x0..tile.x1 {
                let t = (y - tile.y0) as usize * tw + (x - tile.x0) as usize;
                let f = y as usize * self.width as usize + x as usize;
                add(&mut self.main[f], tile.main[t]);
                for (l, layer) in self.layers.iter_mut().enumerate() {
                    add(&mut layer[f], tile.layers[l][t]);
                }
                self.samples[f] += samples;
            }
        }
    }

    pub fn samples(&self) -> &[u32] {
        &self.samples
    }

    fn resolve_sums(&self, sums: &[[f64; 3]]) -> Vec<Rgb> {
        sums.iter()
            .zip(&self.samples)
            .map(|(s, &n)| {
                if n == 0 {
                    Rgb::ZERO
                } else {
                    let k = 1.0 / n as f64;
                    Rgb::new((s[0] * k) as f32, (s[1] * k) as f32, (s[2] * k) as f32)
                }
            })
            .collect()
    }

    /// The main image: each pixel's sum over its sample count (black where none finished).
    pub fn image(&self) -> Vec<Rgb> {
        self.resolve_sums(&self.main)
    }

    /// Lighting layer `k`, normalised like the main image.
    pub fn layer(&self, k: usize) -> Vec<Rgb> {
        self.resolve_sums(&self.layers[k])
    }
}

#[inline]
fn add(acc: &mut [f64; 3], v: Rgb) {
    acc[0] += v.r as f64;
    acc[1] += v.g as f64;
    acc[2] += v.b as f64;
}

/// Deposit counts a unit's accumulator reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct DepositCounts {
    /// Deposits with a NaN, infinite or negative value: counted, never written.
    pub invalid: u64,
    /// Deposits outside the unit's tile (a plugin breaking its accumulation style).
    pub stray: u64,
}

/// A work unit's private tile buffer (thesis §5.9: tiles are disjoint, so no locking while the
/// unit runs; the host merges the tile into the frame when the unit ends).
pub struct TileAccumulator {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
    main: Vec<Rgb>,
    layers: Vec<Vec<Rgb>>,
    pub counts: DepositCounts,
}

impl TileAccumulator {
    pub fn new(x0: u32, y0: u32, x1: u32, y1: u32, layer_count: u32) -> Self {
        let n = ((x1 - x0) * (y1 - y0)) as usize;
        TileAccumulator {
            x0,
            y0,
            x1,
            y1,
            main: vec![Rgb::ZERO; n],
            layers: (0..layer_count).map(|_| vec![Rgb::ZERO; n]).collect(),
            counts: DepositCounts::default(),
        }
    }
}

impl Accumulator for TileAccumulator {
    fn deposit(&mut self, deposits: &[Deposit]) {
        for d in deposits {
            if !d.value.is_valid_radiance() {
                self.counts.invalid += 1;
                continue;
            }
            let (fx, fy) = (d.x.floor(), d.y.floor());
            if !(fx >= self.x0 as f32
                && fy >= self.y0 as f32
                && fx < self.x1 as f32
                && fy < self.y1 as f32)
            {
                self.counts.stray += 1;
                continue;
            }
            let i = (fy as u32 - self.y0) as usize * (self.x1 - self.x0) as usize
                + (fx as u32 - self.x0) as usize;
            self.main[i] += d.value;
            if let Some(layer) = self.layers.get_mut(d.layer as usize) {
                layer[i] += d.value;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_discards_and_counts_invalid_and_stray_deposits() {
        let mut t = TileAccumulator::new(2, 2, 4, 4, 2);
        let d = |x: f32, y: f32, layer: u32, v: f32| Deposit {
            x,
            y,
            layer,
            value: Rgb::splat(v),
        };
        t.deposit(&[
            d(2.5, 2.5, 0, 1.0),
            d(3.5, 2.5, 1, 2.0),
            d(2.5, 2.5, 0, f32::NAN),
            d(2.5, 2.5, 0, f32::INFINITY),
            d(2.5, 2.5, 0, -1.0),
            d(0.5, 0.5, 0, 1.0),
        ]);
        assert_eq!(t.counts.invalid, 3);
        assert_eq!(t.counts.stray, 1);
        let mut f = Frame::new(4, 4, 2);
        f.merge(&t, 2);
        let img = f.image();
        assert_eq!(img[2 * 4 + 2], Rgb::splat(0.5));
        assert_eq!(img[2 * 4 + 3], Rgb::splat(1.0));
        assert_eq!(img[0], Rgb::ZERO);
        assert_eq!(f.layer(1)[2 * 4 + 3], Rgb::splat(1.0));
        assert_eq!(f.layer(0)[2 * 4 + 3], Rgb::ZERO);
        assert_eq!(f.samples()[0], 0);
    }
}
