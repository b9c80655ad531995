//! Robust ray origins, after Wächter & Binder, "A Fast and Robust Method for Avoiding
//! Self-Intersection" (Ray Tracing Gems, ch. 6). The hit point is moved along the geometric
//! normal by a fixed number of float ulps (integer arithmetic on the bit pattern), which scales
//! with the magnitude of the coordinates, so no scene-dependent epsilon is needed. Near the
//! origin, where ulps are tiny, a small absolute offset is used instead.

use glam::Vec3;

use super::Ray;

const ORIGIN: f32 = 1.0 / 32.0;
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
const INT_SCALE: f32 = 256.0;

#[inline(always)]
fn offset_component(p: f32, n: f32) -> f32 {
    if p.abs() < ORIGIN {
        return p + FLOAT_SCALE * n;
    }
    // `as i32` for every |256 n| below 10⁹ (a unit normal's is at most 256), written so that a
    // loop over rays can convert in vector lanes (Rust's saturating `as` stays scalar there).
    // NaN becomes -10⁹ (`as` would give 0): a NaN normal's offset is meaningless either way.
    // SAFETY: `max` turns NaN into its bound, so the value lies in ±10⁹, within `i32`.
    // (Not `clamp`, which keeps NaN.)
    #[allow(clippy::manual_clamp)]
    let of_i = unsafe { (INT_SCALE * n).max(-1e9).min(1e9).to_int_unchecked::<i32>() };
    let bits = p.to_bits() as i32;
    let moved = if p < 0.0 { bits - of_i } else { bits + of_i };
    f32::from_bits(moved as u32)
}

/// Moves `p` off the surface with geometric normal `ng` to the side that `w` points into.
#[inline]
pub fn offset_ray_origin(p: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
    let n = if ng.dot(w) < 0.0 { -ng } else { ng };
    #[cfg(target_arch = "x86_64")]
    {
        offset_sse(p, n)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        offset_components(p, n)
    }
}

/// [`offset_ray_origin`] axis by axis in plain arithmetic (the same bits for finite input):
/// for loops over several rays, which the compiler runs in vector lanes across the rays.
#[inline(always)]
pub fn offset_ray_origin_lanewise(p: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
    let n = if ng.dot(w) < 0.0 { -ng } else { ng };
    offset_components(p, n)
}

#[inline(always)]
fn offset_components(p: Vec3, n: Vec3) -> Vec3 {
    Vec3::new(offset_component(p.x, n.x), offset_component(p.y, n.y), offset_component(p.z, n.z))
}

/// [`offset_component`] on the three axes at once in SSE2 lanes: the same arithmetic (the
/// sign bit picks the direction where `|p| >= ORIGIN`, which is `p < 0` there), so the same
/// bits for finite input.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn offset_sse(p: Vec3, n: Vec3) -> Vec3 {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of the x86_64 baseline; only registers are used.
    unsafe {
        let pv = _mm_setr_ps(p.x, p.y, p.z, 0.0);
        let nv = _mm_setr_ps(n.x, n.y, n.z, 0.0);
        let near = _mm_cmplt_ps(_mm_andnot_ps(_mm_set1_ps(-0.0), pv), _mm_set1_ps(ORIGIN));
        let small = _mm_add_ps(pv, _mm_mul_ps(_mm_set1_ps(FLOAT_SCALE), nv));
        let of_i = _mm_cvttps_epi32(_mm_mul_ps(_mm_set1_ps(INT_SCALE), nv));
        let bits = _mm_castps_si128(pv);
        let neg = _mm_srai_epi32(bits, 31);
        let moved = _mm_add_epi32(bits, _mm_sub_epi32(_mm_xor_si128(of_i, neg), neg));
        let r = _mm_or_ps(_mm_and_ps(near, small), _mm_andnot_ps(near, _mm_castsi128_ps(moved)));
        let mut out = [0.0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), r);
        Vec3::new(out[0], out[1], out[2])
    }
}

/// A ray leaving the surface point `p` (geometric normal `ng`) in direction `d`.
#[inline]
pub fn spawn_ray(p: Vec3, ng: Vec3, d: Vec3) -> Ray {
    Ray::new(offset_ray_origin(p, ng, d), d)
}

/// [`spawn_ray`] with [`offset_ray_origin_lanewise`], for loops over several rays.
#[inline(always)]
pub fn spawn_ray_lanewise(p: Vec3, ng: Vec3, d: Vec3) -> Ray {
    Ray::new(offset_ray_origin_lanewise(p, ng, d), d)
}

/// A ray from surface point `p` towards the point `q` (on a surface with normal `nq`, or
/// `Vec3::ZERO` for a point light). Returns the ray, with `t = 1` at the (offset) target, and
/// the largest `t` that a shadow test should consider.
#[inline]
pub fn spawn_ray_to(p: Vec3, ng: Vec3, q: Vec3, nq: Vec3) -> (Ray, f32) {
    spawn_ray_to_with(p, ng, q, nq, offset_ray_origin)
}

/// [`spawn_ray_to`] with [`offset_ray_origin_lanewise`], for loops over several rays.
#[inline(always)]
pub fn spawn_ray_to_lanewise(p: Vec3, ng: Vec3, q: Vec3, nq: Vec3) -> (Ray, f32) {
    spawn_ray_to_with(p, ng, q, nq, offset_ray_origin_lanewise)
}

#[inline(always)]
fn spawn_ray_to_with(p: Vec3, ng: Vec3, q: Vec3, nq: Vec3, offset: impl Fn(Vec3, Vec3, Vec3) -> Vec3) -> (Ray, f32) {
    let o = offset(p, ng, q - p);
    let target = if nq == Vec3::ZERO { q } else { offset(q, nq, o - q) };
    (Ray::new(o, target - o), 1.0 - 1e-4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_moves_to_the_requested_side() {
        for p in [Vec3::new(1e3, -2e3, 5.0), Vec3::new(1e-3, 0.0, -1e-4), Vec3::splat(-7.5)] {
            let n = Vec3::new(0.3, -0.5, 0.8).normalize();
            let up = offset_ray_origin(p, n, n);
            let down = offset_ray_origin(p, n, -n);
            assert!((up - p).dot(n) > 0.0, "{p}");
            assert!((down - p).dot(n) < 0.0, "{p}");
        }
    }

    /// The three-lane offset gives the axis-by-axis one's bits, near the origin and far from it,
    /// on both sides of zero.
    #[test]
    fn lanes_match_the_scalar_offset() {
        let mut rng = crate::sampling::Pcg32::new(3, 5);
        for i in 0..100_000 {
            let scale = [1e-3f32, 0.03, 1.0, 1e3, 1e6][i % 5];
            let mut c = || (rng.next_f32() - 0.5) * 2.0 * scale;
            let p = Vec3::new(c(), c(), c());
            let n = Vec3::new(c(), c(), c()).normalize_or(Vec3::Z);
            let got = offset_ray_origin(p, n, n);
            let want = offset_ray_origin_lanewise(p, n, n);
            assert_eq!(got.to_array().map(f32::to_bits), want.to_array().map(f32::to_bits), "{p} {n}");
            // And so the shadow ray to a point on a light, whichever offset it takes.
            let (q, nq) = (p + Vec3::new(c(), c(), c()), -n);
            let ((a, ta), (b, tb)) = (spawn_ray_to(p, n, q, nq), spawn_ray_to_lanewise(p, n, q, nq));
            let bits = |r: Ray| [r.o, r.d].map(|v| v.to_array().map(f32::to_bits));
            assert_eq!((bits(a), ta.to_bits()), (bits(b), tb.to_bits()), "{p} {n} {q}");
        }
    }
}
