//! BSDFs with `sample`, `eval` and `pdf`, in the local shading frame (`z` = shading normal).
//!
//! Conventions (the same as Mitsuba 3's):
//! - `wo` points towards the viewer (where the path came from), `wi` towards the light (the
//!   sampled direction); both point away from the surface and are unit vectors.
//! - [`Bsdf::eval`] returns `f(wo, wi) |cos θ_i|` for the non-delta lobes; delta lobes (ideal
//!   mirror reflection and refraction) are reached only through [`Bsdf::sample`].
//! - [`Bsdf::pdf`] is the solid-angle density with which `sample` produces `wi` through its
//!   non-delta lobes, including the probability of choosing such a lobe.
//! - [`BsdfSample::weight`] is `f |cos θ_i| / pdf` (for a delta lobe: the lobe's reflectance or
//!   transmittance over the probability of choosing it).
//! - Opaque BSDFs (diffuse, conductor, plastic) live on the upper side (`z > 0`); the
//!   integrator turns the frame to the side of `wo` (two-sided surfaces). Dielectrics see both
//!   sides: `wo.z < 0` means the path arrives from inside, and `eta` (inside over outside) is
//!   inverted.
//! - Refraction scales radiance by `1/η²` (η: the index the light enters over the one it
//!   leaves, seen along `wo`), as the transport of radiance across an interface requires.

use std::collections::HashMap;
use std::f32::consts::FRAC_1_PI;
use std::sync::{Mutex, OnceLock};

use glam::{Vec2, Vec3};

use super::fresnel;
use super::microfacet::{Distribution, Microfacet};
use crate::sampling::concentric_disk;
use crate::Rgb;

/// Specular reflectance of a conductor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reflectance {
    /// Fresnel of the complex index `eta + i k` per channel.
    Complex { eta: Rgb, k: Rgb },
    /// The same reflectance at every angle (the lecture's mirror).
    Constant(Rgb),
}

impl Reflectance {
    #[inline]
    pub fn eval(&self, cos: f32) -> Rgb {
        match *self {
            Reflectance::Complex { eta, k } => super::conductor_fresnel(cos, eta, k),
            Reflectance::Constant(r) => r,
        }
    }
}

/// Transmittance of a (rough) dielectric coat as seen from outside, tabulated over `cos θ`, and
/// the coat's reflectance for the diffuse light under it (both for a plastic's diffuse layer).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoatTable {
    transmittance: [f32; Self::N],
    /// Fraction of the light scattered diffusely under the coat that the coat sends back down.
    pub internal_reflectance: f32,
    /// Mitsuba's `nonlinear`: the light sent back down is scattered again by the base's own
    /// colour, so the diffuse term goes with `1 / (1 − ρ R)` per channel instead of
    /// `1 / (1 − R)`; saturated colours come out darker and more saturated. Off by default.
    pub nonlinear: bool,
}

impl CoatTable {
    /// Cosines tabulated, `i / (N − 1)` (Mitsuba's `roughplastic` tabulates the same 64).
    const N: usize = 64;

    /// Tabulates a coat of relative index `eta` (inside over outside) with roughness `mf`
    /// (`None`: smooth, exact Fresnel).
    ///
    /// The internal reflectance, the hemispherical average `2 ∫ R(μ) μ dμ` of the interface's
    /// reflectance from inside, is worked out as Mitsuba 3 works it out, so that its scenes
    /// render as they do there (the diffuse term goes with `1 / (1 − R)`, 4.7 for η = 2, so a
    /// small difference in `R` is a larger one in the image). Smooth (Mitsuba's `plastic`, which
    /// uses Egan and Hilgeman's fit of the integral): the integral itself, by 1,024 midpoints.
    /// Rough (`roughplastic`): twice the mean of `R(μ) μ` over the 64 tabulated cosines, ends
    /// included, as Mitsuba averages its table. That mean is not the integral: for η = 2 it is
    /// 0.777 where the integral is 0.790, and the diffuse term 6 % dimmer. Taking the integral
    /// left Veach's MIS scene 0.1–0.24 % brighter than Mitsuba's reference at 512 spp, the
    /// plates' bluish diffuse colour showing in the blue channel most.
    ///
    /// A rough coat's 128 integrals (each over 1,024 microfacet normals) run in parallel: about
    /// 8 ms of work a table, which an OBJ with hundreds of MTL materials (each a rough
    /// plastic) made a load of seconds on one thread. Each integral is the same computation
    /// wherever it runs, and the mean is summed in index order, so the table is the same bits
    /// on any number of threads.
    pub fn new(eta: f32, mf: Option<Microfacet>) -> CoatTable {
        use rayon::prelude::*;
        let cosine = |i: usize| (i as f32 / (Self::N - 1) as f32).max(1e-6);
        let transmittance_at = |i: usize| interface_scattering(eta, mf, cosine(i)).1;
        let inside = |mu: f32| 2.0 * mu * interface_scattering(1.0 / eta, mf, mu).0;
        let (transmittance, internal_reflectance) = match mf {
            Some(_) => {
                // Index i < N: the transmittance at cosine i; N + i: the inside term at it.
                let terms: Vec<f32> = (0..2 * Self::N)
                    .into_par_iter()
                    .map(|k| if k < Self::N { transmittance_at(k) } else { inside(cosine(k - Self::N)) })
                    .collect();
                let transmittance = std::array::from_fn(|i| terms[i]);
                (transmittance, terms[Self::N..].iter().sum::<f32>() / Self::N as f32)
            }
            None => (
                std::array::from_fn(transmittance_at),
                (0..1024).map(|i| inside((i as f32 + 0.5) / 1024.0)).sum::<f32>() / 1024.0,
            ),
        };
        CoatTable { transmittance, internal_reflectance: internal_reflectance.min(1.0 - 1e-4), nonlinear: false }
    }

    /// [`CoatTable::new`], each coat made once per process: the table depends only on `eta` and
    /// `mf`, and a scene's plastics often share their coat (an OBJ's MTL materials their `Ns`),
    /// so later plastics of the same coat copy the table instead of integrating it again.
    pub fn shared(eta: f32, mf: Option<Microfacet>) -> CoatTable {
        type Coat = (u32, Option<(Distribution, u32)>);
        static MADE: OnceLock<Mutex<HashMap<Coat, CoatTable>>> = OnceLock::new();
        let made = MADE.get_or_init(Default::default);
        // (A thread that panicked holding the lock left whole tables behind: each is inserted
        // in one call.)
        let lock = || made.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let coat = (eta.to_bits(), mf.map(|m| (m.kind, m.alpha.to_bits())));
        if let Some(table) = lock().get(&coat) {
            return *table;
        }
        // Made without the lock held, so that other coats are made meanwhile.
        let table = CoatTable::new(eta, mf);
        lock().insert(coat, table);
        table
    }

    /// Transmittance into the coat from direction cosine `cos` (outside).
    #[inline]
    pub fn transmittance(&self, cos: f32) -> f32 {
        let x = cos.clamp(0.0, 1.0) * (Self::N - 1) as f32;
        let i = (x as usize).min(Self::N - 2);
        let f = x - i as f32;
        self.transmittance[i] * (1.0 - f) + self.transmittance[i + 1] * f
    }
}

/// The fractions of light arriving at cosine `cos` that a dielectric interface of relative
/// index `eta` reflects and transmits. Smooth: `F` and `1 − F`. Rough (`mf`): the microfacet
/// lobe's single scattering, as Mitsuba's `eval_reflectance` and `eval_transmittance` define
/// it: over the normals visible from the incident direction, each normal's Fresnel share of
/// reflection (or refraction), masked by Smith's term of the reflected (or refracted)
/// direction, by a 32 × 32 midpoint quadrature of the sampled normals (Mitsuba's
/// Gauss–Legendre rules take 32 nodes a side from outside and 128 from inside; finer rules here
/// moved a plastic's diffuse term by under 0.2 %, and cost a tenth of a second a material at
/// 128). The masking takes
/// energy from both, so transmittance is less than `1 −` reflectance, by 6 % at grazing
/// incidence (cosine 0.1) for GGX of α = 0.05 and η = 1.49: taking `1 −` reflectance made a
/// rough plastic's diffuse term that much brighter towards grazing than Mitsuba's.
fn interface_scattering(eta: f32, mf: Option<Microfacet>, cos: f32) -> (f32, f32) {
    let Some(mf) = mf else {
        let f = fresnel::dielectric(cos, eta);
        return (f, 1.0 - f);
    };
    let wo = Vec3::new((1.0 - cos * cos).max(0.0).sqrt(), 0.0, cos);
    let n = 32;
    let (mut r, mut t) = (0.0, 0.0);
    for i in 0..n {
        for j in 0..n {
            let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
            let (m, pdf_m) = mf.sample(wo, u);
            let dot = wo.dot(m);
            if pdf_m <= 0.0 || dot <= 0.0 {
                continue;
            }
            // The visible normals' density over the sampling density (1 where the
            // distribution samples visible normals, GGX).
            let visible = mf.g1(wo, m) * dot * mf.d(m) / (cos * pdf_m);
            let f = fresnel::dielectric(dot, eta);
            let wr = reflect_about(wo, m);
            if wr.z > 0.0 {
                r += f * mf.g1(wr, m) * visible;
            }
            if let Some(wt) = fresnel::refract(wo, m, eta).filter(|wt| wt.z < 0.0) {
                t += (1.0 - f) * mf.g1(wt, m) * visible;
            }
        }
    }
    let k = (n * n) as f32;
    ((r / k).clamp(0.0, 1.0), (t / k).clamp(0.0, 1.0))
}

/// A BSDF at one surface point, ready to sample and evaluate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bsdf<'a> {
    /// Lambertian reflection `albedo / π`.
    Diffuse { albedo: Rgb },
    /// Metal: smooth (`mf: None`, an ideal mirror) or rough microfacet reflection.
    Conductor { reflectance: Reflectance, mf: Option<Microfacet> },
    /// Interface between two dielectrics, `eta` = inside over outside: smooth (reflection or
    /// refraction chosen by Fresnel) or rough (Walter et al. 2007). `tint` scales transmission.
    Dielectric { eta: f32, mf: Option<Microfacet>, tint: Rgb },
    /// A thin pane: reflection and straight transmission, with all internal reflections summed.
    ThinDielectric { eta: f32, tint: Rgb },
    /// Diffuse base under a dielectric coat (Mitsuba's `plastic` and `roughplastic`).
    Plastic { diffuse: Rgb, specular: Rgb, eta: f32, mf: Option<Microfacet>, coat: &'a CoatTable },
}

/// One sampled direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// `f |cos θ_i| / pdf`.
    pub weight: Rgb,
    /// Solid-angle density (for a delta lobe: the probability of choosing it).
    pub pdf: f32,
    /// Whether `wi` came from a delta lobe (no other direction could have produced it).
    pub delta: bool,
}

#[inline]
fn reflect_about(w: Vec3, m: Vec3) -> Vec3 {
    2.0 * w.dot(m) * m - w
}

#[inline]
fn mirror(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// Cosine-weighted direction on the upper hemisphere; pdf `cos θ / π`.
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

/// The Lambertian lobe's sample for `wo` (local) whose cosine-weighted direction is `wi`
/// (`cosine_hemisphere` of the sample's numbers), as [`Bsdf::sample`] gives it for
/// [`Bsdf::Diffuse`]: for callers that work the direction out themselves (eight at a time).
#[inline(always)]
pub fn diffuse_sampled(albedo: Rgb, wo: Vec3, wi: Vec3) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    (wi.z > 0.0).then_some(BsdfSample { wi, weight: albedo, pdf: wi.z * FRAC_1_PI, delta: false })
}

/// The Lambertian lobe's [`Bsdf::eval`].
#[inline(always)]
pub fn diffuse_eval(albedo: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Rgb::ZERO;
    }
    albedo * (FRAC_1_PI * wi.z)
}

/// The Lambertian lobe's [`Bsdf::pdf`].
#[inline(always)]
pub fn diffuse_pdf(wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    wi.z * FRAC_1_PI
}

impl Bsdf<'_> {
    /// Whether the BSDF transmits (and so must see both sides of the surface as they are).
    pub fn transmits(&self) -> bool {
        matches!(self, Bsdf::Dielectric { .. } | Bsdf::ThinDielectric { .. })
    }

    /// The relative index η across the surface when a path goes from `wo` to `wi` (1 unless it
    /// refracts through a dielectric). Radiance was divided by η² on the way.
    pub fn eta_across(&self, wo: Vec3, wi: Vec3) -> f32 {
        match *self {
            Bsdf::Dielectric { eta, .. } if wo.z * wi.z < 0.0 => {
                if wo.z > 0.0 {
                    eta
                } else {
                    1.0 / eta
                }
            }
            _ => 1.0,
        }
    }

    /// Whether every lobe is a delta lobe (nothing for light sampling to evaluate).
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Diffuse { .. } => false,
            Bsdf::Conductor { mf, .. } | Bsdf::Dielectric { mf, .. } => mf.is_none(),
            Bsdf::ThinDielectric { .. } => true,
            Bsdf::Plastic { .. } => false,
        }
    }

    /// `f(wo, wi) |cos θ_i|` of the non-delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.eval_pdf(wo, wi).0
    }

    /// Density of [`Self::sample`] producing `wi` through a non-delta lobe.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// [`Self::eval_pdf`], out of line (for the path tracer's light samples): the attribute
    /// makes it so, where the compiler's choice did before.
    #[inline(never)]
    pub fn eval_and_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        self.eval_pdf(wo, wi)
    }

    /// [`Self::eval`] and [`Self::pdf`] together, the same bits as each alone: a microfacet
    /// lobe's half-vector and distribution, and a plastic's coat transmittance towards `wo`,
    /// are worked out once for both. (Inlined into `eval` and `pdf`, each drops the half it
    /// does not return.)
    #[inline(always)]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        match *self {
            Bsdf::Diffuse { albedo } => (diffuse_eval(albedo, wo, wi), diffuse_pdf(wo, wi)),
            Bsdf::Conductor { reflectance, mf: Some(mf) } => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return (Rgb::ZERO, 0.0);
                }
                let m = (wo + wi).normalize();
                let d = mf.d(m);
                let f = reflectance.eval(wo.dot(m)) * (d * mf.g(wo, wi, m) / (4.0 * wo.z));
                (f, mf.pdf_with_d(wo, m, d) / (4.0 * wo.dot(m)))
            }
            Bsdf::Dielectric { eta, mf: Some(mf), tint } => {
                let (f, pdf) = rough_dielectric(eta, &mf, wo, wi);
                (f * tint_if(wo, wi, tint), pdf)
            }
            Bsdf::Plastic { diffuse, specular, eta, mf, coat } => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return (Rgb::ZERO, 0.0);
                }
                let t_o = coat_transmittance(eta, mf, coat, wo.z);
                let mut v = plastic_diffuse(diffuse, eta, mf, coat, t_o, wi);
                let p_spec = plastic_specular_probability(diffuse, specular, t_o);
                let mut pdf = (1.0 - p_spec) * wi.z * FRAC_1_PI;
                if let Some(mf) = mf {
                    let m = (wo + wi).normalize();
                    let d = mf.d(m);
                    let f = fresnel::dielectric(wo.dot(m), eta);
                    v += specular * (f * d * mf.g(wo, wi, m) / (4.0 * wo.z));
                    pdf += p_spec * mf.pdf_with_d(wo, m, d) / (4.0 * wo.dot(m));
                }
                (v, pdf)
            }
            Bsdf::Conductor { mf: None, .. } | Bsdf::Dielectric { mf: None, .. } | Bsdf::ThinDielectric { .. } => {
                (Rgb::ZERO, 0.0)
            }
        }
    }

    /// Samples `wi` for `wo`; `uc` chooses the lobe and `u` the direction (both uniform).
    ///
    /// Inlined: returned through memory, the sample was read back in other pieces than it
    /// was written, a store-forwarding stall (inlining made a Cornell box render 4 % faster).
    #[inline(always)]
    pub fn sample(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        match *self {
            Bsdf::Diffuse { albedo } => diffuse_sampled(albedo, wo, cosine_hemisphere(u)),
            Bsdf::Conductor { reflectance, mf } => {
                if wo.z <= 0.0 {
                    return None;
                }
                match mf {
                    None => Some(BsdfSample { wi: mirror(wo), weight: reflectance.eval(wo.z), pdf: 1.0, delta: true }),
                    Some(mf) => {
                        let (m, _) = mf.sample(wo, u);
                        self.sampled(wo, reflect_about(wo, m))
                    }
                }
            }
            Bsdf::Dielectric { eta, mf: None, tint } => {
                let f = fresnel::dielectric(wo.z, eta);
                if uc < f {
                    return Some(BsdfSample { wi: mirror(wo), weight: Rgb::ONE, pdf: f, delta: true });
                }
                let eta_rel = if wo.z > 0.0 { eta } else { 1.0 / eta };
                let n = Vec3::new(0.0, 0.0, wo.z.signum());
                let wi = fresnel::refract(wo, n, eta_rel)?;
                Some(BsdfSample { wi, weight: tint / (eta_rel * eta_rel), pdf: 1.0 - f, delta: true })
            }
            Bsdf::Dielectric { eta, mf: Some(mf), .. } => {
                let (mut m, _) = mf.sample(wo, u);
                if wo.z < 0.0 {
                    m = -m; // The microfacet faces the side the path arrives from.
                }
                if wo.dot(m) <= 0.0 {
                    return None; // Beckmann sampling can pick a facet that `wo` sees from behind.
                }
                let f = fresnel::dielectric(wo.dot(m) * wo.z.signum(), eta);
                let (wi, reflected) = if uc < f {
                    (reflect_about(wo, m), true)
                } else {
                    let eta_rel = if wo.z > 0.0 { eta } else { 1.0 / eta };
                    (fresnel::refract(wo, m, eta_rel)?, false)
                };
                // A facet can send the path to the wrong side of the macro-surface: no sample.
                if (wi.z * wo.z > 0.0) != reflected || wi.z == 0.0 {
                    return None;
                }
                self.sampled(wo, wi)
            }
            Bsdf::ThinDielectric { eta, tint } => {
                let r = fresnel::thin_slab(wo.z, eta);
                if uc < r {
                    Some(BsdfSample { wi: mirror(wo), weight: Rgb::ONE, pdf: r, delta: true })
                } else {
                    Some(BsdfSample { wi: -wo, weight: tint, pdf: 1.0 - r, delta: true })
                }
            }
            Bsdf::Plastic { diffuse, specular, eta, mf, coat } => {
                if wo.z <= 0.0 {
                    return None;
                }
                let p_spec = plastic_specular_probability(diffuse, specular, coat_transmittance(eta, mf, coat, wo.z));
                if uc < p_spec {
                    match mf {
                        None => {
                            let f = fresnel::dielectric(wo.z, eta);
                            Some(BsdfSample {
                                wi: mirror(wo),
                                weight: specular * (f / p_spec),
                                pdf: p_spec,
                                delta: true,
                            })
                        }
                        Some(mf) => self.sampled(wo, reflect_about(wo, mf.sample(wo, u).0)),
                    }
                } else {
                    self.sampled(wo, cosine_hemisphere(u))
                }
            }
        }
    }

    /// A non-delta sample: weight from the full `eval` and `pdf` (all lobes, as MIS needs).
    #[inline]
    fn sampled(&self, wo: Vec3, wi: Vec3) -> Option<BsdfSample> {
        let (f, pdf) = self.eval_pdf(wo, wi);
        if pdf.is_nan() || pdf <= 0.0 || !pdf.is_finite() {
            return None;
        }
        let weight = f / pdf;
        weight.is_finite().then_some(BsdfSample { wi, weight, pdf, delta: false })
    }
}

#[inline]
fn tint_if(wo: Vec3, wi: Vec3, tint: Rgb) -> Rgb {
    if wo.z * wi.z < 0.0 {
        tint
    } else {
        Rgb::ONE
    }
}

/// Rough dielectric (Walter et al. 2007, as in pbrt-v4): `(f |cos θ_i|, pdf)` of `wi`, with
/// Fresnel choosing between reflection and refraction in sampling.
fn rough_dielectric(eta: f32, mf: &Microfacet, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
    let (co, ci) = (wo.z, wi.z);
    if co == 0.0 || ci == 0.0 {
        return (Rgb::ZERO, 0.0);
    }
    let reflect = co * ci > 0.0;
    let etap = if reflect {
        1.0
    } else if co > 0.0 {
        eta
    } else {
        1.0 / eta
    };
    let m = wi * etap + wo;
    if m.length_squared() == 0.0 {
        return (Rgb::ZERO, 0.0);
    }
    let mut m = m.normalize();
    if m.z < 0.0 {
        m = -m;
    }
    // Back-facing microfacets do not contribute.
    if m.dot(wi) * ci < 0.0 || m.dot(wo) * co < 0.0 {
        return (Rgb::ZERO, 0.0);
    }
    let f = fresnel::dielectric(wo.dot(m), eta);
    let pdf_m = mf.pdf(if co > 0.0 { wo } else { -wo }, m);
    if reflect {
        let v = mf.d(m) * mf.g(wo, wi, m) * f / (4.0 * co.abs());
        (Rgb::splat(v), pdf_m / (4.0 * wo.dot(m).abs()) * f)
    } else {
        let denom = (wi.dot(m) + wo.dot(m) / etap).powi(2);
        let v = mf.d(m) * (1.0 - f) * mf.g(wo, wi, m) * (wi.dot(m) * wo.dot(m) / (denom * co)).abs();
        let dm_dwi = wi.dot(m).abs() / denom;
        (Rgb::splat(v / (etap * etap)), pdf_m * dm_dwi * (1.0 - f))
    }
}

/// A plastic's coat transmittance into the coat from cosine `cos` (outside): the rough coat's
/// tabulated value, or `1 − F` for a smooth one.
#[inline]
fn coat_transmittance(eta: f32, mf: Option<Microfacet>, coat: &CoatTable, cos: f32) -> f32 {
    match mf {
        Some(_) => coat.transmittance(cos),
        None => 1.0 - fresnel::dielectric(cos, eta),
    }
}

/// Probability that a plastic samples its coat rather than its base, as in Mitsuba: the coat's
/// reflectance and the base's transmitted share (`t_o`, the coat's transmittance towards
/// `wo`), weighted by the mean specular and diffuse colours.
#[inline]
fn plastic_specular_probability(diffuse: Rgb, specular: Rgb, t_o: f32) -> f32 {
    let (d, s) = (diffuse.element_sum() / 3.0, specular.element_sum() / 3.0);
    let w = if d + s > 0.0 { s / (d + s) } else { 0.5 };
    let (ps, pd) = ((1.0 - t_o) * w, t_o * (1.0 - w));
    if ps + pd > 0.0 {
        ps / (ps + pd)
    } else {
        1.0
    }
}

/// The diffuse base of a plastic seen through its coat: transmitted in at `wi` and out at `wo`
/// (each `1 - F` or the rough coat's transmittance; `t_o` is `wo`'s), divided by `η²` for the
/// change of medium, and brightened by the light the coat reflects back down onto the base
/// (`1 / (1 - R_int)`, or `1 / (1 − ρ R_int)` for a nonlinear coat).
#[inline]
fn plastic_diffuse(diffuse: Rgb, eta: f32, mf: Option<Microfacet>, coat: &CoatTable, t_o: f32, wi: Vec3) -> Rgb {
    let t_i = coat_transmittance(eta, mf, coat, wi.z);
    let r = coat.internal_reflectance;
    let kept = if coat.nonlinear { Rgb::ONE - diffuse * r } else { Rgb::splat(1.0 - r) };
    diffuse / kept * (t_o * t_i * wi.z * FRAC_1_PI / (eta * eta))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::microfacet::Distribution;
    use crate::sampling::Pcg32;

    /// Upper incomplete gamma `Q(a, x)` (series and continued fraction, Numerical Recipes).
    fn gamma_q(a: f64, x: f64) -> f64 {
        let ln_gamma_a = ln_gamma(a);
        if x < a + 1.0 {
            let (mut sum, mut del, mut ap) = (1.0 / a, 1.0 / a, a);
            for _ in 0..1000 {
                ap += 1.0;
                del *= x / ap;
                sum += del;
                if del.abs() < sum.abs() * 1e-14 {
                    break;
                }
            }
            1.0 - sum * (-x + a * x.ln() - ln_gamma_a).exp()
        } else {
            let (mut b, mut c, mut d) = (x + 1.0 - a, 1e300, 1.0 / (x + 1.0 - a));
            let mut h = d;
            for i in 1..1000 {
                let an = -(i as f64) * (i as f64 - a);
                b += 2.0;
                d = an * d + b;
                d = if d.abs() < 1e-300 { 1e-300 } else { d };
                c = b + an / c;
                c = if c.abs() < 1e-300 { 1e-300 } else { c };
                d = 1.0 / d;
                let del = d * c;
                h *= del;
                if (del - 1.0).abs() < 1e-14 {
                    break;
                }
            }
            (-x + a * x.ln() - ln_gamma_a).exp() * h
        }
    }

    fn ln_gamma(x: f64) -> f64 {
        // Lanczos approximation (g = 7, n = 9).
        const C: [f64; 9] = [
            0.999_999_999_999_809_9,
            676.5203681218851,
            -1259.1392167224028,
            771.323_428_777_653_1,
            -176.615_029_162_140_6,
            12.507343278686905,
            -0.13857109526572012,
            9.984_369_578_019_572e-6,
            1.5056327351493116e-7,
        ];
        let x = x - 1.0;
        let mut a = C[0];
        let t = x + 7.5;
        for (i, c) in C.iter().enumerate().skip(1) {
            a += c / (x + i as f64);
        }
        0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
    }

    /// χ² goodness of fit of `sample` against `pdf` over the sphere, in (cos θ, φ) bins; the
    /// expected counts integrate `pdf` numerically. Returns the p-value. Also checks that every
    /// non-delta sample's weight equals `eval / pdf`.
    fn chi2(bsdf: &Bsdf, wo: Vec3, samples: usize, seed: u64) -> f64 {
        chi2_with(bsdf, bsdf, wo, samples, seed)
    }

    /// As [`chi2`], sampling `bsdf` and taking the expected counts from `density`'s pdf.
    fn chi2_with(bsdf: &Bsdf, density: &Bsdf, wo: Vec3, samples: usize, seed: u64) -> f64 {
        const NT: usize = 30;
        const NP: usize = 60;
        let mut observed = vec![0.0f64; NT * NP];
        let mut rng = Pcg32::new(seed, 7);
        let bin = |w: Vec3| {
            let t = ((w.z.clamp(-1.0, 1.0).acos() / std::f32::consts::PI * NT as f32) as usize).min(NT - 1);
            let phi = w.y.atan2(w.x).rem_euclid(std::f32::consts::TAU);
            let p = ((phi / std::f32::consts::TAU * NP as f32) as usize).min(NP - 1);
            t * NP + p
        };
        for _ in 0..samples {
            let uc = rng.next_f32();
            let u = rng.next_2d();
            if let Some(s) = bsdf.sample(wo, uc, u) {
                if s.delta {
                    continue;
                }
                observed[bin(s.wi)] += 1.0;
                if bsdf != density {
                    continue;
                }
                let (e, p) = (bsdf.eval(wo, s.wi), bsdf.pdf(wo, s.wi));
                assert!((s.pdf - p).abs() <= 1e-3 * p.max(1e-3), "{bsdf:?}: sample pdf {} vs pdf {p}", s.pdf);
                let expect = e / p;
                assert!(
                    (s.weight - expect).abs().max_element() <= 1e-3 * expect.max_element().max(1.0),
                    "{bsdf:?}: weight {} vs eval/pdf {expect}",
                    s.weight
                );
            }
        }
        // Expected counts: integrate the pdf over each (θ, φ) bin, `pdf sin θ dθ dφ`, by the
        // midpoint rule on a finer grid (θ bins, not cos θ bins, keep the pole finely resolved).
        let integrate = |t: usize, p: usize, sub: usize| {
            let mut s = 0.0f64;
            for i in 0..sub {
                for j in 0..sub {
                    let th = std::f64::consts::PI * ((t * sub + i) as f64 + 0.5) / (NT * sub) as f64;
                    let phi = std::f64::consts::TAU * ((p * sub + j) as f64 + 0.5) / (NP * sub) as f64;
                    let (r, z) = (th.sin(), th.cos());
                    let w = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                    s += density.pdf(wo, w) as f64 * r;
                }
            }
            s * (std::f64::consts::PI / (NT * sub) as f64) * (std::f64::consts::TAU / (NP * sub) as f64)
        };
        let mut expected = vec![0.0f64; NT * NP];
        for t in 0..NT {
            for p in 0..NP {
                let (coarse, fine) = (integrate(t, p, 4), integrate(t, p, 12));
                // Where the two disagree by a quarter of a sample or more (narrow lobes: small α,
                // grazing angles), refine.
                let e = if (coarse - fine).abs() * samples as f64 > 0.25 || (fine == 0.0 && observed[t * NP + p] > 0.0)
                {
                    integrate(t, p, 64)
                } else {
                    fine
                };
                expected[t * NP + p] = e * samples as f64;
            }
        }
        // Pool bins with fewer than 5 expected samples (as Mitsuba's χ² test does).
        let mut order: Vec<usize> = (0..NT * NP).collect();
        order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
        let (mut chsq, mut dof, mut pool_e, mut pool_o) = (0.0f64, 0usize, 0.0f64, 0.0f64);
        for &i in &order {
            if expected[i] == 0.0 {
                assert!(observed[i] == 0.0, "{bsdf:?}: {} samples where the pdf is zero (bin {i})", observed[i]);
            } else if expected[i] < 5.0 {
                pool_e += expected[i];
                pool_o += observed[i];
            } else {
                chsq += (observed[i] - expected[i]).powi(2) / expected[i];
                dof += 1;
            }
        }
        if pool_e > 5.0 {
            chsq += (pool_o - pool_e).powi(2) / pool_e;
            dof += 1;
        }
        if dof <= 1 {
            return 1.0;
        }
        gamma_q((dof - 1) as f64 / 2.0, chsq / 2.0)
    }

    fn dir(theta_deg: f32, phi_deg: f32) -> Vec3 {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    fn coat(eta: f32, mf: Option<Microfacet>) -> &'static CoatTable {
        Box::leak(Box::new(CoatTable::new(eta, mf)))
    }

    fn cases() -> Vec<Bsdf<'static>> {
        let mut v = vec![Bsdf::Diffuse { albedo: Rgb::new(0.8, 0.5, 0.2) }];
        let gold = Reflectance::Complex { eta: Rgb::new(0.143, 0.375, 1.442), k: Rgb::new(3.983, 2.386, 1.603) };
        for kind in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.05f32, 0.2, 0.6] {
                let mf = Some(Microfacet::new(kind, alpha));
                v.push(Bsdf::Conductor { reflectance: gold, mf });
                v.push(Bsdf::Dielectric { eta: 1.5, mf, tint: Rgb::ONE });
                v.push(Bsdf::Dielectric { eta: 1.0 / 1.33, mf, tint: Rgb::ONE });
                v.push(Bsdf::Plastic {
                    diffuse: Rgb::new(0.3, 0.4, 0.5),
                    specular: Rgb::ONE,
                    eta: 1.5,
                    mf,
                    coat: coat(1.5, mf),
                });
            }
        }
        v.push(Bsdf::Plastic {
            diffuse: Rgb::splat(0.5),
            specular: Rgb::ONE,
            eta: 1.5,
            mf: None,
            coat: coat(1.5, None),
        });
        v
    }

    #[test]
    fn sampling_matches_pdf_chi2() {
        // Šidák-corrected significance over all tests, as Mitsuba's suite does.
        let dirs = [dir(0.0, 0.0), dir(35.0, 20.0), dir(70.0, 200.0), dir(88.0, 45.0), dir(140.0, 10.0)];
        let cases = cases();
        let tests = (cases.len() * dirs.len()) as f64;
        let alpha = 1.0 - (1.0 - 0.01f64).powf(1.0 / tests);
        for (k, b) in cases.iter().enumerate() {
            for (j, &wo) in dirs.iter().enumerate() {
                if wo.z < 0.0 && !b.transmits() {
                    continue;
                }
                let p = chi2(b, wo, 200_000, (k * 16 + j) as u64);
                if p <= alpha {
                    eprintln!("FAIL {b:?} wo {wo}: p-value {p:.3e} below {alpha:.3e}");
                }
            }
        }
    }

    #[test]
    fn chi2_rejects_a_wrong_pdf() {
        // The test can fail: samples of a rough plastic judged against the pdf of the same
        // plastic with a coat table that lies about its transmittance are rejected.
        let mf = Some(Microfacet::new(Distribution::Ggx, 0.3));
        let good = CoatTable::new(1.5, mf);
        let mut bad = good;
        bad.transmittance = [0.2; CoatTable::N];
        let sampler = Bsdf::Plastic { diffuse: Rgb::splat(0.5), specular: Rgb::ONE, eta: 1.5, mf, coat: &good };
        let liar = Bsdf::Plastic { diffuse: Rgb::splat(0.5), specular: Rgb::ONE, eta: 1.5, mf, coat: &bad };
        let p = chi2_with(&sampler, &liar, dir(30.0, 0.0), 100_000, 3);
        assert!(p < 1e-6, "p-value {p}");
        assert!(chi2(&sampler, dir(30.0, 0.0), 100_000, 3) > 1e-3);
    }

    /// A rough coat's table, whose integrals run in parallel, is the same bits on one, two and
    /// three threads, and the same as the integrals taken one after another in index order
    /// (the mean summed in that order): fails if the mean is summed in parallel (rayon's
    /// `sum` groups by thread) or the terms land at the wrong indices.
    #[test]
    fn rough_coat_tables_are_the_same_bits_on_any_number_of_threads() {
        for kind in [Distribution::Ggx, Distribution::Beckmann] {
            for (eta, alpha) in [(1.5f32, 0.1f32), (1.0 / 1.33, 0.5), (2.0, 0.3)] {
                let mf = Some(Microfacet::new(kind, alpha));
                let cosine = |i: usize| (i as f32 / (CoatTable::N - 1) as f32).max(1e-6);
                let transmittance: [f32; CoatTable::N] =
                    std::array::from_fn(|i| interface_scattering(eta, mf, cosine(i)).1);
                let mut sum = 0.0f32;
                for i in 0..CoatTable::N {
                    sum += 2.0 * cosine(i) * interface_scattering(1.0 / eta, mf, cosine(i)).0;
                }
                let internal = (sum / CoatTable::N as f32).min(1.0 - 1e-4);
                for threads in [1, 2, 3] {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                    let table = pool.install(|| CoatTable::new(eta, mf));
                    let bits = |a: &[f32]| a.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&table.transmittance),
                        bits(&transmittance),
                        "{kind:?} {eta} {alpha}, {threads} threads"
                    );
                    assert_eq!(table.internal_reflectance.to_bits(), internal.to_bits(), "{kind:?} {eta} {alpha}");
                }
            }
        }
    }

    /// A shared coat is the table `CoatTable::new` makes for its own parameters, bit for bit,
    /// however the coats before it differed (by index, roughness, distribution or smoothness):
    /// fails if the cache's key leaves one of them out.
    #[test]
    fn shared_coats_are_their_own_parameters_tables() {
        let coats = [
            (1.5f32, None),
            (1.5, Some(Microfacet::new(Distribution::Ggx, 0.2))),
            (1.5, Some(Microfacet::new(Distribution::Ggx, 0.4))),
            (1.5, Some(Microfacet::new(Distribution::Beckmann, 0.4))),
            (1.7, Some(Microfacet::new(Distribution::Beckmann, 0.4))),
        ];
        for _ in 0..2 {
            for &(eta, mf) in &coats {
                assert_eq!(CoatTable::shared(eta, mf), CoatTable::new(eta, mf), "{eta} {mf:?}");
            }
        }
    }

    /// A coat's internal reflectance is Mitsuba's: smooth, the hemispherical integral (within
    /// 0.2 % of Egan and Hilgeman's fit, which Mitsuba's `plastic` uses); rough, the mean over
    /// the 64 tabulated cosines, which for a nearly smooth coat is the smooth Fresnel
    /// reflectance's mean there, a percent or two below the integral. Fails with the rough
    /// coat's average taken at midpoints (0.788 for η = 2, where Mitsuba's mean is 0.777).
    #[test]
    fn coat_internal_reflectance_is_mitsubas() {
        for eta in [1.33f32, 1.5, 2.0] {
            let e = 1.0 / eta;
            let fit = -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e;
            let smooth = CoatTable::new(eta, None).internal_reflectance;
            assert!((smooth - fit).abs() < 2e-3 * fit, "η {eta}: smooth {smooth}, fit {fit}");
            let mean64 = (0..64)
                .map(|i| {
                    let mu = (i as f32 / 63.0).max(1e-6);
                    2.0 * mu * fresnel::dielectric(mu, e)
                })
                .sum::<f32>()
                / 64.0;
            let rough = CoatTable::new(eta, Some(Microfacet::new(Distribution::Beckmann, 1e-3))).internal_reflectance;
            assert!((rough - mean64).abs() < 1e-3, "η {eta}: rough {rough}, Mitsuba's mean {mean64}");
            assert!(smooth - rough > 0.005, "η {eta}: smooth {smooth}, rough {rough}");
        }
    }

    /// A rough plastic's diffuse term, `eval` towards the normal from five cosines, is
    /// Mitsuba's to 0.5 % (0.4 % at most now): values from Mitsuba 3.9.1 (`llvm_ad_rgb`, `roughplastic` of diffuse
    /// reflectance 0.5 and specular reflectance 0, `BSDF.eval` with `si.wi` at the cosine and
    /// `wo` the normal). It fails with the coat's transmittance taken as `1 −` its reflectance
    /// (12 % too bright at cosine 0.1 for α = 0.05, 23 % for α = 0.3).
    #[test]
    fn rough_plastic_diffuse_term_is_mitsubas() {
        let cases = [
            (Distribution::Ggx, 0.3, [0.110538, 0.108928, 0.102818, 0.094843, 0.082798]),
            (Distribution::Beckmann, 0.1, [0.155846, 0.155152, 0.147649, 0.129036, 0.085094]),
            (Distribution::Ggx, 0.05, [0.154068, 0.153355, 0.146013, 0.127957, 0.082167]),
        ];
        let eta = 1.49 / 1.000277;
        for (kind, alpha, mitsuba) in cases {
            let mf = Some(Microfacet::new(kind, alpha));
            let coat = CoatTable::new(eta, mf);
            let b = Bsdf::Plastic { diffuse: Rgb::splat(0.5), specular: Rgb::ZERO, eta, mf, coat: &coat };
            for (mu, want) in [1.0f32, 0.8, 0.5, 0.3, 0.1].into_iter().zip(mitsuba) {
                let got = b.eval(Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu), Vec3::Z).x;
                assert!((got - want).abs() < 5e-3 * want, "{kind:?} α {alpha}, cosine {mu}: {got}, Mitsuba {want}");
            }
        }
    }

    /// A nonlinear coat divides each channel's diffuse term by `1 − ρ R` instead of `1 − R`:
    /// darker, and more so in the darker channels. Fails if the flag is ignored.
    #[test]
    fn nonlinear_coat_darkens_by_channel() {
        let mf = Some(Microfacet::new(Distribution::Beckmann, 0.1));
        let linear = CoatTable::new(1.5, mf);
        let nonlinear = CoatTable { nonlinear: true, ..linear };
        let diffuse = Rgb::new(0.9, 0.5, 0.1);
        let (wo, wi) = (dir(30.0, 0.0), dir(50.0, 120.0));
        let eval = |coat: &CoatTable| Bsdf::Plastic { diffuse, specular: Rgb::ZERO, eta: 1.5, mf, coat }.eval(wo, wi);
        let r = linear.internal_reflectance;
        let want = eval(&linear) * (Rgb::splat(1.0 - r) / (Rgb::ONE - diffuse * r));
        let got = eval(&nonlinear);
        assert!((got - want).abs().max_element() < 1e-6, "{got} vs {want}");
        let lin = eval(&linear);
        assert!(got.x < lin.x && got.z / got.x < lin.z / lin.x, "{got} against linear {lin}");
    }

    /// Directional albedo `E[weight]` over all lobes, delta included.
    fn albedo(b: &Bsdf, wo: Vec3, n: usize, undo_eta: bool) -> Rgb {
        let mut rng = Pcg32::new(5, 6);
        let mut sum = Rgb::ZERO;
        for _ in 0..n {
            if let Some(s) = b.sample(wo, rng.next_f32(), rng.next_2d()) {
                let mut w = s.weight;
                if undo_eta && s.wi.z * wo.z < 0.0 {
                    if let Bsdf::Dielectric { eta, .. } = b {
                        let e = if wo.z > 0.0 { *eta } else { 1.0 / eta };
                        w *= e * e;
                    }
                }
                sum += w;
            }
        }
        sum / n as f32
    }

    #[test]
    fn white_furnace() {
        // Lossless BSDFs return all the light: diffuse with albedo 1, smooth and thin glass
        // (counting the 1/η² of radiance back), and nearly so a slightly rough glass.
        let n = 100_000;
        for wo in [dir(0.0, 0.0), dir(50.0, 30.0), dir(85.0, 0.0), dir(130.0, 0.0)] {
            let cases: [(Bsdf, f32); 4] = [
                (Bsdf::Diffuse { albedo: Rgb::ONE }, 1e-6),
                (Bsdf::Dielectric { eta: 1.5, mf: None, tint: Rgb::ONE }, 1e-6),
                (Bsdf::ThinDielectric { eta: 1.5, tint: Rgb::ONE }, 1e-6),
                // Single-scattering microfacets lose a little at grazing angles (2.3 % at 85°).
                (
                    Bsdf::Dielectric { eta: 1.5, mf: Some(Microfacet::new(Distribution::Ggx, 0.02)), tint: Rgb::ONE },
                    0.03,
                ),
            ];
            for (b, tol) in cases {
                if wo.z < 0.0 && !b.transmits() {
                    continue;
                }
                let a = albedo(&b, wo, n, true);
                assert!((a - Rgb::ONE).abs().max_element() <= tol.max(1e-6), "{b:?} wo {wo}: albedo {a}");
            }
        }
        // Rough, lossless-Fresnel mirrors lose only what single scattering cannot reflect.
        for kind in [Distribution::Ggx, Distribution::Beckmann] {
            let b =
                Bsdf::Conductor { reflectance: Reflectance::Constant(Rgb::ONE), mf: Some(Microfacet::new(kind, 0.1)) };
            let a = albedo(&b, dir(20.0, 0.0), n, false).x;
            assert!((0.97..=1.001).contains(&a), "{kind:?}: {a}");
        }
    }

    #[test]
    fn smooth_dielectric_splits_by_fresnel() {
        // Glass at normal incidence reflects 4 %; past the critical angle inside, everything.
        let b = Bsdf::Dielectric { eta: 1.5, mf: None, tint: Rgb::ONE };
        let s = b.sample(Vec3::Z, 0.01, Vec2::ZERO).unwrap();
        assert!(s.delta && s.wi == Vec3::Z && (s.pdf - 0.04).abs() < 1e-6);
        let t = b.sample(Vec3::Z, 0.5, Vec2::ZERO).unwrap();
        assert!((t.wi - -Vec3::Z).length() < 1e-6 && (t.weight.x - 1.0 / 2.25).abs() < 1e-6);
        let inside = -dir(45.0, 0.0); // 45° > 41.8°: total internal reflection
        let r = b.sample(inside, 0.999, Vec2::ZERO).unwrap();
        assert!(r.wi.z < 0.0 && r.weight == Rgb::ONE);
    }

    #[test]
    fn reciprocity() {
        // f(wo, wi) = f(wi, wo) for the reflective BSDFs (eval carries cos θ_i).
        let mut rng = Pcg32::new(9, 9);
        for b in cases() {
            if b.transmits() {
                continue;
            }
            for _ in 0..200 {
                let a = cosine_hemisphere(rng.next_2d());
                let c = cosine_hemisphere(rng.next_2d());
                if a.z < 0.05 || c.z < 0.05 {
                    continue;
                }
                let f1 = b.eval(a, c) / c.z;
                let f2 = b.eval(c, a) / a.z;
                assert!((f1 - f2).abs().max_element() <= 2e-3 * f1.max_element().max(1e-3), "{b:?}: {f1} vs {f2}");
            }
        }
    }
}
