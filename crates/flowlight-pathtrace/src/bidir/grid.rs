//! A hashed uniform grid over the light vertices of an iteration, for the range queries of
//! vertex merging: every light vertex within the radius r of a camera vertex.
//!
//! Cells are cubes of side 2r, so a ball of radius r overlaps at most two cells per axis
//! (eight in all). Cells are hashed into a table of a power of two ≥ the vertex count
//! buckets; the vertices are sorted by bucket (a counting sort), so a bucket is one range of
//! an index array. Two cells of one query can share a bucket: the query visits each bucket
//! once, so no vertex is counted twice. The buffers are kept between iterations (the
//! thread's arena) with power-of-two capacities: building allocates only when an iteration's
//! vertex count passes a power of two that no earlier iteration reached.

use glam::{IVec3, Vec3};

/// The grid (module docs). Empty until [`HashGrid::build`].
#[derive(Clone, Debug, Default)]
pub struct HashGrid {
    origin: Vec3,
    inv_cell: f32,
    radius2: f32,
    mask: u32,
    /// Per bucket, the end of its range in `indices` (its start is the previous end).
    ends: Vec<u32>,
    indices: Vec<u32>,
    buckets: Vec<u32>,
    /// The counting sort's fill positions, kept like the other buffers so that a build
    /// allocates nothing once they are large enough.
    cursor: Vec<u32>,
}

impl HashGrid {
    /// Builds the grid over `points` for queries of `radius`.
    pub fn build(&mut self, points: impl ExactSizeIterator<Item = Vec3> + Clone, radius: f32) {
        let n = points.len();
        self.indices.clear();
        self.ends.clear();
        self.buckets.clear();
        self.radius2 = radius * radius;
        if n == 0 || radius <= 0.0 || radius.is_nan() {
            self.mask = 0;
            return;
        }
        let lo = points.clone().fold(Vec3::INFINITY, Vec3::min);
        self.origin = lo;
        self.inv_cell = 1.0 / (2.0 * radius);
        let size = n.next_power_of_two().max(1);
        self.mask = (size - 1) as u32;
        // Every buffer takes a power-of-two capacity (`vertices` grows by doubling too), so
        // a build allocates only when the vertex count passes a power of two it never reached.
        for buffer in [
            &mut self.ends,
            &mut self.indices,
            &mut self.buckets,
            &mut self.cursor,
        ] {
            buffer.reserve_exact(size);
        }
        self.ends.resize(size, 0);
        let mut buckets = std::mem::take(&mut self.buckets);
        buckets.extend(points.clone().map(|p| self.bucket(self.cell(p))));
        self.buckets = buckets;
        for &b in &self.buckets {
            self.ends[b as usize] += 1;
        }
        let mut sum = 0;
        for e in self.ends.iter_mut() {
            sum += *e;
            *e = sum;
        }
        self.indices.resize(n, 0);
        // Fill each bucket from its end backwards: afterwards `ends[b]` still ends it and the
        // previous bucket's end starts it.
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.ends);
        for (i, &b) in self.buckets.iter().enumerate().rev() {
            self.cursor[b as usize] -= 1;
            self.indices[self.cursor[b as usize] as usize] = i as u32;
        }
    }

    #[inline]
    fn cell(&self, p: Vec3) -> IVec3 {
        let c = (p - self.origin) * self.inv_cell;
        IVec3::new(floor_to_i32(c.x), floor_to_i32(c.y), floor_to_i32(c.z))
    }

    #[inline]
    fn bucket(&self, c: IVec3) -> u32 {
        let h = (c.x as u32).wrapping_mul(73_856_093)
            ^ (c.y as u32).wrapping_mul(19_349_663)
            ^ (c.z as u32).wrapping_mul(83_492_791);
        h & self.mask
    }

    /// Calls `visit(i)` for every point `i` of the build within the radius of `p`
    /// (`position(i)` gives point i's position).
    #[inline]
    pub fn query(&self, p: Vec3, position: impl Fn(u32) -> Vec3, mut visit: impl FnMut(u32)) {
        if self.ends.is_empty() || !p.is_finite() {
            return;
        }
        let r = 0.5 / self.inv_cell;
        let (lo, hi) = (self.cell(p - Vec3::splat(r)), self.cell(p + Vec3::splat(r)));
        let mut seen = [u32::MAX; 8];
        let mut count = 0;
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let b = self.bucket(IVec3::new(x, y, z));
                    if seen[..count].contains(&b) {
                        continue;
                    }
                    if count < seen.len() {
                        seen[count] = b;
                        count += 1;
                    }
                    let start = if b == 0 { 0 } else { self.ends[b as usize - 1] };
                    for &i in &self.indices[start as usize..self.ends[b as usize] as usize] {
                        if position(i).distance_squared(p) <= self.radius2 {
                            visit(i);
                        }
                    }
                }
            }
        }
    }
}

/// ⌊x⌋ as an i32, saturating as `x.floor() as i32` does, without `floorf`: baseline x86-64
/// has no rounding instruction (`roundss` is SSE4.1), so `f32::floor` is a libm call, about 1%
/// of a VCM render. Truncation rounds toward zero; a negative non-integer is one above its
/// floor.
#[inline]
fn floor_to_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_sub(i32::from(x < t as f32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::rng::Rng;

    #[test]
    fn floor_to_i32_is_floor_as_i32() {
        let mut rng = Rng::new(7, 0);
        let special = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999_999_8,
            -2.999_999_8,
            1e-38,
            -1e-38,
            8_388_607.5,
            -8_388_607.5,
            2.1e9,
            -2.1e9,
            3e9,
            -3e9,
            f32::MAX,
            f32::MIN,
        ];
        let random = (0..100_000).map(|_| (rng.uniform() - 0.5) * 2e3);
        for x in special.into_iter().chain(random) {
            assert_eq!(floor_to_i32(x), x.floor() as i32, "x = {x}");
        }
    }

    #[test]
    fn a_query_finds_exactly_the_points_within_the_radius_once_each() {
        let mut rng = Rng::new(7, 0);
        let points: Vec<Vec3> = (0..2000)
            .map(|_| Vec3::new(rng.uniform(), rng.uniform(), rng.uniform() * 0.1) * 3.0)
            .collect();
        let mut grid = HashGrid::default();
        for radius in [0.05f32, 0.2, 1.0] {
            grid.build(points.iter().copied(), radius);
            for _ in 0..200 {
                let q = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform() * 0.1) * 3.0;
                let mut found = Vec::new();
                grid.query(q, |i| points[i as usize], |i| found.push(i));
                found.sort_unstable();
                let expected: Vec<u32> = (0..points.len() as u32)
                    .filter(|&i| points[i as usize].distance_squared(q) <= radius * radius)
                    .collect();
                assert_eq!(found, expected, "radius {radius}, query {q}");
            }
        }
    }

    #[test]
    fn an_empty_grid_finds_nothing() {
        let mut grid = HashGrid::default();
        grid.build(std::iter::empty::<Vec3>(), 0.1);
        grid.query(Vec3::ZERO, |_| Vec3::ZERO, |_| panic!("nothing to find"));
    }
}
