use glam::Vec3;

use crate::geometry::Aabb;

/// A sphere in object space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vec3,
    pub radius: f32,
}

impl Sphere {
    pub fn aabb(&self) -> Aabb {
        Aabb::new(self.center - Vec3::splat(self.radius), self.center + Vec3::splat(self.radius))
    }
}

/// Ray/sphere intersection accepting `0 < t < t_max`, for any (not necessarily unit) direction.
/// Uses the numerically robust form of the discriminant (Haines et al., "Precision Improvements
/// for Ray/Sphere Intersection", Ray Tracing Gems ch. 7) so that small spheres far away and rays
/// grazing the silhouette stay accurate.
#[inline]
pub fn intersect_sphere(s: &Sphere, o: Vec3, d: Vec3, t_max: f32) -> Option<f32> {
    let f = o - s.center;
    let a = d.length_squared();
    if a == 0.0 || !a.is_finite() {
        return None;
    }
    let b = f.dot(d);
    let r2 = s.radius * s.radius;
    let l = f - d * (b / a);
    let disc = r2 - l.length_squared();
    if disc < 0.0 {
        return None;
    }
    let c = f.length_squared() - r2;
    let q = -b - (a * disc).sqrt().copysign(b);
    let (mut t0, mut t1) = (c / q, q / a);
    if q == 0.0 {
        // Origin on the sphere and direction tangent: one root at 0.
        t0 = 0.0;
        t1 = 0.0;
    }
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if t0 > 0.0 && t0 < t_max {
        Some(t0)
    } else if t1 > 0.0 && t1 < t_max {
        Some(t1)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_hits_front_then_back_from_inside() {
        let s = Sphere { center: Vec3::new(0.0, 0.0, -5.0), radius: 1.0 };
        let t = intersect_sphere(&s, Vec3::ZERO, -Vec3::Z, f32::INFINITY).unwrap();
        assert!((t - 4.0).abs() < 1e-5);
        let t = intersect_sphere(&s, Vec3::new(0.0, 0.0, -5.0), -Vec3::Z * 2.0, f32::INFINITY).unwrap();
        assert!((t - 0.5).abs() < 1e-6);
        assert!(intersect_sphere(&s, Vec3::ZERO, Vec3::Z, f32::INFINITY).is_none());
        assert!(intersect_sphere(&s, Vec3::new(0.0, 1.01, 0.0), -Vec3::Z, f32::INFINITY).is_none());
    }

    #[test]
    fn tiny_far_sphere_is_accurate() {
        let s = Sphere { center: Vec3::new(0.0, 0.0, -1e4), radius: 1e-2 };
        let t = intersect_sphere(&s, Vec3::ZERO, -Vec3::Z, f32::INFINITY).unwrap();
        assert!((t - (1e4 - 1e-2)).abs() < 2e-3, "{t}");
    }
}
