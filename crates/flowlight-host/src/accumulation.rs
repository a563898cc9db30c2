//! Accumulators: the whole-image frame and the per-unit tile buffers merged into it
//! (thesis §5.9).
//!
//! Each work unit deposits into a private buffer covering its tile and, for integrators whose
//! chains wander (ERPT), a flange around it; the host merges the buffer into the frame when
//! the unit ends, so no locking happens while a unit runs. A deposit beyond the flange is not
//! lost: it is kept in the unit's overflow list and merged the same way.
//!
//! # Exact, order-free sums
//!
//! Every sum (tile buffers, pass and frame) is a fixed-point integer: each deposit's channel
//! value v ≥ 0 becomes q(v) = ⌊v · 2^[`FIXED_FRAC_BITS`]⌋ in a `u128` ([`to_fixed`]), and
//! sums are integer additions. Integer addition is associative, so a pixel's sum is
//! Σ_deposits q(v) whatever the grouping into units, passes, threads or sample ranges: a
//! render of samples [0, 64) and the merge of renders of [0, 16), [16, 32), … hold the same
//! integers, and resolve to the same bits (docs/distributed.md). Floating-point sums could
//! not promise that (f64 addition is not associative). The scale 2⁻⁶⁴ ≈ 5.4·10⁻²⁰ keeps
//! every f32 value down to 2⁻⁴¹ ≈ 4.5·10⁻¹³ exactly (smaller ones lose their bits below
//! 2⁻⁶⁴, an absolute error under 10⁻¹⁹ per deposit). Channel values of [`FIXED_LIMIT`]
//! (2³² ≈ 4.3·10⁹) or more, which only absurdly bright scenes deposit (a 10³⁰ emitter is
//! legal), go to a sparse per-pixel f64 sum instead ([`Frame`]'s large-value map), so the
//! fixed-point sums never saturate before 2³² such deposits; those large values are added
//! in floating point, where the order can matter, and only they.

use flowlight_core::Rgb;
use flowlight_sdk::abi::Deposit;
use flowlight_sdk::Accumulator;

/// The image being rendered: sums of deposits (main image and lighting layers) and, per
/// pixel, how many camera samples have been completed. Fixed-point sums (module
/// documentation) keep long renders exact and independent of the order of additions.
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub layer_count: u32,
    main: Vec<[u128; 3]>,
    layers: Vec<Vec<[u128; 3]>>,
    samples: Vec<u32>,
    /// When set, every pixel is divided by this many samples instead of its own count
    /// (flanged integrators, whose pixels also receive their neighbours' deposits).
    uniform_spp: Option<f64>,
    /// Channel values ≥ [`FIXED_LIMIT`], summed in f64 per pixel: index 0 the main image,
    /// k + 1 layer k (sparse: empty in ordinary renders).
    large: Vec<LargeSums>,
}

/// Per-pixel f64 sums of large channel values (pixel index → RGB).
pub type LargeSums = std::collections::BTreeMap<usize, [f64; 3]>;

impl Frame {
    pub fn new(width: u32, height: u32, layer_count: u32) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width,
            height,
            layer_count,
            main: vec![[0; 3]; n],
            layers: (0..layer_count).map(|_| vec![[0; 3]; n]).collect(),
            samples: vec![0; n],
            uniform_spp: None,
            large: vec![LargeSums::new(); layer_count as usize + 1],
        }
    }

    /// A frame from stored sums (a part of a distributed render read back): `main` and each
    /// of `layers` hold `width · height` fixed-point RGB sums, `samples` the per-pixel counts.
    pub fn from_sums(
        width: u32,
        height: u32,
        main: Vec<[u128; 3]>,
        layers: Vec<Vec<[u128; 3]>>,
        samples: Vec<u32>,
        uniform_spp: Option<f64>,
        large: Vec<LargeSums>,
    ) -> Frame {
        let n = width as usize * height as usize;
        debug_assert!(main.len() == n && samples.len() == n && layers.iter().all(|l| l.len() == n));
        debug_assert_eq!(large.len(), layers.len() + 1);
        Frame {
            width,
            height,
            layer_count: layers.len() as u32,
            main,
            layers,
            samples,
            uniform_spp,
            large,
        }
    }

    /// The f64 sums of large channel values: `k` = 0 the main image, k + 1 layer k.
    pub fn large_sums(&self, k: usize) -> &LargeSums {
        &self.large[k]
    }

    /// The fixed-point sums of the main image.
    pub fn main_sums(&self) -> &[[u128; 3]] {
        &self.main
    }

    /// The fixed-point sums of lighting layer `k`.
    pub fn layer_sums(&self, k: usize) -> &[[u128; 3]] {
        &self.layers[k]
    }

    /// The uniform sample count set by [`Frame::set_uniform_spp`], if any.
    pub fn uniform_spp(&self) -> Option<f64> {
        self.uniform_spp
    }

    /// Normalises every pixel by `spp` samples, which may be fractional (a pass cut after
    /// m of its n tiles counts m/n: see the scheduler's documentation), instead of by the
    /// pixel's own sample count. With `spp` = 0 the image is black.
    pub fn set_uniform_spp(&mut self, spp: f64) {
        self.uniform_spp = Some(spp);
    }

    fn add_at(&mut self, f: usize, layer: u32, v: Rgb) {
        let mut large = [0.0f64; 3];
        let mut small = [0u128; 3];
        for (c, x) in v.to_array().into_iter().enumerate() {
            if x >= FIXED_LIMIT {
                large[c] = x as f64;
            } else {
                small[c] = to_fixed(x);
            }
        }
        add_sums(&mut self.main[f], &small);
        if let Some(l) = self.layers.get_mut(layer as usize) {
            add_sums(&mut l[f], &small);
        }
        if large != [0.0; 3] {
            let mut put = |k: usize| {
                let e = self.large[k].entry(f).or_insert([0.0; 3]);
                for c in 0..3 {
                    e[c] += large[c];
                }
            };
            put(0);
            if (layer as usize) < self.layers.len() {
                put(layer as usize + 1);
            }
        }
    }

    /// Adds a finished unit: its buffer (tile and flange), its overflow deposits, and
    /// `samples` more samples for each pixel of its tile.
    pub fn merge(&mut self, tile: &TileAccumulator, samples: u32) {
        let bw = (tile.bx1 - tile.bx0) as usize;
        for y in tile.by0..tile.by1 {
            for x in tile.bx0..tile.bx1 {
                let t = (y - tile.by0) as usize * bw + (x - tile.bx0) as usize;
                let f = y as usize * self.width as usize + x as usize;
                add_sums(&mut self.main[f], &tile.main[t]);
                for (l, layer) in self.layers.iter_mut().enumerate() {
                    add_sums(&mut layer[f], &tile.layers[l][t]);
                }
            }
        }
        for d in &tile.overflow {
            let f = d.y as usize * self.width as usize + d.x as usize;
            self.add_at(f, d.layer, d.value);
        }
        for y in tile.y0..tile.y1 {
            for x in tile.x0..tile.x1 {
                self.samples[y as usize * self.width as usize + x as usize] += samples;
            }
        }
    }

    /// Adds another frame of the same size (a finished pass): its sums and sample counts.
    pub fn add_frame(&mut self, other: &Frame) {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        for (a, b) in self.main.iter_mut().zip(&other.main) {
            add_sums(a, b);
        }
        for (la, lb) in self.layers.iter_mut().zip(&other.layers) {
            for (a, b) in la.iter_mut().zip(lb) {
                add_sums(a, b);
            }
        }
        for (a, b) in self.samples.iter_mut().zip(&other.samples) {
            *a += b;
        }
        for (la, lb) in self.large.iter_mut().zip(&other.large) {
            for (f, v) in lb {
                let e = la.entry(*f).or_insert([0.0; 3]);
                for c in 0..3 {
                    e[c] += v[c];
                }
            }
        }
    }

    /// Zeroes every sum and count, keeping the buffers.
    pub fn clear(&mut self) {
        self.main.fill([0; 3]);
        for l in &mut self.layers {
            l.fill([0; 3]);
        }
        self.samples.fill(0);
        for l in &mut self.large {
            l.clear();
        }
    }

    pub fn samples(&self) -> &[u32] {
        &self.samples
    }

    fn resolve_sums(&self, sums: &[[u128; 3]], large: &LargeSums) -> Vec<Rgb> {
        let scaled = |i: usize, s: &[u128; 3], k: f64| {
            let l = large.get(&i).copied().unwrap_or([0.0; 3]);
            Rgb::new(
                ((from_fixed(s[0]) + l[0]) * k) as f32,
                ((from_fixed(s[1]) + l[1]) * k) as f32,
                ((from_fixed(s[2]) + l[2]) * k) as f32,
            )
        };
        if let Some(n) = self.uniform_spp {
            let k = if n > 0.0 { 1.0 / n } else { 0.0 };
            return sums
                .iter()
                .enumerate()
                .map(|(i, s)| scaled(i, s, k))
                .collect();
        }
        sums.iter()
            .zip(&self.samples)
            .enumerate()
            .map(|(i, (s, &n))| {
                if n == 0 {
                    Rgb::ZERO
                } else {
                    scaled(i, s, 1.0 / n as f64)
                }
            })
            .collect()
    }

    /// The main image: each pixel's sum over its sample count (black where none finished),
    /// or over the uniform count when one is set.
    pub fn image(&self) -> Vec<Rgb> {
        self.resolve_sums(&self.main, &self.large[0])
    }

    /// Lighting layer `k`, normalised like the main image.
    pub fn layer(&self, k: usize) -> Vec<Rgb> {
        self.resolve_sums(&self.layers[k], &self.large[k + 1])
    }
}

/// Fractional bits of the fixed-point sums (module documentation).
pub const FIXED_FRAC_BITS: i32 = 64;

/// Channel values from here on are summed in f64 rather than in fixed point (2³²).
pub const FIXED_LIMIT: f32 = 4_294_967_296.0;

/// q(v) = ⌊v · 2⁶⁴⌋ for a deposit value v ≥ 0 (the cast truncates and saturates; NaN and
/// negative values, which never reach an accumulator, would give 0).
#[inline]
pub fn to_fixed(v: f32) -> u128 {
    (v as f64 * (2.0f64).powi(FIXED_FRAC_BITS)) as u128
}

/// A fixed-point sum as a float: s · 2⁻⁶⁴ (rounded to the nearest f64).
#[inline]
pub fn from_fixed(s: u128) -> f64 {
    s as f64 * (2.0f64).powi(-FIXED_FRAC_BITS)
}

#[inline]
fn add(acc: &mut [u128; 3], v: Rgb) {
    acc[0] = acc[0].saturating_add(to_fixed(v.r));
    acc[1] = acc[1].saturating_add(to_fixed(v.g));
    acc[2] = acc[2].saturating_add(to_fixed(v.b));
}

#[inline]
fn add_sums(acc: &mut [u128; 3], v: &[u128; 3]) {
    for c in 0..3 {
        acc[c] = acc[c].saturating_add(v[c]);
    }
}

/// Deposit counts a unit's accumulator reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct DepositCounts {
    /// Deposits with a NaN, infinite or negative value: counted, never written.
    pub invalid: u64,
    /// Deposits off the film: counted and dropped (a plugin bug).
    pub stray: u64,
    /// Deposits beyond the flange, merged from the overflow list.
    pub overflow: u64,
}

/// A deposit kept for pixel (x, y) outside the unit's buffer.
#[derive(Clone, Copy, Debug)]
pub struct PixelDeposit {
    pub x: u32,
    pub y: u32,
    pub layer: u32,
    pub value: Rgb,
}

/// A work unit's private buffer: its tile plus a flange, clipped to the film.
pub struct TileAccumulator {
    /// The tile (whose pixels the unit samples).
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
    /// The buffer: tile plus flange, clipped to the film.
    bx0: u32,
    by0: u32,
    bx1: u32,
    by1: u32,
    width: u32,
    height: u32,
    main: Vec<[u128; 3]>,
    layers: Vec<Vec<[u128; 3]>>,
    overflow: Vec<PixelDeposit>,
    pub counts: DepositCounts,
}

impl TileAccumulator {
    /// A buffer for tile [x0, x1) × [y0, y1) of a `width` × `height` film with `flange`
    /// pixels around it.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        x0: u32,
        y0: u32,
        x1: u32,
        y1: u32,
        flange: u32,
        width: u32,
        height: u32,
        layer_count: u32,
    ) -> Self {
        let (bx0, by0) = (x0.saturating_sub(flange), y0.saturating_sub(flange));
        let (bx1, by1) = ((x1 + flange).min(width), (y1 + flange).min(height));
        let n = ((bx1 - bx0) * (by1 - by0)) as usize;
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
            main: vec![[0; 3]; n],
            layers: (0..layer_count).map(|_| vec![[0; 3]; n]).collect(),
            overflow: Vec::new(),
            counts: DepositCounts::default(),
        }
    }
}

impl Accumulator for TileAccumulator {
    fn deposit(&mut self, deposits: &[Deposit]) {
        for d in deposits {
            if !d.value.is_valid_radiance() {
                self.counts.invalid += 1;
                continue;
            }
            let (fx, fy) = (d.x.floor(), d.y.floor());
            if !(fx >= 0.0 && fy >= 0.0 && fx < self.width as f32 && fy < self.height as f32) {
                self.counts.stray += 1;
                continue;
            }
            let (px, py) = (fx as u32, fy as u32);
            let large = d.value.to_array().iter().any(|&c| c >= FIXED_LIMIT);
            if large {
                // The frame sums large values in f64 (module documentation).
                self.overflow.push(PixelDeposit {
                    x: px,
                    y: py,
                    layer: d.layer,
                    value: d.value,
                });
                continue;
            }
            if px < self.bx0 || py < self.by0 || px >= self.bx1 || py >= self.by1 {
                self.counts.overflow += 1;
                self.overflow.push(PixelDeposit {
                    x: px,
                    y: py,
                    layer: d.layer,
                    value: d.value,
                });
                continue;
            }
            let i = (py - self.by0) as usize * (self.bx1 - self.bx0) as usize
                + (px - self.bx0) as usize;
            add(&mut self.main[i], d.value);
            if let Some(layer) = self.layers.get_mut(d.layer as usize) {
                add(&mut layer[i], d.value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn d(x: f32, y: f32, layer: u32, v: f32) -> Deposit {
        Deposit {
            x,
            y,
            layer,
            value: Rgb::splat(v),
        }
    }

    #[test]
    fn tile_discards_and_counts_invalid_deposits() {
        let mut t = TileAccumulator::new(2, 2, 4, 4, 0, 4, 4, 2);
        t.deposit(&[
            d(2.5, 2.5, 0, 1.0),
            d(3.5, 2.5, 1, 2.0),
            d(2.5, 2.5, 0, f32::NAN),
            d(2.5, 2.5, 0, f32::INFINITY),
            d(2.5, 2.5, 0, -1.0),
            d(-0.5, 0.5, 0, 1.0),
        ]);
        assert_eq!(t.counts.invalid, 3);
        assert_eq!(t.counts.stray, 1);
        let mut f = Frame::new(4, 4, 2);
        f.merge(&t, 2);
        let img = f.image();
        assert_eq!(img[2 * 4 + 2], Rgb::splat(0.5));
        assert_eq!(img[2 * 4 + 3], Rgb::splat(1.0));
        assert_eq!(img[0], Rgb::ZERO);
        assert_eq!(f.layer(1)[2 * 4 + 3], Rgb::splat(1.0));
        assert_eq!(f.layer(0)[2 * 4 + 3], Rgb::ZERO);
        assert_eq!(f.samples()[0], 0);
    }

    #[test]
    fn flange_and_overflow_deposits_are_merged_not_lost() {
        // Tile (4..6)², flange 1 → buffer (3..7)² of an 8×8 film.
        let mut t = TileAccumulator::new(4, 4, 6, 6, 1, 8, 8, 0);
        t.deposit(&[
            d(4.5, 4.5, 0, 1.0),
            d(3.5, 6.5, 0, 2.0),
            d(0.5, 7.5, 0, 3.0),
        ]);
        assert_eq!(t.counts.overflow, 1);
        let mut f = Frame::new(8, 8, 0);
        f.merge(&t, 1);
        // Other units sample the flange and overflow pixels.
        let other = TileAccumulator::new(0, 0, 8, 8, 0, 8, 8, 0);
        f.merge(&other, 1);
        let img = f.image();
        assert_eq!(img[4 * 8 + 4], Rgb::splat(0.5));
        assert_eq!(img[6 * 8 + 3], Rgb::splat(2.0));
        assert_eq!(img[7 * 8], Rgb::splat(3.0));
        assert_eq!(f.samples()[4 * 8 + 4], 2);
        assert_eq!(f.samples()[0], 1);
    }

    #[test]
    fn uniform_normalisation_divides_every_pixel_alike() {
        // Pixel 0 got a neighbour's deposit but no sample of its own: per-pixel
        // normalisation leaves it black, a uniform 1.5 samples does not.
        let mut t = TileAccumulator::new(1, 0, 2, 1, 1, 2, 1, 1);
        t.deposit(&[d(0.5, 0.5, 0, 3.0), d(1.5, 0.5, 0, 6.0)]);
        let mut f = Frame::new(2, 1, 1);
        f.merge(&t, 1);
        assert_eq!(f.image(), vec![Rgb::ZERO, Rgb::splat(6.0)]);
        f.set_uniform_spp(1.5);
        assert_eq!(f.image(), vec![Rgb::splat(2.0), Rgb::splat(4.0)]);
        assert_eq!(f.layer(0), vec![Rgb::splat(2.0), Rgb::splat(4.0)]);
        f.set_uniform_spp(0.0);
        assert_eq!(f.image(), vec![Rgb::ZERO; 2]);
    }

    #[test]
    fn sums_do_not_depend_on_the_grouping_of_deposits() {
        // Values whose f32/f64 sums depend on the order: 1e8 + 1 − … in floating point.
        let values = [1.0e8f32, 1.0, 3.0e-7, 2.5, 7.0e-12, 1.0e8, 0.1];
        let mut one = TileAccumulator::new(0, 0, 1, 1, 0, 1, 1, 0);
        for &v in &values {
            one.deposit(&[d(0.5, 0.5, 0, v)]);
        }
        let mut a = Frame::new(1, 1, 0);
        a.merge(&one, 7);
        // The same deposits split over three units merged in another order.
        let mut b = Frame::new(1, 1, 0);
        for chunk in [&values[4..], &values[..2], &values[2..4]] {
            let mut t = TileAccumulator::new(0, 0, 1, 1, 0, 1, 1, 0);
            for &v in chunk.iter().rev() {
                t.deposit(&[d(0.5, 0.5, 0, v)]);
            }
            let mut pass = Frame::new(1, 1, 0);
            pass.merge(&t, chunk.len() as u32);
            b.add_frame(&pass);
        }
        assert_eq!(a.main_sums(), b.main_sums());
        assert_eq!(a.image()[0].r.to_bits(), b.image()[0].r.to_bits());
        // And the sum is the exact one, to 2⁻⁶⁴ per deposit.
        let exact: f64 = values.iter().map(|&v| v as f64).sum();
        assert!((from_fixed(a.main_sums()[0][0]) - exact).abs() <= 1e-9 * exact);
        assert_eq!(to_fixed(1.0), 1u128 << 64);
        // A 10³⁰ deposit keeps its energy (f64 side sum), beside a small one in fixed point.
        let mut t = TileAccumulator::new(0, 0, 1, 1, 0, 1, 1, 1);
        t.deposit(&[d(0.5, 0.5, 0, 1.0e30), d(0.5, 0.5, 0, 0.5)]);
        let mut f = Frame::new(1, 1, 1);
        f.merge(&t, 2);
        let r = f.image()[0].r as f64;
        assert!((r / 5.0e29 - 1.0).abs() < 1e-6, "{r}");
        assert_eq!(f.layer(0)[0], f.image()[0]);
        assert_eq!(f.large_sums(0).len(), 1);
        assert_eq!(to_fixed(0.5) + to_fixed(0.25), to_fixed(0.75));
    }
}
