//! Eight lanes of `f32`: plain arrays whose per-lane loops the compiler turns into vector
//! instructions (one AVX2 instruction for eight lanes inside a function compiled with
//! `avx2`, two SSE instructions otherwise). Each operation is the scalar one lane by lane,
//! so a lane's result is the scalar code's bit for bit where the operations and their order
//! are the same (glam's `Vec3` ones, spelled out below).

use std::ops::{Add, Div, Mul, Neg, Sub};

pub const L: usize = 8;

/// Eight `f32`s.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub struct F(pub [f32; L]);

/// Eight lane conditions: all ones (true) or zero, as the vector compares give them.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub struct M(pub [u32; L]);

#[inline(always)]
fn lanes<T: Copy + Default>(f: impl Fn(usize) -> T) -> [T; L] {
    let mut out = [T::default(); L];
    for (i, o) in out.iter_mut().enumerate() {
        *o = f(i);
    }
    out
}

#[inline(always)]
fn mask(c: bool) -> u32 {
    (c as u32).wrapping_neg()
}

macro_rules! lane_op {
    ($trait:ident, $fn:ident, $op:tt) => {
        impl $trait for F {
            type Output = F;
            #[inline(always)]
            fn $fn(self, rhs: F) -> F {
                F(lanes(|i| self.0[i] $op rhs.0[i]))
            }
        }
    };
}
lane_op!(Add, add, +);
lane_op!(Sub, sub, -);
lane_op!(Mul, mul, *);
lane_op!(Div, div, /);

impl Neg for F {
    type Output = F;
    #[inline(always)]
    fn neg(self) -> F {
        F(lanes(|i| -self.0[i]))
    }
}

impl F {
    #[inline(always)]
    pub fn splat(v: f32) -> F {
        F([v; L])
    }
    #[inline(always)]
    pub fn abs(self) -> F {
        F(lanes(|i| self.0[i].abs()))
    }
    #[inline(always)]
    pub fn sqrt(self) -> F {
        F(lanes(|i| self.0[i].sqrt()))
    }
    /// `f32::max`: the other operand where one is NaN.
    #[inline(always)]
    pub fn max(self, o: F) -> F {
        F(lanes(|i| self.0[i].max(o.0[i])))
    }
    #[inline(always)]
    pub fn lt(self, o: F) -> M {
        M(lanes(|i| mask(self.0[i] < o.0[i])))
    }
    #[inline(always)]
    pub fn gt(self, o: F) -> M {
        M(lanes(|i| mask(self.0[i] > o.0[i])))
    }
    #[inline(always)]
    pub fn le(self, o: F) -> M {
        M(lanes(|i| mask(self.0[i] <= o.0[i])))
    }
    #[inline(always)]
    pub fn eq(self, o: F) -> M {
        M(lanes(|i| mask(self.0[i] == o.0[i])))
    }
    #[inline(always)]
    pub fn ne(self, o: F) -> M {
        M(lanes(|i| mask(self.0[i] != o.0[i])))
    }
    /// `1.0f32.copysign(self)`, lane by lane.
    #[inline(always)]
    pub fn sign(self) -> F {
        F(lanes(|i| 1.0f32.copysign(self.0[i])))
    }
}

impl M {
    /// Whether lane `i`'s condition holds.
    #[inline(always)]
    pub fn at(&self, i: usize) -> bool {
        self.0[i] != 0
    }
    #[inline(always)]
    pub fn and(self, o: M) -> M {
        M(lanes(|i| self.0[i] & o.0[i]))
    }
    #[inline(always)]
    pub fn or(self, o: M) -> M {
        M(lanes(|i| self.0[i] | o.0[i]))
    }
    #[inline(always)]
    pub fn not(self) -> M {
        M(lanes(|i| !self.0[i]))
    }
    /// `a` where the lane's condition holds, else `b`.
    #[inline(always)]
    pub fn select(self, a: F, b: F) -> F {
        F(lanes(|i| {
            f32::from_bits((a.0[i].to_bits() & self.0[i]) | (b.0[i].to_bits() & !self.0[i]))
        }))
    }
    #[inline(always)]
    pub fn select3(self, a: V3, b: V3) -> V3 {
        V3 {
            x: self.select(a.x, b.x),
            y: self.select(a.y, b.y),
            z: self.select(a.z, b.z),
        }
    }
}

/// Eight 3-vectors, one component per register.
#[derive(Clone, Copy, Debug, Default)]
pub struct V3 {
    pub x: F,
    pub y: F,
    pub z: F,
}

impl Add for V3 {
    type Output = V3;
    #[inline(always)]
    fn add(self, o: V3) -> V3 {
        V3 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl Sub for V3 {
    type Output = V3;
    #[inline(always)]
    fn sub(self, o: V3) -> V3 {
        V3 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

/// Component by component (glam's `Vec3 * Vec3`, and `Rgb * Rgb`).
impl Mul for V3 {
    type Output = V3;
    #[inline(always)]
    fn mul(self, o: V3) -> V3 {
        V3 {
            x: self.x * o.x,
            y: self.y * o.y,
            z: self.z * o.z,
        }
    }
}

/// Each lane's vector times that lane's scalar (glam's `Vec3 * f32`).
impl Mul<F> for V3 {
    type Output = V3;
    #[inline(always)]
    fn mul(self, s: F) -> V3 {
        V3 {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
}

impl Div<F> for V3 {
    type Output = V3;
    #[inline(always)]
    fn div(self, s: F) -> V3 {
        V3 {
            x: self.x / s,
            y: self.y / s,
            z: self.z / s,
        }
    }
}

impl Neg for V3 {
    type Output = V3;
    #[inline(always)]
    fn neg(self) -> V3 {
        V3 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

impl V3 {
    #[inline(always)]
    pub fn set(&mut self, i: usize, v: glam::Vec3) {
        self.x.0[i] = v.x;
        self.y.0[i] = v.y;
        self.z.0[i] = v.z;
    }
    #[inline(always)]
    pub fn get(&self, i: usize) -> glam::Vec3 {
        glam::Vec3::new(self.x.0[i], self.y.0[i], self.z.0[i])
    }
    #[inline(always)]
    pub fn dot(self, o: V3) -> F {
        (self.x * o.x) + (self.y * o.y) + (self.z * o.z)
    }
    #[inline(always)]
    pub fn cross(self, o: V3) -> V3 {
        V3 {
            x: self.y * o.z - o.y * self.z,
            y: self.z * o.x - o.z * self.x,
            z: self.x * o.y - o.x * self.y,
        }
    }
    #[inline(always)]
    pub fn abs(self) -> V3 {
        V3 {
            x: self.x.abs(),
            y: self.y.abs(),
            z: self.z.abs(),
        }
    }
    /// glam's `length_recip`: 1 / √(v·v).
    #[inline(always)]
    pub fn length_recip(self) -> F {
        F::splat(1.0) / self.dot(self).sqrt()
    }
    #[inline(always)]
    pub fn normalize(self) -> V3 {
        self * self.length_recip()
    }
    /// glam's `normalize_or_zero`: zero where 1 / |v| is not a positive finite number.
    #[inline(always)]
    pub fn normalize_or_zero(self) -> V3 {
        let r = self.length_recip();
        let ok = M(lanes(|i| mask(r.0[i].is_finite() && r.0[i] > 0.0)));
        ok.select3(self * r, V3::default())
    }
}
