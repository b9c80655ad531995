//! Materials: what a scene file names ([`Material`]), and the BSDF each one has at a surface
//! point ([`bsdf::Bsdf`], with `sample`, `eval` and `pdf`).
//!
//! The Whitted integrator treats two kinds of scattering differently: *delta* lobes (ideal
//! mirror reflection and refraction) spawn new rays of the ray tree, while the *non-delta*
//! parts (Lambertian, microfacet lobes) are evaluated only against the lights
//! (`Bsdf::eval` on the shadow rays). The path integrator samples all of them.

pub mod bsdf;
pub mod fresnel;
pub mod microfacet;

use glam::{Vec2, Vec3};

use crate::Rgb;
use bsdf::{Bsdf, CoatTable, Reflectance};
use microfacet::{Distribution, Microfacet};

/// A colour that may vary over a surface, looked up by texture coordinates.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    Constant(Rgb),
    /// Squares of `a` and `b`, `scale` squares per unit of `u` and of `v`.
    Checker {
        a: Rgb,
        b: Rgb,
        scale: f32,
    },
    /// An image, repeated; `uv · scale` indexes it (shared, not copied, between materials).
    Image {
        image: std::sync::Arc<ImageTexture>,
        scale: Vec2,
    },
}

/// A linear RGB image for textures, row by row from the top. Texture coordinates have `v = 0`
/// at the bottom of the image (OBJ's and OpenGL's convention; Mitsuba's after its OBJ reader
/// flips `v`) and repeat outside `[0, 1)`; lookups are bilinear between pixel centres.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageTexture {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

impl ImageTexture {
    /// `width · height ≥ 1` pixels, each channel finite and not negative (see
    /// [`check_pixels`](crate::image::check_pixels)).
    pub fn new(width: usize, height: usize, pixels: Vec<Rgb>) -> Result<ImageTexture, crate::image::BadPixels> {
        crate::image::check_pixels(width, height, &pixels)?;
        Ok(ImageTexture { width, height, pixels })
    }

    pub fn eval(&self, uv: Vec2) -> Rgb {
        let x = uv.x * self.width as f32 - 0.5;
        let y = (1.0 - uv.y) * self.height as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return Rgb::ZERO;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |i: f32, n: usize| (i as i64).rem_euclid(n as i64) as usize;
        let px = |i: f32, j: f32| self.pixels[wrap(j, self.height) * self.width + wrap(i, self.width)];
        let top = px(x0, y0) * (1.0 - fx) + px(x0 + 1.0, y0) * fx;
        let bottom = px(x0, y0 + 1.0) * (1.0 - fx) + px(x0 + 1.0, y0 + 1.0) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// The mean colour.
    pub fn mean(&self) -> Rgb {
        self.pixels.iter().sum::<Rgb>() / self.pixels.len() as f32
    }
}

impl Texture {
    /// The colour, where it is the same at every point.
    pub fn constant(&self) -> Option<Rgb> {
        match self {
            Texture::Constant(c) => Some(*c),
            _ => None,
        }
    }

    /// The average colour over the texture.
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checker { a, b, .. } => (*a + *b) * 0.5,
            Texture::Image { image, .. } => image.mean(),
        }
    }

    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checker { a, b, scale } => {
                let s = (uv * *scale).floor();
                if (s.x + s.y).rem_euclid(2.0) < 1.0 {
                    *a
                } else {
                    *b
                }
            }
            Texture::Image { image, scale } => image.eval(uv * *scale),
        }
    }
}

impl From<Rgb> for Texture {
    fn from(c: Rgb) -> Texture {
        Texture::Constant(c)
    }
}

/// A surface material. [`Material::bsdf`] gives its BSDF at a surface point.
#[derive(Clone, Debug, PartialEq)]
pub enum Material {
    /// Lambertian: `albedo / π`.
    Diffuse { albedo: Texture },
    /// A diffuse base under a dielectric coat of index `ior` (Mitsuba's `plastic` and
    /// `roughplastic`): the coat reflects Fresnel's share, smooth (`roughness = 0`, an ideal
    /// mirror lobe) or rough (a microfacet lobe of that `alpha`), scaled by `specular`; the rest
    /// reaches the base. Build with [`Material::plastic`], which tabulates the coat.
    Plastic {
        diffuse: Texture,
        specular: Rgb,
        ior: f32,
        roughness: f32,
        distribution: Distribution,
        coat: Box<CoatTable>,
    },
    /// Metal with Fresnel from the complex index of refraction `eta + i·k` per RGB channel:
    /// an ideal mirror (`roughness = 0`) or microfacet reflection with that `alpha`.
    Conductor { eta: Rgb, k: Rgb, roughness: f32, distribution: Distribution },
    /// The lecture's alternative: a mirror with a constant reflectance at every angle.
    Mirror { reflectance: Rgb },
    /// Dielectric interface of index `ior` inside (glass, water, diamond): reflects `F` and
    /// refracts `1 - F` (times `transmittance`), with total internal reflection; smooth
    /// (`roughness = 0`) or rough (Walter et al. 2007).
    Dielectric { ior: f32, transmittance: Rgb, roughness: f32, distribution: Distribution },
    /// A thin pane of index `ior`: reflects, and transmits without bending (all internal
    /// reflections summed).
    ThinDielectric { ior: f32, transmittance: Rgb },
    /// An opaque material that reflects on the front side only (the side of the geometric
    /// normal) and is black from behind, as Mitsuba's BSDFs are unless wrapped in `twosided`.
    /// Snell's own materials are two-sided.
    OneSided(Box<Material>),
}

#[inline]
fn microfacet(roughness: f32, distribution: Distribution) -> Option<Microfacet> {
    (roughness > 0.0).then(|| Microfacet::new(distribution, roughness))
}

impl Material {
    /// A plastic, with its coat tabulated (see [`CoatTable`]).
    pub fn plastic(diffuse: Texture, specular: Rgb, ior: f32, roughness: f32, distribution: Distribution) -> Material {
        let coat = Box::new(CoatTable::shared(ior, microfacet(roughness, distribution)));
        Material::Plastic { diffuse, specular, ior, roughness, distribution, coat }
    }

    /// The material itself, without the one-sided wrapper.
    pub fn surface(&self) -> &Material {
        match self {
            Material::OneSided(m) => m.surface(),
            m => m,
        }
    }

    /// Whether the surface reflects on both sides (all but [`Material::OneSided`]).
    pub fn two_sided(&self) -> bool {
        !matches!(self, Material::OneSided(_))
    }

    /// The BSDF at a point with texture coordinates `uv`, in the local shading frame.
    #[inline(always)]
    pub fn bsdf(&self, uv: Vec2) -> Bsdf<'_> {
        match self.surface() {
            Material::Diffuse { albedo } => Bsdf::Diffuse { albedo: albedo.eval(uv) },
            Material::Plastic { diffuse, specular, ior, roughness, distribution, coat } => Bsdf::Plastic {
                diffuse: diffuse.eval(uv),
                specular: *specular,
                eta: *ior,
                mf: microfacet(*roughness, *distribution),
                coat,
            },
            Material::Conductor { eta, k, roughness, distribution } => Bsdf::Conductor {
                reflectance: Reflectance::Complex { eta: *eta, k: *k },
                mf: microfacet(*roughness, *distribution),
            },
            Material::Mirror { reflectance } => {
                Bsdf::Conductor { reflectance: Reflectance::Constant(*reflectance), mf: None }
            }
            Material::Dielectric { ior, transmittance, roughness, distribution } => {
                Bsdf::Dielectric { eta: *ior, mf: microfacet(*roughness, *distribution), tint: *transmittance }
            }
            Material::ThinDielectric { ior, transmittance } => Bsdf::ThinDielectric { eta: *ior, tint: *transmittance },
            Material::OneSided(_) => Bsdf::Diffuse { albedo: Rgb::ZERO }, // `surface` unwraps it
        }
    }

    /// The albedo of a Lambertian material that is the same at every point: where this is
    /// `Some(albedo)`, [`Material::bsdf`] gives `Bsdf::Diffuse { albedo }` at every `uv`.
    pub fn uniform_diffuse(&self) -> Option<Rgb> {
        match self.surface() {
            Material::Diffuse { albedo } => albedo.constant(),
            _ => None,
        }
    }

    /// The surface's colour at `uv` for the albedo AOV: the diffuse albedo where there is one,
    /// a metal's reflectance at normal incidence, a dielectric's transmittance.
    pub fn albedo(&self, uv: Vec2) -> Rgb {
        match self.surface() {
            Material::Diffuse { albedo } | Material::Plastic { diffuse: albedo, .. } => albedo.eval(uv),
            Material::Conductor { eta, k, .. } => conductor_fresnel(1.0, *eta, *k),
            Material::Mirror { reflectance } => *reflectance,
            Material::Dielectric { transmittance, .. } | Material::ThinDielectric { transmittance, .. } => {
                *transmittance
            }
            Material::OneSided(_) => Rgb::ZERO, // `surface` unwraps it
        }
    }

    /// The diffuse albedo at `uv`, for the ambient term.
    pub fn diffuse_albedo(&self, uv: Vec2) -> Rgb {
        match self.surface() {
            Material::Diffuse { albedo } | Material::Plastic { diffuse: albedo, .. } => albedo.eval(uv),
            _ => Rgb::ZERO,
        }
    }
}

/// An orthonormal shading frame: `n` is the local `z` axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    pub fn new(n: Vec3) -> Frame {
        let (s, t) = crate::geometry::orthonormal_basis(n);
        Frame { s, t, n }
    }

    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
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

    /// `f(wo, wi) |n · wi|` in world space, with shading normal `n`.
    fn eval_world(m: &Material, n: Vec3, wo: Vec3, wi: Vec3) -> Rgb {
        let f = Frame::new(n);
        m.bsdf(Vec2::ZERO).eval(f.to_local(wo), f.to_local(wi))
    }

    #[test]
    fn lambertian_is_albedo_over_pi_times_cosine() {
        let m = Material::Diffuse { albedo: Rgb::splat(0.5).into() };
        let wi = Vec3::new(0.6, 0.0, 0.8);
        let v = eval_world(&m, Vec3::Z, Vec3::Z, wi);
        assert!((v.x - 0.5 * std::f32::consts::FRAC_1_PI * 0.8).abs() < 1e-7);
        assert_eq!(eval_world(&m, Vec3::Z, Vec3::Z, -wi), Rgb::ZERO);
    }

    #[test]
    fn glossy_highlight_peaks_in_mirror_direction() {
        let m = Material::plastic(Rgb::ZERO.into(), Rgb::ONE, 1.5, 0.1, Distribution::Ggx);
        let wo = Vec3::new(0.5, 0.0, 0.866).normalize();
        let mirror = fresnel::reflect(wo, Vec3::Z);
        let off = Vec3::new(-0.2, 0.3, 0.93).normalize();
        assert!(eval_world(&m, Vec3::Z, wo, mirror).x > 10.0 * eval_world(&m, Vec3::Z, wo, off).x);
    }

    #[test]
    fn rough_materials_do_not_create_energy() {
        // Directional albedo ∫ f cos dω ≤ 1 by quadrature, for a few view angles.
        let mats = [
            Material::plastic(Rgb::ONE.into(), Rgb::ONE, 1.5, 0.3, Distribution::Ggx),
            Material::plastic(Rgb::ONE.into(), Rgb::ONE, 1.5, 0.3, Distribution::Beckmann),
            Material::Conductor {
                eta: Rgb::splat(0.2),
                k: Rgb::splat(3.0),
                roughness: 0.2,
                distribution: Distribution::Ggx,
            },
            Material::plastic(Rgb::ONE.into(), Rgb::ONE, 1.5, 0.0, Distribution::Ggx),
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
                        sum += (eval_world(&m, Vec3::Z, wo, wi).x * dw) as f64;
                    }
                }
                assert!(sum <= 1.01, "{m:?} at {deg}°: albedo {sum}");
                assert!(sum > 0.05, "{m:?} at {deg}°: albedo {sum}");
            }
        }
    }

    #[test]
    fn image_texture_is_bilinear_repeats_and_has_v_up() {
        // 2×2: top row red, green; bottom row blue, white.
        let img = ImageTexture::new(2, 2, vec![Rgb::X, Rgb::Y, Rgb::Z, Rgb::ONE]).unwrap();
        // Pixel centres: u = 0.25 / 0.75, v = 0.75 (top) / 0.25 (bottom).
        assert_eq!(img.eval(Vec2::new(0.25, 0.75)), Rgb::X);
        assert_eq!(img.eval(Vec2::new(0.75, 0.25)), Rgb::ONE);
        assert_eq!(img.eval(Vec2::new(1.25, -0.25)), Rgb::X, "repeats");
        let mid = img.eval(Vec2::new(0.5, 0.75));
        assert!((mid - Rgb::new(0.5, 0.5, 0.0)).length() < 1e-6, "{mid}");
        let t = Texture::Image { image: std::sync::Arc::new(img), scale: Vec2::splat(2.0) };
        assert_eq!(t.eval(Vec2::new(0.125, 0.375)), Rgb::X);
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
