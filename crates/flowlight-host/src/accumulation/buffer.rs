//! Buffering (pane-based splitting): one whole-image private buffer per worker thread,
//! every framebuffer, flushed into the frame once when the render ends. No lock while
//! rendering; memory grows with threads × framebuffers (thesis §5.9's trap: 12 threads ×
//! 1080p × 8 layers ≈ 2.2 GB of f32).

use super::cells::{add_to_planes, Cells};
use super::{classify, is_large, DepositCounts, PixelDeposit, Precision, SharedFrame};
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;

/// A worker thread's whole-image buffer.
pub struct ThreadBuffer {
    width: u32,
    height: u32,
    precision: Precision,
    /// Framebuffers: 0 the main image, k + 1 layer k.
    planes: Vec<Cells>,
    /// Values too large for fixed point (exact precision), merged at the flush.
    large: Vec<PixelDeposit>,
    pub counts: DepositCounts,
}

impl ThreadBuffer {
    pub fn new(width: u32, height: u32, layer_count: u32, precision: Precision) -> ThreadBuffer {
        let n = width as usize * height as usize;
        ThreadBuffer {
            width,
            height,
            precision,
            planes: Cells::planes(precision, layer_count, n),
            large: Vec::new(),
            counts: DepositCounts::default(),
        }
    }

    /// Bytes of the buffer's cells.
    pub fn bytes(&self) -> u64 {
        self.planes.len() as u64 * self.planes[0].len() as u64 * self.precision.partial_cell_bytes()
    }

    /// Adds the whole buffer into `shared`, one lock per framebuffer.
    pub fn flush_into(&self, shared: &SharedFrame) {
        shared.count_flush();
        let n = self.planes[0].len();
        for (k, cells) in self.planes.iter().enumerate() {
            let mut guard = shared.lock_plane(k);
            guard.0.add_cells(0, cells, 0, n);
        }
        shared.add_deposits(&self.large);
    }

    /// [`ThreadBuffer::flush_into`], then empties the buffer for the deposits to come.
    pub fn flush_and_clear(&mut self, shared: &SharedFrame) {
        self.flush_into(shared);
        for cells in &mut self.planes {
            let n = cells.len();
            cells.clear_range(0, n);
        }
        self.large.clear();
    }
}

impl Accumulator for ThreadBuffer {
    fn deposit(&mut self, deposits: &[Deposit]) {
        for d in deposits {
            let Some((px, py)) = classify(d, self.width, self.height, &mut self.counts) else {
                continue;
            };
            if self.precision == Precision::Exact && is_large(d.value) {
                self.large.push(PixelDeposit {
                    x: px,
                    y: py,
                    layer: d.layer,
                    value: d.value,
                });
                continue;
            }
            let i = py as usize * self.width as usize + px as usize;
            add_to_planes(&mut self.planes, i, d.layer, d.value);
        }
    }
}
