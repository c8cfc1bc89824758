//! Integers wide enough to hold every product the exact predicates form from `f32`
//! inputs, without allocating.
//!
//! Every finite `f32` is an integer multiple of `2^-149`, and below `2^128`: scaled by
//! `2^149` it is an integer of at most 277 bits. The predicates multiply at most four
//! such numbers (or differences of them, one bit more) and add a few dozen products,
//! then shift by 151 bits at most: under 1,280 bits, twenty 64-bit limbs. Values are
//! sign and magnitude; the magnitude's limbs are little-endian, `len` of them in use.

use std::cmp::Ordering;

/// Limbs of a [`Big`].
const LIMBS: usize = 28;

/// A signed integer of up to 1,792 bits (see the module docs): the predicates' width.
pub(crate) type Big = Wide<LIMBS>;

/// A signed integer of up to `64 L` bits. The distance tests compare products of
/// ten differences of `f32`s (`exact::distance`): [`Wider`].
#[derive(Clone, Copy)]
pub(crate) struct Wide<const L: usize> {
    neg: bool,
    len: usize,
    mag: [u64; L],
}

/// 3,072 bits: ten factors of 279 bits and their sums' carries.
pub(crate) type Wider = Wide<48>;

impl<const L: usize> std::fmt::Debug for Wide<L> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}0x", if self.neg { "-" } else { "" })?;
        if self.len == 0 {
            return write!(f, "0");
        }
        for (i, limb) in self.mag[..self.len].iter().rev().enumerate() {
            if i == 0 {
                write!(f, "{limb:x}")?;
            } else {
                write!(f, "_{limb:016x}")?;
            }
        }
        Ok(())
    }
}

impl<const L: usize> Wide<L> {
    /// Zero.
    pub const ZERO: Self = Wide { neg: false, len: 0, mag: [0; L] };

    /// `x * 2^149`, exactly (`x` finite).
    pub fn of(x: f32) -> Self {
        debug_assert!(x.is_finite());
        let bits = x.to_bits();
        let exponent = (bits >> 23) & 0xFF;
        let fraction = (bits & 0x7F_FFFF) as u64;
        // A normal number is (1.f) 2^(e - 127) = (2^23 + f) 2^(e - 150); a subnormal
        // one f 2^-149.
        let (mantissa, shift) = if exponent == 0 { (fraction, 0) } else { (fraction | 1 << 23, exponent - 1) };
        Self::from_u64(mantissa).shl(shift as usize).negate_if(bits >> 31 == 1)
    }

    /// A small non-negative integer.
    pub fn from_u64(x: u64) -> Self {
        let mut b = Self::ZERO;
        if x != 0 {
            b.mag[0] = x;
            b.len = 1;
        }
        b
    }

    /// `-1`, `0` or `1`.
    pub fn signum(&self) -> i32 {
        match (self.len, self.neg) {
            (0, _) => 0,
            (_, true) => -1,
            (_, false) => 1,
        }
    }

    /// Whether it is zero.
    pub fn is_zero(&self) -> bool {
        self.len == 0
    }

    /// Whether it is below zero.
    pub fn is_negative(&self) -> bool {
        self.neg && self.len != 0
    }

    /// The value negated when `neg`.
    pub fn negate_if(mut self, neg: bool) -> Self {
        if neg && self.len != 0 {
            self.neg = !self.neg;
        }
        self
    }

    /// `-self`.
    pub fn neg(self) -> Self {
        self.negate_if(true)
    }

    /// `self * 2^n`.
    pub fn shl(self, n: usize) -> Self {
        if self.len == 0 {
            return self;
        }
        let (words, bits) = (n / 64, n % 64);
        let mut out = Wide { neg: self.neg, len: 0, mag: [0; L] };
        for i in 0..self.len {
            let limb = self.mag[i];
            out.mag[i + words] |= limb << bits;
            if bits != 0 && i + words + 1 < L {
                out.mag[i + words + 1] |= limb >> (64 - bits);
            }
        }
        out.len = (self.len + words + 1).min(L);
        out.trim();
        out
    }

    /// Drops leading zero limbs (and the sign of zero), in place (the values are
    /// hundreds of bytes; a move in and out per operation is avoidable).
    fn trim(&mut self) {
        while self.len > 0 && self.mag[self.len - 1] == 0 {
            self.len -= 1;
        }
        if self.len == 0 {
            self.neg = false;
        }
    }

    /// Compares magnitudes.
    fn cmp_mag(&self, other: &Self) -> Ordering {
        if self.len != other.len {
            return self.len.cmp(&other.len);
        }
        for i in (0..self.len).rev() {
            match self.mag[i].cmp(&other.mag[i]) {
                Ordering::Equal => continue,
                unequal => return unequal,
            }
        }
        Ordering::Equal
    }

    /// `|a| + |b|` with the sign `neg`.
    fn add_mag(a: &Self, b: &Self, neg: bool) -> Self {
        let n = a.len.max(b.len);
        let mut out = Wide { neg, len: 0, mag: [0; L] };
        let mut carry = 0u64;
        for i in 0..n {
            let (s1, c1) = a.mag[i].overflowing_add(b.mag[i]);
            let (s2, c2) = s1.overflowing_add(carry);
            out.mag[i] = s2;
            carry = (c1 | c2) as u64;
        }
        assert!(n < L || carry == 0, "exact arithmetic overflowed its width");
        if n < L {
            out.mag[n] = carry;
        }
        out.len = (n + 1).min(L);
        out.trim();
        out
    }

    /// `|a| - |b|` (`|a| >= |b|`) with the sign `neg`.
    fn sub_mag(a: &Self, b: &Self, neg: bool) -> Self {
        let mut out = Wide { neg, len: a.len, mag: [0; L] };
        let mut borrow = 0u64;
        for i in 0..a.len {
            let (d1, b1) = a.mag[i].overflowing_sub(b.mag[i]);
            let (d2, b2) = d1.overflowing_sub(borrow);
            out.mag[i] = d2;
            borrow = (b1 | b2) as u64;
        }
        debug_assert_eq!(borrow, 0);
        out.trim();
        out
    }

    /// `self + other`, `other`'s sign flipped when `flip`.
    fn add_signed(&self, other: &Self, flip: bool) -> Self {
        let other_neg = other.neg != flip && other.len != 0;
        if self.neg == other_neg || self.len == 0 || other.len == 0 {
            let neg = if self.len == 0 { other_neg } else { self.neg };
            return Self::add_mag(self, other, neg);
        }
        match self.cmp_mag(other) {
            Ordering::Less => Self::sub_mag(other, self, other_neg),
            _ => Self::sub_mag(self, other, self.neg),
        }
    }

    /// `self + other`.
    pub fn add(&self, other: &Self) -> Self {
        self.add_signed(other, false)
    }

    /// `self - other`.
    pub fn sub(&self, other: &Self) -> Self {
        self.add_signed(other, true)
    }

    /// `self * other`.
    pub fn mul(&self, other: &Self) -> Self {
        if self.len == 0 || other.len == 0 {
            return Self::ZERO;
        }
        assert!(self.len + other.len <= L + 1, "exact arithmetic overflowed its width");
        let mut out = Wide { neg: self.neg != other.neg, len: 0, mag: [0; L] };
        for i in 0..self.len {
            let mut carry = 0u128;
            let a = self.mag[i] as u128;
            for j in 0..other.len {
                let k = i + j;
                let cur = out.mag[k] as u128 + a * other.mag[j] as u128 + carry;
                out.mag[k] = cur as u64;
                carry = cur >> 64;
            }
            let k = i + other.len;
            if k < L {
                out.mag[k] = carry as u64;
            } else {
                assert_eq!(carry, 0, "exact arithmetic overflowed its width");
            }
        }
        out.len = (self.len + other.len).min(L);
        out.trim();
        out
    }

    /// Compares values.
    pub fn cmp(&self, other: &Self) -> Ordering {
        match (self.signum(), other.signum()) {
            (a, b) if a != b => a.cmp(&b),
            (0, _) => Ordering::Equal,
            (1, _) => self.cmp_mag(other),
            _ => other.cmp_mag(self),
        }
    }

    /// The value as `m * 2^e` with `m` an `f64` in `[0.5, 1)` (or 0), rounded toward
    /// zero to 64 bits and then to `f64`: within `2^-52` relative.
    pub fn scaled_f64(&self) -> (f64, i32) {
        if self.len == 0 {
            return (0.0, 0);
        }
        let top = self.mag[self.len - 1];
        let lead = top.leading_zeros();
        let below = if self.len >= 2 { self.mag[self.len - 2] } else { 0 };
        let bits = if lead == 0 { top } else { (top << lead) | (below >> (64 - lead)) };
        let m = bits as f64 / 2f64.powi(64);
        let e = 64 * self.len as i32 - lead as i32;
        (if self.neg { -m } else { m }, e)
    }

    /// `self / other` as an `f64` (within a few `2^-52` relative; `other` not zero).
    pub fn ratio(&self, other: &Self) -> f64 {
        let (a, ea) = self.scaled_f64();
        let (b, eb) = other.scaled_f64();
        scaled(a / b, ea - eb)
    }
}

/// `x * 2^e` (to infinity or zero past `f64`'s range).
pub(crate) fn scaled(x: f64, e: i32) -> f64 {
    let e = e.clamp(-2200, 2200);
    let half = e / 2;
    x * 2f64.powi(half) * 2f64.powi(e - half)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value as an `i128`, where it fits.
    fn small(b: &Big) -> i128 {
        assert!(b.len <= 1 || (b.len == 2 && b.mag[1] < 1 << 62));
        let m = b.mag[0] as i128 | (b.mag[1] as i128) << 64;
        if b.neg {
            -m
        } else {
            m
        }
    }

    fn big(x: i128) -> Big {
        let m = x.unsigned_abs();
        let mut b = Big::ZERO;
        b.mag[0] = m as u64;
        b.mag[1] = (m >> 64) as u64;
        b.len = 2;
        b.neg = x < 0;
        b.trim();
        b
    }

    #[test]
    fn floats_scale_to_their_integers() {
        assert_eq!(small(&Big::of(f32::from_bits(1))), 1);
        assert_eq!(small(&Big::of(-f32::from_bits(3))), -3);
        assert_eq!(Big::of(0.0).signum(), 0);
        assert_eq!(Big::of(-0.0).signum(), 0);
        // 1.0 = 2^149 in these units; 1.5 = 3 * 2^148.
        assert_eq!(Big::of(1.0).cmp(&Big::from_u64(1).shl(149)), Ordering::Equal);
        assert_eq!(Big::of(-1.5).cmp(&Big::from_u64(3).shl(148).neg()), Ordering::Equal);
        // The smallest normal number, 2^-126 = 2^23 units.
        assert_eq!(small(&Big::of(f32::MIN_POSITIVE)), 1 << 23);
        let max = Big::of(f32::MAX);
        assert_eq!(max.len, 5, "{max:?}");
    }

    #[test]
    fn arithmetic_agrees_with_i128() {
        let mut s = 0x1234_5678_9ABC_DEF0_u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for _ in 0..20_000 {
            let a = (next() as i64 >> (next() % 64)) as i128;
            let b = (next() as i64 >> (next() % 64)) as i128;
            let (x, y) = (big(a), big(b));
            assert_eq!(small(&x.add(&y)), a + b);
            assert_eq!(small(&x.sub(&y)), a - b);
            assert_eq!(small(&x.mul(&y)), a * b);
            assert_eq!(x.cmp(&y), a.cmp(&b));
            assert_eq!(x.signum(), a.signum() as i32);
        }
    }

    #[test]
    fn wide_products_round_trip_through_the_shift() {
        // (2^600 + 1)(2^600 - 1) = 2^1200 - 1.
        let one = Big::from_u64(1);
        let p = one.shl(600).add(&one).mul(&one.shl(600).sub(&one));
        assert_eq!(p.add(&one).cmp(&one.shl(1200)), Ordering::Equal);
        let (m, e) = p.scaled_f64();
        assert_eq!((m, e), (1.0, 1200));
        assert_eq!(one.shl(700).ratio(&one.shl(650).neg()), -(2f64.powi(50)));
    }
}
