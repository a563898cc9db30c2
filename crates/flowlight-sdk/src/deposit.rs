//! Deposit batching: a plugin's [`Film`] gathers deposits and hands them to the host's
//! accumulators ([`Accumulator`]) in coarse calls.

use crate::abi::{Deposit, FilmTable};
use flowlight_core::Rgb;

/// Batches deposits locally and hands them to the host's accumulator in coarse calls.
/// Flushed when full and when dropped.
pub struct Film<'a> {
    table: &'a FilmTable,
    buffer: [Deposit; Film::BATCH],
    len: usize,
}

impl<'a> Film<'a> {
    /// Deposits buffered before they are handed to the host in one call.
    pub const BATCH: usize = 256;

    /// A film over the host's accumulator `table`.
    pub fn new(table: &'a FilmTable) -> Self {
        Film {
            table,
            buffer: [Deposit {
                x: 0.0,
                y: 0.0,
                layer: 0,
                value: Rgb::ZERO,
            }; Film::BATCH],
            len: 0,
        }
    }

    /// Records `value` at raster position (x, y) in lighting `layer`. Zero values are skipped;
    /// the host discards and counts non-finite or negative ones.
    #[inline]
    pub fn deposit(&mut self, x: f32, y: f32, layer: u32, value: Rgb) {
        if value.is_black() {
            return;
        }
        self.buffer[self.len] = Deposit { x, y, layer, value };
        self.len += 1;
        if self.len == Film::BATCH {
            self.flush();
        }
    }

    /// Hands the buffered deposits to the host (also done when full and on drop).
    pub fn flush(&mut self) {
        if self.len > 0 {
            // SAFETY: the buffer holds `len` initialised deposits for the call's duration.
            unsafe { (self.table.deposit)(self.table.ctx, self.buffer.as_ptr(), self.len) };
            self.len = 0;
        }
    }
}

impl Drop for Film<'_> {
    fn drop(&mut self) {
        self.flush();
    }
}

/// The host side of a film: anything that can take a batch of deposits. The host implements
/// it for its accumulators and exposes them through [`Accumulator::table`].
pub trait Accumulator {
    /// Accumulates a batch of deposits.
    fn deposit(&mut self, deposits: &[Deposit]);

    /// A C-ABI table pointing at `self`, valid while `self` is borrowed.
    fn table(&mut self) -> FilmTable
    where
        Self: Sized,
    {
        unsafe extern "C" fn trampoline<A: Accumulator>(
            ctx: *mut std::ffi::c_void,
            d: *const Deposit,
            n: usize,
        ) {
            // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
            // ABI rules in `abi.rs` for the C entry points).
            unsafe {
                let acc = &mut *(ctx as *mut A);
                let deposits = if n == 0 {
                    &[][..]
                } else {
                    std::slice::from_raw_parts(d, n)
                };
                // A panic must not unwind into the plugin: abort instead.
                if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| acc.deposit(deposits)))
                    .is_err()
                {
                    std::process::abort();
                }
            }
        }
        FilmTable {
            ctx: self as *mut Self as *mut std::ffi::c_void,
            deposit: trampoline::<Self>,
        }
    }
}
