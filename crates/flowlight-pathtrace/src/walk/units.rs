//! Camera samples of a work unit grouped into waves: the loop every plugin that walks camera
//! paths as wavefronts runs (MCPT's image, ERPT's seeds).

use crate::sampler::{sample_start, PixelSampler};
use flowlight_sdk::WorkUnit;
use glam::Vec2;
use std::ops::Range;

/// A camera sample: its pixel and its index among the pixel's samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleKey {
    pub x: u32,
    pub y: u32,
    pub s: u32,
}

/// The pixels of `unit`, row by row.
pub fn unit_pixels(unit: &WorkUnit) -> impl Iterator<Item = (u32, u32)> + Clone + '_ {
    (unit.y0..unit.y1).flat_map(move |y| (unit.x0..unit.x1).map(move |x| (x, y)))
}

/// The camera samples `samples` of each of `pixels` (render seed `seed`), in (pixel,
/// sample) order, in waves of at most `size`: `flush` gets each wave's starts (numbers and
/// raster position, [`sample_start`]) and their keys. The same samples in the same order
/// as a path-at-a-time loop, so an image does not depend on the wave size.
pub fn for_each_wave<S: PixelSampler>(
    seed: u64,
    pixels: impl Iterator<Item = (u32, u32)>,
    samples: Range<u32>,
    size: usize,
    mut flush: impl FnMut(&[(S, Vec2)], &[SampleKey]),
) {
    let size = size.max(1);
    let mut starts = Vec::with_capacity(size);
    let mut keys = Vec::with_capacity(size);
    for (x, y) in pixels {
        for s in samples.clone() {
            starts.push(sample_start::<S>(seed, x, y, s));
            keys.push(SampleKey { x, y, s });
            if starts.len() == size {
                flush(&starts, &keys);
                starts.clear();
                keys.clear();
            }
        }
    }
    if !starts.is_empty() {
        flush(&starts, &keys);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::rng::Rng;

    /// Every sample once, in (row, pixel, sample) order, whatever the wave size.
    #[test]
    fn waves_cover_the_unit_in_order() {
        let pixels = [(0, 0), (1, 0), (0, 1)];
        let mut want = Vec::new();
        for_each_wave::<Rng>(7, pixels.into_iter(), 2..5, 1000, |_, keys| {
            want.extend_from_slice(keys)
        });
        assert_eq!(want.len(), 9);
        assert_eq!(want[0], SampleKey { x: 0, y: 0, s: 2 });
        assert_eq!(want[8], SampleKey { x: 0, y: 1, s: 4 });
        for size in [1, 2, 4, 9] {
            let mut got = Vec::new();
            let mut rasters = Vec::new();
            for_each_wave::<Rng>(7, pixels.into_iter(), 2..5, size, |starts, keys| {
                assert!(keys.len() <= size && keys.len() == starts.len());
                got.extend_from_slice(keys);
                rasters.extend(starts.iter().map(|(_, r)| *r));
            });
            assert_eq!(got, want, "wave size {size}");
            for (k, r) in got.iter().zip(&rasters) {
                assert_eq!(sample_start::<Rng>(7, k.x, k.y, k.s).1, *r);
            }
        }
    }
}
