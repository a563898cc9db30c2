//! The image being rendered: the frame's framebuffers (main image and lighting layers) in
//! the render's precision, and the per-pixel sample counts.

use super::cells::Cells;
use super::{add_sums, from_fixed, is_large, to_fixed, Precision};
use flowlight_core::Rgb;

/// One framebuffer's RGB sums: fixed point (exact precision), or f32 stored as planar R, G,
/// B channels (the EXR's layout, so a resolved f32 framebuffer is its sums scaled in place).
pub enum Plane {
    Exact(Vec<[u128; 3]>),
    F32([Vec<f32>; 3]),
}

impl Plane {
    pub fn new(precision: Precision, n: usize) -> Plane {
        match precision {
            Precision::Exact => Plane::Exact(vec![[0; 3]; n]),
            Precision::F32 => Plane::F32(std::array::from_fn(|_| vec![0.0; n])),
        }
    }

    /// Adds `n` partial sums `cells[src..src + n]` to pixels `dst..dst + n` (a row).
    #[inline]
    pub fn add_cells(&mut self, dst: usize, cells: &Cells, src: usize, n: usize) {
        match (self, cells) {
            (Plane::Exact(p), Cells::Exact(c)) => {
                for (a, b) in p[dst..dst + n].iter_mut().zip(&c[src..src + n]) {
                    add_sums(a, b);
                }
            }
            (Plane::F32(p), Cells::Wide(c)) => {
                for (k, channel) in p.iter_mut().enumerate() {
                    for (a, b) in channel[dst..dst + n].iter_mut().zip(&c[src..src + n]) {
                        // One rounding per flush of a pixel (module documentation).
                        *a = (*a as f64 + b[k]) as f32;
                    }
                }
            }
            _ => unreachable!("private buffers share the frame's precision"),
        }
    }

    /// Adds one deposit value (below the fixed-point limit for an exact plane).
    #[inline]
    pub fn add_value(&mut self, i: usize, v: Rgb) {
        match self {
            Plane::Exact(p) => add_sums(&mut p[i], &[to_fixed(v.r), to_fixed(v.g), to_fixed(v.b)]),
            Plane::F32(p) => {
                p[0][i] += v.r;
                p[1][i] += v.g;
                p[2][i] += v.b;
            }
        }
    }

    /// Adds another plane of the same size and precision.
    pub fn add_plane(&mut self, other: &Plane) {
        match (self, other) {
            (Plane::Exact(a), Plane::Exact(b)) => {
                for (x, y) in a.iter_mut().zip(b) {
                    add_sums(x, y);
                }
            }
            (Plane::F32(a), Plane::F32(b)) => {
                for (ca, cb) in a.iter_mut().zip(b) {
                    for (x, y) in ca.iter_mut().zip(cb) {
                        *x += y;
                    }
                }
            }
            _ => unreachable!("frames of one render share a precision"),
        }
    }

    /// Pixel `i`'s sum as f64.
    #[inline]
    pub fn get(&self, i: usize) -> [f64; 3] {
        match self {
            Plane::Exact(p) => p[i].map(from_fixed),
            Plane::F32(p) => [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64],
        }
    }

    /// Bytes of the sums.
    pub fn bytes(&self) -> u64 {
        match self {
            Plane::Exact(p) => (p.len() * 48) as u64,
            Plane::F32(p) => (p[0].len() * 12) as u64,
        }
    }
}

/// The image being rendered: sums of deposits (main image and lighting layers) and, per
/// pixel, how many camera samples have been completed. In exact precision the sums are
/// fixed point and independent of the order of additions (module documentation).
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub layer_count: u32,
    /// Framebuffers: 0 the main image, k + 1 layer k.
    planes: Vec<Plane>,
    samples: Vec<u32>,
    /// When set, every pixel is divided by this many samples instead of its own count
    /// (flanged integrators, whose pixels also receive their neighbours' deposits).
    uniform_spp: Option<f64>,
    /// Channel values ≥ [`super::FIXED_LIMIT`] of an exact frame, summed in f64 per pixel:
    /// index 0 the main image, k + 1 layer k (sparse: empty in ordinary renders).
    large: Vec<LargeSums>,
}

/// Per-pixel f64 sums of large channel values (pixel index → RGB).
pub type LargeSums = std::collections::BTreeMap<usize, [f64; 3]>;

impl Frame {
    /// An exact-precision frame.
    pub fn new(width: u32, height: u32, layer_count: u32) -> Frame {
        Frame::with_precision(width, height, layer_count, Precision::Exact)
    }

    pub fn with_precision(
        width: u32,
        height: u32,
        layer_count: u32,
        precision: Precision,
    ) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width,
            height,
            layer_count,
            planes: (0..=layer_count)
                .map(|_| Plane::new(precision, n))
                .collect(),
            samples: vec![0; n],
            uniform_spp: None,
            large: vec![LargeSums::new(); layer_count as usize + 1],
        }
    }

    /// A frame from its parts (the shared frame of a finished render).
    pub(crate) fn from_planes(
        width: u32,
        height: u32,
        planes: Vec<Plane>,
        samples: Vec<u32>,
        large: Vec<LargeSums>,
    ) -> Frame {
        Frame {
            width,
            height,
            layer_count: planes.len() as u32 - 1,
            planes,
            samples,
            uniform_spp: None,
            large,
        }
    }

    /// An exact frame from stored sums (a part of a distributed render read back): `main`
    /// and each of `layers` hold `width · height` fixed-point RGB sums, `samples` the
    /// per-pixel counts.
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
            planes: std::iter::once(main)
                .chain(layers)
                .map(Plane::Exact)
                .collect(),
            samples,
            uniform_spp,
            large,
        }
    }

    /// The frame's precision.
    pub fn precision(&self) -> Precision {
        match self.planes[0] {
            Plane::Exact(_) => Precision::Exact,
            Plane::F32(_) => Precision::F32,
        }
    }

    /// Bytes of the framebuffers and sample counts.
    pub fn bytes(&self) -> u64 {
        self.planes.iter().map(Plane::bytes).sum::<u64>() + 4 * self.samples.len() as u64
    }

    /// The f64 sums of large channel values: `k` = 0 the main image, k + 1 layer k.
    pub fn large_sums(&self, k: usize) -> &LargeSums {
        &self.large[k]
    }

    fn exact(&self, k: usize) -> &[[u128; 3]] {
        match &self.planes[k] {
            Plane::Exact(p) => p,
            Plane::F32(_) => panic!(
                "exact sums of an f32 frame (distributed parts refuse render.precision = \"f32\")"
            ),
        }
    }

    /// The fixed-point sums of the main image. Panics for an f32 frame.
    pub fn main_sums(&self) -> &[[u128; 3]] {
        self.exact(0)
    }

    /// The fixed-point sums of lighting layer `k`. Panics for an f32 frame.
    pub fn layer_sums(&self, k: usize) -> &[[u128; 3]] {
        self.exact(k + 1)
    }

    /// Framebuffer `k`'s (0 the main image, k + 1 layer k) unnormalised sum at pixel index
    /// `i`, large values included.
    pub fn sum(&self, k: usize, i: usize) -> [f64; 3] {
        let s = self.planes[k].get(i);
        let l = self.large[k].get(&i).copied().unwrap_or([0.0; 3]);
        [s[0] + l[0], s[1] + l[1], s[2] + l[2]]
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

    /// Adds another frame of the same size and precision: its sums and sample counts.
    pub fn add_frame(&mut self, other: &Frame) {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        for (a, b) in self.planes.iter_mut().zip(&other.planes) {
            a.add_plane(b);
        }
        for (a, b) in self.samples.iter_mut().zip(&other.samples) {
            *a += b;
        }
        for (la, lb) in self.large.iter_mut().zip(&other.large) {
            add_large(la, lb);
        }
    }

    pub fn samples(&self) -> &[u32] {
        &self.samples
    }

    fn resolve(&self, k: usize) -> Vec<Rgb> {
        let scale = pixel_scale(self.uniform_spp, &self.samples);
        (0..self.samples.len())
            .map(|i| {
                let (s, f) = (self.sum(k, i), scale(i));
                Rgb::new((s[0] * f) as f32, (s[1] * f) as f32, (s[2] * f) as f32)
            })
            .collect()
    }

    /// Framebuffer `k` (0 the main image, k + 1 layer k) resolved like [`Frame::image`] into
    /// planar R, G, B channels, and its sums freed: the EXR writer takes the frame apart one
    /// framebuffer at a time, so writing needs one framebuffer more than the frame, not a
    /// second image. The frame's other framebuffers stay valid; this one is empty (reading it
    /// again panics).
    pub fn take_channels(&mut self, k: usize) -> [Vec<f32>; 3] {
        let n = self.samples.len();
        let scale = pixel_scale(self.uniform_spp, &self.samples);
        let precision = self.precision();
        match std::mem::replace(&mut self.planes[k], Plane::new(precision, 0)) {
            // Scaled in place: the f32 sums become the channels.
            Plane::F32(mut p) => {
                for channel in &mut p {
                    for (i, v) in channel.iter_mut().enumerate() {
                        // Zero stays zero, and pages no deposit reached stay unwritten
                        // (not resident).
                        if *v != 0.0 {
                            *v = (*v as f64 * scale(i)) as f32;
                        }
                    }
                }
                p
            }
            plane @ Plane::Exact(_) => {
                let large = std::mem::take(&mut self.large[k]);
                let mut out: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(n));
                for i in 0..n {
                    let s = plane.get(i);
                    let l = large.get(&i).copied().unwrap_or([0.0; 3]);
                    let f = scale(i);
                    for c in 0..3 {
                        out[c].push(((s[c] + l[c]) * f) as f32);
                    }
                }
                out
            }
        }
    }

    /// The main image: each pixel's sum over its sample count (black where none finished),
    /// or over the uniform count when one is set.
    pub fn image(&self) -> Vec<Rgb> {
        self.resolve(0)
    }

    /// Lighting layer `k`, normalised like the main image.
    pub fn layer(&self, k: usize) -> Vec<Rgb> {
        self.resolve(k + 1)
    }
}

/// One deposit into one plane (and its large-value sums).
pub(crate) fn add_deposit_to_plane(plane: &mut Plane, large: &mut LargeSums, f: usize, v: Rgb) {
    if matches!(plane, Plane::Exact(_)) && is_large(v) {
        let mut small = [0.0f32; 3];
        let e = large.entry(f).or_insert([0.0; 3]);
        for (c, x) in v.to_array().into_iter().enumerate() {
            if x >= super::FIXED_LIMIT {
                e[c] += x as f64;
            } else {
                small[c] = x;
            }
        }
        plane.add_value(f, Rgb::from_array(small));
    } else {
        plane.add_value(f, v);
    }
}

/// The factor pixel `i`'s sums are multiplied by: 1 / the uniform sample count when one is
/// set (0 for none), else 1 / the pixel's own count (0, a black pixel, where none finished).
pub(crate) fn pixel_scale(uniform_spp: Option<f64>, samples: &[u32]) -> impl Fn(usize) -> f64 + '_ {
    let uniform = uniform_spp.map(|spp| if spp > 0.0 { 1.0 / spp } else { 0.0 });
    move |i| match (uniform, samples[i]) {
        (Some(k), _) => k,
        (None, 0) => 0.0,
        (None, s) => 1.0 / s as f64,
    }
}

pub(crate) fn add_large(a: &mut LargeSums, b: &LargeSums) {
    for (f, v) in b {
        let e = a.entry(*f).or_insert([0.0; 3]);
        for c in 0..3 {
            e[c] += v[c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{from_fixed, to_fixed, SharedFrame, TileAccumulator};
    use super::*;
    use flowlight_sdk::abi::Deposit;
    use flowlight_sdk::Accumulator;

    /// An exact buffer for tile (x0, y0, x1, y1) of a `film`, with `flange` and `layers`.
    fn tile(
        t: (u32, u32, u32, u32),
        flange: u32,
        film: (u32, u32),
        layers: u32,
    ) -> TileAccumulator {
        TileAccumulator::with_precision(t, flange, film, layers, Precision::Exact)
    }

    /// The frame of `units` (buffer, samples) merged as the scheduler merges Blasting units.
    fn merged(film: (u32, u32), layers: u32, units: &[(&TileAccumulator, u32)]) -> Frame {
        let shared = SharedFrame::new(film.0, film.1, layers, Precision::Exact);
        for (t, samples) in units {
            shared.merge_tile(t, *samples);
        }
        shared.into_frame()
    }

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
        let mut t = tile((2, 2, 4, 4), 0, (4, 4), 2);
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
        let f = merged((4, 4), 2, &[(&t, 2)]);
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
        let mut t = tile((4, 4, 6, 6), 1, (8, 8), 0);
        t.deposit(&[
            d(4.5, 4.5, 0, 1.0),
            d(3.5, 6.5, 0, 2.0),
            d(0.5, 7.5, 0, 3.0),
        ]);
        assert_eq!(t.counts.overflow, 1);
        // Other units sample the flange and overflow pixels.
        let other = tile((0, 0, 8, 8), 0, (8, 8), 0);
        let f = merged((8, 8), 0, &[(&t, 1), (&other, 1)]);
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
        let mut t = tile((1, 0, 2, 1), 1, (2, 1), 1);
        t.deposit(&[d(0.5, 0.5, 0, 3.0), d(1.5, 0.5, 0, 6.0)]);
        let mut f = merged((2, 1), 1, &[(&t, 1)]);
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
        let mut one = tile((0, 0, 1, 1), 0, (1, 1), 0);
        for &v in &values {
            one.deposit(&[d(0.5, 0.5, 0, v)]);
        }
        let a = merged((1, 1), 0, &[(&one, 7)]);
        // The same deposits split over three units merged in another order.
        let mut b = Frame::new(1, 1, 0);
        for chunk in [&values[4..], &values[..2], &values[2..4]] {
            let mut t = tile((0, 0, 1, 1), 0, (1, 1), 0);
            for &v in chunk.iter().rev() {
                t.deposit(&[d(0.5, 0.5, 0, v)]);
            }
            b.add_frame(&merged((1, 1), 0, &[(&t, chunk.len() as u32)]));
        }
        assert_eq!(a.main_sums(), b.main_sums());
        assert_eq!(a.image()[0].r.to_bits(), b.image()[0].r.to_bits());
        // And the sum is the exact one, to 2⁻⁶⁴ per deposit.
        let exact: f64 = values.iter().map(|&v| v as f64).sum();
        assert!((from_fixed(a.main_sums()[0][0]) - exact).abs() <= 1e-9 * exact);
        assert_eq!(to_fixed(1.0), 1u128 << 64);
        // A 10³⁰ deposit keeps its energy (f64 side sum), beside a small one in fixed point.
        let mut t = tile((0, 0, 1, 1), 0, (1, 1), 1);
        t.deposit(&[d(0.5, 0.5, 0, 1.0e30), d(0.5, 0.5, 0, 0.5)]);
        let f = merged((1, 1), 1, &[(&t, 2)]);
        let r = f.image()[0].r as f64;
        assert!((r / 5.0e29 - 1.0).abs() < 1e-6, "{r}");
        assert_eq!(f.layer(0)[0], f.image()[0]);
        assert_eq!(f.large_sums(0).len(), 1);
        assert_eq!(to_fixed(0.5) + to_fixed(0.25), to_fixed(0.75));
    }

    #[test]
    fn taken_channels_are_the_resolved_image_bit_for_bit() {
        for precision in [Precision::Exact, Precision::F32] {
            for uniform in [None, Some(1.5)] {
                let mut t = TileAccumulator::with_precision((0, 0, 2, 2), 1, (3, 2), 1, precision);
                t.deposit(&[
                    d(0.5, 0.5, 0, 0.3),
                    d(1.5, 1.5, 1, 7.0e-3),
                    d(2.5, 0.5, 0, 1.0e31),
                    d(2.5, 1.5, 0, 2.0),
                ]);
                let shared = SharedFrame::new(3, 2, 1, precision);
                shared.merge_tile(&t, 3);
                let mut f = shared.into_frame();
                if let Some(spp) = uniform {
                    f.set_uniform_spp(spp);
                }
                let want = [f.image(), f.layer(0)];
                for (k, w) in want.iter().enumerate() {
                    let got = f.take_channels(k);
                    for (i, p) in w.iter().enumerate() {
                        for (channel, v) in got.iter().zip(p.to_array()) {
                            assert_eq!(
                                channel[i].to_bits(),
                                v.to_bits(),
                                "{precision:?} {uniform:?} framebuffer {k} pixel {i}"
                            );
                        }
                    }
                }
            }
        }
    }
}
