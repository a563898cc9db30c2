//! The frame while a render runs: one lock per framebuffer (thesis §5.9's "one KeyLock per
//! framebuffer"), so flushes into different layers proceed side by side, and counters of
//! every lock taken and every one found held (the contention the 16-thread behaviour is
//! estimated from).

use super::frame::{add_deposit_to_plane, Frame, LargeSums, Plane};
use super::{PixelDeposit, Precision, TileAccumulator};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard, TryLockError};

/// The shared frame of a running render.
pub struct SharedFrame {
    pub width: u32,
    pub height: u32,
    pub precision: Precision,
    /// Framebuffers, each behind its own lock: 0 the main image, k + 1 layer k; each with
    /// its large-value sums (exact precision).
    planes: Vec<Mutex<(Plane, LargeSums)>>,
    samples: Mutex<Vec<u32>>,
    locks: AtomicU64,
    contended: AtomicU64,
    flushes: AtomicU64,
}

/// Flush and lock counts of a render's accumulation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlushCounts {
    /// Flushes of private memory into the frame (units, cache batches, thread buffers).
    pub flushes: u64,
    /// Framebuffer locks taken by those flushes.
    pub locks: u64,
    /// Of those, locks another thread held at the time (the caller waited).
    pub contended: u64,
}

impl SharedFrame {
    pub fn new(width: u32, height: u32, layer_count: u32, precision: Precision) -> SharedFrame {
        let n = width as usize * height as usize;
        SharedFrame {
            width,
            height,
            precision,
            planes: (0..=layer_count)
                .map(|_| Mutex::new((Plane::new(precision, n), LargeSums::new())))
                .collect(),
            samples: Mutex::new(vec![0; n]),
            locks: AtomicU64::new(0),
            contended: AtomicU64::new(0),
            flushes: AtomicU64::new(0),
        }
    }

    /// Number of framebuffers (main image and layers).
    pub fn plane_count(&self) -> usize {
        self.planes.len()
    }

    /// Locks framebuffer `k`, counting whether it was held.
    pub fn lock_plane(&self, k: usize) -> MutexGuard<'_, (Plane, LargeSums)> {
        self.locks.fetch_add(1, Ordering::Relaxed);
        match self.planes[k].try_lock() {
            Ok(g) => g,
            Err(TryLockError::WouldBlock) => {
                self.contended.fetch_add(1, Ordering::Relaxed);
                self.planes[k].lock().unwrap_or_else(|e| e.into_inner())
            }
            Err(TryLockError::Poisoned(e)) => e.into_inner(),
        }
    }

    /// Counts one flush of private memory.
    pub fn count_flush(&self) {
        self.flushes.fetch_add(1, Ordering::Relaxed);
    }

    /// Adds `samples` finished samples to each pixel of tile [x0, x1) × [y0, y1).
    pub fn add_samples(&self, tile: (u32, u32, u32, u32), samples: u32) {
        let (x0, y0, x1, y1) = tile;
        let mut s = self.samples.lock().unwrap_or_else(|e| e.into_inner());
        for y in y0..y1 {
            let row = y as usize * self.width as usize;
            for v in &mut s[row + x0 as usize..row + x1 as usize] {
                *v += samples;
            }
        }
    }

    /// Adds deposits kept outside private buffers, one framebuffer lock each.
    pub fn add_deposits(&self, deposits: &[PixelDeposit]) {
        if deposits.is_empty() {
            return;
        }
        for k in 0..self.planes.len() {
            let mut guard = self.lock_plane(k);
            self.add_to_plane(k, &mut guard, deposits);
        }
    }

    /// The deposits of framebuffer `k` (all for the main image, those of layer k − 1
    /// otherwise) into its locked sums.
    fn add_to_plane(&self, k: usize, guard: &mut (Plane, LargeSums), deposits: &[PixelDeposit]) {
        let (plane, large) = guard;
        for d in deposits {
            if k == 0 || d.layer as usize + 1 == k {
                let f = d.y as usize * self.width as usize + d.x as usize;
                add_deposit_to_plane(plane, large, f, d.value);
            }
        }
    }

    /// Merges a finished Blasting unit (its buffer and its overflow deposits, under one lock
    /// per framebuffer) and its `samples` samples.
    pub fn merge_tile(&self, tile: &TileAccumulator, samples: u32) {
        self.count_flush();
        for k in 0..self.planes.len() {
            let mut guard = self.lock_plane(k);
            tile.flush_plane(k, &mut guard.0, self.width);
            self.add_to_plane(k, &mut guard, tile.overflow());
        }
        self.add_samples(tile.tile(), samples);
    }

    /// Flush and lock counts so far.
    pub fn counts(&self) -> FlushCounts {
        FlushCounts {
            flushes: self.flushes.load(Ordering::Relaxed),
            locks: self.locks.load(Ordering::Relaxed),
            contended: self.contended.load(Ordering::Relaxed),
        }
    }

    /// The main image as the frame holds it now, for a live preview: each pixel's sum over
    /// its finished samples, or over `uniform_spp` when given (flanged integrators). Deposits
    /// still in the threads' private buffers are not in it yet. Takes the main framebuffer's
    /// lock (and the sample counts') for the copy.
    pub fn snapshot_image(&self, uniform_spp: Option<f64>) -> Vec<flowlight_core::Rgb> {
        let samples = self
            .samples
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let guard = self.lock_plane(0);
        let (plane, large) = &*guard;
        let scale = super::frame::pixel_scale(uniform_spp, &samples);
        (0..samples.len())
            .map(|i| {
                let s = plane.get(i);
                let l = large.get(&i).copied().unwrap_or([0.0; 3]);
                let f = scale(i);
                flowlight_core::Rgb::new(
                    ((s[0] + l[0]) * f) as f32,
                    ((s[1] + l[1]) * f) as f32,
                    ((s[2] + l[2]) * f) as f32,
                )
            })
            .collect()
    }

    /// The finished frame.
    pub fn into_frame(self) -> Frame {
        let mut planes = Vec::with_capacity(self.planes.len());
        let mut large = Vec::with_capacity(self.planes.len());
        for m in self.planes {
            let (p, l) = m.into_inner().unwrap_or_else(|e| e.into_inner());
            planes.push(p);
            large.push(l);
        }
        let samples = self.samples.into_inner().unwrap_or_else(|e| e.into_inner());
        Frame::from_planes(self.width, self.height, planes, samples, large)
    }
}
