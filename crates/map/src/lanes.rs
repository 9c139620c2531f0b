//! Eight `f32` lanes: a row of a block's voxels, as the integrator updates it.
//!
//! Two implementations give the same results bit for bit (each operation is the same IEEE
//! operation, lane by lane): `wide`'s `f32x8`, portable (two SSE2 halves on baseline x86-64,
//! NEON on aarch64), and [`Avx2`], one 256-bit register, which x86-64 CPUs with AVX2 run when
//! it is detected at run time. The program stays built for baseline x86-64, so it runs on any
//! robot's CPU; the wider registers are a choice made per frame (see `integrate`).

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

use wide::{f32x8, i32x8, u32x8};

use crate::layer::TSDF_STEPS;

/// What the integrator computes with. Comparisons return masks of the same type (all bits
/// set where true); `select` and `to_bitmask` read them.
pub(crate) trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
{
    fn splat(value: f32) -> Self;
    fn new(values: [f32; 8]) -> Self;
    fn to_array(self) -> [f32; 8];
    fn simd_ge(self, rhs: Self) -> Self;
    fn simd_gt(self, rhs: Self) -> Self;
    fn simd_le(self, rhs: Self) -> Self;
    fn simd_lt(self, rhs: Self) -> Self;
    /// Lanes neither infinite nor NaN.
    fn is_finite(self) -> Self;
    /// The smaller lane; `self` where `rhs` is NaN, `rhs` where only `self` is.
    fn min(self, rhs: Self) -> Self;
    fn abs(self) -> Self;
    /// `if_true` where this mask is set, else `if_false`.
    fn select(self, if_true: Self, if_false: Self) -> Self;
    /// One bit per lane: the mask's sign bits, lane 0 lowest.
    fn to_bitmask(self) -> u32;
    /// Truncated towards zero, saturating as `as i32` does (NaN gives 0).
    fn trunc_int(self) -> [i32; 8];
    /// A voxel's stored parts, as `TsdfVoxel::new` rounds them: distances (over the
    /// truncation distance) in steps of `1 / TSDF_STEPS`, half away from zero, NaN as 0,
    /// clamped to ±`i16::MAX`; weights as the bits of their nearest bfloat16, ties to even.
    fn encode(tsdf: Self, weight: Self) -> ([i16; 8], [u16; 8]);
    /// Stored distances in steps, as `TsdfVoxel::tsdf` decodes each.
    fn decode_steps(steps: [i16; 8]) -> Self;
    /// bfloat16 bits as the `f32` they stand for.
    fn from_bfloat(bits: [u16; 8]) -> Self;
    /// One bit per lane whose bits are not all zero (a weight's: observed).
    fn nonzero_bitmask(self) -> u32;
}

impl Lanes for f32x8 {
    #[inline(always)]
    fn splat(value: f32) -> Self {
        f32x8::splat(value)
    }
    #[inline(always)]
    fn new(values: [f32; 8]) -> Self {
        f32x8::new(values)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        f32x8::to_array(self)
    }
    #[inline(always)]
    fn simd_ge(self, rhs: Self) -> Self {
        f32x8::simd_ge(self, rhs)
    }
    #[inline(always)]
    fn simd_gt(self, rhs: Self) -> Self {
        f32x8::simd_gt(self, rhs)
    }
    #[inline(always)]
    fn simd_le(self, rhs: Self) -> Self {
        f32x8::simd_le(self, rhs)
    }
    #[inline(always)]
    fn simd_lt(self, rhs: Self) -> Self {
        f32x8::simd_lt(self, rhs)
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        f32x8::is_finite(self)
    }
    #[inline(always)]
    fn min(self, rhs: Self) -> Self {
        f32x8::min(self, rhs)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f32x8::abs(self)
    }
    #[inline(always)]
    fn select(self, if_true: Self, if_false: Self) -> Self {
        f32x8::select(self, if_true, if_false)
    }
    #[inline(always)]
    fn to_bitmask(self) -> u32 {
        f32x8::to_bitmask(self)
    }
    #[inline(always)]
    fn trunc_int(self) -> [i32; 8] {
        f32x8::trunc_int(self).to_array()
    }
    #[inline(always)]
    fn encode(tsdf: Self, weight: Self) -> ([i16; 8], [u16; 8]) {
        let steps = tsdf * f32x8::splat(TSDF_STEPS);
        // Half away from zero (`copysign`), then the saturating conversion, clamped.
        let half = f32x8::splat(0.5) | (steps & f32x8::splat(-0.0));
        let rounded = (steps + half)
            .trunc_int()
            .max(i32x8::splat(-i16::MAX as i32))
            .min(i32x8::splat(i16::MAX as i32))
            .to_array();
        let bits: u32x8 = bytemuck::cast(weight);
        let odd: u32x8 = (bits >> 16u32) & u32x8::splat(1);
        let rounded_up: u32x8 = bits + u32x8::splat(0x7fff) + odd;
        let bfloat = (rounded_up >> 16u32).to_array();
        (rounded.map(|s| s as i16), bfloat.map(|b| b as u16))
    }
    #[inline(always)]
    fn decode_steps(steps: [i16; 8]) -> Self {
        f32x8::from_i32x8(i32x8::new(steps.map(i32::from))) * f32x8::splat(1.0 / TSDF_STEPS)
    }
    #[inline(always)]
    fn from_bfloat(bits: [u16; 8]) -> Self {
        f32x8::new(bits.map(|b| f32::from_bits(u32::from(b) << 16)))
    }
    #[inline(always)]
    fn nonzero_bitmask(self) -> u32 {
        let bits: u32x8 = bytemuck::cast(self);
        !u32x8::simd_eq(bits, u32x8::ZERO).to_bitmask() & 0xff
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use avx2::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! Every method is a few AVX or AVX2 instructions, inlined into a caller compiled with
    //! `#[target_feature(enable = "avx2")]`, which only runs where the CPU has AVX2.

    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

    use super::{Lanes, TSDF_STEPS};

    /// Eight `f32` lanes in one AVX register.
    #[derive(Clone, Copy)]
    #[repr(transparent)]
    pub(crate) struct Avx2(__m256);

    // SAFETY (every `unsafe` block below): the intrinsics need AVX or AVX2, which the only
    // callers (compiled with those features, run after detecting them) guarantee; loads and
    // stores are unaligned ones of arrays of exactly their width.

    macro_rules! binary {
        ($trait:ident, $method:ident, $intrinsic:ident) => {
            impl $trait for Avx2 {
                type Output = Avx2;
                #[inline(always)]
                fn $method(self, rhs: Avx2) -> Avx2 {
                    Avx2(unsafe { $intrinsic(self.0, rhs.0) })
                }
            }
        };
    }
    binary!(Add, add, _mm256_add_ps);
    binary!(Sub, sub, _mm256_sub_ps);
    binary!(Mul, mul, _mm256_mul_ps);
    binary!(Div, div, _mm256_div_ps);
    binary!(BitAnd, bitand, _mm256_and_ps);
    binary!(BitOr, bitor, _mm256_or_ps);

    impl Avx2 {
        #[inline(always)]
        fn compare<const PREDICATE: i32>(self, rhs: Avx2) -> Avx2 {
            Avx2(unsafe { _mm256_cmp_ps::<PREDICATE>(self.0, rhs.0) })
        }

        #[inline(always)]
        fn bits(self) -> __m256i {
            unsafe { _mm256_castps_si256(self.0) }
        }

        /// Eight `i32` lanes packed into eight `i16`, saturating (callers clamp first).
        #[inline(always)]
        fn pack_i16(v: __m256i) -> [i16; 8] {
            let mut out = [0i16; 8];
            unsafe {
                let packed =
                    _mm_packs_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
                _mm_storeu_si128(out.as_mut_ptr().cast(), packed);
            }
            out
        }
    }

    impl Lanes for Avx2 {
        #[inline(always)]
        fn splat(value: f32) -> Self {
            Avx2(unsafe { _mm256_set1_ps(value) })
        }
        #[inline(always)]
        fn new(values: [f32; 8]) -> Self {
            Avx2(unsafe { _mm256_loadu_ps(values.as_ptr()) })
        }
        #[inline(always)]
        fn to_array(self) -> [f32; 8] {
            let mut out = [0.0; 8];
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }
        // Ordered, quiet comparisons: false where either lane is NaN, as `wide`'s.
        #[inline(always)]
        fn simd_ge(self, rhs: Self) -> Self {
            self.compare::<_CMP_GE_OQ>(rhs)
        }
        #[inline(always)]
        fn simd_gt(self, rhs: Self) -> Self {
            self.compare::<_CMP_GT_OQ>(rhs)
        }
        #[inline(always)]
        fn simd_le(self, rhs: Self) -> Self {
            self.compare::<_CMP_LE_OQ>(rhs)
        }
        #[inline(always)]
        fn simd_lt(self, rhs: Self) -> Self {
            self.compare::<_CMP_LT_OQ>(rhs)
        }
        #[inline(always)]
        fn is_finite(self) -> Self {
            // The exponent's bits, shifted past the sign, are not all set.
            unsafe {
                let exponent = _mm256_set1_epi32(0xff00_0000u32 as i32);
                let shifted = _mm256_and_si256(_mm256_slli_epi32::<1>(self.bits()), exponent);
                let infinite_or_nan = _mm256_cmpeq_epi32(shifted, exponent);
                Avx2(_mm256_castsi256_ps(_mm256_xor_si256(
                    infinite_or_nan,
                    _mm256_set1_epi32(-1),
                )))
            }
        }
        #[inline(always)]
        fn min(self, rhs: Self) -> Self {
            // MINPS gives `rhs` where either lane is NaN: `self` is kept where `rhs` is NaN.
            let rhs_nan = rhs.compare::<_CMP_UNORD_Q>(rhs);
            rhs_nan.select(self, Avx2(unsafe { _mm256_min_ps(self.0, rhs.0) }))
        }
        #[inline(always)]
        fn abs(self) -> Self {
            self & Avx2::splat(f32::from_bits(i32::MAX as u32))
        }
        #[inline(always)]
        fn select(self, if_true: Self, if_false: Self) -> Self {
            // Masks are whole lanes of ones or zeros, so the sign bit BLENDV reads decides
            // as the whole mask does.
            Avx2(unsafe { _mm256_blendv_ps(if_false.0, if_true.0, self.0) })
        }
        #[inline(always)]
        fn to_bitmask(self) -> u32 {
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn trunc_int(self) -> [i32; 8] {
            let mut out = [0i32; 8];
            unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), self.trunc_saturating()) };
            out
        }
        #[inline(always)]
        fn encode(tsdf: Self, weight: Self) -> ([i16; 8], [u16; 8]) {
            let steps = tsdf * Avx2::splat(TSDF_STEPS);
            let half = Avx2::splat(0.5) | (steps & Avx2::splat(-0.0));
            let rounded = (steps + half).trunc_saturating();
            let steps = unsafe {
                let low = _mm256_set1_epi32(-(i16::MAX as i32));
                let high = _mm256_set1_epi32(i16::MAX as i32);
                Avx2::pack_i16(_mm256_min_epi32(_mm256_max_epi32(rounded, low), high))
            };
            let mut bfloat = [0u16; 8];
            unsafe {
                let bits = weight.bits();
                let odd = _mm256_and_si256(_mm256_srli_epi32::<16>(bits), _mm256_set1_epi32(1));
                let rounded_up =
                    _mm256_add_epi32(_mm256_add_epi32(bits, _mm256_set1_epi32(0x7fff)), odd);
                let upper = _mm256_srli_epi32::<16>(rounded_up);
                // Every lane is at most 0xffff: the unsigned pack is exact.
                let packed = _mm_packus_epi32(
                    _mm256_castsi256_si128(upper),
                    _mm256_extracti128_si256::<1>(upper),
                );
                _mm_storeu_si128(bfloat.as_mut_ptr().cast(), packed);
            }
            (steps, bfloat)
        }
        #[inline(always)]
        fn decode_steps(steps: [i16; 8]) -> Self {
            unsafe {
                let wide = _mm256_cvtepi16_epi32(_mm_loadu_si128(steps.as_ptr().cast()));
                Avx2(_mm256_cvtepi32_ps(wide)) * Avx2::splat(1.0 / TSDF_STEPS)
            }
        }
        #[inline(always)]
        fn from_bfloat(bits: [u16; 8]) -> Self {
            unsafe {
                let wide = _mm256_cvtepu16_epi32(_mm_loadu_si128(bits.as_ptr().cast()));
                Avx2(_mm256_castsi256_ps(_mm256_slli_epi32::<16>(wide)))
            }
        }
        #[inline(always)]
        fn nonzero_bitmask(self) -> u32 {
            unsafe {
                let zero = _mm256_cmpeq_epi32(self.bits(), _mm256_setzero_si256());
                !(_mm256_movemask_ps(_mm256_castsi256_ps(zero)) as u32) & 0xff
            }
        }
    }

    impl Avx2 {
        /// `as i32` lane by lane: CVTTPS2DQ gives `i32::MIN` for NaN and out-of-range lanes;
        /// NaN lanes are zeroed first, and lanes at or above 2³¹ flip to `i32::MAX`.
        #[inline(always)]
        fn trunc_saturating(self) -> __m256i {
            let not_nan = self.compare::<_CMP_EQ_OQ>(self);
            let too_big = self.compare::<_CMP_GE_OQ>(Avx2::splat(2_147_483_648.0));
            unsafe {
                let truncated = _mm256_cvttps_epi32((self & not_nan).0);
                _mm256_xor_si256(truncated, too_big.bits())
            }
        }
    }
}

/// The vector unit the integrator's rows run on, chosen once per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum VectorUnit {
    /// `wide`'s portable lanes.
    Portable,
    /// One AVX2 register per row (x86-64 CPUs that have it).
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl VectorUnit {
    /// The widest unit this CPU has: the project's one choice (`voxpan_core::cpu`), so
    /// that `cpu::as_built` keeps the integrator on portable lanes too.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if voxpan_core::cpu::use_avx2() {
            return VectorUnit::Avx2;
        }
        VectorUnit::Portable
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// Values where conversions, comparisons and NaN handling decide.
    const EDGES: [f32; 24] = [
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.5,
        -2.5,
        1.0e-40,
        -1.0e-40,
        3.3e-7,
        255.49998,
        32767.5,
        -32767.5,
        2_147_483_520.0,
        2_147_483_648.0,
        -2_147_483_648.0,
        -3.0e9,
        1.0e30,
        f32::MAX,
        f32::MIN_POSITIVE,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        -f32::NAN,
        0.1,
    ];

    fn bits(values: [f32; 8]) -> [u32; 8] {
        values.map(f32::to_bits)
    }

    /// Each operation of `Avx2` against `wide`'s, on every window of eight edge values
    /// paired with every other window.
    #[test]
    fn avx2_lanes_match_the_portable_ones_bit_for_bit() {
        if !std::is_x86_feature_detected!("avx2") {
            // A machine without AVX2 cannot check the AVX2 path: said loudly, as any missing
            // prerequisite, and skipped only when that is allowed.
            assert!(
                voxpan_test_support::missing_data_allowed(),
                "this CPU has no AVX2, so the AVX2 lanes cannot be checked here (set {}=1 to \
                 skip)",
                voxpan_test_support::ALLOW_MISSING_ENV
            );
            eprintln!("SKIPPED: this CPU has no AVX2");
            return;
        }
        // SAFETY: AVX2 was detected above.
        unsafe { compare_all() }
    }

    #[target_feature(enable = "avx2")]
    unsafe fn compare_all() {
        let n = EDGES.len();
        let window = |start: usize| -> [f32; 8] { std::array::from_fn(|i| EDGES[(start + i) % n]) };
        for a in 0..n {
            for b in 0..n {
                let (x, y) = (window(a), window(b * 5 + 3));
                let (p, q) = (<f32x8 as Lanes>::new(x), <f32x8 as Lanes>::new(y));
                let (r, s) = (Avx2::new(x), Avx2::new(y));
                let same = |portable: f32x8, avx: Avx2, what: &str| {
                    assert_eq!(
                        bits(Lanes::to_array(portable)),
                        bits(avx.to_array()),
                        "{what} of {x:?} and {y:?}"
                    );
                };
                same(p + q, r + s, "+");
                same(p - q, r - s, "-");
                same(p * q, r * s, "*");
                same(p / q, r / s, "/");
                same(p & q, r & s, "&");
                same(p | q, r | s, "|");
                same(Lanes::simd_ge(p, q), r.simd_ge(s), ">=");
                same(Lanes::simd_gt(p, q), r.simd_gt(s), ">");
                same(Lanes::simd_le(p, q), r.simd_le(s), "<=");
                same(Lanes::simd_lt(p, q), r.simd_lt(s), "<");
                same(Lanes::is_finite(p), r.is_finite(), "is_finite");
                same(Lanes::min(p, q), r.min(s), "min");
                same(Lanes::abs(p), r.abs(), "abs");
                let mask = Lanes::simd_lt(p, q);
                same(
                    Lanes::select(mask, p, q),
                    r.simd_lt(s).select(r, s),
                    "select",
                );
                assert_eq!(Lanes::to_bitmask(p), r.to_bitmask(), "bitmask of {x:?}");
                assert_eq!(Lanes::trunc_int(p), r.trunc_int(), "trunc of {x:?}");
                assert_eq!(
                    <f32x8 as Lanes>::encode(p, q),
                    Avx2::encode(r, s),
                    "encode {x:?} {y:?}"
                );
                assert_eq!(
                    Lanes::nonzero_bitmask(p),
                    r.nonzero_bitmask(),
                    "nonzero {x:?}"
                );
                let steps: [i16; 8] = std::array::from_fn(|i| x[i].to_bits() as i16);
                same(
                    <f32x8 as Lanes>::decode_steps(steps),
                    Avx2::decode_steps(steps),
                    "decode",
                );
                let halves: [u16; 8] = std::array::from_fn(|i| (y[i].to_bits() >> 16) as u16);
                same(
                    <f32x8 as Lanes>::from_bfloat(halves),
                    Avx2::from_bfloat(halves),
                    "bfloat",
                );
            }
        }
    }
}
