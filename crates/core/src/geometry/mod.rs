//! Rays, axis-aligned boxes, affine transforms and robust ray offsets.

mod aabb;
mod offset;
mod ray;
mod transform;

pub use aabb::{Aabb, EXIT_ROUNDING};
pub use offset::{
    offset_ray_origin, offset_ray_origin_lanewise, spawn_ray, spawn_ray_lanewise, spawn_ray_to, spawn_ray_to_lanewise,
};
pub use ray::Ray;
pub use transform::Transform;

/// Builds an orthonormal basis `(s, t)` around the unit vector `n` (Duff et al. 2017).
#[inline]
pub fn orthonormal_basis(n: glam::Vec3) -> (glam::Vec3, glam::Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (glam::Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), glam::Vec3::new(b, sign + n.y * n.y * a, -n.y))
}
