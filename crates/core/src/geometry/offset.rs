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

#[inline]
fn offset_component(p: f32, n: f32) -> f32 {
    if p.abs() < ORIGIN {
        return p + FLOAT_SCALE * n;
    }
    let of_i = (INT_SCALE * n) as i32;
    let bits = p.to_bits() as i32;
    let moved = if p < 0.0 { bits - of_i } else { bits + of_i };
    f32::from_bits(moved as u32)
}

/// Moves `p` off the surface with geometric normal `ng` to the side that `w` points into.
#[inline]
pub fn offset_ray_origin(p: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
    let n = if ng.dot(w) < 0.0 { -ng } else { ng };
    Vec3::new(offset_component(p.x, n.x), offset_component(p.y, n.y), offset_component(p.z, n.z))
}

/// A ray leaving the surface point `p` (geometric normal `ng`) in direction `d`.
#[inline]
pub fn spawn_ray(p: Vec3, ng: Vec3, d: Vec3) -> Ray {
    Ray::new(offset_ray_origin(p, ng, d), d)
}

/// A ray from surface point `p` towards the point `q` (on a surface with normal `nq`, or
/// `Vec3::ZERO` for a point light). Returns the ray, with `t = 1` at the (offset) target, and
/// the largest `t` that a shadow test should consider.
#[inline]
pub fn spawn_ray_to(p: Vec3, ng: Vec3, q: Vec3, nq: Vec3) -> (Ray, f32) {
    let o = offset_ray_origin(p, ng, q - p);
    let target = if nq == Vec3::ZERO { q } else { offset_ray_origin(q, nq, o - q) };
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
}
