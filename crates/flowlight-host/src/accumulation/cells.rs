//! Private partial sums: the cells of a unit's tile buffer, a thread's buffer or a cache's
//! micro-tiles, in the number format the frame's precision asks for (module documentation
//! of [`super`]).

use super::{add_sums, to_fixed, Precision};
use flowlight_core::Rgb;

/// RGB partial sums of `len` pixels: fixed point for an exact frame, f64 for an f32 one.
pub enum Cells {
    Exact(Vec<[u128; 3]>),
    Wide(Vec<[f64; 3]>),
}

impl Cells {
    /// `len` zeroed cells.
    pub fn new(precision: Precision, len: usize) -> Cells {
        match precision {
            Precision::Exact => Cells::Exact(vec![[0; 3]; len]),
            Precision::F32 => Cells::Wide(vec![[0.0; 3]; len]),
        }
    }

    /// Zeroed cells of `len` pixels for every framebuffer: the main image and `layer_count`
    /// lighting layers.
    pub fn planes(precision: Precision, layer_count: u32, len: usize) -> Vec<Cells> {
        (0..=layer_count)
            .map(|_| Cells::new(precision, len))
            .collect()
    }

    pub fn len(&self) -> usize {
        match self {
            Cells::Exact(c) => c.len(),
            Cells::Wide(c) => c.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds a deposit value (finite, ≥ 0, and below the fixed-point limit for exact cells).
    #[inline]
    pub fn add(&mut self, i: usize, v: Rgb) {
        match self {
            Cells::Exact(c) => {
                let q = [to_fixed(v.r), to_fixed(v.g), to_fixed(v.b)];
                add_sums(&mut c[i], &q);
            }
            Cells::Wide(c) => {
                let s = &mut c[i];
                s[0] += v.r as f64;
                s[1] += v.g as f64;
                s[2] += v.b as f64;
            }
        }
    }

    /// Zeroes cells [start, start + n).
    pub fn clear_range(&mut self, start: usize, n: usize) {
        match self {
            Cells::Exact(c) => c[start..start + n].fill([0; 3]),
            Cells::Wide(c) => c[start..start + n].fill([0.0; 3]),
        }
    }
}

/// Adds a deposit value to the main image's cells (`planes[0]`) and to its lighting layer's
/// (`planes[layer + 1]`, when the render has that layer), at cell `i`.
#[inline]
pub(crate) fn add_to_planes(planes: &mut [Cells], i: usize, layer: u32, v: Rgb) {
    planes[0].add(i, v);
    if let Some(l) = planes.get_mut(layer as usize + 1) {
        l.add(i, v);
    }
}
