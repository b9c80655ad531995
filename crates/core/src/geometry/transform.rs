use glam::{Affine3A, Mat3, Vec3};

use super::{Aabb, Ray};

/// An invertible affine transform with its inverse, object space → world space.
/// Points go through the matrix, directions through its linear part, and normals through the
/// inverse transpose of the linear part (so they stay perpendicular under non-uniform scale).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    pub m: Affine3A,
    pub inv: Affine3A,
    /// Inverse transpose of the linear part, for normals.
    normal_m: Mat3,
}

impl Transform {
    pub const IDENTITY: Transform =
        Transform { m: Affine3A::IDENTITY, inv: Affine3A::IDENTITY, normal_m: Mat3::IDENTITY };

    /// `None` when `m` is singular or not finite.
    pub fn try_new(m: Affine3A) -> Option<Transform> {
        let det = m.matrix3.determinant();
        if !det.is_finite() || det.abs() < 1e-30 || !m.is_finite() {
            return None;
        }
        let inv = m.inverse();
        if !inv.is_finite() {
            return None;
        }
        let normal_m = Mat3::from(inv.matrix3).transpose();
        Some(Transform { m, inv, normal_m })
    }

    pub fn is_identity(&self) -> bool {
        self.m == Affine3A::IDENTITY
    }

    #[inline]
    pub fn point(&self, p: Vec3) -> Vec3 {
        self.m.transform_point3(p)
    }

    #[inline]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        self.m.transform_vector3(v)
    }

    /// Transforms a normal (not normalized afterwards).
    #[inline]
    pub fn normal(&self, n: Vec3) -> Vec3 {
        self.normal_m * n
    }

    /// World-space ray → object-space ray with the same parameter `t`.
    #[inline]
    pub fn ray_to_object(&self, r: &Ray) -> Ray {
        Ray::new(self.inv.transform_point3(r.o), self.inv.transform_vector3(r.d))
    }

    /// The box of the 8 transformed corners of `b`.
    pub fn aabb(&self, b: &Aabb) -> Aabb {
        b.transformed(&self.m)
    }

    /// Whether the linear part is a rotation times a uniform scale (and if so, the scale).
    pub fn uniform_scale(&self) -> Option<f32> {
        let m = Mat3::from(self.m.matrix3);
        let s = m.x_axis.length();
        let mtm = m.transpose() * m;
        let ok =
            (mtm - Mat3::from_diagonal(Vec3::splat(s * s))).to_cols_array().iter().all(|v| v.abs() <= 1e-4 * s * s);
        ok.then_some(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_stay_perpendicular_under_nonuniform_scale() {
        let t = Transform::try_new(Affine3A::from_scale(Vec3::new(4.0, 1.0, 1.0))).unwrap();
        // A surface with tangent (1,1,0) and normal (1,-1,0).
        let tangent = t.vector(Vec3::new(1.0, 1.0, 0.0));
        let n = t.normal(Vec3::new(1.0, -1.0, 0.0));
        assert!(tangent.dot(n).abs() < 1e-6);
    }

    #[test]
    fn singular_transform_is_rejected() {
        assert!(Transform::try_new(Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0))).is_none());
        assert!(Transform::try_new(Affine3A::from_translation(Vec3::NAN)).is_none());
    }

    #[test]
    fn ray_to_object_keeps_t() {
        let t = Transform::try_new(Affine3A::from_scale_rotation_translation(
            Vec3::splat(2.0),
            glam::Quat::from_rotation_y(0.3),
            Vec3::new(1.0, 2.0, 3.0),
        ))
        .unwrap();
        let r = Ray::new(Vec3::new(0.1, 0.2, -4.0), Vec3::new(0.2, 0.1, 1.0));
        let lr = t.ray_to_object(&r);
        let p = t.point(lr.at(1.7));
        assert!((p - r.at(1.7)).length() < 1e-5);
        assert_eq!(t.uniform_scale().map(|s| (s * 1e4).round()), Some(2e4));
    }
}
