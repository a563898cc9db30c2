//! Flush-to-zero and denormals-are-zero for the length of ray queries, Embree's and the
//! pure-Rust BVH's.
//!
//! Embree's performance notes ask for both MXCSR flags on every thread that traces: without
//! them, denormal operands send its traversal down the CPU's slow microcode path. On an Intel
//! Xeon VM, Embree's share of a Stanford dragon render halved with them (2348–2564 samples →
//! 1185–1261) and the render took 0.65–0.78× the CPU, the image unchanged bit for bit
//! (`127b24e`, 2026-12-03; docs/performance.md, "Standing decisions"). The pure-Rust BVH
//! (`flowlight_bvh::Bvh`) has the same need: a ray leaving a surface that lies in a coordinate
//! plane (the Cornell box's floor and walls at 0) starts at the smallest subnormal in that
//! coordinate (`offset_ray_origin` rounds 0 away from the surface), and every product with it
//! in the triangle test was a microcode assist on Intel: the BVH's Cornell box render took 2.2×
//! the CPU it takes in this mode (`053ae62`, 2026-12-05).
//!
//! The flags are set only around the queries (one query, or a batch's loop of them) and
//! restored right after. So the renderer's own arithmetic, host and plugins alike, keeps
//! IEEE denormals and gives the same bits as before. Rust assumes the default
//! floating-point environment, so between the two MXCSR writes there is only the queries'
//! own arithmetic, their data being moved, integer bookkeeping and the ray interval's
//! comparisons (a denormal `t_max` gives an empty interval in either mode). Where a query
//! calls back into other Rust code, a hit filter, the callback runs in the thread's own mode
//! ([`with_denormals_kept`]).
//!
//! Other architectures: the closure runs as it is.

/// MXCSR bit 15 (FTZ: flush denormal results to zero) and bit 6 (DAZ: read denormal operands
/// as zero).
#[cfg(target_arch = "x86_64")]
const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn read_mxcsr() -> u32 {
    let mut csr = 0u32;
    // SAFETY: `stmxcsr` stores the 32-bit MXCSR to the given, writable address.
    unsafe {
        std::arch::asm!("stmxcsr [{p}]", p = in(reg) &mut csr as *mut u32, options(nostack, preserves_flags));
    }
    csr
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn write_mxcsr(csr: u32) {
    // SAFETY: `ldmxcsr` loads MXCSR from the given address. The values written are the
    // thread's own, read by `read_mxcsr`, with at most the FTZ and DAZ bits changed: valid
    // control words, all exceptions still masked as they were.
    unsafe {
        std::arch::asm!("ldmxcsr [{p}]", p = in(reg) &csr as *const u32, options(nostack, preserves_flags, readonly));
    }
}

/// Runs `f` (ray queries) with FTZ and DAZ set, then restores the thread's mode. Nested, the
/// inner call only reads the mode (no write).
#[inline(always)]
pub fn with_denormals_flushed<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        let old = read_mxcsr();
        if old & FTZ_DAZ == FTZ_DAZ {
            return f();
        }
        write_mxcsr(old | FTZ_DAZ);
        let r = f();
        write_mxcsr(old);
        r
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        f()
    }
}

/// Runs `f` (Rust code a query calls back: a hit filter) with FTZ and DAZ cleared, as the
/// thread had them before the query, then puts the query's mode back.
#[inline(always)]
pub fn with_denormals_kept<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        let query_mode = read_mxcsr();
        write_mxcsr(query_mode & !FTZ_DAZ);
        let r = f();
        write_mxcsr(query_mode);
        r
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        f()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The smallest positive subnormal, halved and doubled by code that cannot be folded.
    /// Every result passes through `black_box`: the compiler assumes the default float mode
    /// and may move a multiplication whose result is not pinned across the MXCSR writes (the
    /// release build computed the callback's doubling after Embree's mode was back, so the
    /// test failed under `cargo test --release` only). `black_box` and the `asm!` blocks keep
    /// their order, so each multiplication runs in the mode around it.
    fn subnormal_round_trip() -> f32 {
        use std::hint::black_box;
        let tiny = black_box(f32::from_bits(2));
        black_box(black_box(tiny * 0.5) * 2.0)
    }

    #[test]
    fn flags_hold_inside_and_are_restored_after() {
        assert_eq!(subnormal_round_trip(), f32::from_bits(2));
        #[cfg(target_arch = "x86_64")]
        {
            let before = read_mxcsr();
            let inside = with_denormals_flushed(|| {
                (
                    read_mxcsr(),
                    subnormal_round_trip(),
                    with_denormals_kept(subnormal_round_trip),
                )
            });
            assert_eq!(inside.0 & FTZ_DAZ, FTZ_DAZ);
            assert_eq!(
                inside.1, 0.0,
                "FTZ/DAZ flush the subnormal inside the query"
            );
            assert_eq!(
                inside.2,
                f32::from_bits(2),
                "the callback sees IEEE denormals"
            );
            assert_eq!(read_mxcsr(), before);
        }
        assert_eq!(subnormal_round_trip(), f32::from_bits(2));
    }
}
