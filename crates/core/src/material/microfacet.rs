//! The GGX (Trowbridge–Reitz) microfacet distribution with Smith's height-correlated
//! masking-shadowing, for the rough specular highlights of direct lighting.
//! All vectors are in world space; `n` is the unit shading normal, `alpha` the GGX roughness
//! (Mitsuba's `alpha`; 0.01 is nearly a mirror, 0.5 quite rough).

use glam::Vec3;

/// Normal distribution `D(h)`.
#[inline]
pub fn ggx_d(n: Vec3, h: Vec3, alpha: f32) -> f32 {
    let c = n.dot(h);
    if c <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let d = c * c * (a2 - 1.0) + 1.0;
    a2 / (std::f32::consts::PI * d * d)
}

#[inline]
fn lambda(n: Vec3, w: Vec3, alpha: f32) -> f32 {
    let c = n.dot(w).abs().min(1.0);
    let tan2 = (1.0 - c * c).max(0.0) / (c * c).max(1e-12);
    0.5 * ((1.0 + alpha * alpha * tan2).sqrt() - 1.0)
}

/// Height-correlated Smith masking-shadowing `G2(wo, wi)`.
#[inline]
pub fn smith_g2(n: Vec3, wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    1.0 / (1.0 + lambda(n, wo, alpha) + lambda(n, wi, alpha))
}

/// Cook–Torrance specular BRDF value without Fresnel: `D·G / (4 cos_o cos_i)`.
/// Multiply by the Fresnel reflectance at `wo · h`.
#[inline]
pub fn cook_torrance(n: Vec3, wo: Vec3, wi: Vec3, alpha: f32) -> (f32, f32) {
    let (co, ci) = (n.dot(wo), n.dot(wi));
    if co <= 0.0 || ci <= 0.0 {
        return (0.0, 0.0);
    }
    let h = (wo + wi).normalize();
    let value = ggx_d(n, h, alpha) * smith_g2(n, wo, wi, alpha) / (4.0 * co * ci);
    (value, wo.dot(h).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ggx_projected_area_integrates_to_one() {
        // ∫ D(h) cos θ_h dω_h = 1, by midpoint quadrature over the hemisphere.
        for alpha in [0.1f32, 0.3, 0.8] {
            let (nt, np) = (2000, 8);
            let mut sum = 0.0f64;
            for i in 0..nt {
                let th = (i as f32 + 0.5) / nt as f32 * std::f32::consts::FRAC_PI_2;
                let h = Vec3::new(th.sin(), 0.0, th.cos());
                let dth = std::f32::consts::FRAC_PI_2 / nt as f32;
                sum += (ggx_d(Vec3::Z, h, alpha) * th.cos() * th.sin() * dth * std::f32::consts::TAU) as f64;
            }
            let _ = np;
            assert!((sum - 1.0).abs() < 1e-2, "alpha {alpha}: {sum}");
        }
    }
}
