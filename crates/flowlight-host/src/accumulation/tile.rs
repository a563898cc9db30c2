//! Blasting: a work unit's private buffer over its tile (plus the integrator's flange),
//! merged into the frame when the unit ends. Deposits beyond the buffer are not lost: they
//! wait in the unit's overflow list and are merged with it.

use super::cells::{add_to_planes, Cells};
use super::frame::Plane;
use super::{classify, is_large, DepositCounts, PixelDeposit, Precision};
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;

/// A work unit's private buffer: its tile plus a flange, clipped to the film.
pub struct TileAccumulator {
    /// The tile (whose pixels the unit samples).
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
    /// The buffer: tile plus flange, clipped to the film.
    bx0: u32,
    by0: u32,
    bx1: u32,
    by1: u32,
    width: u32,
    height: u32,
    precision: Precision,
    /// Framebuffers: 0 the main image, k + 1 layer k.
    planes: Vec<Cells>,
    overflow: Vec<PixelDeposit>,
    pub counts: DepositCounts,
}

impl TileAccumulator {
    /// A buffer for `tile` = (x0, y0, x1, y1) of a `film` = (width, height) in `precision`.
    pub fn with_precision(
        tile: (u32, u32, u32, u32),
        flange: u32,
        film: (u32, u32),
        layer_count: u32,
        precision: Precision,
    ) -> Self {
        let (x0, y0, x1, y1) = tile;
        let (width, height) = film;
        let (bx0, by0) = (x0.saturating_sub(flange), y0.saturating_sub(flange));
        let (bx1, by1) = (
            x1.saturating_add(flange).min(width),
            y1.saturating_add(flange).min(height),
        );
        let n = (bx1 - bx0) as usize * (by1 - by0) as usize;
        TileAccumulator {
            x0,
            y0,
            x1,
            y1,
            bx0,
            by0,
            bx1,
            by1,
            width,
            height,
            precision,
            planes: Cells::planes(precision, layer_count, n),
            overflow: Vec::new(),
            counts: DepositCounts::default(),
        }
    }

    /// The tile (x0, y0, x1, y1) whose pixels the unit samples.
    pub fn tile(&self) -> (u32, u32, u32, u32) {
        (self.x0, self.y0, self.x1, self.y1)
    }

    /// Deposits kept outside the buffer (beyond the flange, or too large for fixed point).
    pub fn overflow(&self) -> &[PixelDeposit] {
        &self.overflow
    }

    /// Bytes of the buffer's cells.
    pub fn bytes(&self) -> u64 {
        self.planes.len() as u64 * self.planes[0].len() as u64 * self.precision.partial_cell_bytes()
    }

    /// Adds framebuffer `k` of the buffer into `plane`, a `width`-wide frame plane.
    pub(crate) fn flush_plane(&self, k: usize, plane: &mut Plane, width: u32) {
        let bw = (self.bx1 - self.bx0) as usize;
        for (row, y) in (self.by0..self.by1).enumerate() {
            let dst = y as usize * width as usize + self.bx0 as usize;
            plane.add_cells(dst, &self.planes[k], row * bw, bw);
        }
    }
}

impl Accumulator for TileAccumulator {
    fn deposit(&mut self, deposits: &[Deposit]) {
        for d in deposits {
            let Some((px, py)) = classify(d, self.width, self.height, &mut self.counts) else {
                continue;
            };
            let kept = PixelDeposit {
                x: px,
                y: py,
                layer: d.layer,
                value: d.value,
            };
            if self.precision == Precision::Exact && is_large(d.value) {
                // The frame sums large values in f64 (module documentation).
                self.overflow.push(kept);
                continue;
            }
            if px < self.bx0 || py < self.by0 || px >= self.bx1 || py >= self.by1 {
                self.counts.overflow += 1;
                self.overflow.push(kept);
                continue;
            }
            let i = (py - self.by0) as usize * (self.bx1 - self.bx0) as usize
                + (px - self.bx0) as usize;
            add_to_planes(&mut self.planes, i, d.layer, d.value);
        }
    }
}
