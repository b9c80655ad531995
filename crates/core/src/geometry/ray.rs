use glam::Vec3;

/// A ray `o + t·d`. The direction need not be unit length (rays carried into an instance's
/// object space keep the same `t` as in world space and so are generally not normalized).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Ray {
    pub o: Vec3,
    pub d: Vec3,
}

impl Ray {
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> Ray {
        Ray { o, d }
    }

    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}
