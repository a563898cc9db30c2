//! Memory limits of a render: what its frame and output buffers take, and the refusal of a
//! render that would need more than the memory available (`MemAvailable`, the memory
//! cgroup's limit, `RLIMIT_AS`: [`flowlight_scene::memory`]), before anything is allocated.

use crate::accumulation::Precision;

/// Bytes an exact-precision `width` × `height` render with `layers` lighting layers needs
/// for its image buffers ([`frame_bytes_with`]).
pub fn frame_bytes(width: u32, height: u32, layers: u32) -> Option<u64> {
    frame_bytes_with(width, height, layers, Precision::Exact)
}

/// Bytes a `width` × `height` render with `layers` lighting layers needs for its image
/// buffers, or `None` beyond 2⁶⁴: per pixel, the frame (per framebuffer 48 B of fixed-point
/// RGB sums, or 12 B of f32, plus a u32 sample count) and at write time the resolved f32
/// images, the EXR channel copies and encoded data (12 B each per framebuffer) and 3 B of
/// PNG: (c + 36)·(1 + L) + 7 bytes for c bytes per frame cell. Private buffers (Buffering's
/// thread buffers, Caching's cap) come on top ([`check_memory`]).
pub fn frame_bytes_with(width: u32, height: u32, layers: u32, precision: Precision) -> Option<u64> {
    let planes = (layers as u64).checked_add(1)?;
    let per_pixel = (precision.frame_cell_bytes() + 36)
        .checked_mul(planes)?
        .checked_add(7)?;
    (width as u64)
        .checked_mul(height as u64)?
        .checked_mul(per_pixel)
}

/// The bytes this process may still allocate: the least of the host's `MemAvailable`, the
/// room under its memory cgroup's limit (v2 `memory.max`, v1 `memory.limit_in_bytes`) and
/// the address space left under `RLIMIT_AS` ([`flowlight_scene::memory`]).
pub fn available_memory() -> Option<u64> {
    flowlight_scene::memory::available_memory()
}

fn human_bytes(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b as f64;
    let mut i = 0;
    while v >= 1024.0 && i + 1 < units.len() {
        v /= 1024.0;
        i += 1;
    }
    format!("{v:.1} {}", units[i])
}

/// Refuses an exact-precision render whose image buffers ([`frame_bytes`]) exceed the
/// available memory (or the address space), before anything is allocated.
pub fn check_frame_memory(width: u32, height: u32, layers: u32) -> Result<(), String> {
    check_memory(width, height, layers, Precision::Exact, 0)
}

/// Refuses a render whose image buffers ([`frame_bytes_with`]) and `private` bytes of
/// accumulation buffers exceed the available memory (or the address space).
pub fn check_memory(
    width: u32,
    height: u32,
    layers: u32,
    precision: Precision,
    private: u64,
) -> Result<(), String> {
    let what = format!("a {width}x{height} image with {layers} lighting layers");
    let Some(need) = frame_bytes_with(width, height, layers, precision)
        .and_then(|b| b.checked_add(private))
        .filter(|&b| b <= isize::MAX as u64)
    else {
        return Err(format!(
            "{what} needs more than {} bytes of buffers, beyond this machine's address space; lower render.width/render.height",
            isize::MAX
        ));
    };
    if let Some(avail) = available_memory() {
        if need > avail {
            let hint = if private > need / 2 {
                "; use render.accumulation = \"caching\" or fewer threads"
            } else if precision == Precision::Exact {
                "; lower render.width/render.height, or set render.precision = \"f32\" (a quarter of the frame)"
            } else {
                "; lower render.width/render.height"
            };
            return Err(format!(
                "{what} needs about {} ({need} bytes) of buffers but {} is available{hint}",
                human_bytes(need),
                human_bytes(avail)
            ));
        }
    }
    Ok(())
}
