use glam::Vec3;

/// Slab tests round their exit distance up by this factor, so that they stay conservative:
/// the distances carry up to about 2 ulp of error each, which could reject a ray that grazes a
/// box holding a primitive it really hits.
pub const EXIT_ROUNDING: f32 = 1.0 + 4.0 * f32::EPSILON;

/// An axis-aligned bounding box. The empty box has `min = +inf`, `max = -inf`, so that
/// [`Aabb::union`] with it is the identity and every slab test against it fails.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Aabb::EMPTY
    }
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { min: Vec3::INFINITY, max: Vec3::NEG_INFINITY };

    #[inline]
    pub fn new(a: Vec3, b: Vec3) -> Aabb {
        Aabb { min: a.min(b), max: a.max(b) }
    }

    #[inline]
    pub fn from_point(p: Vec3) -> Aabb {
        Aabb { min: p, max: p }
    }

    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, |b, p| b.grow(p))
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    #[inline]
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }

    #[inline]
    pub fn union(self, o: Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    #[inline]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    #[inline]
    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    /// Half the surface area (all that SAH ratios need); 0 for empty or flat boxes.
    #[inline]
    pub fn half_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.extent();
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    #[inline]
    pub fn surface_area(&self) -> f32 {
        2.0 * self.half_area()
    }

    /// The axis (0, 1, 2) along which the box is widest.
    #[inline]
    pub fn largest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    #[inline]
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The 8 corners, in the order of the bits (x = bit 0, y = bit 1, z = bit 2) choosing max.
    pub fn corners(&self) -> [Vec3; 8] {
        std::array::from_fn(|i| {
            Vec3::new(
                if i & 1 != 0 { self.max.x } else { self.min.x },
                if i & 2 != 0 { self.max.y } else { self.min.y },
                if i & 4 != 0 { self.max.z } else { self.min.z },
            )
        })
    }

    /// The slab test. `inv_d` is `1 / ray.d` component-wise (±inf for zero components).
    /// Returns the parametric entry distance if the ray meets the box within `[t_min, t_max]`.
    ///
    /// Per axis the near and far planes are chosen by the sign of the direction (Williams et
    /// al. 2005), so each slab gives exactly one entry and one exit distance. That makes the
    /// lecture's edge cases come out right:
    /// - a zero direction component gives `±inf` distances, so a ray parallel to a slab is
    ///   inside it exactly when its origin is;
    /// - `0 · inf = NaN` arises only for an origin lying *on* a plane of a slab it is parallel
    ///   to; `f32::max/min` ignore a NaN operand, so that slab imposes no limit (boxes are
    ///   closed sets);
    /// - a ray starting inside the box returns `t_min`;
    /// - the empty box (`min = +inf`, `max = -inf`) is never hit;
    /// - NaN in the ray never panics: it yields a miss or a conservative hit, and the
    ///   primitive test decides.
    #[inline]
    pub fn slab(&self, o: Vec3, inv_d: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
        let neg = inv_d.cmplt(Vec3::ZERO);
        let near = Vec3::select(neg, self.max, self.min);
        let far = Vec3::select(neg, self.min, self.max);
        let tn = (near - o) * inv_d;
        let tf = (far - o) * inv_d;
        let t_enter = t_min.max(tn.x).max(tn.y).max(tn.z);
        let t_exit = t_max.min(tf.x).min(tf.y).min(tf.z);
        if t_enter <= t_exit * EXIT_ROUNDING {
            Some(t_enter)
        } else {
            None
        }
    }

    /// The box of `self` transformed by `m`: the box of its 8 transformed corners, as the
    /// lecture prescribes for instances (conservative, never smaller than the true bounds).
    pub fn transformed(&self, m: &glam::Affine3A) -> Aabb {
        if self.is_empty() {
            return Aabb::EMPTY;
        }
        Aabb::from_points(self.corners().into_iter().map(|c| m.transform_point3(c)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }

    fn hit(b: &Aabb, o: Vec3, d: Vec3) -> Option<f32> {
        b.slab(o, d.recip(), 0.0, f32::INFINITY)
    }

    #[test]
    fn slab_basic_hit_and_miss() {
        let b = unit();
        assert_eq!(hit(&b, Vec3::new(-1.0, 0.5, 0.5), Vec3::X), Some(1.0));
        assert_eq!(hit(&b, Vec3::new(-1.0, 1.5, 0.5), Vec3::X), None);
        // Pointing away.
        assert_eq!(hit(&b, Vec3::new(-1.0, 0.5, 0.5), -Vec3::X), None);
        // Beyond t_max.
        assert_eq!(b.slab(Vec3::new(-1.0, 0.5, 0.5), Vec3::X.recip(), 0.0, 0.5), None);
    }

    #[test]
    fn slab_axis_parallel_rays() {
        let b = unit();
        // Parallel to x, inside the y and z slabs: hit. Outside either: miss.
        assert!(hit(&b, Vec3::new(-5.0, 0.3, 0.7), Vec3::X).is_some());
        assert!(hit(&b, Vec3::new(-5.0, -0.3, 0.7), Vec3::X).is_none());
        assert!(hit(&b, Vec3::new(-5.0, 0.3, 1.7), Vec3::X).is_none());
        // Negative zero direction components behave like positive ones.
        assert!(hit(&b, Vec3::new(0.5, 0.5, 5.0), Vec3::new(-0.0, 0.0, -1.0)).is_some());
        assert!(hit(&b, Vec3::new(1.5, 0.5, 5.0), Vec3::new(-0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn slab_ray_in_face_plane_counts_as_inside() {
        let b = unit();
        // Origin exactly on the y = 1 plane, moving along x: 0 * inf = NaN in y; closed box.
        assert!(hit(&b, Vec3::new(-1.0, 1.0, 0.5), Vec3::X).is_some());
        assert!(hit(&b, Vec3::new(-1.0, 0.0, 0.0), Vec3::X).is_some());
    }

    #[test]
    fn slab_ray_starting_inside() {
        let b = unit();
        assert_eq!(hit(&b, Vec3::splat(0.5), Vec3::new(0.3, -0.2, 0.9)), Some(0.0));
        assert_eq!(b.slab(Vec3::splat(0.5), Vec3::X.recip(), 0.25, 10.0), Some(0.25));
    }

    #[test]
    fn slab_nan_never_panics_and_empty_box_misses() {
        let b = unit();
        let _ = hit(&b, Vec3::new(f32::NAN, 0.5, 0.5), Vec3::X);
        let _ = hit(&b, Vec3::splat(0.5), Vec3::new(f32::NAN, 0.0, 1.0));
        assert!(hit(&Aabb::EMPTY, Vec3::splat(0.5), Vec3::X).is_none());
        assert!(hit(&Aabb::EMPTY, Vec3::splat(-1.0), Vec3::ONE).is_none());
    }

    #[test]
    fn slab_diagonal_corner_graze() {
        let b = unit();
        // Through the corner (1,1,·) exactly.
        assert!(hit(&b, Vec3::new(0.0, 2.0, 0.5), Vec3::new(1.0, -1.0, 0.0)).is_some());
    }

    #[test]
    fn transformed_box_contains_transformed_corners() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 0.5, 4.0));
        let m = glam::Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 0.5, 1.0),
            glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
            Vec3::new(5.0, -2.0, 1.0),
        );
        let tb = b.transformed(&m);
        for c in b.corners() {
            assert!(tb.contains(m.transform_point3(c)));
        }
    }
}
