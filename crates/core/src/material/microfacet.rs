//! Microfacet distributions: GGX (Trowbridge–Reitz) and Beckmann, isotropic, with Smith's
//! masking. All vectors are in the local shading frame (`z` = normal); `alpha` is the
//! roughness as Mitsuba and pbrt define it (0.01 is nearly a mirror, 0.5 quite rough).
//!
//! Masking-shadowing is the separable Smith form `G1(wo) G1(wi)`, as in Mitsuba 3.
//! GGX samples the distribution of *visible* normals (Heitz 2018); Beckmann samples `D cos θ`.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

/// Which normal distribution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Distribution {
    Ggx,
    Beckmann,
}

/// An isotropic microfacet distribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Microfacet {
    pub kind: Distribution,
    pub alpha: f32,
}

impl Microfacet {
    pub fn new(kind: Distribution, alpha: f32) -> Microfacet {
        // Below 1e-4 the densities overflow f32; such surfaces are mirrors in all but name.
        Microfacet { kind, alpha: alpha.max(1e-4) }
    }

    /// Normal distribution `D(m)`, normalised so that `∫ D(m) cos θ_m dω_m = 1`.
    #[inline]
    pub fn d(&self, m: Vec3) -> f32 {
        let c2 = m.z * m.z;
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let tan2 = (1.0 - c2).max(0.0) / c2;
        match self.kind {
            Distribution::Ggx => {
                let k = a2 + tan2;
                a2 / (PI * c2 * c2 * k * k)
            }
            Distribution::Beckmann => crate::sampling::exp(-tan2 / a2) / (PI * a2 * c2 * c2),
        }
    }

    /// Smith's auxiliary function Λ(w).
    #[inline]
    fn lambda(&self, w: Vec3) -> f32 {
        let c2 = w.z * w.z;
        let tan2 = (1.0 - c2).max(0.0) / c2.max(1e-20);
        match self.kind {
            Distribution::Ggx => 0.5 * ((1.0 + self.alpha * self.alpha * tan2).sqrt() - 1.0),
            Distribution::Beckmann => {
                // Walter et al.'s rational fit, as pbrt and Mitsuba use it.
                let a = 1.0 / (self.alpha * tan2.sqrt());
                if a >= 1.6 {
                    0.0
                } else {
                    (1.0 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a)
                }
            }
        }
    }

    /// Masking of microfacet `m` seen from `w`: zero when `w` sees the back of `m`.
    #[inline]
    pub fn g1(&self, w: Vec3, m: Vec3) -> f32 {
        if w.dot(m) * w.z <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + self.lambda(w))
    }

    /// Masking-shadowing `G(wo, wi) = G1(wo) G1(wi)`.
    #[inline]
    pub fn g(&self, wo: Vec3, wi: Vec3, m: Vec3) -> f32 {
        self.g1(wo, m) * self.g1(wi, m)
    }

    /// Samples a microfacet normal (upper hemisphere) for a ray leaving along `wo`; returns it
    /// with [`Self::pdf`]. `wo` below the surface is mirrored first (for transmission).
    pub fn sample(&self, wo: Vec3, u: Vec2) -> (Vec3, f32) {
        let m = match self.kind {
            Distribution::Ggx => {
                let wo = if wo.z < 0.0 { -wo } else { wo };
                let a = self.alpha;
                let vh = Vec3::new(a * wo.x, a * wo.y, wo.z).normalize();
                let len2 = vh.x * vh.x + vh.y * vh.y;
                let t1 = if len2 > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { Vec3::X };
                let t2 = vh.cross(t1);
                let r = u.x.sqrt();
                let phi = 2.0 * PI * u.y;
                let p1 = r * phi.cos();
                let s = 0.5 * (1.0 + vh.z);
                let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
                let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
                Vec3::new(a * nh.x, a * nh.y, nh.z.max(1e-6)).normalize()
            }
            Distribution::Beckmann => {
                let tan2 = -self.alpha * self.alpha * (1.0 - u.x).max(1e-30).ln();
                let cos = 1.0 / (1.0 + tan2).sqrt();
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)
            }
        };
        (m, self.pdf(wo, m))
    }

    /// Density (solid angle of `m`) with which [`Self::sample`] returns `m` for `wo`.
    #[inline]
    pub fn pdf(&self, wo: Vec3, m: Vec3) -> f32 {
        self.pdf_with_d(wo, m, self.d(m))
    }

    /// [`Self::pdf`] given `d` = [`Self::d`]`(m)`, for callers that have it already.
    #[inline]
    pub fn pdf_with_d(&self, wo: Vec3, m: Vec3, d: f32) -> f32 {
        match self.kind {
            Distribution::Ggx => {
                let wo = if wo.z < 0.0 { -wo } else { wo };
                if wo.z == 0.0 {
                    return 0.0;
                }
                self.g1(wo, m) * wo.dot(m).max(0.0) * d / wo.z
            }
            Distribution::Beckmann => d * m.z.max(0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projected_area_integrates_to_one() {
        // ∫ D(m) cos θ_m dω_m = 1, by midpoint quadrature over the hemisphere.
        for kind in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.1f32, 0.3, 0.8] {
                let mf = Microfacet::new(kind, alpha);
                let nt = 4000;
                let mut sum = 0.0f64;
                for i in 0..nt {
                    let th = (i as f32 + 0.5) / nt as f32 * std::f32::consts::FRAC_PI_2;
                    let m = Vec3::new(th.sin(), 0.0, th.cos());
                    let dth = std::f32::consts::FRAC_PI_2 / nt as f32;
                    sum += (mf.d(m) * th.cos() * th.sin() * dth * 2.0 * PI) as f64;
                }
                assert!((sum - 1.0).abs() < 1e-2, "{kind:?} alpha {alpha}: {sum}");
            }
        }
    }

    #[test]
    fn visible_normals_integrate_to_one() {
        // ∫ G1(wo, m) max(0, wo·m) D(m) / cos θ_o dω_m = 1 for every wo (the pdf of sampling).
        for kind in [Distribution::Ggx, Distribution::Beckmann] {
            let mf = Microfacet::new(kind, 0.4);
            for deg in [0.0f32, 40.0, 75.0] {
                let wo = Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
                let (nt, np) = (400, 400);
                let mut sum = 0.0f64;
                for i in 0..nt {
                    for j in 0..np {
                        let th = (i as f32 + 0.5) / nt as f32 * std::f32::consts::FRAC_PI_2;
                        let ph = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                        let m = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                        let dw = th.sin() * (std::f32::consts::FRAC_PI_2 / nt as f32) * (2.0 * PI / np as f32);
                        sum += (mf.pdf(wo, m) * dw) as f64;
                    }
                }
                assert!((sum - 1.0).abs() < 2e-2, "{kind:?} at {deg}°: {sum}");
            }
        }
    }
}
