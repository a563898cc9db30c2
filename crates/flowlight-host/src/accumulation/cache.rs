//! Caching (thesis §5.9's micro-tiling): each worker thread keeps the [`MICRO_TILE`]² pixel
//! micro-tiles its chains deposit into, every framebuffer of them, in a cache of a fixed
//! number of slots. A deposit into a micro-tile not in the cache takes a free slot; when
//! none is free, the older half of the slots (least recently entered) is flushed into the
//! shared frame as one batch, one framebuffer lock per batch, and freed. The cache never
//! holds more than its slots, so a render's accumulation memory is the frame plus
//! `render.accumulation_cache_mib` whatever the threads and layers.
//!
//! Markov chains stay near their seed for many steps (a perturbation moves a few pixels), so
//! the micro-tiles of a thread's current unit and its flange stay cached across its chains,
//! and consecutive deposits usually hit the micro-tile of the one before (checked first).

use super::cells::{add_to_planes, Cells};
use super::{classify, is_large, DepositCounts, PixelDeposit, Precision, SharedFrame};
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;
use std::collections::HashMap;

/// Side of a micro-tile in pixels.
pub const MICRO_TILE: u32 = 8;
const CELLS: usize = (MICRO_TILE * MICRO_TILE) as usize;
/// Bytes of a slot's bookkeeping counted against the cap (key, last use, free list and the
/// hash map's share, rounded up).
const SLOT_BOOKKEEPING: u64 = 64;
const NO_KEY: u32 = u32::MAX;

/// A worker thread's micro-tile cache over a shared frame.
pub struct MicroTileCache<'a> {
    shared: &'a SharedFrame,
    /// Micro-tile columns of the film.
    columns: u32,
    capacity: usize,
    /// Framebuffers: 0 the main image, k + 1 layer k; `capacity` × [`MICRO_TILE`]² cells
    /// each, allocated at the first deposit.
    planes: Vec<Cells>,
    /// The micro-tile in each slot ([`NO_KEY`] when free) and when it was last entered.
    keys: Vec<u32>,
    last_use: Vec<u64>,
    slot_of: HashMap<u32, u32>,
    free: Vec<u32>,
    clock: u64,
    /// The (micro-tile, slot) of the previous deposit.
    last: (u32, u32),
    pub counts: DepositCounts,
    /// Batches this cache flushed (the final flush included).
    pub batches: u64,
}

impl<'a> MicroTileCache<'a> {
    /// Bytes one slot costs: its cells in every framebuffer and its bookkeeping.
    pub fn slot_bytes(plane_count: usize, precision: Precision) -> u64 {
        CELLS as u64 * plane_count as u64 * precision.partial_cell_bytes() + SLOT_BOOKKEEPING
    }

    /// Slots a cache of `cap_bytes` holds (0 when not even one fits), never more than the
    /// film's micro-tiles.
    pub fn slots_for(cap_bytes: u64, shared: &SharedFrame) -> usize {
        let per_slot = Self::slot_bytes(shared.plane_count(), shared.precision);
        let tiles =
            shared.width.div_ceil(MICRO_TILE) as u64 * shared.height.div_ceil(MICRO_TILE) as u64;
        (cap_bytes / per_slot).min(tiles) as usize
    }

    /// A cache of `capacity` ≥ 1 slots feeding `shared`.
    pub fn new(shared: &'a SharedFrame, capacity: usize) -> MicroTileCache<'a> {
        assert!(capacity >= 1, "a micro-tile cache needs at least one slot");
        MicroTileCache {
            shared,
            columns: shared.width.div_ceil(MICRO_TILE),
            capacity,
            planes: Vec::new(),
            keys: Vec::new(),
            last_use: Vec::new(),
            slot_of: HashMap::new(),
            free: Vec::new(),
            clock: 0,
            last: (NO_KEY, 0),
            counts: DepositCounts::default(),
            batches: 0,
        }
    }

    /// Bytes the cache holds now (at most `capacity` × [`Self::slot_bytes`]).
    pub fn bytes(&self) -> u64 {
        if self.planes.is_empty() {
            0
        } else {
            self.capacity as u64 * Self::slot_bytes(self.planes.len(), self.shared.precision)
        }
    }

    fn allocate(&mut self) {
        let n = self.capacity * CELLS;
        self.planes = (0..self.shared.plane_count())
            .map(|_| Cells::new(self.shared.precision, n))
            .collect();
        self.keys = vec![NO_KEY; self.capacity];
        self.last_use = vec![0; self.capacity];
        self.slot_of.reserve(self.capacity);
        self.free = (0..self.capacity as u32).rev().collect();
    }

    /// The slot of micro-tile `key`, entering it (and flushing the older half when full).
    fn slot_for(&mut self, key: u32) -> u32 {
        if self.planes.is_empty() {
            self.allocate();
        }
        self.clock += 1;
        let slot = match self.slot_of.get(&key) {
            Some(&s) => s,
            None => {
                if self.free.is_empty() {
                    self.flush_older_half();
                }
                let s = self.free.pop().expect("a flush frees at least one slot");
                self.keys[s as usize] = key;
                self.slot_of.insert(key, s);
                s
            }
        };
        self.last_use[slot as usize] = self.clock;
        self.last = (key, slot);
        slot
    }

    fn flush_older_half(&mut self) {
        let mut used: Vec<u32> = (0..self.capacity as u32)
            .filter(|&s| self.keys[s as usize] != NO_KEY)
            .collect();
        used.sort_unstable_by_key(|&s| self.last_use[s as usize]);
        used.truncate(used.len().div_ceil(2));
        self.flush_slots(&used);
    }

    /// Flushes every cached micro-tile (the end of the render).
    pub fn flush(&mut self) {
        let used: Vec<u32> = (0..self.keys.len() as u32)
            .filter(|&s| self.keys[s as usize] != NO_KEY)
            .collect();
        if !used.is_empty() {
            self.flush_slots(&used);
        }
    }

    /// Adds `slots` into the shared frame as one batch (one lock per framebuffer) and frees
    /// them.
    fn flush_slots(&mut self, slots: &[u32]) {
        let shared = self.shared;
        shared.count_flush();
        self.batches += 1;
        let (w, h) = (shared.width, shared.height);
        for (k, cells) in self.planes.iter().enumerate() {
            let mut guard = shared.lock_plane(k);
            for &s in slots {
                let key = self.keys[s as usize];
                let (mx, my) = (
                    key % self.columns * MICRO_TILE,
                    key / self.columns * MICRO_TILE,
                );
                let run = (w - mx).min(MICRO_TILE) as usize;
                for ly in 0..(h - my).min(MICRO_TILE) {
                    let dst = (my + ly) as usize * w as usize + mx as usize;
                    let src = s as usize * CELLS + (ly * MICRO_TILE) as usize;
                    guard.0.add_cells(dst, cells, src, run);
                }
            }
        }
        for &s in slots {
            for cells in &mut self.planes {
                cells.clear_range(s as usize * CELLS, CELLS);
            }
            self.slot_of.remove(&self.keys[s as usize]);
            self.keys[s as usize] = NO_KEY;
            self.free.push(s);
        }
        self.last = (NO_KEY, 0);
    }
}

impl Accumulator for MicroTileCache<'_> {
    fn deposit(&mut self, deposits: &[Deposit]) {
        let (w, h) = (self.shared.width, self.shared.height);
        for d in deposits {
            let Some((px, py)) = classify(d, w, h, &mut self.counts) else {
                continue;
            };
            if self.shared.precision == Precision::Exact && is_large(d.value) {
                // Rare (channel values ≥ 2³²): straight into the frame's f64 sums.
                self.shared.add_deposits(&[PixelDeposit {
                    x: px,
                    y: py,
                    layer: d.layer,
                    value: d.value,
                }]);
                continue;
            }
            let key = (py / MICRO_TILE) * self.columns + px / MICRO_TILE;
            let slot = if key == self.last.0 {
                self.last.1
            } else {
                self.slot_for(key)
            };
            let i =
                slot as usize * CELLS + ((py % MICRO_TILE) * MICRO_TILE + px % MICRO_TILE) as usize;
            add_to_planes(&mut self.planes, i, d.layer, d.value);
        }
    }
}
