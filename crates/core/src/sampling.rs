//! Random numbers and warps.
//!
//! Determinism: every random number the renderer uses comes from a [`Pcg32`] stream seeded by
//! hashing `(seed, pixel index, sample index)` (see [`Pcg32::for_sample`]), and a sample draws
//! its dimensions in a fixed order. Nothing depends on which thread renders which pixel, so an
//! image is bit-identical whatever the thread count.

use crate::lanes::F64Lanes;
use glam::{Vec2, Vec3};

/// PCG32 (O'Neill 2014): 64-bit state, 32-bit output.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

const PCG_MULT: u64 = 0x5851_f42d_4c95_7f2d;

/// A strong 64-bit mix (the SplitMix64 finalizer).
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Pcg32 {
    pub fn new(seed: u64, stream: u64) -> Pcg32 {
        let mut r = Pcg32 { state: 0, inc: (stream << 1) | 1 };
        r.next_u32();
        r.state = r.state.wrapping_add(seed);
        r.next_u32();
        r
    }

    /// The stream for one camera sample: a function of the user's seed, the pixel and the sample.
    /// One strong mix of the three (the seed's own mix is the same for every sample of a render)
    /// gives both the state and the stream (increment): every camera sample pays for it, and
    /// the four mixes and two steps this took before cost ~15 % of a sample that sees only the
    /// sky.
    #[inline]
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Pcg32 {
        let key = mix64(seed) ^ pixel.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ sample.wrapping_mul(0xd1b5_4a32_d192_ed03);
        let h = mix64(key);
        Pcg32 { state: h, inc: ((h ^ 0xda3e_39cb_94b9_5bdb).rotate_left(29) << 1) | 1 }
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(PCG_MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in `[0, 1)`, 24 bits of resolution.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_f32();
        Vec2::new(x, self.next_f32())
    }
}

/// Which sample generator a render uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SamplerKind {
    /// Independent random numbers (PCG32); camera samples stratified over the pixel and lens.
    #[default]
    Independent,
    /// Owen-scrambled Sobol points, padded (pbrt-v4's `PaddedSobolSampler`): every pair of
    /// dimensions is a scrambled 2D Sobol sequence over the pixel's samples, with its own
    /// scramble and its own shuffle of the sample order, so dimensions do not correlate.
    Sobol,
}

impl std::str::FromStr for SamplerKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "independent" => Ok(SamplerKind::Independent),
            "sobol" => Ok(SamplerKind::Sobol),
            _ => Err(format!("unknown sampler '{s}' (expected independent or sobol)")),
        }
    }
}

/// The random numbers of one camera sample: independent, or low-discrepancy.
/// Either way a function of `(seed, pixel, sample index)` only.
#[derive(Clone, Debug)]
pub struct Sampler {
    kind: SamplerKind,
    rng: Pcg32,
    /// Hash of seed and pixel, the root of every dimension's scramble.
    key: u64,
    index: u32,
    spp: u32,
    dim: u32,
}

/// A 32-bit integer hash (Wellons' "lowbias32").
#[inline]
fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// The first Sobol dimension (van der Corput in base 2): the bits of `a` reversed.
#[inline]
fn sobol0(a: u32) -> u32 {
    a.reverse_bits()
}

/// The second Sobol dimension: direction numbers `v_k = v_{k-1} ^ (v_{k-1} >> 1)` from `2^31`.
#[inline]
fn sobol1(mut a: u32) -> u32 {
    let (mut v, mut x) = (1u32 << 31, 0u32);
    while a != 0 {
        if a & 1 != 0 {
            x ^= v;
        }
        a >>= 1;
        v ^= v >> 1;
    }
    x
}

/// Owen scrambling of a 32-bit fixed-point value, the fast hash-based form of Laine and Karras
/// (2011) with Burley's (2020) constants: on the bit-reversed value, additions and
/// multiplications by even numbers change each bit only as a function of the bits below it, so
/// each bit of the result is flipped by a function of the bits above it (a nested scramble,
/// which keeps the (0, m, 2)-net structure of Sobol points).
#[inline]
fn owen_scramble(v: u32, seed: u32) -> u32 {
    let mut x = v.reverse_bits();
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x.reverse_bits()
}

#[inline]
fn to_unit(v: u32) -> f32 {
    (v >> 8) as f32 * (1.0 / 16_777_216.0)
}

impl Sampler {
    /// The generator for sample `index` of `spp` at `pixel`.
    pub fn new(kind: SamplerKind, seed: u64, pixel: u64, index: u32, spp: u32) -> Sampler {
        // The scramble key serves the Sobol points only.
        let key = match kind {
            SamplerKind::Sobol => mix64(seed ^ mix64(pixel.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x5851_f42d)),
            SamplerKind::Independent => 0,
        };
        Sampler { kind, rng: Pcg32::for_sample(seed, pixel, index as u64), key, index, spp: spp.max(1), dim: 0 }
    }

    /// The independent stream behind this sample (for strategies that stratify on their own).
    pub fn rng(&mut self) -> &mut Pcg32 {
        &mut self.rng
    }

    /// The scramble seed and the shuffled sample index of the next dimension (pair).
    #[inline]
    fn next_dim(&mut self) -> (u32, u32) {
        let h = mix64(self.key ^ (self.dim as u64).wrapping_mul(0xd1b5_4a32_d192_ed03));
        let index = permute(self.index, self.spp, h as u32);
        (index, (h >> 32) as u32)
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        match self.kind {
            SamplerKind::Independent => self.rng.next_f32(),
            SamplerKind::Sobol => {
                let (index, seed) = self.next_dim();
                self.dim += 1;
                to_unit(owen_scramble(sobol0(index), seed))
            }
        }
    }

    /// Uniform in `[0, 1)²`.
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        match self.kind {
            SamplerKind::Independent => self.rng.next_2d(),
            SamplerKind::Sobol => {
                let (index, seed) = self.next_dim();
                self.dim += 2;
                Vec2::new(
                    to_unit(owen_scramble(sobol0(index), seed)),
                    to_unit(owen_scramble(sobol1(index), hash32(seed ^ 0x68bc_21eb))),
                )
            }
        }
    }
}

/// Kensler's hash-based permutation of `0..n` ("Correlated Multi-Jittered Sampling", 2013):
/// `permute(i, n, key)` for `i in 0..n` visits each of `0..n` exactly once.
pub fn permute(i: u32, n: u32, key: u32) -> u32 {
    permute_within(i, n, mask_of(n), key)
}

/// The smallest all-ones mask covering `0..n` (what [`permute`] hashes within).
fn mask_of(n: u32) -> u32 {
    let mut w = n.saturating_sub(1);
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    w
}

/// [`permute`] with `w = mask_of(n)` worked out by the caller.
#[inline(always)]
fn permute_within(mut i: u32, n: u32, w: u32, key: u32) -> u32 {
    if n <= 1 {
        return 0;
    }
    loop {
        i ^= key;
        i = i.wrapping_mul(0xe170_893d);
        i ^= key >> 16;
        i ^= (i & w) >> 4;
        i ^= key >> 8;
        i = i.wrapping_mul(0x0929_eb3f);
        i ^= key >> 23;
        i ^= (i & w) >> 1;
        i = i.wrapping_mul(1 | (key >> 27));
        i = i.wrapping_mul(0x6935_fa69);
        i ^= (i & w) >> 11;
        i = i.wrapping_mul(0x74dc_b303);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0x9e50_1cc3);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0xc860_a3df);
        i &= w;
        i ^= i >> 5;
        if i < n {
            break;
        }
    }
    div_rem(i.wrapping_add(key), n).1
}

/// `(a / n, a % n)` (`n > 0`), by a shift and a mask where `n` is a power of two (sample
/// counts mostly are), which spares integer divisions on the per-sample path. The same values
/// either way.
#[inline(always)]
fn div_rem(a: u32, n: u32) -> (u32, u32) {
    if n.is_power_of_two() {
        (a >> n.trailing_zeros(), a & (n - 1))
    } else {
        (a / n, a % n)
    }
}

/// Samples stratified in 2D, `n` of them: a jittered grid when `n` is a square, otherwise a
/// Latin hypercube (one sample per row and per column), with a `key`-dependent pairing of the
/// strata. Worked out once for all `n` samples (the renderer draws every camera sample from the
/// same `n`, Whitted's lights all of a point's samples).
#[derive(Clone, Copy, Debug)]
pub struct Strata {
    n: u32,
    /// The grid's side where `n` is a square, otherwise 0 (a Latin hypercube).
    side: u32,
    /// [`permute`]'s mask for `n`.
    mask: u32,
    /// `1 / side` (or `1 / n` for a Latin hypercube) where that divisor is a power of two, so
    /// that multiplying by it gives exactly the quotient; otherwise 0 (divide).
    inv: f32,
}

impl Strata {
    pub fn new(n: u32) -> Strata {
        let k = (n as f32).sqrt() as u32;
        let side = if k * k == n { k } else { 0 };
        let d = if side != 0 { side } else { n };
        Strata { n, side, mask: mask_of(n), inv: if d.is_power_of_two() { 1.0 / d as f32 } else { 0.0 } }
    }

    /// Sample `i` (of `n`), its cell on a jittered grid chosen by a hash permutation keyed by
    /// `key`.
    #[inline]
    pub fn sample(&self, i: u32, key: u32, rng: &mut Pcg32) -> Vec2 {
        self.sample_with(i, key, rng, true)
    }

    /// [`Strata::sample`], but on a jittered grid sample `i` takes cell `i` (row by row)
    /// rather than a cell chosen by `key`; a Latin hypercube still pairs its rows and columns
    /// by `key`. The same strata and the same jitter. For samples whose other dimensions do
    /// not depend on their index (the film position: each camera sample's random numbers are
    /// hashed from it), the order costs nothing in quality, and it spares the permutation.
    #[inline]
    pub fn sample_in_order(&self, i: u32, key: u32, rng: &mut Pcg32) -> Vec2 {
        self.sample_with(i, key, rng, false)
    }

    #[inline(always)]
    fn sample_with(&self, i: u32, key: u32, rng: &mut Pcg32, shuffle_grid: bool) -> Vec2 {
        let j = rng.next_2d();
        let (n, k) = (self.n, self.side);
        let (x, y, d) = if k != 0 {
            let cell = if shuffle_grid { permute_within(i, n, self.mask, key) } else { i };
            let (row, col) = div_rem(cell, k);
            (col as f32 + j.x, row as f32 + j.y, k as f32)
        } else {
            (i as f32 + j.x, permute_within(i, n, self.mask, key) as f32 + j.y, n as f32)
        };
        // A multiply where it is exact (a power-of-two divisor: the usual sample counts), as
        // the division's latency sits on the path of every camera sample.
        let v = if self.inv != 0.0 { Vec2::new(x, y) * self.inv } else { Vec2::new(x, y) / d };
        v.min(Vec2::splat(1.0 - f32::EPSILON / 2.0))
    }
}

/// `(sin x, cos x)` for `|x| ≤ π/4`, by the minimax polynomials of Cephes' `sinf` and `cosf`
/// for that interval (within 6·10⁻⁸ of the true values; no range reduction, no call). Sampling
/// needs sines and cosines of angles it makes itself, whose range it knows: libm's `sincosf`
/// was 3 % of a Cornell box render.
#[inline]
pub fn sin_cos_octant(x: f32) -> (f32, f32) {
    let z = x * x;
    let s = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * x + x;
    let c = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    (s, c)
}

/// `(sin x, cos x)` in double precision, within 3·10⁻¹⁶ of the true values for `|x| ≤ 16` (the
/// angles of [`crate::light::SphericalRectangle::sample`], in `[0, 2π]`); beyond, libm's. See
/// [`sin_cos_reduced`]. libm's `sincos` in f64 cost about 140 instructions a call, half of a
/// spherical rectangle's sample.
#[inline]
pub fn sin_cos_f64(x: f64) -> (f64, f64) {
    if !x.all_within(SIN_COS_F64_REDUCED) {
        return x.sin_cos();
    }
    sin_cos_reduced(x)
}

/// The largest `|x|` that [`sin_cos_reduced`] takes.
pub const SIN_COS_F64_REDUCED: f64 = 16.0;

/// `(sin x, cos x)` lane by lane for `|x| ≤` [`SIN_COS_F64_REDUCED`] (not NaN). The nearest
/// quarter turn is taken out with π/2 in two parts (its first 33 bits, whose multiples by the
/// quarter count are exact, and the rest), and what is left, at most π/4, goes through fdlibm's
/// minimax polynomials for `sin` and `cos` on `[−π/4, π/4]`.
#[inline(always)]
pub fn sin_cos_reduced<L: F64Lanes>(x: L) -> (L, L) {
    // π/2 to 33 bits, and the rest.
    const PIO2_HI: f64 = 1.570_796_326_734_125_6;
    const PIO2_LO: f64 = 6.077_100_506_506_192e-11;
    // Adding 1.5 · 2^52 rounds to the nearest integer (`round` is a call on the x86-64
    // baseline), which then sits in the low bits of the sum's mantissa; |q| ≤ 10.
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let k = L::splat;
    let t = x * k(std::f64::consts::FRAC_2_PI) + k(SHIFTER);
    let q = t - k(SHIFTER);
    let r = (x - q * k(PIO2_HI)) - q * k(PIO2_LO);
    let z = r * r;
    let s = r + r
        * z
        * (k(-1.666_666_666_666_663_2e-1)
            + z * (k(8.333_333_333_322_49e-3)
                + z * (k(-1.984_126_982_985_795e-4)
                    + z * (k(2.755_731_370_707_006_8e-6)
                        + z * (k(-2.505_076_025_340_686_3e-8) + z * k(1.589_690_995_211_55e-10))))));
    let c = k(1.0) - k(0.5) * z
        + z * z
            * (k(4.166_666_666_666_66e-2)
                + z * (k(-1.388_888_888_887_411e-3)
                    + z * (k(2.480_158_728_947_673e-5)
                        + z * (k(-2.755_731_435_139_066_3e-7)
                            + z * (k(2.087_572_321_298_175e-9) + z * k(-1.135_964_755_778_819_5e-11))))));
    L::quarter_turns(t, s, c)
}

/// `atan2(y, x)` in `[−π, π]`, within 3·10⁻⁷ rad of the exact value for finite arguments: the
/// quadrant taken out exactly, the rest an arc tangent of `min / max` in `[0, 1]` by Cephes'
/// `atanf` (its reduction about `tan(π/8)` and its minimax polynomial). Where the image
/// coordinates of a direction are needed (an environment image's lookup and density, a
/// sphere's UV), libm's `atan2f` cost about 290 instructions a call, a tenth of a render lit
/// by an image. NaN arguments give NaN; `(±0, ±0)` gives `±0` or `±π` as `atan2` does; two
/// infinite arguments give NaN (where `atan2` gives a multiple of π/4).
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let swap = ay > ax;
    let (num, den) = if swap { (ax, ay) } else { (ay, ax) };
    // Above tan(π/8) the reduction about π/4, `(t − 1) / (t + 1)` for `t = num / den`, is
    // taken as `(num − den) / (num + den)`: one division on the way instead of two in a row
    // (and the difference exact where `num / den ≥ 1/2`). 0 / 0 (both zero) is 0; NaN
    // arguments stay NaN.
    let big = num > 0.414_213_57 * den; // tan(π/8)
    let (base, n, d) = if big { (FRAC_PI_4, num - den, num + den) } else { (0.0, num, den) };
    let t = if d == 0.0 { n } else { n / d };
    let z = t * t;
    let mut r = base + ((((8.053_744_5e-2 * z - 1.387_768_6e-1) * z + 1.997_771_1e-1) * z - 3.333_295e-1) * z * t + t);
    if swap {
        r = FRAC_PI_2 - r;
    }
    if x.is_sign_negative() {
        r = PI - r;
    }
    r.copysign(y)
}

/// `x.round()` (halves away from zero), the same bits, without a call. The release build
/// targets x86-64's baseline, which has no rounding instruction (SSE4.1's `roundss`), so
/// `f32::round` is a call to `roundf` through the GOT: about 30 instructions on every
/// environment light sample ([`cos_sin_turn`]; 0.7 % of the bunny's render time under a
/// constant environment). Below 2^23, `x` plus `0.5 − 2^-25` with `x`'s sign, truncated, is
/// `x` rounded: where `x`'s fraction is one half or more the rounded sum reaches the next
/// integer (the exact sum falls short of it by 2^-25, less than half the spacing of floats
/// there, a tie only at 1 − 2^-25, which rounds to even: 1), and where it is less the sum
/// stays below it (short by at least `x`'s own spacing and 2^-25, more than half the spacing
/// there, at most twice `x`'s). From 2^23 up every float is an integer, and infinities and
/// NaN pass through; a zero result takes `x`'s sign, as `roundf`'s does.
#[inline(always)]
pub fn round(x: f32) -> f32 {
    const HALF_BELOW: f32 = 0.5 - 1.0 / 33_554_432.0; // the float below 0.5
    if x.abs() < 8_388_608.0 {
        // SAFETY: `|x| < 2^23`, so the sum lies well within `i32`'s range.
        (unsafe { (x + HALF_BELOW.copysign(x)).to_int_unchecked::<i32>() } as f32).copysign(x)
    } else {
        x
    }
}

/// `eˣ` within one unit in the last place, without a call where the result is a normal float
/// (`x` in `[−87, 88]`). libm's `expf` is a call through the GOT, and below −87.3 (a Beckmann
/// distribution's `e^(−tan²θ/α²)` for a small α) it goes through its underflow handling and
/// sets `errno`: together 6 % of a render of Veach's MIS scene, whose rough plates are
/// Beckmann and whose film splats through a Gaussian. `x = k ln 2 + r` with `|r| ≤ ln 2 / 2`
/// (ln 2 in two parts, Cody and Waite's reduction, so that `k ln 2` loses nothing), `eʳ` by a
/// degree-6 polynomial fitted for relative error, and `2ᵏ` put into the exponent's bits.
/// Below −104 the result is 0, as `expf`'s is (e⁻¹⁰⁴ is under half the smallest subnormal);
/// between −104 and −87 (subnormal results), above 88 and for NaN, `expf` itself.
#[inline]
pub fn exp(x: f32) -> f32 {
    if !(-87.0..=88.0).contains(&x) {
        return if x < -104.0 { 0.0 } else { x.exp() };
    }
    exp_in_range(x)
}

/// [`exp`] for `x` in `[−87, 88]`, where it is a normal float; outside that range the result is
/// wrong. Without a branch, so that a loop over lanes of it is vectorised.
#[inline(always)]
pub fn exp_in_range(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75; // 0x3f317200: k · LN2_HI is exact for |k| < 2^8
    const LN2_LO: f32 = 1.428_606_8e-6; // ln 2 − LN2_HI
    const ROUNDER: f32 = 12_582_912.0; // 1.5 · 2^23: adding it rounds to an integer
    let biased = x * std::f32::consts::LOG2_E + ROUNDER;
    let k = biased - ROUNDER;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let p = (((1.375_176e-3 * r + 8.368_915e-3) * r + 4.166_952_5e-2) * r + 1.666_651_8e-1) * r + 0.499_999_88;
    let er = 1.0 + (r + r * r * p);
    // `biased` is 1.5 · 2^23 + k, so its bits are ROUNDER's plus `k`; `k` lies in [−126, 127],
    // so `2ᵏ` is a normal float.
    let k_bits = biased.to_bits().wrapping_sub(ROUNDER.to_bits());
    er * f32::from_bits(k_bits.wrapping_add(127) << 23)
}

/// `(cos 2πu, sin 2πu)` for `u` in `[0, 1]`: the nearest quarter turn is taken out exactly
/// (`4u − q` has no rounding error) and the rest is an angle of at most π/4.
#[inline]
pub fn cos_sin_turn(u: f32) -> (f32, f32) {
    let t = 4.0 * u;
    let q = round(t);
    let (s, c) = sin_cos_octant((t - q) * std::f32::consts::FRAC_PI_2);
    // By quarter turn `q & 3`: (c, s), (−s, c), (−c, −s), (s, −c). Worked out with bit masks
    // (an odd quarter swaps the two, the second and third negate the cosine, the third and
    // fourth the sine), not a `match`: a jump on a quarter drawn at random was mispredicted
    // three times in four. Negation flips the sign bit, as `-x` does.
    let (s, c) = (s.to_bits(), c.to_bits());
    let q = q as i32 as u32;
    let swap = 0u32.wrapping_sub(q & 1);
    let (x, y) = ((c & !swap) | (s & swap), (s & !swap) | (c & swap));
    let neg_x = (q.wrapping_add(1) & 2) << 30;
    let neg_y = (q & 2) << 30;
    (f32::from_bits(x ^ neg_x), f32::from_bits(y ^ neg_y))
}

/// Uniform point on the unit disk (Shirley–Chiu concentric map).
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o == Vec2::ZERO {
        return Vec2::ZERO;
    }
    // θ = π/4 · (y/x) for the left and right wedges, π/2 − π/4 · (x/y) for the others, whose
    // cosine and sine are the sine and cosine of π/4 · (x/y).
    if o.x.abs() > o.y.abs() {
        let (s, c) = sin_cos_octant(std::f32::consts::FRAC_PI_4 * (o.y / o.x));
        o.x * Vec2::new(c, s)
    } else {
        let (s, c) = sin_cos_octant(std::f32::consts::FRAC_PI_4 * (o.x / o.y));
        o.y * Vec2::new(s, c)
    }
}

/// Direction uniform within the cone about +z of half-angle θmax, given as `1 − cos θmax`; pdf
/// `1 / (2π (1 − cos θmax))`. The cone's size is taken as `1 − cos θmax`, and each direction's
/// sine from `1 − cos θ`, so that a narrow cone (a small or distant sphere light, where
/// `cos θmax` rounds to within a few units of 1) keeps its size and shape: see
/// [`one_minus_cos_asin`].
pub fn uniform_cone(u: Vec2, one_minus_cos_max: f32) -> Vec3 {
    let one_minus_cos_t = u.x * one_minus_cos_max;
    let cos_t = 1.0 - one_minus_cos_t;
    let sin_t = (one_minus_cos_t * (2.0 - one_minus_cos_t)).max(0.0).sqrt();
    let (cos_p, sin_p) = cos_sin_turn(u.y);
    Vec3::new(cos_p * sin_t, sin_p * sin_t, cos_t)
}

/// `1 − cos θ` for the angle θ whose sine squared is `sin2` (in [0, 1]), without the
/// cancellation of `1 − sqrt(1 − sin2)`: `sin2 / (1 + sqrt(1 − sin2))`. A sphere of radius r
/// seen from distance d subtends the cone `sin² θmax = r² / d²`; in f32 the difference form is
/// off by 0.14 % for r / d = 0.005 (the sun from the earth), 7 % for 0.001, and 0 below
/// 1.7·10⁻⁴, where this keeps full precision.
#[inline]
pub fn one_minus_cos_asin(sin2: f32) -> f32 {
    sin2 / (1.0 + (1.0 - sin2).max(0.0).sqrt())
}

/// Barycentrics `(b1, b2)` uniform over a triangle (area preserving square-root map).
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

/// Index `i` with probability `weights[i] / sum`, by inverse CDF, given `cdf` from [`build_cdf`];
/// returns the index and `u` rescaled to `[0, 1)` within the chosen interval.
pub fn sample_cdf(cdf: &[f32], u: f32) -> (usize, f32) {
    let total = *cdf.last().unwrap_or(&0.0);
    let x = u * total;
    let i = cdf.partition_point(|&c| c <= x).min(cdf.len().saturating_sub(1));
    cdf_interval(cdf, i, x)
}

/// `(i, x)`'s place within interval `i` of `cdf`, rescaled to `[0, 1)`, after `i`.
#[inline(always)]
fn cdf_interval(cdf: &[f32], i: usize, x: f32) -> (usize, f32) {
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    let w = cdf[i] - lo;
    (i, if w > 0.0 { ((x - lo) / w).clamp(0.0, 1.0 - f32::EPSILON) } else { 0.0 })
}

/// Each index's probability under [`sample_cdf`] with this `cdf`: its weight over the sum
/// (every one 0 where the sum is not positive).
pub fn cdf_probabilities(cdf: &[f32]) -> Vec<f32> {
    let total = cdf.last().copied().unwrap_or(0.0);
    (0..cdf.len())
        .map(|i| {
            let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
            if total > 0.0 {
                (cdf[i] - lo) / total
            } else {
                0.0
            }
        })
        .collect()
}

/// Running sums of `weights` (the unnormalised CDF).
pub fn build_cdf(weights: impl IntoIterator<Item = f32>) -> Vec<f32> {
    let mut acc = 0.0f64;
    weights
        .into_iter()
        .map(|w| {
            acc += w.max(0.0) as f64;
            acc as f32
        })
        .collect()
}

/// Buckets of a CDF's guide table ([`cdf_guide`]): a power of two, so that a bucket's bounds
/// `k / GUIDE_BUCKETS` and the bucket of `u` are exact.
const GUIDE_BUCKETS: usize = 64;

/// The guide table of `cdf` (Chen and Asau's, in equal steps of `u`): entry `k` is where
/// [`sample_cdf`]'s search lands for `u = k / GUIDE_BUCKETS`, but the first, which is 0 (a `u`
/// below 0 lands before any leading zero weights). The last is the CDF's length.
fn cdf_guide(cdf: &[f32]) -> [u32; GUIDE_BUCKETS + 1] {
    let total = *cdf.last().unwrap_or(&0.0);
    let mut g = [0u32; GUIDE_BUCKETS + 1];
    for (k, slot) in g.iter_mut().enumerate().skip(1) {
        let x = (k as f32 / GUIDE_BUCKETS as f32) * total;
        *slot = cdf.partition_point(|&c| c <= x) as u32;
    }
    g
}

/// [`sample_cdf`]`(cdf, u)`, the same bits, through `cdf`'s [`cdf_guide`]: a binary search
/// over the few entries between two guide entries instead of all of them (the search of a
/// 1,024-entry row of an environment map's distribution waited on about ten dependent loads,
/// most of them cache misses: 62 % of an environment sample's time, perf). The search's
/// answer, the first entry above `x = u · total`, only grows with `u`; `u`'s bucket `k` has
/// `k / B ≤ u < (k + 1) / B`, whose products with the total bound `x` (a product with a
/// non-negative number is monotone in the other factor), so the answer lies between guide
/// entries `k` and `k + 1`. A `u` outside `[0, 1)`, or NaN, falls into the first or the last
/// bucket, whose outer bounds are the CDF's ends.
#[inline(always)]
fn sample_guided_cdf(cdf: &[f32], guide: &[u32], u: f32) -> (usize, f32) {
    let total = *cdf.last().unwrap_or(&0.0);
    let x = u * total;
    let k = ((u * GUIDE_BUCKETS as f32) as usize).min(GUIDE_BUCKETS - 1);
    let (lo, hi) = (guide[k] as usize, guide[k + 1] as usize);
    let i = (lo + cdf[lo..hi].partition_point(|&c| c <= x)).min(cdf.len().saturating_sub(1));
    cdf_interval(cdf, i, x)
}

/// The cell `(x, y)` of a `width × height` grid over `[0, 1)²` that holds `p` (the last row or
/// column for coordinates of 1 or more, the first for negative ones or NaN): where
/// [`Distribution2D::pdf`] finds a density, and an environment image the pixel it shows.
#[inline(always)]
pub fn grid_cell(p: Vec2, width: usize, height: usize) -> (usize, usize) {
    let x = ((p.x * width as f32) as usize).min(width - 1);
    let y = ((p.y * height as f32) as usize).min(height - 1);
    (x, y)
}

/// A piecewise-constant 2D distribution over `[0, 1)²` on a `width × height` grid of
/// non-negative weights (pbrt's `PiecewiseConstant2D`): a marginal over rows, a conditional
/// per row, each searched through a guide table (`cdf_guide`). The rows' running sums lie
/// in one array, row after row, as do their guides.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution2D {
    width: usize,
    height: usize,
    /// Row by row, each row's running sums of its weights (`width` each).
    rows: Vec<f32>,
    /// Row by row, each row's guide table (`GUIDE_BUCKETS + 1` each).
    row_guides: Vec<u32>,
    /// Running sums of the rows' totals.
    marginal: Vec<f32>,
    /// The marginal's guide table (on the heap: inline, it made every light 440 bytes).
    marginal_guide: Vec<u32>,
}

impl Distribution2D {
    /// `weights` row by row (`weights[y * width + x]`). `None` if everything is zero.
    pub fn new(width: usize, height: usize, weights: &[f32]) -> Option<Distribution2D> {
        if width == 0 || height == 0 || weights.len() != width * height {
            return None;
        }
        let rows: Vec<f32> = weights.chunks(width).flat_map(|r| build_cdf(r.iter().copied())).collect();
        let row_guides = rows.chunks(width).flat_map(cdf_guide).collect();
        let marginal = build_cdf(rows.chunks(width).map(|r| r[width - 1]));
        let marginal_guide = cdf_guide(&marginal).to_vec();
        (*marginal.last()? > 0.0).then_some(Distribution2D {
            width,
            height,
            rows,
            row_guides,
            marginal,
            marginal_guide,
        })
    }

    /// Row `y`'s running sums.
    #[inline(always)]
    fn row(&self, y: usize) -> &[f32] {
        &self.rows[y * self.width..(y + 1) * self.width]
    }

    /// Row `y`'s guide table.
    #[inline(always)]
    fn row_guide(&self, y: usize) -> &[u32] {
        &self.row_guides[y * (GUIDE_BUCKETS + 1)..(y + 1) * (GUIDE_BUCKETS + 1)]
    }

    /// A point in `[0, 1)²` and its density (with respect to area in `[0, 1)²`).
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (y, fy) = sample_guided_cdf(&self.marginal, &self.marginal_guide, u.y);
        let (x, fx) = sample_guided_cdf(self.row(y), self.row_guide(y), u.x);
        let p = Vec2::new((x as f32 + fx) / self.width as f32, (y as f32 + fy) / self.height as f32);
        (p, self.pdf(p))
    }

    /// The density in cell `(x, y)`.
    pub fn cell_pdf(&self, x: usize, y: usize) -> f32 {
        let row = self.row(y);
        let w = row[x] - if x == 0 { 0.0 } else { row[x - 1] };
        let total = *self.marginal.last().unwrap_or(&1.0);
        w / total * (self.width * self.height) as f32
    }

    /// The density at `p ∈ [0, 1)²`.
    pub fn pdf(&self, p: Vec2) -> f32 {
        let (x, y) = grid_cell(p, self.width, self.height);
        self.cell_pdf(x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The inline `round` gives `f32::round`'s bits: every float in [0.25, 4) and its negation
    /// (the quarter turns' range), each half-integer up to 2^23 and its neighbours, the
    /// powers of two around 2^23 and their neighbours, a million random bit patterns, and the
    /// zeros, infinities and NaN. It fails with the constant at exactly 0.5 (0.49999997 rounds
    /// to 1) or without the final `copysign` (−0.4 rounds to +0).
    #[test]
    fn inline_round_is_roundf() {
        let check = |x: f32| {
            let (a, b) = (round(x), x.round());
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "round({x:e}) = {a:e}, not {b:e}");
        };
        let (lo, hi) = (0.25f32.to_bits(), 4.0f32.to_bits());
        for bits in lo..hi {
            check(f32::from_bits(bits));
            check(-f32::from_bits(bits));
        }
        for k in 0..(1u32 << 23) {
            let x = k as f32 + 0.5;
            for v in [x, x.next_up(), x.next_down()] {
                check(v);
                check(-v);
            }
        }
        for e in 20..=32 {
            let x = (e as f32).exp2();
            for v in [x, x.next_up(), x.next_down(), x + 0.5, x - 0.5] {
                check(v);
                check(-v);
            }
        }
        let mut rng = Pcg32::new(7, 8);
        for _ in 0..1_000_000 {
            check(f32::from_bits(rng.next_u32()));
        }
        for x in
            [0.0, -0.0, 0.4, -0.4, 0.5, -0.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, f32::MAX, f32::MIN_POSITIVE]
        {
            check(x);
        }
    }

    /// The inline `exp` is within one unit in the last place of `eˣ` (worked out in f64) over
    /// every 61st float of its own range [−87, 88], a million random floats from −110 to 90,
    /// and the ends of each range with their neighbours; outside its own range it gives
    /// `expf`'s bits (0 below −104). It fails without the low part of ln 2 (16 units off at
    /// x = 0.35) or without the polynomial's top term (2 units).
    #[test]
    fn inline_exp_is_within_an_ulp() {
        let check = |x: f32| {
            let (a, want) = (exp(x), (x as f64).exp() as f32);
            if (-87.0..=88.0).contains(&x) {
                let ulps = (a.to_bits() as i64 - want.to_bits() as i64).abs();
                assert!(ulps <= 1, "exp({x:e}) = {a:e}, e^x = {want:e}: {ulps} units apart");
            } else {
                let b = x.exp();
                assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "exp({x:e}) = {a:e}, not expf's {b:e}"
                );
            }
        };
        for bits in (0..=88.0f32.to_bits()).step_by(61) {
            check(f32::from_bits(bits));
        }
        for bits in (0..=87.0f32.to_bits()).step_by(61) {
            check(-f32::from_bits(bits));
        }
        let mut rng = Pcg32::new(9, 10);
        for _ in 0..1_000_000 {
            check(rng.next_f32() * 200.0 - 110.0);
        }
        for x in [-104.0f32, -87.0, 88.0, 0.0] {
            for v in [x, x.next_up(), x.next_down()] {
                check(v);
            }
        }
        for x in [-0.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, f32::MAX, f32::MIN, -1e-30, 1e-30] {
            check(x);
        }
    }

    /// `cos_sin_turn`'s quarter turns taken by bit masks give the bits of the `match` on the
    /// quarter it replaced, over the turn and beyond it (negative `u`, several turns).
    #[test]
    fn quarter_turns_by_masks_are_the_match() {
        let by_match = |u: f32| {
            let t = 4.0 * u;
            let q = t.round();
            let (s, c) = sin_cos_octant((t - q) * std::f32::consts::FRAC_PI_2);
            match q as i32 & 3 {
                0 => (c, s),
                1 => (-s, c),
                2 => (-c, -s),
                _ => (s, -c),
            }
        };
        let n = 1 << 18;
        for i in -3 * n..=3 * n {
            let u = i as f32 / n as f32;
            for v in [u, u.next_up(), u.next_down()] {
                let (a, b) = (cos_sin_turn(v), by_match(v));
                assert_eq!((a.0.to_bits(), a.1.to_bits()), (b.0.to_bits(), b.1.to_bits()), "u = {v:e}");
            }
        }
    }

    /// The polynomial sine and cosine against f64's, over their whole interval and over the
    /// turn (every quarter, both signs): absolute error below 1.2·10⁻⁷, two steps of f32 near 1
    /// (measured: 5.7·10⁻⁸ and 8.8·10⁻⁸).
    #[test]
    fn polynomial_sine_and_cosine_match_f64() {
        let n = 200_000;
        let mut worst = 0.0f64;
        for i in 0..=n {
            let x = (-std::f64::consts::FRAC_PI_4 + std::f64::consts::FRAC_PI_2 * i as f64 / n as f64) as f32;
            let (s, c) = sin_cos_octant(x);
            worst = worst.max((s as f64 - (x as f64).sin()).abs()).max((c as f64 - (x as f64).cos()).abs());
        }
        assert!(worst < 1.2e-7, "octant: {worst:e}");
        let mut worst = 0.0f64;
        for i in 0..=n {
            let u = i as f32 / n as f32;
            let (c, s) = cos_sin_turn(u);
            let a = std::f64::consts::TAU * u as f64;
            worst = worst.max((s as f64 - a.sin()).abs()).max((c as f64 - a.cos()).abs());
        }
        assert!(worst < 1.2e-7, "turn: {worst:e}");
    }

    /// The polynomial arc tangent against f64's `atan2`: around the whole circle at several
    /// radii, near the axes and diagonals, over magnitudes far apart, and at the signed zeros.
    #[test]
    fn polynomial_sin_cos_matches_libm_in_f64() {
        let mut worst = 0.0f64;
        let mut check = |x: f64| {
            let ((s, c), (s0, c0)) = (sin_cos_f64(x), x.sin_cos());
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        };
        let n = 2_000_000;
        for i in 0..=n {
            check(-0.5 + (std::f64::consts::TAU + 1.0) * i as f64 / n as f64);
        }
        let mut rng = Pcg32::new(5, 6);
        for _ in 0..200_000 {
            check((rng.next_f32() as f64 * 2.0 - 1.0) * 16.0);
            // Near the quarter turns, where the reduction leaves little.
            check(std::f64::consts::FRAC_PI_2 * (rng.next_u32() % 11) as f64 + (rng.next_f32() as f64 - 0.5) * 1e-9);
        }
        assert!(worst < 3e-16, "{worst:e}");
        assert_eq!(sin_cos_f64(0.0), (0.0, 1.0));
        // Beyond the reduced range and for NaN: libm's answer.
        assert_eq!(sin_cos_f64(100.0), 100.0f64.sin_cos());
        assert!(sin_cos_f64(f64::NAN).0.is_nan());
    }

    #[test]
    fn polynomial_atan2_matches_f64() {
        let mut worst = 0.0f64;
        let mut check = |y: f32, x: f32| {
            let (a, b) = (atan2(y, x) as f64, (y as f64).atan2(x as f64));
            worst = worst.max((a - b).abs());
        };
        let n = 400_000;
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            for r in [1e-30f64, 1e-3, 1.0, 7.5, 1e30] {
                check((r * a.sin()) as f32, (r * a.cos()) as f32);
            }
        }
        let mut rng = Pcg32::new(1, 2);
        for _ in 0..200_000 {
            let (u, v) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
            let e = (rng.next_f32() * 60.0 - 30.0).exp2();
            check(u, v * e);
            check(u * e, v);
            check(u, u * (1.0 + 1e-3 * v)); // near the diagonals
        }
        assert!(worst < 3e-7, "{worst:e}");
        // Exact where atan2 is: the axes and the signed zeros.
        use std::f32::consts::{FRAC_PI_2, PI};
        assert_eq!(atan2(0.0, 1.0).to_bits(), 0.0f32.to_bits());
        assert_eq!(atan2(-0.0, 1.0).to_bits(), (-0.0f32).to_bits());
        assert_eq!(atan2(0.0, -1.0), PI);
        assert_eq!(atan2(-0.0, -1.0), -PI);
        assert_eq!(atan2(0.0, -0.0), PI);
        assert_eq!(atan2(2.0, 0.0), FRAC_PI_2);
        assert_eq!(atan2(-2.0, 0.0), -FRAC_PI_2);
        assert_eq!(atan2(0.0, 0.0), 0.0);
        assert!(atan2(f32::NAN, 1.0).is_nan() && atan2(1.0, f32::NAN).is_nan());
    }

    #[test]
    fn sobol_points_of_a_pixel_form_a_net() {
        // 16 Owen-scrambled Sobol points: every elementary interval of area 1/16 (1×16, 2×8,
        // 4×4, 8×2, 16×1 grids) holds exactly one, in every dimension pair.
        for pixel in [0u64, 7, 12345] {
            for pair in 0..4 {
                let pts: Vec<Vec2> = (0..16)
                    .map(|i| {
                        let mut s = Sampler::new(SamplerKind::Sobol, 3, pixel, i, 16);
                        for _ in 0..pair {
                            s.next_2d();
                        }
                        s.next_2d()
                    })
                    .collect();
                for k in 0..=4 {
                    let (nx, ny) = (1u32 << k, 1u32 << (4 - k));
                    let mut seen = vec![0; 16];
                    for p in &pts {
                        assert!(p.x >= 0.0 && p.x < 1.0 && p.y >= 0.0 && p.y < 1.0);
                        seen[((p.y * ny as f32) as u32 * nx + (p.x * nx as f32) as u32) as usize] += 1;
                    }
                    assert!(seen.iter().all(|&c| c == 1), "pixel {pixel} pair {pair} grid {nx}x{ny}: {seen:?}");
                }
            }
        }
    }

    #[test]
    fn sobol_integrates_better_than_independent() {
        // ∫∫ (x + y²) over the unit square = 1/2 + 1/3, estimated per pixel with 64 samples.
        let f = |p: Vec2| p.x + p.y * p.y;
        let err = |kind: SamplerKind| {
            let mut e = 0.0f64;
            for pixel in 0..200u64 {
                let est: f32 = (0..64).map(|i| f(Sampler::new(kind, 1, pixel, i, 64).next_2d())).sum::<f32>() / 64.0;
                e += ((est - 5.0 / 6.0) as f64).powi(2);
            }
            (e / 200.0).sqrt()
        };
        let (sobol, indep) = (err(SamplerKind::Sobol), err(SamplerKind::Independent));
        assert!(sobol < 0.25 * indep, "Sobol RMSE {sobol} vs independent {indep}");
        // And the mean over pixels is unbiased.
        let mean: f64 =
            (0..2000u64).map(|p| f(Sampler::new(SamplerKind::Sobol, 9, p, 5, 64).next_2d()) as f64).sum::<f64>()
                / 2000.0;
        assert!((mean - 5.0 / 6.0).abs() < 0.02, "{mean}");
    }

    /// The guided search is `sample_cdf`'s, index and fraction bit for bit: over CDFs with
    /// runs of zero weights (at the start, in the middle, at the end), a single spike, equal
    /// weights, random ones, lengths from 1 to 3,000, and `u` at and beside every bucket
    /// bound, at random, at 0, below 0, at and above 1, and NaN. It fails if a bucket's
    /// bounds are taken one bucket off (`k + 1` and `k + 2`) or the first guide entry is the
    /// search's answer for `u = 0` (past leading zero weights) instead of 0.
    #[test]
    fn guided_cdf_search_is_the_binary_search() {
        let mut rng = Pcg32::new(21, 22);
        let mut weight_sets: Vec<Vec<f32>> = vec![
            vec![1.0],
            vec![0.0, 0.0, 3.0, 0.0, 0.0],
            vec![0.0; 7].into_iter().chain([1.0]).chain(vec![0.0; 9]).collect(),
            vec![1.0; 1024],
            (0..1024).map(|i| if i == 700 { 1e6 } else { 1e-3 }).collect(),
        ];
        for n in [2usize, 3, 63, 64, 65, 100, 1024, 3000] {
            weight_sets.push((0..n).map(|_| if rng.next_f32() < 0.3 { 0.0 } else { rng.next_f32().powi(4) }).collect());
        }
        for w in &weight_sets {
            let cdf = build_cdf(w.iter().copied());
            let guide = cdf_guide(&cdf);
            let mut us: Vec<f32> = vec![0.0, -0.0, -0.5, 1.0, 1.5, 1.0 - f32::EPSILON / 2.0, f32::NAN, f32::INFINITY];
            for k in 0..=GUIDE_BUCKETS {
                let b = k as f32 / GUIDE_BUCKETS as f32;
                us.extend([b, b.next_up(), b.next_down()]);
            }
            us.extend((0..20_000).map(|_| rng.next_f32()));
            for u in us {
                let (a, b) = (sample_guided_cdf(&cdf, &guide, u), sample_cdf(&cdf, u));
                assert_eq!((a.0, a.1.to_bits()), (b.0, b.1.to_bits()), "u = {u:e}, {} weights", w.len());
            }
        }
    }

    #[test]
    fn distribution_2d_samples_match_its_pdf() {
        let w = [0.0, 1.0, 2.0, 3.0, 0.5, 0.0];
        let d = Distribution2D::new(3, 2, &w).unwrap();
        let mut counts = [0usize; 6];
        let mut rng = Pcg32::new(4, 4);
        let n = 120_000;
        for _ in 0..n {
            let (p, pdf) = d.sample(rng.next_2d());
            let (x, y) = ((p.x * 3.0) as usize, (p.y * 2.0) as usize);
            assert!(pdf > 0.0 && (pdf - d.pdf(p)).abs() < 1e-5);
            counts[y * 3 + x] += 1;
        }
        let total: f32 = w.iter().sum();
        for i in 0..6 {
            let expect = w[i] / total;
            let got = counts[i] as f32 / n as f32;
            assert!((got - expect).abs() < 0.01, "cell {i}: {got} vs {expect}");
            // The pdf integrates to the cell's share: pdf · cell area.
            let centre = Vec2::new((i % 3) as f32 / 3.0 + 0.1, (i / 3) as f32 / 2.0 + 0.1);
            assert!((d.pdf(centre) / 6.0 - expect).abs() < 1e-6);
        }
        assert!(Distribution2D::new(2, 1, &[0.0, 0.0]).is_none());
    }

    #[test]
    fn permute_is_a_permutation() {
        for n in [1u32, 2, 3, 7, 16, 100] {
            for key in [0u32, 1, 0xdead_beef] {
                let mut seen = vec![false; n as usize];
                for i in 0..n {
                    let p = permute(i, n, key) as usize;
                    assert!(!seen[p]);
                    seen[p] = true;
                }
            }
        }
    }

    /// Both orders fill every stratum once: each cell of a jittered grid (shuffled by the key,
    /// or in order: sample `i` in cell `i`, row by row), each row and column of a Latin
    /// hypercube (which the in-order variant leaves as it was, the same points).
    #[test]
    fn strata_in_order_and_shuffled_fill_every_stratum() {
        for (n, key) in [(16u32, 77u32), (64, 5), (10, 77), (12, 3)] {
            let strata = Strata::new(n);
            let side = (n as f32).sqrt() as u32;
            let (mut a, mut b) = (Pcg32::new(1, 2), Pcg32::new(1, 2));
            let shuffled: Vec<Vec2> = (0..n).map(|i| strata.sample(i, key, &mut a)).collect();
            let in_order: Vec<Vec2> = (0..n).map(|i| strata.sample_in_order(i, key, &mut b)).collect();
            for pts in [&shuffled, &in_order] {
                assert!(pts.iter().all(|p| p.x >= 0.0 && p.x < 1.0 && p.y >= 0.0 && p.y < 1.0));
            }
            if side * side == n {
                let cell = |p: &Vec2| (p.y * side as f32) as u32 * side + (p.x * side as f32) as u32;
                let mut cells: Vec<u32> = shuffled.iter().map(cell).collect();
                assert_ne!(cells, (0..n).collect::<Vec<_>>(), "n = {n}: the shuffled grid is in order");
                cells.sort();
                assert_eq!(cells, (0..n).collect::<Vec<_>>(), "n = {n}");
                assert_eq!(in_order.iter().map(cell).collect::<Vec<_>>(), (0..n).collect::<Vec<_>>(), "n = {n}");
            } else {
                assert_eq!(shuffled, in_order, "n = {n}");
                for axis in [0, 1] {
                    let mut s: Vec<u32> = shuffled.iter().map(|p| (p[axis] * n as f32) as u32).collect();
                    s.sort();
                    assert_eq!(s, (0..n).collect::<Vec<_>>(), "n = {n}, axis {axis}");
                }
            }
        }
    }

    #[test]
    fn cdf_sampling_follows_weights() {
        let cdf = build_cdf([1.0, 0.0, 3.0]);
        assert_eq!(sample_cdf(&cdf, 0.1).0, 0);
        assert_eq!(sample_cdf(&cdf, 0.26).0, 2);
        assert_eq!(sample_cdf(&cdf, 0.999).0, 2);
    }
}
