//! One double or two at once: the arithmetic that a routine written once over [`F64Lanes`] runs
//! on, so that it computes one value (`f64`) or two in an SSE2 register ([`F64x2`]) with the
//! same IEEE operations in the same order, hence the same bits in every lane.
//!
//! Used where samples from one point are drawn in pairs and their work is a serial chain of
//! double-precision square roots and divisions (a spherical rectangle's sample): two chains in
//! one register take the time and the instructions of one.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Lane-wise `f64` arithmetic, each operation the one `f64` would do.
pub trait F64Lanes:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    fn splat(x: f64) -> Self;
    fn sqrt(self) -> Self;
    /// `f64::max(self, c)` for a `c` that is not NaN (NaN lanes give `c`).
    fn max_const(self, c: f64) -> Self;
    /// `f64::clamp` (NaN lanes stay NaN).
    fn clamp(self, lo: Self, hi: Self) -> Self;
    fn copysign(self, sign: Self) -> Self;
    /// `if self < limit { then } else { other }`, lane by lane.
    fn lt_select(self, limit: f64, then: Self, other: Self) -> Self;
    /// `(sin, cos)`, as [`crate::sampling::sin_cos_f64`] gives them.
    fn sin_cos(self) -> (Self, Self);
    /// Whether every lane is a number with `|x| <= limit`.
    fn all_within(self, limit: f64) -> bool;
    /// `(sin, cos)` of `x` from the sine `s` and cosine `c` of `x` less its nearest number of
    /// quarter turns, that number being the low bits of `t`'s mantissa (`t`: `x · 2/π` rounded
    /// to an integer by adding 1.5 · 2⁵²).
    fn quarter_turns(t: Self, s: Self, c: Self) -> (Self, Self);
}

impl F64Lanes for f64 {
    #[inline(always)]
    fn splat(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn max_const(self, c: f64) -> f64 {
        f64::max(self, c)
    }
    #[inline(always)]
    fn clamp(self, lo: f64, hi: f64) -> f64 {
        f64::clamp(self, lo, hi)
    }
    #[inline(always)]
    fn copysign(self, sign: f64) -> f64 {
        f64::copysign(self, sign)
    }
    #[inline(always)]
    fn lt_select(self, limit: f64, then: f64, other: f64) -> f64 {
        if self < limit {
            then
        } else {
            other
        }
    }
    #[inline(always)]
    fn sin_cos(self) -> (f64, f64) {
        crate::sampling::sin_cos_f64(self)
    }
    #[inline(always)]
    fn all_within(self, limit: f64) -> bool {
        self.abs() <= limit
    }
    #[inline(always)]
    fn quarter_turns(t: f64, s: f64, c: f64) -> (f64, f64) {
        match t.to_bits() & 3 {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub use x2::F64x2;

#[cfg(target_arch = "x86_64")]
mod x2 {
    use super::F64Lanes;
    use std::arch::x86_64::*;
    use std::ops::{Add, Div, Mul, Neg, Sub};

    /// Two doubles in an SSE2 register (part of every x86-64 CPU).
    #[derive(Clone, Copy, Debug)]
    pub struct F64x2(__m128d);

    // SAFETY (every intrinsic below): SSE2 is part of the x86-64 baseline.

    impl F64x2 {
        #[inline(always)]
        pub fn new(a: f64, b: f64) -> F64x2 {
            F64x2(unsafe { _mm_setr_pd(a, b) })
        }

        #[inline(always)]
        pub fn lanes(self) -> [f64; 2] {
            let mut out = [0.0; 2];
            unsafe { _mm_storeu_pd(out.as_mut_ptr(), self.0) };
            out
        }

        /// Lanes of `a` where `mask` is set, of `b` elsewhere.
        #[inline(always)]
        fn select(mask: __m128d, a: __m128d, b: __m128d) -> __m128d {
            unsafe { _mm_or_pd(_mm_and_pd(mask, a), _mm_andnot_pd(mask, b)) }
        }

        /// The sign bit.
        #[inline(always)]
        fn sign() -> __m128d {
            unsafe { _mm_set1_pd(-0.0) }
        }
    }

    macro_rules! binary {
        ($trait:ident, $f:ident, $op:ident) => {
            impl $trait for F64x2 {
                type Output = F64x2;
                #[inline(always)]
                fn $f(self, o: F64x2) -> F64x2 {
                    F64x2(unsafe { $op(self.0, o.0) })
                }
            }
        };
    }
    binary!(Add, add, _mm_add_pd);
    binary!(Sub, sub, _mm_sub_pd);
    binary!(Mul, mul, _mm_mul_pd);
    binary!(Div, div, _mm_div_pd);

    impl Neg for F64x2 {
        type Output = F64x2;
        #[inline(always)]
        fn neg(self) -> F64x2 {
            F64x2(unsafe { _mm_xor_pd(self.0, F64x2::sign()) })
        }
    }

    impl F64Lanes for F64x2 {
        #[inline(always)]
        fn splat(x: f64) -> F64x2 {
            F64x2(unsafe { _mm_set1_pd(x) })
        }
        #[inline(always)]
        fn sqrt(self) -> F64x2 {
            F64x2(unsafe { _mm_sqrt_pd(self.0) })
        }
        #[inline(always)]
        fn max_const(self, c: f64) -> F64x2 {
            // `maxpd` gives its second operand where either is NaN.
            F64x2(unsafe { _mm_max_pd(self.0, _mm_set1_pd(c)) })
        }
        #[inline(always)]
        fn clamp(self, lo: F64x2, hi: F64x2) -> F64x2 {
            // `lo > x ? lo : x`, then `hi < y ? hi : y`: a NaN `x` passes through both, and
            // an `x` equal to a bound (zeros of either sign included) is kept, as in
            // `f64::clamp`.
            F64x2(unsafe { _mm_min_pd(hi.0, _mm_max_pd(lo.0, self.0)) })
        }
        #[inline(always)]
        fn copysign(self, sign: F64x2) -> F64x2 {
            F64x2(F64x2::select(F64x2::sign(), sign.0, self.0))
        }
        #[inline(always)]
        fn lt_select(self, limit: f64, then: F64x2, other: F64x2) -> F64x2 {
            F64x2(F64x2::select(unsafe { _mm_cmplt_pd(self.0, _mm_set1_pd(limit)) }, then.0, other.0))
        }
        #[inline(always)]
        fn sin_cos(self) -> (F64x2, F64x2) {
            if self.all_within(crate::sampling::SIN_COS_F64_REDUCED) {
                crate::sampling::sin_cos_reduced(self)
            } else {
                let [(s0, c0), (s1, c1)] = self.lanes().map(crate::sampling::sin_cos_f64);
                (F64x2::new(s0, s1), F64x2::new(c0, c1))
            }
        }
        #[inline(always)]
        fn all_within(self, limit: f64) -> bool {
            // Ordered comparison: false for NaN.
            unsafe {
                let abs = _mm_andnot_pd(F64x2::sign(), self.0);
                _mm_movemask_pd(_mm_cmple_pd(abs, _mm_set1_pd(limit))) == 3
            }
        }
        #[inline(always)]
        fn quarter_turns(t: F64x2, s: F64x2, c: F64x2) -> (F64x2, F64x2) {
            unsafe {
                let bits = _mm_castpd_si128(t.0);
                // Bit 0 of each lane to its sign bit, then spread over the lane: odd turns
                // swap sine and cosine.
                let odd = _mm_shuffle_epi32::<0b11_11_01_01>(_mm_srai_epi32::<31>(_mm_slli_epi64::<63>(bits)));
                let odd = _mm_castsi128_pd(odd);
                // Turns 2 and 3 negate the sine, turns 1 and 2 the cosine: bit 1, and bit 0
                // xor bit 1, moved to the sign bit.
                let b1 = _mm_slli_epi64::<62>(bits);
                let neg_sin = _mm_and_pd(_mm_castsi128_pd(b1), F64x2::sign());
                let neg_cos =
                    _mm_and_pd(_mm_castsi128_pd(_mm_xor_si128(b1, _mm_slli_epi64::<63>(bits))), F64x2::sign());
                let sin = _mm_xor_pd(F64x2::select(odd, c.0, s.0), neg_sin);
                let cos = _mm_xor_pd(F64x2::select(odd, s.0, c.0), neg_cos);
                (F64x2(sin), F64x2(cos))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn two_lanes_give_the_bits_of_one() {
        use super::{F64Lanes, F64x2};
        let values = [
            0.0,
            -0.0,
            1e-300,
            0.3,
            -2.5,
            1.0 - 1e-12,
            3.0,
            7.9,
            15.9,
            16.0,
            17.0,
            -100.0,
            1e30,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for &a in &values {
            for &b in &values {
                let v = F64x2::new(a, b);
                let check = |got: F64x2, want: [f64; 2], what: &str| {
                    let g = got.lanes();
                    assert!(same(g[0], want[0]) && same(g[1], want[1]), "{what}({a}, {b}): {g:?} against {want:?}");
                };
                check(v.sqrt(), [a.sqrt(), b.sqrt()], "sqrt");
                check(v.max_const(1e-300), [a.max(1e-300), b.max(1e-300)], "max");
                check(-v, [-a, -b], "neg");
                check(v / F64x2::splat(3.0), [a / 3.0, b / 3.0], "div");
                check(v.copysign(F64x2::new(-1.0, 1.0)), [a.copysign(-1.0), b.copysign(1.0)], "copysign");
                check(
                    v.clamp(F64x2::splat(-0.0), F64x2::splat(7.9)),
                    [a.clamp(-0.0, 7.9), b.clamp(-0.0, 7.9)],
                    "clamp",
                );
                let (t, o) = (F64x2::splat(1.0), F64x2::splat(2.0));
                check(v.lt_select(0.3, t, o), [a.lt_select(0.3, 1.0, 2.0), b.lt_select(0.3, 1.0, 2.0)], "select");
                let (s, c) = v.sin_cos();
                let ((sa, ca), (sb, cb)) = (F64Lanes::sin_cos(a), F64Lanes::sin_cos(b));
                check(s, [sa, sb], "sin");
                check(c, [ca, cb], "cos");
                assert_eq!(v.all_within(16.0), a.all_within(16.0) && b.all_within(16.0), "within({a}, {b})");
            }
        }
        // Every quarter turn from −10 to 10, each lane on its own.
        for q in -10..=10 {
            let x = q as f64 * std::f64::consts::FRAC_PI_2 + 0.1;
            let (s, c) = F64x2::new(x, -x).sin_cos();
            let ((sa, ca), (sb, cb)) = (F64Lanes::sin_cos(x), F64Lanes::sin_cos(-x));
            assert!(same(s.lanes()[0], sa) && same(s.lanes()[1], sb), "sin at quarter turn {q}");
            assert!(same(c.lanes()[0], ca) && same(c.lanes()[1], cb), "cos at quarter turn {q}");
        }
    }
}
