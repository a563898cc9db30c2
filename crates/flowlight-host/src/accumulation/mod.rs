//! Accumulation: the image being rendered ([`Frame`]), and the three ways work units feed it
//! (thesis §5.9, "Accumulation Styles").
//!
//! # The three styles
//!
//! | style | private memory | when it flushes | locks |
//! |---|---|---|---|
//! | [`Style::Blasting`] | one buffer per work unit: its tile (plus the integrator's flange) | when the unit ends | one per framebuffer, once per unit |
//! | [`Style::Buffering`] | one whole-image buffer per worker thread (pane-based splitting) | once, when the render ends | one per framebuffer, once per thread |
//! | [`Style::Caching`] | per worker thread, a cache of 8×8-pixel micro-tiles within a memory cap | when a cache fills (its older half) and when the render ends | one per framebuffer, once per flushed batch |
//!
//! A *framebuffer* is the main image or one lighting layer; the shared frame
//! ([`SharedFrame`]) keeps one mutex per framebuffer, so two threads flushing different
//! layers never wait on each other. Blasting is path tracing's style: a unit's deposits fall
//! in its own tile, so the buffer is small and the writes into the shared frame are
//! disjoint. Markov chains wander: Buffering gives every thread the whole image (memory
//! grows with threads × framebuffers, the trap §5.9 warns of), Caching keeps only the
//! micro-tiles a thread's chains visit recently, so its memory is capped whatever the
//! threads and layers. The host picks Blasting for tile-local integrators and Caching for
//! flanged ones (`render.accumulation = "auto"`); the config can force any style for any
//! integrator. No deposit on the film is ever dropped: Blasting keeps deposits beyond its
//! buffer in an overflow list merged with the unit, the other styles cover the whole film.
//!
//! # Precision
//!
//! `render.precision` picks the frame's number format:
//!
//! * `"exact"` (default): **fixed-point sums**. Every deposit's channel value v ≥ 0 becomes
//!   q(v) = ⌊v · 2^[`FIXED_FRAC_BITS`]⌋ in a `u128` ([`to_fixed`]), and every sum (private
//!   buffers, caches, frame) is an integer addition. Integer addition is associative, so a
//!   pixel's sum is Σ q(v) whatever the grouping into units, caches, flushes, threads,
//!   passes or sample ranges: the three styles, any thread count and any split into
//!   distributed parts give the **same bits** (docs/distributed.md). The scale 2⁻⁶⁴ keeps
//!   every f32 value down to 2⁻⁴¹ ≈ 4.5·10⁻¹³ exactly (smaller ones lose their bits below
//!   2⁻⁶⁴, an absolute error under 10⁻¹⁹ per deposit). Channel values of [`FIXED_LIMIT`]
//!   (2³²) or more, which only absurdly bright scenes deposit, go to a sparse per-pixel f64
//!   sum instead ([`Frame`]'s large-value map), added in floating point. Cost: 48 bytes per
//!   RGB pixel and framebuffer, four times an f32 image.
//! * `"f32"`: **f32 frame, f64 partial sums**. The frame holds f32 sums (12 bytes per RGB
//!   pixel and framebuffer: one f32 framebuffer set); every private buffer (unit tiles,
//!   thread buffers, cache micro-tiles) sums its deposits in f64. f64 is needed there and
//!   only there: a private buffer takes thousands of small deposits per pixel (an ERPT chain
//!   deposits one quantum per mutation), and an f32 running sum of n such terms loses up to
//!   n·2⁻²⁴ of it, and every term below 2⁻²⁵ of the sum outright (stagnation). The frame
//!   takes one addition per flush of a pixel, a partial sum of many deposits, so k flushes
//!   cost at most k·2⁻²⁴ relative (round-to-nearest errors are unbiased: about √k·2⁻²⁴ in
//!   practice, 6·10⁻⁶ after 10⁴ flushes of one pixel, which the 1080p renders of
//!   docs/performance.md stay far below), under Monte Carlo noise. The f64 partial sums do
//!   the compensating: no separate compensation term is stored in the frame, which would
//!   double it (the memory bound of the Caching style is one f32 framebuffer set). The image no longer depends on the thread
//!   count beyond that rounding, but is not bitwise reproducible across styles or threads
//!   (flush order varies), and distributed parts (`--part`), which merge exact sums, refuse
//!   it.
//!
//! # Limits
//! [`crate::render::check_frame_memory`] refuses, before allocating, a render whose frame,
//! private buffers and output copies exceed the available memory.

mod buffer;
mod cache;
mod cells;
mod frame;
mod shared;
#[cfg(test)]
mod tests;
mod tile;

pub use buffer::ThreadBuffer;
pub use cache::{MicroTileCache, MICRO_TILE};
pub use cells::Cells;
pub use frame::{Frame, LargeSums, Plane};
pub use shared::{FlushCounts, SharedFrame};
pub use tile::TileAccumulator;

use flowlight_core::Rgb;

/// The frame's number format (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Precision {
    /// Fixed-point `u128` sums: order-free, bitwise reproducible.
    #[default]
    Exact,
    /// f32 frame fed by f64 partial sums: a quarter of the memory.
    F32,
}

impl Precision {
    /// Bytes of one RGB pixel of one framebuffer in the frame.
    pub fn frame_cell_bytes(self) -> u64 {
        match self {
            Precision::Exact => 48,
            Precision::F32 => 12,
        }
    }

    /// Bytes of one RGB pixel of a private buffer (exact: `u128`, f32: f64 partial sums).
    pub fn partial_cell_bytes(self) -> u64 {
        match self {
            Precision::Exact => 48,
            Precision::F32 => 24,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Precision::Exact => "exact",
            Precision::F32 => "f32",
        }
    }
}

/// How work units feed the frame (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    Blasting,
    Buffering,
    Caching,
}

impl Style {
    pub fn name(self) -> &'static str {
        match self {
            Style::Blasting => "blasting",
            Style::Buffering => "buffering",
            Style::Caching => "caching",
        }
    }
}

/// Deposit counts an accumulator reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct DepositCounts {
    /// Deposits with a NaN, infinite or negative value: counted, never written.
    pub invalid: u64,
    /// Deposits off the film: counted and dropped (a plugin bug).
    pub stray: u64,
    /// Deposits beyond a Blasting unit's buffer, merged from its overflow list.
    pub overflow: u64,
}

/// A deposit kept for pixel (x, y) outside a private buffer, or too large for fixed point.
#[derive(Clone, Copy, Debug)]
pub struct PixelDeposit {
    pub x: u32,
    pub y: u32,
    pub layer: u32,
    pub value: Rgb,
}

/// Where a deposit goes: `Some((x, y))` for a valid deposit on a `width` × `height` film;
/// `None` (counted) for an invalid value or a position off the film.
#[inline]
pub(crate) fn classify(
    d: &flowlight_sdk::abi::Deposit,
    width: u32,
    height: u32,
    counts: &mut DepositCounts,
) -> Option<(u32, u32)> {
    if !d.value.is_valid_radiance() {
        counts.invalid += 1;
        return None;
    }
    // ⌊x⌋ ∈ [0, width) exactly when x ∈ [0, width) (width is an integer), and there the
    // truncating cast is ⌊x⌋: no `floorf`, which baseline x86-64 calls out to libm (1.2% of
    // a Cornell box render). NaN fails the comparisons, as it did ⌊NaN⌋'s.
    if !(d.x >= 0.0 && d.y >= 0.0 && d.x < width as f32 && d.y < height as f32) {
        counts.stray += 1;
        return None;
    }
    Some((d.x as u32, d.y as u32))
}

/// True when an exact-precision accumulator must send `v` to the f64 large-value sums.
#[inline]
pub(crate) fn is_large(v: Rgb) -> bool {
    v.r >= FIXED_LIMIT || v.g >= FIXED_LIMIT || v.b >= FIXED_LIMIT
}

/// Fractional bits of the fixed-point sums (module documentation).
pub const FIXED_FRAC_BITS: i32 = 64;

/// Channel values from here on are summed in f64 rather than in fixed point (2³²).
pub const FIXED_LIMIT: f32 = 4_294_967_296.0;

/// q(v) = ⌊v · 2⁶⁴⌋ for a deposit value v ≥ 0, saturating at `u128::MAX` (+∞ too); NaN and
/// negative values, which never reach an accumulator, give 0.
///
/// Read off the float's bits: v = M · 2^(e − 150) for a normal v (M the 24-bit significand,
/// e the biased exponent), so q = M · 2^(e − 86), a shift of M. It is the value
/// `(v as f64 * 2⁶⁴) as u128` gives (the test compares them on a million bit patterns), without
/// that cast's call into compiler-rt's soft `__fixunsdfti` (1.8% of a direct-light Cornell
/// box render; three per deposit, six when the render keeps lighting layers).
#[inline]
pub fn to_fixed(v: f32) -> u128 {
    let bits = v.to_bits();
    if bits >> 31 != 0 {
        return 0; // negative, −0 or a NaN with the sign bit set
    }
    let e = (bits >> 23) as i32;
    if e == 0xff {
        return if bits & 0x7f_ffff == 0 { u128::MAX } else { 0 }; // +∞ or NaN
    }
    if e == 0 {
        return 0; // subnormal: below 2⁻¹²⁶, far below 2⁻⁶⁴
    }
    let m = ((bits & 0x7f_ffff) | 0x80_0000) as u128;
    let shift = e - (150 - FIXED_FRAC_BITS);
    if shift >= 0 {
        // m < 2²⁴, so m << shift fits while shift ≤ 104.
        if shift > 104 {
            u128::MAX
        } else {
            m << shift
        }
    } else if shift > -24 {
        m >> -shift
    } else {
        0
    }
}

/// A fixed-point sum as a float: s · 2⁻⁶⁴ (rounded to the nearest f64).
#[inline]
pub fn from_fixed(s: u128) -> f64 {
    s as f64 * (2.0f64).powi(-FIXED_FRAC_BITS)
}

#[inline]
pub(crate) fn add_sums(acc: &mut [u128; 3], v: &[u128; 3]) {
    for c in 0..3 {
        acc[c] = acc[c].saturating_add(v[c]);
    }
}

#[cfg(test)]
mod fixed_tests {
    use super::*;

    /// The float-cast form `to_fixed` replaces: f32 → f64 is exact, × 2⁶⁴ is exact, and the
    /// cast truncates towards zero, saturates, and takes NaN to 0.
    fn by_cast(v: f32) -> u128 {
        (v as f64 * (2.0f64).powi(FIXED_FRAC_BITS)) as u128
    }

    #[test]
    fn fixed_point_from_the_bits_is_the_float_cast() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            0.5,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::EPSILON,
            5.421_011e-20, // 2⁻⁶⁴
            5.421_010_4e-20,
            1.0e-19,
            FIXED_LIMIT,
            1.844_674_4e19, // 2⁶⁴: the first that saturates
            1.844_674_3e19,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            -1.0,
        ];
        for v in specials {
            assert_eq!(to_fixed(v), by_cast(v), "{v:e} ({:#x})", v.to_bits());
        }
        // About a million bit patterns over the whole range (both signs, NaNs, subnormals),
        // and every pattern around each exponent where the shift changes sign or saturates.
        let mut checked = 0;
        for bits in (0..=u32::MAX).step_by(4093) {
            let v = f32::from_bits(bits);
            assert_eq!(to_fixed(v), by_cast(v), "{v:e} ({bits:#x})");
            checked += 1;
        }
        for e in [1u32, 61, 62, 63, 85, 86, 87, 189, 190, 191, 254] {
            for m in [0u32, 1, 2, 0x40_0000, 0x7f_fffe, 0x7f_ffff] {
                let v = f32::from_bits(e << 23 | m);
                assert_eq!(to_fixed(v), by_cast(v), "{v:e}");
            }
        }
        assert!(checked > 1_000_000);
    }
}
