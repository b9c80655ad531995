//! The lecture's formulas: reflection, Snell's law and the transmission vector, and the exact
//! unpolarized Fresnel equations for dielectrics and for conductors.
//!
//! Conventions: `n` is a unit normal, `w` a unit direction pointing *away* from the surface.
//! `eta` is the relative index of refraction `n_t / n_i`: the medium the light enters over the
//! medium it comes from (for a ray arriving from air at glass, `eta = 1.5`).

use glam::Vec3;

/// Mirror reflection of `w` (pointing away from the surface) about `n`.
#[inline]
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    -w + 2.0 * w.dot(n) * n
}

/// Transmission direction by Snell's law, `n_i sin θ_i = n_t sin θ_t`.
///
/// `wi` points away from the surface on the side of the incident medium, `n` is on the same
/// side (`wi · n > 0`), `eta = n_t / n_i`. Returns the unit transmitted direction (pointing
/// away on the other side, in the plane of `wi` and `n`), or `None` for total internal
/// reflection (`sin θ_t > 1`).
#[inline]
pub fn refract(wi: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = wi.dot(n);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wi / eta + (cos_i / eta - cos_t) * n).normalize())
}

/// Fresnel reflectance of a dielectric interface for unpolarized light: the average of the
/// s- and p-polarized reflectances. `cos_theta_i` is the cosine between the incident direction
/// and the normal on the side of the incident medium; a negative value means the light arrives
/// from the other side, and `eta` is inverted. Returns 1 under total internal reflection.
/// Transmittance is `1 - R` (energy conservation at a lossless interface).
pub fn dielectric(cos_theta_i: f32, eta: f32) -> f32 {
    let mut cos_i = cos_theta_i.clamp(-1.0, 1.0);
    let mut eta = eta;
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
    }
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Reflectance of a thin slab of index `eta` (both faces, every internal reflection summed):
/// `R + T² R / (1 − R²)` with the single-interface `R` at `cos_theta_i` (either side).
pub fn thin_slab(cos_theta_i: f32, eta: f32) -> f32 {
    let r = dielectric(cos_theta_i.abs(), eta);
    if r < 1.0 {
        r + (1.0 - r) * (1.0 - r) * r / (1.0 - r * r)
    } else {
        r
    }
}

/// Critical angle (radians) for light going from a medium of index `n_i` into one of `n_t < n_i`.
pub fn critical_angle(n_i: f32, n_t: f32) -> Option<f32> {
    (n_t < n_i).then(|| (n_t / n_i).asin())
}

#[derive(Clone, Copy, Debug)]
struct Complex {
    re: f32,
    im: f32,
}

impl Complex {
    fn new(re: f32, im: f32) -> Complex {
        Complex { re, im }
    }
    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Complex) -> Complex {
        Complex::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Complex) -> Complex {
        Complex::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
    }
    fn scale(self, s: f32) -> Complex {
        Complex::new(self.re * s, self.im * s)
    }
    fn div(self, o: Complex) -> Complex {
        let d = o.re * o.re + o.im * o.im;
        Complex::new((self.re * o.re + self.im * o.im) / d, (self.im * o.re - self.re * o.im) / d)
    }
    fn norm(self) -> f32 {
        self.re * self.re + self.im * self.im
    }
    fn sqrt(self) -> Complex {
        let n = self.norm().sqrt();
        if n == 0.0 {
            return Complex::new(0.0, 0.0);
        }
        let t1 = (0.5 * (n + self.re.abs())).sqrt();
        let t2 = 0.5 * self.im / t1;
        if self.re >= 0.0 {
            Complex::new(t1, t2)
        } else {
            Complex::new(t2.abs(), t1.copysign(self.im))
        }
    }
}

/// Fresnel reflectance of a conductor with complex index of refraction `eta + i·k` (relative to
/// the outside medium) for unpolarized light arriving at `cos_theta_i` (clamped to `[0, 1]`).
pub fn conductor(cos_theta_i: f32, eta: f32, k: f32) -> f32 {
    let cos_i = cos_theta_i.clamp(0.0, 1.0);
    let sin2_i = 1.0 - cos_i * cos_i;
    let e = Complex::new(eta, k);
    let sin2_t = Complex::new(sin2_i, 0.0).div(e.mul(e));
    let cos_t = Complex::new(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = Complex::new(cos_i, 0.0);
    let r_parl = e.scale(cos_i).sub(cos_t).div(e.scale(cos_i).add(cos_t));
    let r_perp = ci.sub(e.mul(cos_t)).div(ci.add(e.mul(cos_t)));
    (0.5 * (r_parl.norm() + r_perp.norm())).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glass_reflects_four_percent_at_normal_incidence() {
        // ((n-1)/(n+1))² = (0.5/2.5)² = 0.04 exactly.
        assert!((dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((dielectric(1.0, 1.33) - (0.33f32 / 2.33).powi(2)).abs() < 1e-6);
        assert!((dielectric(1.0, 2.42) - (1.42f32 / 3.42).powi(2)).abs() < 1e-6);
        // Same value seen from inside (reciprocity at normal incidence).
        assert!((dielectric(-1.0, 1.5) - 0.04).abs() < 1e-6);
    }

    #[test]
    fn reflectance_rises_to_one_at_grazing() {
        assert!(dielectric(0.0, 1.5) > 0.999);
        assert!(dielectric(1e-4, 1.5) > 0.999);
        let mut prev = 0.0;
        // Monotone from the Brewster angle onwards; at 80° well above normal incidence.
        for deg in [60.0f32, 70.0, 80.0, 85.0, 89.0] {
            let r = dielectric(deg.to_radians().cos(), 1.5);
            assert!(r > prev, "{deg}: {r}");
            prev = r;
        }
        // Brewster's angle: p-polarized reflection vanishes; unpolarized R = R_s / 2.
        let tb = 1.5f32.atan();
        let (ci, ct) = (tb.cos(), (tb.sin() / 1.5).asin().cos());
        let rs = ((ci - 1.5 * ct) / (ci + 1.5 * ct)).powi(2);
        assert!((dielectric(ci, 1.5) - 0.5 * rs).abs() < 1e-6);
    }

    #[test]
    fn total_internal_reflection_beyond_the_critical_angle() {
        let crit = critical_angle(1.5, 1.0).unwrap();
        assert!((crit.to_degrees() - 41.81).abs() < 0.01);
        let n = Vec3::Z;
        for (deg, tir) in [(41.0f32, false), (42.0, true), (60.0, true)] {
            let th = deg.to_radians();
            let wi = Vec3::new(th.sin(), 0.0, th.cos());
            // From glass (1.5) into air (1.0): eta = 1/1.5.
            assert_eq!(refract(wi, n, 1.0 / 1.5).is_none(), tir, "{deg}");
            assert_eq!(dielectric(th.cos(), 1.0 / 1.5) == 1.0, tir, "{deg}");
            // And the same through the "arriving from inside" convention.
            assert_eq!(dielectric(-th.cos(), 1.5) == 1.0, tir, "{deg}");
        }
        assert!(critical_angle(1.0, 1.5).is_none());
    }

    #[test]
    fn reflectance_plus_transmittance_is_one() {
        for eta in [1.0f32, 1.33, 1.5, 2.42, 1.0 / 1.5] {
            for i in 0..=90 {
                let c = (i as f32).to_radians().cos();
                let r = dielectric(c, eta);
                let t = 1.0 - r;
                assert!((0.0..=1.0).contains(&r) && (0.0..=1.0).contains(&t));
                assert!((r + t - 1.0).abs() < 1e-6);
            }
        }
        // Index-matched interface: nothing reflects.
        assert!(dielectric(0.3, 1.0).abs() < 1e-7);
    }

    #[test]
    fn snell_law_holds_and_vector_is_unit_and_coplanar() {
        let n = Vec3::new(0.2, 0.9, -0.1).normalize();
        for (eta, deg) in [(1.5f32, 30.0f32), (1.33, 75.0), (2.42, 5.0), (1.0 / 1.5, 35.0)] {
            let (s, _) = crate::geometry::orthonormal_basis(n);
            let th = deg.to_radians();
            let wi = (n * th.cos() + s * th.sin()).normalize();
            let wt = refract(wi, n, eta).unwrap();
            assert!((wt.length() - 1.0).abs() < 1e-5);
            // Opposite side of the surface.
            assert!(wt.dot(n) < 0.0);
            // n1 sin θ1 = n2 sin θ2 with n1 = 1, n2 = eta.
            let sin_i = wi.cross(n).length();
            let sin_t = wt.cross(-n).length();
            assert!((sin_i - eta * sin_t).abs() < 1e-5, "eta {eta}: {sin_i} vs {}", eta * sin_t);
            // In the plane of incidence spanned by wi and n.
            assert!(wt.dot(wi.cross(n).normalize()).abs() < 1e-5);
            // Normal incidence passes straight through.
            assert!((refract(n, n, eta).unwrap() + n).length() < 1e-6);
        }
    }

    #[test]
    fn conductor_matches_known_values() {
        // k = 0 reduces to the dielectric formula.
        for c in [1.0f32, 0.7, 0.2] {
            assert!((conductor(c, 1.5, 0.0) - dielectric(c, 1.5)).abs() < 1e-5);
        }
        // Normal incidence: ((n-1)² + k²) / ((n+1)² + k²); gold's red channel.
        let (n, k) = (0.143119f32, 3.98316f32);
        let r0 = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((conductor(1.0, n, k) - r0).abs() < 1e-5);
        assert!(conductor(0.0, n, k) > 0.999);
    }

    #[test]
    fn reflect_is_mirror() {
        let n = Vec3::Y;
        let w = Vec3::new(1.0, 1.0, 0.0).normalize();
        assert!((reflect(w, n) - Vec3::new(-1.0, 1.0, 0.0).normalize()).length() < 1e-6);
    }
}
