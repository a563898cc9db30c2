//! The seam metric: how much more the luminance jumps across tile borders than inside tiles
//! (`flowlight seams`).
//!
//! # Why
//!
//! Tile-based ERPT (thesis §5.9) keeps each chain's deposits in its tile's buffer (plus a
//! flange), so energy a chain would have carried over a border is redistributed differently
//! on the two sides. Images split into tiles then show "a lattice pattern" at the tile
//! borders. This module puts a number on that artefact so accumulation styles and tile sizes
//! can be compared.
//!
//! # Formula
//!
//! With luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of the linear RGB pixels (computed in
//! `f64`) and tile size T, take every horizontally adjacent pair (x, x + 1) and every
//! vertically adjacent pair (y, y + 1). A pair is a **border** pair when it straddles a tile
//! border, i.e. (x + 1) mod T = 0 (x is the last column of a tile, x + 1 the first of the
//! next; likewise (y + 1) mod T = 0 for vertical pairs), otherwise an **inside** pair. Then
//!
//! ```text
//! ratio = mean |ΔY| over border pairs / mean |ΔY| over inside pairs
//! ```
//!
//! 1.0 means the borders are indistinguishable from the rest of the image (no visible seams;
//! a smooth image, or noise that is the same everywhere); larger means seams. Tiles are
//! anchored at (0, 0); a partial last tile (T not dividing the size) is fine.
//!
//! The ratio also rises where scene edges fall on tile borders, seams or not: the Cornell
//! box reference at 128 × 128 has 8.9 for T = 16, because a strong scene edge lies between
//! pixels 15 and 16, but 1.09 for T = 15 and 0.10 for T = 32 (below 1: those borders happen
//! to cross smoother parts than the average). Judge a render against the ratio of its
//! reference at the same T, or pick a T that the geometry does not line up with.
//!
//! Degenerate inputs are errors rather than a NaN or infinite ratio: a pixel count that is
//! not width × height, T = 0, no border pairs (T ≥ width and T ≥ height), no inside pairs
//! (T = 1), a zero mean inside gradient (a flat image), and non-finite pixels.

use flowlight_core::Rgb;

/// The seam metric of one image and tile size (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamMetric {
    /// `border_mean / inside_mean`: 1.0 means no visible seams, larger means seams.
    pub ratio: f64,
    /// Mean |ΔY| over the adjacent pixel pairs that straddle a tile border.
    pub border_mean: f64,
    /// Mean |ΔY| over the adjacent pixel pairs inside a tile.
    pub inside_mean: f64,
    /// Number of border pairs (horizontal and vertical together).
    pub border_pairs: u64,
    /// Number of inside pairs (horizontal and vertical together).
    pub inside_pairs: u64,
}

/// Rec.709 luminance in `f64`, so the gradients of exact inputs are exact.
fn luminance(p: Rgb) -> f64 {
    0.2126 * f64::from(p.r) + 0.7152 * f64::from(p.g) + 0.0722 * f64::from(p.b)
}

/// The seam metric of `pixels` (row-major, `width * height`) for square tiles of `tile`
/// pixels anchored at (0, 0): mean |ΔY| across tile borders over mean |ΔY| inside tiles.
///
/// Errors (one line each) for a pixel count that is not `width * height`, `tile == 0`, no
/// border pairs (`tile >= width` and `tile >= height`), no inside pairs (`tile == 1`), a zero
/// inside gradient, and a non-finite pixel.
pub fn seam_metric(
    pixels: &[Rgb],
    width: usize,
    height: usize,
    tile: usize,
) -> Result<SeamMetric, String> {
    let count = width
        .checked_mul(height)
        .ok_or_else(|| format!("image size {width}x{height} overflows"))?;
    if pixels.len() != count {
        return Err(format!(
            "{} pixels for a {width}x{height} image (expected {count})",
            pixels.len()
        ));
    }
    if tile == 0 {
        return Err("tile size must be at least 1".to_owned());
    }
    if tile >= width && tile >= height {
        return Err(format!(
            "tile size {tile} covers the whole {width}x{height} image: no tile borders"
        ));
    }
    if let Some(i) = pixels
        .iter()
        .position(|p| !(p.r.is_finite() && p.g.is_finite() && p.b.is_finite()))
    {
        let p = pixels[i];
        return Err(format!(
            "pixel ({}, {}) is not finite ({}, {}, {})",
            i % width,
            i / width,
            p.r,
            p.g,
            p.b
        ));
    }

    let y: Vec<f64> = pixels.iter().map(|&p| luminance(p)).collect();
    let (mut border_sum, mut inside_sum) = (0.0f64, 0.0f64);
    let (mut border_pairs, mut inside_pairs) = (0u64, 0u64);
    let mut add = |d: f64, border: bool| {
        if border {
            border_sum += d.abs();
            border_pairs += 1;
        } else {
            inside_sum += d.abs();
            inside_pairs += 1;
        }
    };
    for row in 0..height {
        let line = &y[row * width..(row + 1) * width];
        // Horizontal pairs (x, x + 1).
        for x in 0..width.saturating_sub(1) {
            add(line[x + 1] - line[x], (x + 1) % tile == 0);
        }
        // Vertical pairs (row, row + 1).
        if row + 1 < height {
            let border = (row + 1) % tile == 0;
            let next = &y[(row + 1) * width..(row + 2) * width];
            for (a, b) in line.iter().zip(next) {
                add(b - a, border);
            }
        }
    }

    if border_pairs == 0 {
        // Unreachable after the tile-size check, kept so the division below is always sound.
        return Err(format!(
            "no tile borders in a {width}x{height} image with tile size {tile}"
        ));
    }
    if inside_pairs == 0 {
        return Err(format!(
            "tile size {tile} leaves no pixel pairs inside tiles (every pair straddles a border)"
        ));
    }
    let border_mean = border_sum / border_pairs as f64;
    let inside_mean = inside_sum / inside_pairs as f64;
    if inside_mean <= 0.0 {
        return Err(format!(
            "the luminance gradient inside tiles is zero (a flat image?): border mean |dY| {border_mean}, ratio undefined"
        ));
    }
    Ok(SeamMetric {
        ratio: border_mean / inside_mean,
        border_mean,
        inside_mean,
        border_pairs,
        inside_pairs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey image (R = G = B = f(x, y)), row-major.
    fn grey(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Vec<Rgb> {
        (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| Rgb::splat(f(x, y)))
            .collect()
    }

    /// Y of a grey pixel of value v, as the metric computes it.
    fn grey_y(v: f64) -> f64 {
        0.2126 * v + 0.7152 * v + 0.0722 * v
    }

    #[test]
    fn linear_ramp_has_ratio_one() {
        // |ΔY| is the same for every pair (equal slopes in x and y, exact in f32), so border
        // and inside means agree; also with partial tiles (7 does not divide 40 or 30).
        for tile in [2, 4, 7, 16] {
            let (w, h) = (40, 30);
            let img = grey(w, h, |x, y| 0.5 * (x + y) as f32);
            let m = seam_metric(&img, w, h, tile).unwrap();
            assert!((m.ratio - 1.0).abs() < 1e-9, "tile {tile}: {m:?}");
            assert!((m.inside_mean - grey_y(0.5)).abs() < 1e-12, "{m:?}");
            assert_eq!(
                m.border_pairs + m.inside_pairs,
                ((w - 1) * h + w * (h - 1)) as u64
            );
            // Columns x with (x + 1) % tile == 0 and x + 1 < w, per row; likewise rows.
            let borders = (w - 1) / tile * h + (h - 1) / tile * w;
            assert_eq!(m.border_pairs, borders as u64, "tile {tile}");
        }
    }

    #[test]
    fn per_tile_offsets_give_the_hand_computed_ratio() {
        // 4x4 image, 2x2 tiles, value = x + y + offset of the tile:
        //   tile (0,0): 0   tile (1,0): 5
        //   tile (0,1): -3  tile (1,1): 7
        // Inside pairs (8 horizontal + 8 vertical): |ΔY| = 1 each, mean 1.
        // Border pairs (4 horizontal at x = 1..2, 4 vertical at y = 1..2):
        //   horizontal rows 0,1: |1 + 5 - 0| = 6;      rows 2,3: |1 + 7 - (-3)| = 11
        //   vertical columns 0,1: |1 + (-3) - 0| = 2;  columns 2,3: |1 + 7 - 5| = 3
        //   mean (2·6 + 2·11 + 2·2 + 2·3) / 8 = 44 / 8 = 5.5, so the ratio is 5.5.
        let offset = |tx: usize, ty: usize| [[0.0, 5.0], [-3.0, 7.0]][ty][tx];
        let img = grey(4, 4, |x, y| (x + y) as f32 + offset(x / 2, y / 2));
        let m = seam_metric(&img, 4, 4, 2).unwrap();
        assert_eq!((m.border_pairs, m.inside_pairs), (8, 16));
        assert!((m.inside_mean - grey_y(1.0)).abs() < 1e-12, "{m:?}");
        assert!((m.border_mean - grey_y(5.5)).abs() < 1e-12, "{m:?}");
        assert!((m.ratio - 5.5).abs() < 1e-12, "{m:?}");
    }

    #[test]
    fn tile_offsets_on_a_larger_ramp_are_far_above_one() {
        // A gentle ramp plus a different constant per 8x8 tile.
        let (w, h, t) = (64, 48, 8);
        let img = grey(w, h, |x, y| {
            let tile_id = (y / t) * (w / t) + x / t;
            0.01 * (x + 2 * y) as f32 + ((tile_id * 7919) % 13) as f32 * 0.1
        });
        let m = seam_metric(&img, w, h, t).unwrap();
        assert!(m.ratio > 10.0, "{m:?}");
        // Without the offsets the same ramp has no such seams.
        let ramp = grey(w, h, |x, y| 0.01 * (x + 2 * y) as f32);
        let r = seam_metric(&ramp, w, h, t).unwrap();
        assert!(r.ratio < 1.5, "{r:?}");
    }

    #[test]
    fn colour_uses_rec709_luminance() {
        // One row, so only horizontal pairs: G rises by 1 per pixel (inside |ΔY| = 0.7152),
        // and a jump of 1 in B at the border (x = 1..2) adds 0.0722 there.
        let (w, h) = (4, 1);
        let img: Vec<Rgb> = (0..w)
            .map(|x| Rgb::new(0.0, x as f32, if x >= 2 { 1.0 } else { 0.0 }))
            .collect();
        let m = seam_metric(&img, w, h, 2).unwrap();
        assert_eq!((m.border_pairs, m.inside_pairs), (1, 2));
        assert!((m.inside_mean - 0.7152).abs() < 1e-12, "{m:?}");
        assert!((m.border_mean - (0.7152 + 0.0722)).abs() < 1e-12, "{m:?}");
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        let ramp = |w, h| grey(w, h, |x, y| (x + y) as f32);
        let err = |img: &[Rgb], w, h, t| seam_metric(img, w, h, t).unwrap_err();

        // No border pairs: the tile covers the image.
        let e = err(&ramp(8, 6), 8, 6, 8);
        assert!(e.contains("no tile borders"), "{e}");
        assert!(seam_metric(&ramp(8, 6), 8, 6, 7).is_ok());
        let e = err(&ramp(0, 0), 0, 0, 4);
        assert!(e.contains("no tile borders"), "{e}");
        // Tile size 0, and 1 (every pair is a border pair).
        assert!(err(&ramp(8, 6), 8, 6, 0).contains("at least 1"));
        let e = err(&ramp(8, 6), 8, 6, 1);
        assert!(e.contains("no pixel pairs inside"), "{e}");
        // Zero inside gradient: a flat image, and flat tiles with seams between them.
        let e = err(&grey(8, 8, |_, _| 0.25), 8, 8, 4);
        assert!(e.contains("gradient inside tiles is zero"), "{e}");
        let steps = grey(8, 8, |x, y| ((x / 4) + 2 * (y / 4)) as f32);
        assert!(err(&steps, 8, 8, 4).contains("zero"));
        // Non-finite pixels name the pixel.
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut img = ramp(8, 6);
            img[2 * 8 + 5].g = bad;
            let e = err(&img, 8, 6, 4);
            assert!(e.contains("pixel (5, 2) is not finite"), "{e}");
        }
        // Wrong pixel count.
        let e = err(&ramp(8, 6), 8, 5, 4);
        assert!(e.contains("48 pixels for a 8x5 image"), "{e}");
    }
}
