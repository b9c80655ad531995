//! Cameras: perspective (pinhole), thin lens and orthographic, all placed by look-at.

use glam::{Vec2, Vec3};

use crate::geometry::Ray;
use crate::sampling::concentric_disk;

/// How film points map to rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Pinhole; `fov_y` is the full vertical field of view in degrees.
    Perspective { fov_y: f32 },
    /// Thin lens of radius `aperture` focused at `focus_distance` along the view direction.
    ThinLens { fov_y: f32, aperture: f32, focus_distance: f32 },
    /// Parallel rays; `half_height` is half the height of the view in world units.
    Orthographic { half_height: f32 },
}

/// A camera placed by eye, target and up vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    projection: Projection,
    /// `tan(fov_y / 2)` of the perspective projections (computed once, not per ray).
    tan_half: f32,
}

impl Camera {
    /// `None` if the view direction is zero or parallel to `up`, or anything is not finite.
    pub fn look_at(eye: Vec3, target: Vec3, up: Vec3, projection: Projection) -> Option<Camera> {
        let forward = (target - eye).normalize_or_zero();
        let right = forward.cross(up).normalize_or_zero();
        if forward == Vec3::ZERO || right == Vec3::ZERO || !eye.is_finite() {
            return None;
        }
        let up = right.cross(forward);
        let tan_half = match projection {
            Projection::Perspective { fov_y } | Projection::ThinLens { fov_y, .. } => (fov_y.to_radians() * 0.5).tan(),
            Projection::Orthographic { .. } => 0.0,
        };
        Some(Camera { eye, forward, right, up, projection, tan_half })
    }

    /// How film points map to rays.
    pub fn projection(&self) -> Projection {
        self.projection
    }

    /// Whether [`Camera::ray`] reads its lens sample (only a thin lens does).
    pub fn has_lens(&self) -> bool {
        matches!(self.projection, Projection::ThinLens { .. })
    }

    /// A camera from its frame as a scene file gives it: the image's `right` and `up` and the
    /// view direction `forward`, orthonormalised (`forward` kept, `up` made perpendicular).
    /// `right` may make a left-handed frame, which mirrors the picture as the file asks.
    pub fn with_frame(eye: Vec3, right: Vec3, up: Vec3, forward: Vec3, projection: Projection) -> Option<Camera> {
        let mut camera = Camera::look_at(eye, eye + forward, up, projection)?;
        if right.dot(camera.right) < 0.0 {
            camera.right = -camera.right;
        }
        Some(camera)
    }

    pub fn forward(&self) -> Vec3 {
        self.forward
    }

    /// The orthonormal frame: right, up, forward.
    pub fn frame(&self) -> (Vec3, Vec3, Vec3) {
        (self.right, self.up, self.forward)
    }

    /// The ray through film position `film` (in pixels, origin top left, y down) of a
    /// `width × height` image; `lens` is a uniform sample for the aperture.
    pub fn ray(&self, film: Vec2, width: u32, height: u32, lens: Vec2) -> Ray {
        let aspect = width as f32 / height as f32;
        // Screen coordinates: y in [-1, 1] up, x in [-aspect, aspect] right.
        let sx = (2.0 * film.x / width as f32 - 1.0) * aspect;
        let sy = 1.0 - 2.0 * film.y / height as f32;
        match self.projection {
            Projection::Perspective { .. } => {
                let t = self.tan_half;
                let d = self.forward + self.right * (sx * t) + self.up * (sy * t);
                Ray::new(self.eye, d.normalize())
            }
            Projection::ThinLens { aperture, focus_distance, .. } => {
                let t = self.tan_half;
                let d = self.forward + self.right * (sx * t) + self.up * (sy * t);
                let focus = self.eye + d * focus_distance;
                let l = concentric_disk(lens) * aperture;
                let o = self.eye + self.right * l.x + self.up * l.y;
                Ray::new(o, (focus - o).normalize())
            }
            Projection::Orthographic { half_height } => {
                let o = self.eye + self.right * (sx * half_height) + self.up * (sy * half_height);
                Ray::new(o, self.forward)
            }
        }
    }

    /// [`Camera::ray`] for eight film positions (and lens samples) at once: the same rays bit
    /// for bit. A perspective camera computes them in SSE lanes (its divisions and square
    /// roots, one per ray, are what a camera ray costs); the other projections call `ray`
    /// eight times.
    ///
    /// The rays are written into `out` (a returned array was copied again by the caller).
    pub fn rays8(&self, film: &[Vec2; 8], width: u32, height: u32, lens: &[Vec2; 8], out: &mut [Ray; 8]) {
        #[cfg(target_arch = "x86_64")]
        if let Projection::Perspective { .. } = self.projection {
            use std::arch::x86_64::*;
            let (w, h) = (width as f32, height as f32);
            let (fx, fy): ([f32; 8], [f32; 8]) = (film.map(|f| f.x), film.map(|f| f.y));
            let mut d = [[0.0f32; 8]; 3];
            // SAFETY: SSE and SSE2 are part of the x86_64 baseline; the loads and stores are
            // unaligned ones of four floats inside local arrays of eight.
            unsafe {
                let set = _mm_set1_ps;
                let (aspect, t) = (set(w / h), set(self.tan_half));
                let (fwd, right, up) = (self.forward.to_array(), self.right.to_array(), self.up.to_array());
                for half in [0, 4] {
                    // `ray`'s arithmetic, in its order: screen coordinates, the direction
                    // `forward + right·(sx·t) + up·(sy·t)`, and glam's `normalize` (the square
                    // root of `x·x + y·y + z·z`, its reciprocal, a multiply).
                    let x = _mm_loadu_ps(fx[half..].as_ptr());
                    let y = _mm_loadu_ps(fy[half..].as_ptr());
                    let sx = _mm_mul_ps(_mm_sub_ps(_mm_div_ps(_mm_mul_ps(set(2.0), x), set(w)), set(1.0)), aspect);
                    let sy = _mm_sub_ps(set(1.0), _mm_div_ps(_mm_mul_ps(set(2.0), y), set(h)));
                    let (a, b) = (_mm_mul_ps(sx, t), _mm_mul_ps(sy, t));
                    let axis = |k: usize| {
                        _mm_add_ps(_mm_add_ps(set(fwd[k]), _mm_mul_ps(set(right[k]), a)), _mm_mul_ps(set(up[k]), b))
                    };
                    let (dx, dy, dz) = (axis(0), axis(1), axis(2));
                    let len2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
                    let inv = _mm_div_ps(set(1.0), _mm_sqrt_ps(len2));
                    _mm_storeu_ps(d[0][half..].as_mut_ptr(), _mm_mul_ps(dx, inv));
                    _mm_storeu_ps(d[1][half..].as_mut_ptr(), _mm_mul_ps(dy, inv));
                    _mm_storeu_ps(d[2][half..].as_mut_ptr(), _mm_mul_ps(dz, inv));
                }
            }
            for (i, out) in out.iter_mut().enumerate() {
                *out = Ray::new(self.eye, Vec3::new(d[0][i], d[1][i], d[2][i]));
            }
            return;
        }
        for (i, out) in out.iter_mut().enumerate() {
            *out = self.ray(film[i], width, height, lens[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_ray_looks_at_target_and_corners_span_fov() {
        let c = Camera::look_at(Vec3::ZERO, -Vec3::Z, Vec3::Y, Projection::Perspective { fov_y: 90.0 }).unwrap();
        let r = c.ray(Vec2::new(50.0, 50.0), 100, 100, Vec2::ZERO);
        assert!((r.d - -Vec3::Z).length() < 1e-6);
        let top = c.ray(Vec2::new(50.0, 0.0), 100, 100, Vec2::ZERO);
        assert!((top.d.y.atan2(-top.d.z).to_degrees() - 45.0).abs() < 1e-3);
    }

    #[test]
    fn thin_lens_rays_converge_at_focus_distance() {
        let p = Projection::ThinLens { fov_y: 40.0, aperture: 0.5, focus_distance: 3.0 };
        let c = Camera::look_at(Vec3::ZERO, -Vec3::Z, Vec3::Y, p).unwrap();
        let film = Vec2::new(30.0, 70.0);
        let a = c.ray(film, 100, 100, Vec2::new(0.1, 0.9));
        let b = c.ray(film, 100, 100, Vec2::new(0.8, 0.3));
        let ta = -3.0 / a.d.z;
        let tb = -3.0 / b.d.z;
        assert!((a.at(ta) - b.at(tb)).length() < 1e-4);
        assert!((a.o - b.o).length() > 0.1);
    }

    /// Eight rays at once are the rays one at a time, bit for bit, for every projection.
    #[test]
    fn eight_rays_at_once_are_the_single_rays() {
        let mut rng = crate::sampling::Pcg32::new(3, 4);
        for projection in [
            Projection::Perspective { fov_y: 37.0 },
            Projection::ThinLens { fov_y: 50.0, aperture: 0.2, focus_distance: 3.0 },
            Projection::Orthographic { half_height: 1.5 },
        ] {
            let c = Camera::look_at(Vec3::new(0.3, -1.2, 4.0), Vec3::new(0.1, 0.2, -0.4), Vec3::Y, projection).unwrap();
            for _ in 0..500 {
                let film: [Vec2; 8] =
                    std::array::from_fn(|_| Vec2::new(rng.next_f32() * 640.0, rng.next_f32() * 480.0));
                let lens: [Vec2; 8] = std::array::from_fn(|_| rng.next_2d());
                let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); 8];
                c.rays8(&film, 640, 480, &lens, &mut rays);
                for i in 0..8 {
                    let want = c.ray(film[i], 640, 480, lens[i]);
                    assert_eq!(rays[i].o.to_array().map(f32::to_bits), want.o.to_array().map(f32::to_bits));
                    assert_eq!(rays[i].d.to_array().map(f32::to_bits), want.d.to_array().map(f32::to_bits));
                }
            }
        }
    }

    #[test]
    fn orthographic_rays_are_parallel() {
        let c = Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, Projection::Orthographic { half_height: 2.0 }).unwrap();
        let a = c.ray(Vec2::new(0.0, 0.0), 10, 10, Vec2::ZERO);
        let b = c.ray(Vec2::new(10.0, 10.0), 10, 10, Vec2::ZERO);
        assert_eq!(a.d, b.d);
        assert!((a.o - Vec3::new(-2.0, 2.0, 1.0)).length() < 1e-6);
        assert!((b.o - Vec3::new(2.0, -2.0, 1.0)).length() < 1e-6);
    }

    #[test]
    fn a_left_handed_frame_mirrors_the_image() {
        let p = Projection::Perspective { fov_y: 60.0 };
        let c = Camera::look_at(Vec3::ZERO, -Vec3::Z, Vec3::Y, p).unwrap();
        let same = Camera::with_frame(Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::Z, p).unwrap();
        let mirrored = Camera::with_frame(Vec3::ZERO, -Vec3::X, Vec3::Y, -Vec3::Z, p).unwrap();
        let film = Vec2::new(10.0, 40.0);
        assert_eq!(same, c);
        let (a, b) = (c.ray(film, 100, 100, Vec2::ZERO), mirrored.ray(film, 100, 100, Vec2::ZERO));
        assert!(a.d.x < 0.0 && (b.d - Vec3::new(-a.d.x, a.d.y, a.d.z)).length() < 1e-6);
    }

    #[test]
    fn degenerate_look_at_is_rejected() {
        assert!(Camera::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y, Projection::Perspective { fov_y: 40.0 }).is_none());
        assert!(Camera::look_at(Vec3::ZERO, Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 40.0 }).is_none());
    }
}
