//! Materials as the lecture has them.
//!
//! The Whitted integrator treats two kinds of scattering differently: *delta* lobes (ideal
//! mirror reflection and refraction) spawn new rays of the ray tree, while the *non-delta*
//! parts (Lambertian and the GGX highlight) are evaluated only against the lights
//! ([`Material::eval_direct`]).

pub mod fresnel;
pub mod microfacet;

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

use crate::Rgb;

/// A colour that may vary over a surface, looked up by texture coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Texture {
    Constant(Rgb),
    /// Squares of `a` and `b`, `scale` squares per unit of `u` and of `v`.
    Checker {
        a: Rgb,
        b: Rgb,
        scale: f32,
    },
}

impl Texture {
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match *self {
            Texture::Constant(c) => c,
            Texture::Checker { a, b, scale } => {
                let s = (uv * scale).floor();
                if (s.x + s.y).rem_euclid(2.0) < 1.0 {
                    a
                } else {
                    b
                }
            }
        }
    }
}

impl From<Rgb> for Texture {
    fn from(c: Rgb) -> Texture {
        Texture::Constant(c)
    }
}

/// A surface material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian: `albedo / π`.
    Diffuse { albedo: Texture },
    /// Lambertian base plus a rough specular highlight (GGX, Fresnel of a dielectric with
    /// index `ior`, scaled by `specular`) for direct light: a plastic-like surface.
    Glossy { albedo: Texture, specular: Rgb, roughness: f32, ior: f32 },
    /// Metal with Fresnel from the complex index of refraction `eta + i·k` per RGB channel.
    /// `roughness = 0`: ideal mirror (recursive reflection); `roughness > 0`: GGX highlight
    /// for direct light only.
    Conductor { eta: Rgb, k: Rgb, roughness: f32 },
    /// The lecture's alternative: a mirror with a constant reflectance at every angle.
    Mirror { reflectance: Rgb },
    /// Smooth dielectric (glass, water, diamond): reflects `F` and refracts `1 - F` (times
    /// `transmittance`), with total internal reflection.
    Dielectric { ior: f32, transmittance: Rgb },
    /// A smooth dielectric coat of index `ior` over a Lambertian `base`: the coat reflects `F`
    /// specularly; the transmitted `1 - F` is shaded by the base.
    Glazed { ior: f32, base: Rgb },
}

impl Material {
    /// Whether the material has a non-delta part that direct lighting must evaluate.
    pub fn has_direct(&self) -> bool {
        match self {
            Material::Diffuse { .. } | Material::Glossy { .. } | Material::Glazed { .. } => true,
            Material::Conductor { roughness, .. } => *roughness > 0.0,
            Material::Mirror { .. } | Material::Dielectric { .. } => false,
        }
    }

    /// The diffuse albedo at `uv`, for the ambient term.
    pub fn diffuse_albedo(&self, uv: Vec2) -> Rgb {
        match self {
            Material::Diffuse { albedo } | Material::Glossy { albedo, .. } => albedo.eval(uv),
            Material::Glazed { base, .. } => *base,
            _ => Rgb::ZERO,
        }
    }

    /// The non-delta BSDF times the cosine, `f(wo, wi) |n · wi|`, for light arriving from `wi`.
    /// `n` is the shading normal on the side of `wo`, `uv` the texture coordinates.
    /// Zero if `wi` is below the surface.
    pub fn eval_direct(&self, n: Vec3, wo: Vec3, wi: Vec3, uv: Vec2) -> Rgb {
        let cos_i = n.dot(wi);
        if cos_i <= 0.0 || n.dot(wo) <= 0.0 {
            return Rgb::ZERO;
        }
        match *self {
            Material::Diffuse { albedo } => albedo.eval(uv) * (FRAC_1_PI * cos_i),
            Material::Glossy { albedo, specular, roughness, ior } => {
                let (spec, cos_h) = microfacet::cook_torrance(n, wo, wi, roughness.max(1e-3));
                let f = fresnel::dielectric(cos_h, ior);
                // The base sees only light the coat lets through, on the way in and out.
                let t = (1.0 - fresnel::dielectric(cos_i, ior)) * (1.0 - fresnel::dielectric(n.dot(wo), ior));
                (albedo.eval(uv) * (FRAC_1_PI * t) + specular * (spec * f)) * cos_i
            }
            Material::Conductor { eta, k, roughness } => {
                let (spec, cos_h) = microfacet::cook_torrance(n, wo, wi, roughness.max(1e-3));
                conductor_fresnel(cos_h, eta, k) * (spec * cos_i)
            }
            Material::Glazed { ior, base } => {
                let t = (1.0 - fresnel::dielectric(cos_i, ior)) * (1.0 - fresnel::dielectric(n.dot(wo), ior));
                base * (FRAC_1_PI * t * cos_i)
            }
            Material::Mirror { .. } | Material::Dielectric { .. } => Rgb::ZERO,
        }
    }
}

/// Conductor Fresnel per RGB channel.
pub fn conductor_fresnel(cos_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    Rgb::new(
        fresnel::conductor(cos_i, eta.x, k.x),
        fresnel::conductor(cos_i, eta.y, k.y),
        fresnel::conductor(cos_i, eta.z, k.z),
    )
}

/// Named metals: `(name, eta, k)` at the red, green and blue primaries (the values Mitsuba and
/// pbrt scenes commonly use, from measured spectra).
pub const METALS: [(&str, [f32; 3], [f32; 3]); 4] = [
    ("gold", [0.143119, 0.374957, 1.44248], [3.98316, 2.38572, 1.60322]),
    ("silver", [0.155265, 0.116723, 0.138342], [4.82835, 3.12225, 2.14696]),
    ("copper", [0.200438, 0.924033, 1.10221], [3.91295, 2.45285, 2.14219]),
    ("aluminium", [1.65746, 0.880369, 0.521229], [9.22387, 6.26952, 4.837]),
];

/// Looks up a metal by name (also the chemical symbols and "aluminum").
pub fn metal(name: &str) -> Option<(Rgb, Rgb)> {
    let canonical = match name.to_ascii_lowercase().as_str() {
        "au" | "gold" => "gold",
        "ag" | "silver" => "silver",
        "cu" | "copper" => "copper",
        "al" | "aluminium" | "aluminum" => "aluminium",
        _ => return None,
    };
    METALS.iter().find(|m| m.0 == canonical).map(|m| (Rgb::from(m.1), Rgb::from(m.2)))
}

/// Named indices of refraction for dielectrics.
pub const IORS: [(&str, f32); 6] =
    [("air", 1.0), ("water", 1.33), ("glass", 1.5), ("optical-glass", 1.5168), ("bk7", 1.5168), ("diamond", 2.42)];

pub fn named_ior(name: &str) -> Option<f32> {
    IORS.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, v)| *v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lambertian_is_albedo_over_pi_times_cosine() {
        let m = Material::Diffuse { albedo: Rgb::splat(0.5).into() };
        let wi = Vec3::new(0.6, 0.0, 0.8);
        let v = m.eval_direct(Vec3::Z, Vec3::Z, wi, Vec2::ZERO);
        assert!((v.x - 0.5 * FRAC_1_PI * 0.8).abs() < 1e-7);
        assert_eq!(m.eval_direct(Vec3::Z, Vec3::Z, -wi, Vec2::ZERO), Rgb::ZERO);
    }

    #[test]
    fn glossy_highlight_peaks_in_mirror_direction() {
        let m = Material::Glossy { albedo: Rgb::ZERO.into(), specular: Rgb::ONE, roughness: 0.1, ior: 1.5 };
        let wo = Vec3::new(0.5, 0.0, 0.866).normalize();
        let mirror = fresnel::reflect(wo, Vec3::Z);
        let off = Vec3::new(-0.2, 0.3, 0.93).normalize();
        assert!(
            m.eval_direct(Vec3::Z, wo, mirror, Vec2::ZERO).x > 10.0 * m.eval_direct(Vec3::Z, wo, off, Vec2::ZERO).x
        );
    }

    #[test]
    fn rough_materials_do_not_create_energy() {
        // Directional albedo ∫ f cos dω ≤ 1 by quadrature, for a few view angles.
        let mats = [
            Material::Glossy { albedo: Rgb::ONE.into(), specular: Rgb::ONE, roughness: 0.3, ior: 1.5 },
            Material::Conductor { eta: Rgb::splat(0.2), k: Rgb::splat(3.0), roughness: 0.2 },
            Material::Glazed { ior: 1.5, base: Rgb::ONE },
        ];
        for m in mats {
            for deg in [0.0f32, 45.0, 80.0] {
                let wo = Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
                let (nt, np) = (200, 400);
                let mut sum = 0.0f64;
                for i in 0..nt {
                    for j in 0..np {
                        let ct = (i as f32 + 0.5) / nt as f32;
                        let st = (1.0 - ct * ct).sqrt();
                        let ph = (j as f32 + 0.5) / np as f32 * std::f32::consts::TAU;
                        let wi = Vec3::new(st * ph.cos(), st * ph.sin(), ct);
                        let dw = std::f32::consts::TAU / (nt * np) as f32;
                        sum += (m.eval_direct(Vec3::Z, wo, wi, Vec2::ZERO).x * dw) as f64;
                    }
                }
                assert!(sum <= 1.01, "{m:?} at {deg}°: albedo {sum}");
                assert!(sum > 0.05, "{m:?} at {deg}°: albedo {sum}");
            }
        }
    }

    #[test]
    fn checker_alternates() {
        let t = Texture::Checker { a: Rgb::ONE, b: Rgb::ZERO, scale: 4.0 };
        assert_eq!(t.eval(Vec2::new(0.1, 0.1)), Rgb::ONE);
        assert_eq!(t.eval(Vec2::new(0.3, 0.1)), Rgb::ZERO);
        assert_eq!(t.eval(Vec2::new(0.3, 0.3)), Rgb::ONE);
        assert_eq!(t.eval(Vec2::new(-0.1, 0.1)), Rgb::ZERO);
    }

    #[test]
    fn presets_resolve() {
        assert_eq!(named_ior("Diamond"), Some(2.42));
        assert_eq!(named_ior("water"), Some(1.33));
        assert!(metal("Au").is_some() && metal("aluminum").is_some() && metal("tin").is_none());
        // Gold reflects red more than blue at normal incidence.
        let (eta, k) = metal("gold").unwrap();
        let r = conductor_fresnel(1.0, eta, k);
        assert!(r.x > r.z + 0.3);
    }
}
