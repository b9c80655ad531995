//! Lights: point, spot and directional (delta lights, one shadow ray each) and area lights
//! (emissive spheres, quads and meshes, sampled with several shadow rays for soft shadows).

use std::f32::consts::PI;

use glam::{Vec2, Vec3, Vec3A};

use crate::geometry::orthonormal_basis;
use crate::lanes::F64Lanes;
use crate::sampling::{one_minus_cos_asin, sample_cdf, uniform_cone, uniform_triangle};
use crate::shape::{intersect_sphere, Sphere};
use crate::Rgb;

/// A light source.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// Isotropic point light; `intensity` in radiant intensity (W/sr per channel).
    Point { position: Vec3, intensity: Rgb },
    /// Spot light pointing along `direction` (unit): full intensity inside `cos_inner`, a smooth
    /// falloff to zero at `cos_outer` (pbrt-v4's convention).
    Spot { position: Vec3, direction: Vec3, intensity: Rgb, cos_inner: f32, cos_outer: f32 },
    /// Distant light travelling along `direction` (unit), delivering `irradiance` on a surface
    /// facing it.
    Directional { direction: Vec3, irradiance: Rgb },
    /// An emissive object.
    Area(AreaLight),
    /// Light from infinitely far away in every direction: constant, or an image.
    Environment(Environment),
}

/// An environment: radiance `scale` from every direction, times an equirectangular image if
/// there is one. Image convention (Mitsuba's): in the environment's own frame `+y` is up (the
/// top row), and `u = atan2(x, -z) / 2π` runs once around.
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    pub scale: Rgb,
    pub map: Option<EnvMap>,
    /// Environment frame to world (a rotation); its inverse is the transpose.
    pub to_world: glam::Mat3,
}

/// An equirectangular radiance image with its sampling distribution (luminance × sin θ).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    pub width: usize,
    pub height: usize,
    /// Row by row, top (`+y`) first: each pixel's radiance with its cell's density under
    /// `distribution`, in one 16-byte texel, so that a direction's radiance and density come
    /// from one cache line (a lookup in a large map misses the caches: the pixel's load and
    /// the density's were 31 % and 26 % of `eval_pdf_map`'s time, perf).
    texels: Vec<Texel>,
    distribution: Option<crate::sampling::Distribution2D>,
}

/// A pixel's radiance and its cell's density under the map's distribution (0 without one).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(16))]
struct Texel {
    rgb: [f32; 3],
    pdf: f32,
}

impl EnvMap {
    /// An error if the size does not match the pixels or a value is negative or not finite
    /// (see [`check_pixels`](crate::image::check_pixels)).
    pub fn new(width: usize, height: usize, pixels: Vec<Rgb>) -> Result<EnvMap, crate::image::BadPixels> {
        crate::image::check_pixels(width, height, &pixels)?;
        let weights: Vec<f32> = pixels
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let theta = ((i / width) as f32 + 0.5) / height as f32 * PI;
                (p.element_sum() / 3.0) * theta.sin()
            })
            .collect();
        let distribution = crate::sampling::Distribution2D::new(width, height, &weights);
        let texels = pixels
            .iter()
            .enumerate()
            .map(|(i, p)| Texel {
                rgb: p.to_array(),
                pdf: distribution.as_ref().map_or(0.0, |d| d.cell_pdf(i % width, i / width)),
            })
            .collect();
        Ok(EnvMap { width, height, texels, distribution })
    }

    /// The mean radiance over the pixels.
    pub fn mean(&self) -> Rgb {
        self.texels.iter().map(|t| Rgb::from_array(t.rgb)).sum::<Rgb>() / self.texels.len() as f32
    }

    /// The texel at image coordinates `uv` (the nearest pixel): the cell whose density
    /// `Distribution2D::pdf` gives at `uv` (both by [`grid_cell`]).
    ///
    /// [`grid_cell`]: crate::sampling::grid_cell
    #[inline(always)]
    fn texel(&self, uv: Vec2) -> &Texel {
        let (x, y) = crate::sampling::grid_cell(uv, self.width, self.height);
        &self.texels[y * self.width + x]
    }

    fn lookup(&self, uv: Vec2) -> Rgb {
        Rgb::from_array(self.texel(uv).rgb)
    }

    /// Asks for the texel at `uv` to be brought into the caches (a hint, no other effect).
    #[inline(always)]
    fn prefetch(&self, uv: Vec2) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a prefetch is a hint with no memory effect.
        unsafe {
            std::arch::x86_64::_mm_prefetch(
                std::ptr::from_ref(self.texel(uv)).cast::<i8>(),
                std::arch::x86_64::_MM_HINT_T0,
            )
        };
        #[cfg(not(target_arch = "x86_64"))]
        let _ = uv;
    }
}

impl Environment {
    /// Image coordinates of a direction in the environment's frame, of any length: both
    /// angles by [`atan2`], which needs no unit vector (a normalisation and an arc cosine were
    /// two square roots and two divisions on the way to a texel).
    ///
    /// [`atan2`]: crate::sampling::atan2
    fn uv(d: Vec3) -> Vec2 {
        // Multiplied by the reciprocals of 2π and π, not divided: two divisions' latency less
        // on the way to a texel. `a` lies within ±1/2 (to rounding) or is NaN, where `rem_euclid(1.0)`
        // is this, the same bits, without its call to `fmodf`.
        let a = crate::sampling::atan2(d.x, -d.z) * (0.5 * std::f32::consts::FRAC_1_PI);
        let u = if a < 0.0 { a + 1.0 } else { a };
        let v = crate::sampling::atan2((d.x * d.x + d.z * d.z).sqrt(), d.y) * std::f32::consts::FRAC_1_PI;
        Vec2::new(u, v)
    }

    /// The direction in the environment's frame of image coordinates `uv` (the inverse of the
    /// lookup): at `φ = 2π u` around and `θ = π v` down from `+y`, their sines and cosines by
    /// [`cos_sin_turn`] (libm's `sinf`, `sincosf` and `cosf` were three calls a sample).
    ///
    /// [`cos_sin_turn`]: crate::sampling::cos_sin_turn
    pub fn direction(uv: Vec2) -> Vec3 {
        let (cos_p, sin_p) = crate::sampling::cos_sin_turn(uv.x);
        let (cos_t, sin_t) = Self::cos_sin_theta(uv.y);
        Vec3::new(sin_t * sin_p, cos_t, -sin_t * cos_p)
    }

    /// `(cos θ, sin θ)` of image row coordinate `v` (`θ = π v`).
    #[inline(always)]
    fn cos_sin_theta(v: f32) -> (f32, f32) {
        crate::sampling::cos_sin_turn(0.5 * v)
    }

    /// Radiance arriving from world direction `-d`, i.e. seen looking along `d`.
    ///
    /// Inlined, so that a constant environment's radiance reaches the caller in registers (a
    /// 12-byte value returned through memory is read back in other pieces than it was written,
    /// which stalls: ~13 % of a camera sample that misses).
    #[inline(always)]
    pub fn eval(&self, d: Vec3) -> Rgb {
        self.eval_at(d, None)
    }

    /// [`Environment::eval`] with `d`'s image coordinates from [`Environment::lookup_ahead`]
    /// where they were made (`None`: worked out here): the same value.
    #[inline(always)]
    pub fn eval_at(&self, d: Vec3, uv: Option<Vec2>) -> Rgb {
        match &self.map {
            None => self.scale,
            Some(m) => self.scale * self.eval_map(m, d, uv),
        }
    }

    fn eval_map(&self, m: &EnvMap, d: Vec3, uv: Option<Vec2>) -> Rgb {
        m.lookup(uv.unwrap_or_else(|| self.local_uv(d)))
    }

    /// Where world direction `d` looks up the image: its image coordinates (`None` without an
    /// image), with the load of its texel started (a prefetch). A path makes them as its next
    /// segment sets out, so that, should the segment leave the scene, its texel (a cache miss
    /// in a large image) has arrived by the time [`Environment::eval_pdf_at`] reads it.
    #[inline]
    pub fn lookup_ahead(&self, d: Vec3) -> Option<Vec2> {
        let m = self.map.as_ref()?;
        let uv = self.local_uv(d);
        m.prefetch(uv);
        Some(uv)
    }

    /// Image coordinates of world direction `d`.
    #[inline(always)]
    fn local_uv(&self, d: Vec3) -> Vec2 {
        Self::uv(self.to_world.transpose() * d)
    }

    /// [`Environment::eval`] and [`Environment::pdf`] of one direction at once, its image
    /// coordinates (an arc tangent and an arc cosine) worked out once for both: the same values
    /// as each alone. Inlined, as `eval` is, for a constant environment's sake.
    #[inline(always)]
    pub fn eval_pdf(&self, d: Vec3) -> (Rgb, f32) {
        self.eval_pdf_at(d, None)
    }

    /// [`Environment::eval_pdf`] with `d`'s image coordinates from
    /// [`Environment::lookup_ahead`] where they were made: the same values.
    #[inline(always)]
    pub fn eval_pdf_at(&self, d: Vec3, uv: Option<Vec2>) -> (Rgb, f32) {
        match &self.map {
            None => (self.scale, 1.0 / (4.0 * PI)),
            Some(m) => {
                let (radiance, pdf) = self.eval_pdf_map(m, d, uv);
                (radiance.into(), pdf)
            }
        }
    }

    /// [`Environment::eval_pdf`] of a map. The radiance comes back in 16-byte lanes: as an
    /// `Rgb` it was merged with a constant environment's through memory, written in two pieces
    /// and read back in two others (a store-forwarding stall on every path that escapes).
    fn eval_pdf_map(&self, m: &EnvMap, d: Vec3, uv: Option<Vec2>) -> (Vec3A, f32) {
        let uv = uv.unwrap_or_else(|| self.local_uv(d));
        let t = m.texel(uv);
        let pdf = match &m.distribution {
            None => 1.0 / (4.0 * PI),
            Some(_) => Self::pdf_of_cell(t.pdf, uv),
        };
        ((self.scale * Rgb::from_array(t.rgb)).into(), pdf)
    }

    /// Solid-angle density of sampling world direction `d`.
    #[inline(always)]
    pub fn pdf(&self, d: Vec3) -> f32 {
        match self.map.as_ref().filter(|m| m.distribution.is_some()) {
            None => 1.0 / (4.0 * PI),
            Some(m) => self.pdf_map(m, d),
        }
    }

    fn pdf_map(&self, m: &EnvMap, d: Vec3) -> f32 {
        let uv = self.local_uv(d);
        Self::pdf_of_cell(m.texel(uv).pdf, uv)
    }

    /// The solid-angle density of the direction at image coordinates `uv`, whose cell has
    /// density `cell_pdf` in the image's `[0, 1)²`.
    #[inline(always)]
    fn pdf_of_cell(cell_pdf: f32, uv: Vec2) -> f32 {
        let sin = Self::cos_sin_theta(uv.y).1;
        if sin <= 0.0 {
            return 0.0;
        }
        cell_pdf / (2.0 * PI * PI * sin)
    }

    /// [`Environment::sample_facing`] from any side (the tests' sampling).
    #[cfg(test)]
    fn sample(&self, u: Vec2) -> Option<LightSample> {
        self.sample_facing(u, None)
    }

    /// A direction towards the environment for `u` uniform in `[0, 1)²`, by its map where it
    /// has one (uniformly over the sphere otherwise), but `None` for a direction on the other
    /// side of `side`'s plane than the path ([`Light::sample_facing`]), before its radiance and
    /// density are looked up. The sample's point is left at the origin: [`Light::sample`] puts
    /// it at `p + wi` for the shading point `p`.
    fn sample_facing(&self, u: Vec2, side: Option<(Vec3, bool)>) -> Option<LightSample> {
        let (wi, radiance, pdf) = match self.map.as_ref().and_then(|m| m.distribution.as_ref()) {
            None => {
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let (cos_p, sin_p) = crate::sampling::cos_sin_turn(u.y);
                let wi = Vec3::new(r * cos_p, r * sin_p, z);
                (wi, self.eval(wi), 1.0 / (4.0 * PI))
            }
            Some(dist) => {
                let (uv, pdf_uv) = dist.sample(u);
                let sin = Self::cos_sin_theta(uv.y).1;
                if pdf_uv <= 0.0 || sin <= 0.0 {
                    return None;
                }
                let wi = self.to_world * Self::direction(uv);
                if side.is_some_and(|(ng, front)| crosses_side(wi, ng, front)) {
                    return None;
                }
                // The pdf as `pdf` computes it from the direction, so that MIS weights agree
                // exactly (rounding can move a direction on a cell border to its neighbour).
                let (radiance, pdf) = self.eval_pdf(wi);
                (wi, radiance, pdf)
            }
        };
        if pdf <= 0.0 {
            return None;
        }
        let value = radiance / pdf;
        // The point, `p + wi`, is the caller's to fill in.
        Some(LightSample::new(wi, Vec3::ZERO, Vec3::ZERO, true, value, pdf))
    }
}

/// An emissive surface: uniform, one-sided radiance `emission` on the side of its normals.
#[derive(Clone, Debug, PartialEq)]
pub struct AreaLight {
    /// Index of the scene object that emits.
    pub object: u32,
    pub emission: Rgb,
    /// Shadow rays per shading point.
    pub samples: u32,
    pub shape: AreaShape,
}

/// The world-space shape of an area light, prepared for sampling.
#[derive(Clone, Debug, PartialEq)]
pub enum AreaShape {
    Sphere(Sphere),
    /// World-space triangles with the running sum of their areas.
    Triangles {
        tris: Vec<[Vec3; 3]>,
        cdf: Vec<f32>,
    },
    /// A rectangle `corner + s·ex + t·ey` (`ex ⟂ ey`, `s, t ∈ [0, 1]`) emitting towards its unit
    /// `normal`, sampled uniformly in the solid angle it subtends (see [`SphericalRectangle`]).
    Rectangle {
        corner: Vec3,
        ex: Vec3,
        ey: Vec3,
        normal: Vec3,
        /// `|ex|·|ey|`, kept rather than recomputed (two square roots) for every sample.
        area: f32,
    },
}

impl AreaShape {
    /// The rectangle `corner + s·ex + t·ey` emitting towards `normal`, with its area.
    pub fn rectangle(corner: Vec3, ex: Vec3, ey: Vec3, normal: Vec3) -> AreaShape {
        AreaShape::Rectangle { corner, ex, ey, normal, area: ex.length() * ey.length() }
    }
}

/// Below this solid angle (sr) a rectangle is sampled by area: the spherical construction
/// loses its precision to cancellation, and the two densities agree anyway (pbrt-v4's bound).
const MIN_SPHERICAL_RECTANGLE: f64 = 3e-4;

/// Solid-angle sampling of a rectangle costs several times area sampling (four arc cosines
/// and a sine and cosine per sample); it pays only where the rectangle looks large, which is
/// judged by `area / distance²` to its centre, an upper bound of the solid angle (sr) that
/// costs nothing to compute.
const SPHERICAL_RECTANGLE_PAYS: f32 = 0.2;

/// The spherical rectangle of `corner + [0,1]·ex + [0,1]·ey` seen from `p`, if solid-angle
/// sampling pays there (see [`SPHERICAL_RECTANGLE_PAYS`]).
///
/// Inlined, so that the test of whether it pays, which turns most points of a room lit by a
/// small light away, costs no call (as a call it was 45 instructions, most of them the call's
/// own, on each of the Cornell box's light samples); the construction stays a call.
#[inline(always)]
fn spherical_rectangle(p: Vec3, corner: Vec3, ex: Vec3, ey: Vec3, area: f32) -> Option<SphericalRectangle> {
    let centre = corner + 0.5 * (ex + ey);
    if area < SPHERICAL_RECTANGLE_PAYS * (centre - p).length_squared() {
        return None;
    }
    SphericalRectangle::new(p, corner, ex, ey).filter(|r| r.solid_angle >= MIN_SPHERICAL_RECTANGLE)
}

/// A rectangle as seen from a point: Ureña, Fajardo and King, "An Area-Preserving
/// Parametrization for Spherical Rectangles" (EGSR 2013). Built in double precision, as the
/// solid angle is a small difference of angles near 2π.
pub struct SphericalRectangle {
    o: glam::DVec3,
    x: glam::DVec3,
    y: glam::DVec3,
    z: glam::DVec3,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    z0: f64,
    b0: f64,
    b1: f64,
    k: f64,
    /// The solid angle.
    pub solid_angle: f64,
}

impl SphericalRectangle {
    /// (Kept out of line: its four arc cosines dwarf a call, and inlined into the light
    /// sample it would crowd the path tracer's loop.)
    #[inline(never)]
    pub fn new(p: Vec3, corner: Vec3, ex: Vec3, ey: Vec3) -> Option<SphericalRectangle> {
        use glam::DVec3;
        let (exl, eyl) = (ex.length() as f64, ey.length() as f64);
        if !(exl > 0.0 && eyl > 0.0) {
            return None;
        }
        let x = ex.as_dvec3() / exl;
        let y = ey.as_dvec3() / eyl;
        let mut z = x.cross(y);
        let o = p.as_dvec3();
        let d = corner.as_dvec3() - o;
        let (x0, y0, mut z0) = (d.dot(x), d.dot(y), d.dot(z));
        if z0 > 0.0 {
            z = -z;
            z0 = -z0;
        }
        if z0 == 0.0 {
            return None;
        }
        let (x1, y1) = (x0 + exl, y0 + eyl);
        let v00 = DVec3::new(x0, y0, z0);
        let v01 = DVec3::new(x0, y1, z0);
        let v10 = DVec3::new(x1, y0, z0);
        let v11 = DVec3::new(x1, y1, z0);
        let n0 = v00.cross(v10).normalize();
        let n1 = v10.cross(v11).normalize();
        let n2 = v11.cross(v01).normalize();
        let n3 = v01.cross(v00).normalize();
        let angle = |a: DVec3, b: DVec3| (-a.dot(b)).clamp(-1.0, 1.0).acos();
        let (g0, g1, g2, g3) = (angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0));
        let k = 2.0 * std::f64::consts::PI - g2 - g3;
        let solid_angle = g0 + g1 - k;
        if !(solid_angle > 0.0 && solid_angle.is_finite()) {
            return None;
        }
        Some(SphericalRectangle { o, x, y, z, x0, x1, y0, y1, z0, b0: n0.z, b1: n2.z, k, solid_angle })
    }

    /// The point of the rectangle whose direction is the `u`-th in solid angle.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Vec3 {
        let (xu, yv) = self.sample_lanes(u.x as f64, u.y as f64);
        self.point(xu, yv)
    }

    /// [`SphericalRectangle::sample`] for two `u`s at once, the same points bit for bit: the
    /// two chains of double-precision square roots and divisions go side by side in SSE2.
    #[inline]
    pub fn sample_pair(&self, u: [Vec2; 2]) -> [Vec3; 2] {
        #[cfg(target_arch = "x86_64")]
        {
            use crate::lanes::F64x2;
            let (xu, yv) =
                self.sample_lanes(F64x2::new(u[0].x as f64, u[1].x as f64), F64x2::new(u[0].y as f64, u[1].y as f64));
            let ([x0, x1], [y0, y1]) = (xu.lanes(), yv.lanes());
            [self.point(x0, y0), self.point(x1, y1)]
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            u.map(|u| self.sample(u))
        }
    }

    /// The rectangle's coordinates `(x, y)` (in its frame at `o`) of the `(u0, u1)`-th
    /// direction, lane by lane.
    #[inline(always)]
    fn sample_lanes<L: F64Lanes>(&self, u0: L, u1: L) -> (L, L) {
        let k = L::splat;
        let (b0, z0) = (k(self.b0), k(self.z0));
        let au = u0 * k(self.solid_angle) + k(self.k);
        let (sin_au, cos_au) = au.sin_cos();
        let fu = (cos_au * b0 - k(self.b1)) / sin_au;
        let cu = (k(1.0) / (fu * fu + b0 * b0).sqrt()).copysign(fu).clamp(k(-1.0), k(1.0));
        let xu = (-(cu * z0) / (k(1.0) - cu * cu).max_const(1e-300).sqrt()).clamp(k(self.x0), k(self.x1));
        let d = (xu * xu + z0 * z0).sqrt();
        let (y0, y1) = (k(self.y0), k(self.y1));
        let h0 = y0 / (d * d + y0 * y0).sqrt();
        let h1 = y1 / (d * d + y1 * y1).sqrt();
        let hv = h0 + u1 * (h1 - h0);
        let hv2 = hv * hv;
        let yv = hv2.lt_select(1.0 - 1e-12, (hv * d / (k(1.0) - hv2).sqrt()).clamp(y0, y1), y1);
        (xu, yv)
    }

    /// The world-space point at the rectangle's coordinates `(xu, yv)`.
    #[inline(always)]
    fn point(&self, xu: f64, yv: f64) -> Vec3 {
        (self.o + self.x * xu + self.y * yv + self.z * self.z0).as_vec3()
    }
}

/// Light arriving at a shading point from one light sample.
///
/// The vectors are kept in 16-byte lanes. A sample is built in one of several arms and read
/// by the integrator after they join, so it passes through memory: as 12-byte vectors the arms
/// stored them in pieces (8 + 4 bytes) that the integrator's loads did not match (4 + 8), and
/// each such load waited for the stores to retire (a store-forwarding stall) at every light
/// sample. Whole 16-byte stores and loads forward.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point towards the light.
    pub wi: Vec3A,
    /// Point on the light (for the shadow ray); meaningless for directional lights.
    pub p: Vec3A,
    /// Surface normal at `p` (zero for point and spot lights).
    pub n: Vec3A,
    /// Whether the light is at infinity (shadow ray without end point).
    pub infinite: bool,
    /// Incident radiance divided by the sampling pdf (solid angle), so that
    /// `f · cos · value` estimates the reflected radiance.
    pub value: Vec3A,
    /// The solid-angle pdf of `wi` (0 for point, spot and directional lights: delta lights,
    /// which no BSDF sample can hit).
    pub pdf: f32,
}

impl LightSample {
    #[inline(always)]
    fn new(wi: Vec3, p: Vec3, n: Vec3, infinite: bool, value: Rgb, pdf: f32) -> LightSample {
        LightSample { wi: wi.into(), p: p.into(), n: n.into(), infinite, value: value.into(), pdf }
    }
}

impl Light {
    /// How many shadow rays this light gets per shading point.
    pub fn samples(&self) -> u32 {
        match self {
            Light::Area(a) => a.samples.max(1),
            _ => 1,
        }
    }

    /// Samples light arriving at `p`; `u` is uniform in `[0, 1)²`.
    ///
    /// Inlined (with the area light's own), so that `p` and the sample stay in registers: the
    /// caller's point, stored in two pieces and read back whole, stalled (Cornell box 3 %).
    #[inline(always)]
    pub fn sample(&self, p: Vec3, u: Vec2) -> Option<LightSample> {
        self.sample_facing(p, u, None)
    }

    /// [`Light::sample`] for a surface that reflects only (light from the other side of its
    /// geometric normal `ng` than the path, which arrives from its front where `front`, brings
    /// it nothing): where `side` is given, an environment drops a direction on the other side
    /// before it looks up the direction's radiance and density (about half of a surface's
    /// samples of an image's bright parts; under an HDR image those lookups are most of a
    /// light sample's cost). The samples it keeps are [`Light::sample`]'s, bit for bit; the
    /// other lights ignore `side`.
    #[inline(always)]
    pub fn sample_facing(&self, p: Vec3, u: Vec2, side: Option<(Vec3, bool)>) -> Option<LightSample> {
        match self {
            Light::Point { position, intensity } => {
                let d = *position - p;
                let d2 = d.length_squared();
                (d2 > 0.0).then(|| LightSample::new(d / d2.sqrt(), *position, Vec3::ZERO, false, *intensity / d2, 0.0))
            }
            Light::Spot { position, direction, intensity, cos_inner, cos_outer } => {
                let d = *position - p;
                let d2 = d.length_squared();
                if d2 <= 0.0 {
                    return None;
                }
                let wi = d / d2.sqrt();
                let cos = (-wi).dot(*direction);
                let falloff = smoothstep(*cos_outer, *cos_inner, cos);
                (falloff > 0.0)
                    .then(|| LightSample::new(wi, *position, Vec3::ZERO, false, *intensity * (falloff / d2), 0.0))
            }
            Light::Directional { direction, irradiance } => {
                Some(LightSample::new(-*direction, p - *direction, Vec3::ZERO, true, *irradiance, 0.0))
            }
            Light::Area(a) => a.sample(p, u),
            // The environment's sample without `p`: given it, the out-of-line call took the
            // point's address, which kept it in memory for every light, stored in two pieces
            // and read back in others (a store-forwarding stall on every light sample).
            Light::Environment(e) => {
                e.sample_facing(u, side).map(|s| LightSample { p: (p + Vec3::from(s.wi)).into(), ..s })
            }
        }
    }
}

/// Whether direction `wi` lies on the other side of the plane with normal `ng` than a path
/// arriving from its front (`front`) or back: `wi · ng` of the other sign, as the path tracer
/// tells a light sample's side (a NaN product is on neither side).
#[inline(always)]
fn crosses_side(wi: Vec3, ng: Vec3, front: bool) -> bool {
    let c = wi.dot(ng);
    if front {
        c <= 0.0
    } else {
        c > 0.0
    }
}

impl Light {
    /// The solid-angle density with which [`Light::sample`] at `p` picks the direction
    /// towards `q`, a point on this area light with unit normal `nq` (0 for delta lights; an
    /// environment's density is [`Environment::pdf`] of the direction).
    pub fn pdf(&self, p: Vec3, q: Vec3, nq: Vec3) -> f32 {
        let Light::Area(a) = self else { return 0.0 };
        match &a.shape {
            AreaShape::Sphere(s) => {
                sphere_cone(s, p).map_or(0.0, |(_, _, one_minus_cos_max)| 1.0 / (2.0 * PI * one_minus_cos_max))
            }
            AreaShape::Rectangle { corner, ex, ey, normal, area } => {
                let d = q - p;
                let dist2 = d.length_squared();
                let cos_l = -normal.dot(d) / dist2.sqrt();
                if (p - *corner).dot(*normal) <= 0.0 || cos_l.is_nan() || cos_l <= 0.0 {
                    return 0.0;
                }
                let area = *area;
                match spherical_rectangle(p, *corner, *ex, *ey, area) {
                    Some(r) => (1.0 / r.solid_angle) as f32,
                    None => dist2 / (cos_l * area),
                }
            }
            AreaShape::Triangles { cdf, .. } => {
                let total = *cdf.last().unwrap_or(&0.0);
                let d = q - p;
                let dist2 = d.length_squared();
                let cos_l = -nq.dot(d) / dist2.sqrt();
                if total <= 0.0 || cos_l <= 0.0 {
                    return 0.0;
                }
                dist2 / (cos_l * total)
            }
        }
    }

    /// Emitted power (mean over the channels), for choosing lights in proportion to it.
    /// `scene_radius` bounds the scene, for directional lights.
    pub fn power(&self, scene_radius: f32) -> f32 {
        let mean = |c: &Rgb| c.element_sum() / 3.0;
        match self {
            Light::Point { intensity, .. } => 4.0 * PI * mean(intensity),
            Light::Spot { intensity, cos_inner, cos_outer, .. } => {
                2.0 * PI * mean(intensity) * (1.0 - 0.5 * (cos_inner + cos_outer))
            }
            Light::Directional { irradiance, .. } => PI * scene_radius * scene_radius * mean(irradiance),
            Light::Area(a) => PI * a.area() * mean(&a.emission),
            Light::Environment(e) => {
                let m = e.map.as_ref().map_or(Rgb::ONE, EnvMap::mean);
                PI * scene_radius * scene_radius * mean(&(e.scale * m))
            }
        }
    }
}

fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    if a == b {
        return if x >= a { 1.0 } else { 0.0 };
    }
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The cone of directions sphere `s` subtends from `p`: the vector to its centre, that
/// vector's squared length, and `1 − cos θmax` (by [`one_minus_cos_asin`], at least the
/// smallest normal float). `None` from inside or on the sphere, which cannot light `p` from
/// outside. What [`AreaLight::sample`] samples and [`Light::pdf`] gives the density of.
#[inline(always)]
fn sphere_cone(s: &Sphere, p: Vec3) -> Option<(Vec3, f32, f32)> {
    let to_c = s.center - p;
    let d2 = to_c.length_squared();
    let r2 = s.radius * s.radius;
    if d2 <= r2 * 1.0001 {
        return None; // (A NaN distance goes on, as it did.)
    }
    Some((to_c, d2, one_minus_cos_asin(r2 / d2).max(f32::MIN_POSITIVE)))
}

impl AreaLight {
    /// Total emitting area (world space).
    pub fn area(&self) -> f32 {
        match &self.shape {
            AreaShape::Sphere(s) => 4.0 * PI * s.radius * s.radius,
            AreaShape::Triangles { cdf, .. } => *cdf.last().unwrap_or(&0.0),
            AreaShape::Rectangle { area, .. } => *area,
        }
    }

    #[inline(always)]
    fn sample(&self, p: Vec3, u: Vec2) -> Option<LightSample> {
        match &self.shape {
            AreaShape::Sphere(s) => {
                let (to_c, d2, one_minus_cos_max) = sphere_cone(s, p)?;
                // Uniform over the cone of directions the sphere subtends (solid-angle sampling).
                let d = d2.sqrt();
                let axis = to_c / d;
                let local = uniform_cone(u, one_minus_cos_max);
                let (s1, s2) = orthonormal_basis(axis);
                let wi = (s1 * local.x + s2 * local.y + axis * local.z).normalize();
                let t = intersect_sphere(s, p, wi, f32::INFINITY).unwrap_or(d * local.z);
                let q = p + wi * t;
                let n = (q - s.center).normalize();
                let pdf = 1.0 / (2.0 * PI * one_minus_cos_max);
                Some(LightSample::new(wi, q, n, false, self.emission / pdf, pdf))
            }
            AreaShape::Rectangle { corner, ex, ey, normal, area } => {
                if (p - *corner).dot(*normal) <= 0.0 {
                    return None; // Behind a one-sided emitter.
                }
                self.rectangle_sample(p, u, spherical_rectangle(p, *corner, *ex, *ey, *area).as_ref())
            }
            AreaShape::Triangles { tris, cdf } => {
                let total = *cdf.last()?;
                if total <= 0.0 {
                    return None;
                }
                let (i, ux) = sample_cdf(cdf, u.x);
                let [a, b, c] = tris[i];
                let (b1, b2) = uniform_triangle(Vec2::new(ux, u.y));
                let q = a * (1.0 - b1 - b2) + b * b1 + c * b2;
                let n = (b - a).cross(c - a).normalize_or_zero();
                self.area_sample(p, q, n, total)
            }
        }
    }
}

impl AreaLight {
    /// A sample of a rectangle light seen from `p` (in front of it): uniform in the solid angle
    /// of its spherical rectangle `r` where that pays, by area otherwise.
    #[inline(always)]
    fn rectangle_sample(&self, p: Vec3, u: Vec2, r: Option<&SphericalRectangle>) -> Option<LightSample> {
        let AreaShape::Rectangle { corner, ex, ey, normal, area } = &self.shape else { return None };
        match r {
            Some(r) => self.spherical_sample(p, r.sample(u), r),
            None => self.area_sample(p, *corner + *ex * u.x + *ey * u.y, *normal, *area),
        }
    }

    /// The sample of this light's point `q` (normal `n`, emitting towards it), drawn uniformly
    /// over its `area`, seen from `p`: the area density 1/A converted to solid angle,
    /// dist² / (cos_l · A). `None` on the emitter's back or at `p` itself (and for a zero `n`).
    /// Written with cos_l · dist (`cos_d`) so that the side test waits for no square root, and
    /// the density and the value (emission over density) divide side by side rather than one
    /// after the other behind the direction's division: a sample's chain of a square root and
    /// three divisions was 4.5 % of the Cornell box's time on an AMD EPYC Zen 1.
    #[inline(always)]
    fn area_sample(&self, p: Vec3, q: Vec3, n: Vec3, area: f32) -> Option<LightSample> {
        let d = q - p;
        let dist2 = d.length_squared();
        let cos_d = -n.dot(d);
        if !(cos_d > 0.0 && dist2 > 0.0) {
            return None; // Back of a one-sided emitter (or p on it).
        }
        let dist = dist2.sqrt();
        // With cos_l = cos_d / dist, the density dist² / (cos_l · A) is dist³ / (cos_d · A).
        let (seen, cube) = (cos_d * area, dist2 * dist);
        Some(LightSample::new(d / dist, q, n, false, self.emission * (seen / cube), cube / seen))
    }

    /// The sample of this rectangle light whose point `q` was drawn from its spherical
    /// rectangle `r` seen from `p`.
    #[inline(always)]
    fn spherical_sample(&self, p: Vec3, q: Vec3, r: &SphericalRectangle) -> Option<LightSample> {
        let AreaShape::Rectangle { normal, .. } = &self.shape else { return None };
        let wi = (q - p).normalize_or_zero();
        if wi == Vec3::ZERO {
            return None;
        }
        let pdf = (1.0 / r.solid_angle) as f32;
        Some(LightSample::new(wi, q, *normal, false, self.emission / pdf, pdf))
    }
}

/// A light made ready for several samples from one point `p`: what [`Light::sample`] works out
/// anew for every sample but does not depend on it (a rectangle's spherical rectangle, four
/// arc cosines in double precision) is worked out once. Its samples are those of
/// [`Light::sample`] at `p`, bit for bit.
pub struct LightFrom<'a> {
    light: &'a Light,
    p: Vec3,
    /// A rectangle light's spherical rectangle from `p`, where solid-angle sampling pays.
    rectangle: Option<SphericalRectangle>,
    /// A one-sided emitter that `p` is behind: no sample.
    behind: bool,
}

impl Light {
    /// This light made ready for samples from `p` (see [`LightFrom`]).
    #[inline]
    pub fn from_point(&self, p: Vec3) -> LightFrom<'_> {
        let (mut rectangle, mut behind) = (None, false);
        if let Light::Area(AreaLight { shape: AreaShape::Rectangle { corner, ex, ey, normal, area }, .. }) = self {
            behind = (p - *corner).dot(*normal) <= 0.0;
            if !behind {
                rectangle = spherical_rectangle(p, *corner, *ex, *ey, *area);
            }
        }
        LightFrom { light: self, p, rectangle, behind }
    }
}

impl LightFrom<'_> {
    /// [`Light::sample`] at the point this was made for; `u` is uniform in `[0, 1)²`. Inlined,
    /// as `Light::sample` is, so that the sample reaches the caller in registers.
    #[inline(always)]
    pub fn sample(&self, u: Vec2) -> Option<LightSample> {
        match self.light {
            Light::Area(a @ AreaLight { shape: AreaShape::Rectangle { .. }, .. }) => {
                if self.behind {
                    return None;
                }
                a.rectangle_sample(self.p, u, self.rectangle.as_ref())
            }
            light => light.sample(self.p, u),
        }
    }

    /// Two samples, those of [`LightFrom::sample`] for `u[0]` and `u[1]`, bit for bit. A
    /// spherical rectangle draws both at once ([`SphericalRectangle::sample_pair`]).
    #[inline(always)]
    pub fn sample_pair(&self, u: [Vec2; 2]) -> [Option<LightSample>; 2] {
        match (self.light, &self.rectangle) {
            (Light::Area(a), Some(r)) => r.sample_pair(u).map(|q| a.spherical_sample(self.p, q, r)),
            _ => [self.sample(u[0]), self.sample(u[1])],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    /// Irradiance at the origin (normal +z) from a light, by Monte Carlo over its samples.
    fn irradiance(l: &Light, n: usize) -> f32 {
        let mut rng = Pcg32::new(3, 4);
        let mut e = 0.0f64;
        for _ in 0..n {
            if let Some(s) = l.sample(Vec3::ZERO, rng.next_2d()) {
                e += (s.value.x * s.wi.z.max(0.0)) as f64;
            }
        }
        (e / n as f64) as f32
    }

    #[test]
    fn sphere_light_irradiance_matches_analytic() {
        // A sphere of radiance L straight above: E = π L sin²α, sin α = r / d.
        let (r, d) = (0.5f32, 2.0f32);
        let l = Light::Area(AreaLight {
            object: 0,
            emission: Rgb::ONE,
            samples: 1,
            shape: AreaShape::Sphere(Sphere { center: Vec3::new(0.0, 0.0, d), radius: r }),
        });
        let e = irradiance(&l, 200_000);
        let exact = PI * (r / d).powi(2);
        assert!((e - exact).abs() < 0.01 * exact, "{e} vs {exact}");
    }

    /// Small and distant spheres (the sun from the earth is r / d = 0.005) keep their irradiance,
    /// their density and their sample points: the cone's size is worked out without the
    /// cancellation of `1 − cos θmax`. With `1 − sqrt(1 − r²/d²)`, r / d = 0.001 is 7 % off
    /// and 10⁻⁴ rounds to a cone of nothing.
    #[test]
    fn small_distant_sphere_lights_keep_their_irradiance() {
        for rd in [0.005f32, 1e-3, 1e-4, 1e-5] {
            let (r, d) = (rd * 1000.0, 1000.0f32);
            let center = Vec3::new(0.0, 0.0, d);
            let l = Light::Area(AreaLight {
                object: 0,
                emission: Rgb::ONE,
                samples: 1,
                shape: AreaShape::Sphere(Sphere { center, radius: r }),
            });
            let e = irradiance(&l, 10_000) as f64;
            let exact = std::f64::consts::PI * (rd as f64).powi(2);
            assert!((e - exact).abs() < 1e-4 * exact, "r/d {rd}: {e} vs {exact}");
            let s = l.sample(Vec3::ZERO, Vec2::new(0.7, 0.2)).unwrap();
            let want_pdf = 1.0 / (2.0 * std::f64::consts::PI * (1.0 - (1.0 - (rd as f64).powi(2)).sqrt()));
            assert!((s.pdf as f64 - want_pdf).abs() < 1e-4 * want_pdf, "r/d {rd}: pdf {} vs {want_pdf}", s.pdf);
            assert_eq!(l.pdf(Vec3::ZERO, s.p.into(), s.n.into()), s.pdf);
            assert!(((Vec3::from(s.p) - center).length() - r).abs() < 1e-3 * r, "r/d {rd}: {} off the sphere", s.p);
        }
    }

    #[test]
    fn quad_light_irradiance_matches_analytic() {
        // A small square of side s at height h facing down: E ≈ L·A·h²/d⁴ summed; compare with
        // the exact form factor of a square centred above (Howell's catalogue, configuration
        // B-? equivalent): E = L · 4 · (x / sqrt(1+x²)) atan(x / sqrt(1+x²)) / 2 with x = s/(2h)…
        // Instead of a closed form, use the far-field limit L·A/h² for a tiny square.
        let h = 10.0f32;
        let s = 0.1f32;
        let c = Vec3::new(-s / 2.0, -s / 2.0, h);
        let tris = vec![[c, c + Vec3::Y * s, c + Vec3::new(s, s, 0.0)], [c, c + Vec3::new(s, s, 0.0), c + Vec3::X * s]];
        let cdf = crate::sampling::build_cdf(tris.iter().map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()));
        let l = Light::Area(AreaLight {
            object: 0,
            emission: Rgb::ONE,
            samples: 1,
            shape: AreaShape::Triangles { tris, cdf },
        });
        let e = irradiance(&l, 10_000);
        let exact = s * s / (h * h);
        assert!((e - exact).abs() < 1e-3 * exact, "{e} vs {exact}");
    }

    fn rectangle(corner: Vec3, ex: Vec3, ey: Vec3) -> Light {
        let normal = ex.cross(ey).normalize();
        Light::Area(AreaLight {
            object: 0,
            emission: Rgb::ONE,
            samples: 1,
            shape: AreaShape::rectangle(corner, ex, ey, normal),
        })
    }

    /// Form factor from a point to a parallel `a × b` rectangle with a corner straight above at
    /// height `h` (Howell's catalogue, B-3).
    fn corner_form_factor(a: f64, b: f64, h: f64) -> f64 {
        let (x, y) = (a / h, b / h);
        let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
        (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
    }

    #[test]
    fn rectangle_light_by_solid_angle_matches_the_form_factor() {
        // A 4 × 2 rectangle at height 1, facing down, with the origin below one corner: close
        // and large, where solid-angle sampling pays.
        let l = rectangle(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 2.0, 0.0), Vec3::new(4.0, 0.0, 0.0));
        let exact = PI as f64 * corner_form_factor(4.0, 2.0, 1.0);
        let e = irradiance(&l, 100_000) as f64;
        assert!((e - exact).abs() < 0.01 * exact, "{e} vs {exact}");
        // Every sample lies on the rectangle, and pdf() agrees with the sample's density.
        let mut rng = Pcg32::new(5, 6);
        for _ in 0..1000 {
            let s = l.sample(Vec3::ZERO, rng.next_2d()).unwrap();
            assert!(
                s.p.x >= -1e-4 && s.p.x <= 4.0001 && s.p.y >= -1e-4 && s.p.y <= 2.0001 && (s.p.z - 1.0).abs() < 1e-5
            );
            let pdf = l.pdf(Vec3::ZERO, s.p.into(), s.n.into());
            assert!((pdf - s.pdf).abs() < 1e-5 * s.pdf, "{pdf} vs {}", s.pdf);
            let solid_angle = 1.0 / s.pdf as f64;
            assert!(solid_angle > 0.0 && solid_angle < 2.0 * std::f64::consts::PI);
        }
        // From behind: nothing, with density 0.
        let behind = Vec3::new(1.0, 1.0, 2.0);
        assert!(l.sample(behind, Vec2::splat(0.5)).is_none());
        assert_eq!(l.pdf(behind, Vec3::new(1.0, 1.0, 1.0), -Vec3::Z), 0.0);
        // Where it looks small (area / distance² below 0.2), sampled by area: the density is
        // distance² / (cos · area).
        let small = rectangle(Vec3::new(-0.5, -0.5, 3.0), Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 0.0, 0.0));
        let s = small.sample(Vec3::ZERO, Vec2::new(0.3, 0.8)).unwrap();
        let area_pdf = s.p.length_squared() / (s.wi.z * 1.0);
        assert!((s.pdf - area_pdf).abs() < 1e-5 * area_pdf, "{} vs {area_pdf}", s.pdf);
        assert!((small.pdf(Vec3::ZERO, s.p.into(), s.n.into()) - area_pdf).abs() < 1e-5 * area_pdf);
        // The value (emission over density) and the density are divided apart: they agree.
        let product = s.value * s.pdf;
        assert!((product - glam::Vec3A::ONE).abs().max_element() < 1e-5, "{product}");
        // Far away, where the solid angle is tiny, it falls back to area sampling (same answer).
        let far = rectangle(Vec3::new(-0.05, -0.05, 20.0), Vec3::new(0.0, 0.1, 0.0), Vec3::new(0.1, 0.0, 0.0));
        let e = irradiance(&far, 10_000);
        assert!((e - 0.01 / 400.0).abs() < 1e-3 * 0.01 / 400.0, "{e}");
    }

    /// `sample_facing` keeps `sample`'s samples bit for bit and drops, from an image, exactly
    /// those on the other side of the given plane than the path; without a side, or from a
    /// constant environment, it drops nothing. It fails if the drop looks at the wrong side
    /// (`c > 0.0` for a path from the front) or drops a sample `sample` keeps.
    #[test]
    fn facing_samples_are_the_samples_from_the_paths_side() {
        let mut rng = Pcg32::new(31, 32);
        let p = Vec3::new(0.3, -1.0, 2.0);
        for (e, image) in [(env(None), false), (env(Some(test_map())), true)] {
            let light = Light::Environment(e);
            let mut dropped = 0;
            for _ in 0..20_000 {
                let u = rng.next_2d();
                let ng = Environment::direction(rng.next_2d());
                let front = rng.next_f32() < 0.5;
                let all = light.sample(p, u);
                assert_eq!(bits(light.sample_facing(p, u, None)), bits(all));
                let facing = light.sample_facing(p, u, Some((ng, front)));
                // The other side: `wi · ng` positive for a path from the back, not for one
                // from the front.
                let other = |s: &LightSample| (Vec3::from(s.wi).dot(ng) > 0.0) != front;
                match (&all, &facing) {
                    (Some(a), None) => {
                        assert!(image && other(a), "dropped from the path's side");
                        dropped += 1;
                    }
                    (Some(a), Some(_)) => {
                        assert!(!image || !other(a), "kept from the other side");
                        assert_eq!(bits(facing), bits(all));
                    }
                    (None, f) => assert!(f.is_none()),
                }
            }
            assert_eq!(dropped > 5_000, image, "{dropped} dropped");
        }
    }

    /// Samples as a comparable tuple of bits (`LightSample` has no `PartialEq`).
    fn bits(s: Option<LightSample>) -> Option<[u32; 14]> {
        s.map(|s| {
            let v = |a: glam::Vec3A| a.to_array().map(f32::to_bits);
            let [a, b, c, d] = [v(s.wi), v(s.p), v(s.n), v(s.value)];
            [a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], d[0], d[1], d[2], s.pdf.to_bits(), s.infinite as u32]
        })
    }

    #[test]
    fn a_light_made_ready_at_a_point_samples_as_the_light_does() {
        // Rectangles seen large (solid-angle samples), small (area samples) and from behind,
        // and every other kind of light, from points around them: `from_point(p).sample(u)`
        // must be `sample(p, u)` bit for bit.
        let lights = [
            rectangle(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 2.0, 0.0), Vec3::new(4.0, 0.0, 0.0)),
            rectangle(Vec3::new(-0.5, -0.5, 3.0), Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 0.0, 0.0)),
            Light::Area(AreaLight {
                object: 0,
                emission: Rgb::ONE,
                samples: 4,
                shape: AreaShape::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 2.0), radius: 0.5 }),
            }),
            Light::Point { position: Vec3::new(1.0, 2.0, 3.0), intensity: Rgb::splat(2.0) },
            Light::Directional { direction: -Vec3::Z, irradiance: Rgb::ONE },
            Light::Environment(env(Some(test_map()))),
        ];
        let points = [Vec3::ZERO, Vec3::new(1.0, 1.0, 2.0), Vec3::new(0.3, -0.2, 0.9), Vec3::new(5.0, 0.0, -1.0)];
        let mut rng = Pcg32::new(9, 10);
        let (mut some, mut spherical) = (0, 0);
        for light in &lights {
            for &p in &points {
                let from = light.from_point(p);
                spherical += from.rectangle.is_some() as u32;
                for _ in 0..64 {
                    let u = rng.next_2d();
                    let (a, b) = (bits(light.sample(p, u)), bits(from.sample(u)));
                    assert_eq!(a, b, "light {light:?} from {p}, u {u}");
                    some += a.is_some() as u32;
                }
            }
        }
        // Both regimes of the rectangle and lights that do give samples were exercised.
        assert!(spherical >= 2 && some > 1000, "{spherical} spherical rectangles, {some} samples");
    }

    #[test]
    fn spherical_rectangle_pairs_are_its_single_samples() {
        // Points near and far, on either side, in front of rectangles large and small (some
        // seen at a grazing angle), and u at the edges of the square: two at a time, the same
        // points bit for bit, and the same light samples through `LightFrom`.
        let mut rng = Pcg32::new(11, 12);
        let mut pairs = 0;
        for case in 0..400 {
            let v = |rng: &mut Pcg32, s: f32| (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * s;
            let (corner, ex) = (v(&mut rng, 4.0), v(&mut rng, 3.0));
            let ey = ex.cross(v(&mut rng, 1.0)).normalize_or_zero() * (0.01 + 2.0 * rng.next_f32());
            let p = corner + v(&mut rng, if case % 4 == 0 { 40.0 } else { 3.0 });
            let normal = ex.cross(ey).normalize_or_zero();
            let Some(r) = SphericalRectangle::new(p, corner, ex, ey) else { continue };
            let edges = [0.0, 1.0 - f32::EPSILON / 2.0, 0.5];
            for i in 0..16 {
                let u = |rng: &mut Pcg32, j: usize| {
                    if i < 9 {
                        Vec2::new(edges[(i + j) % 3], edges[(i / 3 + j) % 3])
                    } else {
                        rng.next_2d()
                    }
                };
                let us = [u(&mut rng, 0), u(&mut rng, 1)];
                let got = r.sample_pair(us);
                for k in 0..2 {
                    assert_eq!(got[k].to_array().map(f32::to_bits), r.sample(us[k]).to_array().map(f32::to_bits));
                }
                let light = Light::Area(AreaLight {
                    object: 0,
                    emission: Rgb::ONE,
                    samples: 2,
                    shape: AreaShape::rectangle(corner, ex, ey, normal),
                });
                let from = light.from_point(p);
                let two = from.sample_pair(us);
                for k in 0..2 {
                    let one = from.sample(us[k]);
                    assert_eq!(two[k].is_some(), one.is_some());
                    if let (Some(a), Some(b)) = (two[k], one) {
                        assert_eq!((a.wi, a.p, a.value, a.pdf.to_bits()), (b.wi, b.p, b.value, b.pdf.to_bits()));
                    }
                }
                pairs += from.rectangle.is_some() as usize;
            }
        }
        assert!(pairs > 1000, "{pairs} pairs drawn from spherical rectangles");
    }

    #[test]
    fn spherical_rectangle_samples_are_uniform_in_solid_angle() {
        // The fraction of samples landing in the rectangle's left half equals that half's
        // share of the solid angle.
        let (p, corner) = (Vec3::new(0.3, -0.2, 0.0), Vec3::new(-1.0, -1.0, 0.8));
        let (ex, ey) = (Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0));
        let full = SphericalRectangle::new(p, corner, ex, ey).unwrap();
        let left = SphericalRectangle::new(p, corner, ex * 0.5, ey).unwrap();
        let mut rng = Pcg32::new(7, 8);
        let n = 200_000;
        let hits = (0..n).filter(|_| full.sample(rng.next_2d()).x < 0.0).count();
        let share = left.solid_angle / full.solid_angle;
        assert!((hits as f64 / n as f64 - share).abs() < 0.005, "{} vs {share}", hits as f64 / n as f64);
    }

    #[test]
    fn one_sided_emitter_is_dark_from_behind() {
        let c = Vec3::new(-0.5, -0.5, 1.0);
        // Facing +z (away from the origin).
        let tris = vec![[c, c + Vec3::X, c + Vec3::new(1.0, 1.0, 0.0)]];
        let cdf = vec![0.5];
        let l = Light::Area(AreaLight {
            object: 0,
            emission: Rgb::ONE,
            samples: 1,
            shape: AreaShape::Triangles { tris, cdf },
        });
        assert_eq!(irradiance(&l, 100), 0.0);
    }

    fn env(map: Option<EnvMap>) -> Environment {
        Environment { scale: Rgb::ONE, map, to_world: glam::Mat3::from_rotation_y(0.7) }
    }

    /// A small image with a bright spot, a dark band and a colour gradient.
    fn test_map() -> EnvMap {
        let (w, h) = (16, 8);
        let pixels = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let base = Rgb::new(0.2 + x as f32 / w as f32, 0.3, 0.1 + y as f32 / h as f32);
                if (x, y) == (5, 2) {
                    base * 200.0
                } else if y == 6 {
                    Rgb::ZERO
                } else {
                    base
                }
            })
            .collect();
        EnvMap::new(w, h, pixels).unwrap()
    }

    #[test]
    fn environment_pdf_integrates_to_one_and_matches_sampling() {
        for e in [env(None), env(Some(test_map()))] {
            // ∫ pdf dω = 1 by quadrature.
            let (nt, np) = (400, 800);
            let mut sum = 0.0f64;
            for i in 0..nt {
                for j in 0..np {
                    let th = (i as f32 + 0.5) / nt as f32 * PI;
                    let ph = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                    let d = Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
                    sum += (e.pdf(d) * th.sin() * (PI / nt as f32) * (2.0 * PI / np as f32)) as f64;
                }
            }
            assert!((sum - 1.0).abs() < 2e-3, "∫ pdf = {sum}");
            // Each sample's pdf is the pdf of its direction, and value = L / pdf; the estimate of
            // ∫ L dω from samples matches the quadrature.
            let mut rng = Pcg32::new(8, 8);
            let n = 100_000;
            let mut est = Rgb::ZERO;
            for _ in 0..n {
                // `None` only where a direction rounds into a black cell (measure zero).
                let Some(s) = e.sample(rng.next_2d()) else { continue };
                assert!((s.pdf - e.pdf(s.wi.into())).abs() <= 1e-3 * s.pdf, "{} vs {}", s.pdf, e.pdf(s.wi.into()));
                assert!(s.infinite && (s.wi.length() - 1.0).abs() < 1e-5);
                est += Vec3::from(s.value) / n as f32;
            }
            let mut exact = Rgb::ZERO;
            for i in 0..nt {
                for j in 0..np {
                    let th = (i as f32 + 0.5) / nt as f32 * PI;
                    let ph = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                    let d = Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
                    exact += e.eval(d) * (th.sin() * (PI / nt as f32) * (2.0 * PI / np as f32));
                }
            }
            assert!((est - exact).abs().max_element() < 0.01 * exact.max_element(), "{est} vs {exact}");
        }
    }

    #[test]
    fn environment_radiance_and_density_together_are_each_alone() {
        // `eval_pdf` is `(eval, pdf)` bit for bit, for a constant environment, a rotated image
        // and an image whose distribution is missing (all black), over directions that are
        // not unit too; so are `eval_pdf_at` and `eval_at` given `lookup_ahead`'s coordinates.
        let black = EnvMap::new(2, 2, vec![Rgb::ZERO; 4]).unwrap();
        assert!(black.distribution.is_none());
        let mut rng = Pcg32::new(11, 12);
        for e in [env(None), env(Some(test_map())), env(Some(black))] {
            for _ in 0..2000 {
                let u = rng.next_2d();
                let d = Environment::direction(u) * (0.5 + 2.0 * rng.next_f32());
                let (radiance, pdf) = e.eval_pdf(d);
                assert_eq!(radiance.to_array().map(f32::to_bits), e.eval(d).to_array().map(f32::to_bits), "{d}");
                assert_eq!(pdf.to_bits(), e.pdf(d).to_bits(), "{d}");
                // And the same again from the image coordinates a path makes ahead.
                let ahead = e.lookup_ahead(d);
                assert_eq!(ahead.is_some(), e.map.is_some());
                let (r2, p2) = e.eval_pdf_at(d, ahead);
                assert_eq!(r2.to_array().map(f32::to_bits), radiance.to_array().map(f32::to_bits), "{d}");
                assert_eq!(p2.to_bits(), pdf.to_bits(), "{d}");
                assert_eq!(e.eval_at(d, ahead).to_array().map(f32::to_bits), radiance.to_array().map(f32::to_bits));
            }
        }
    }

    #[test]
    fn environment_image_orientation() {
        // Mitsuba's convention: the top row is +y, u = atan2(x, -z) / 2π (so -z is the left edge
        // and the middle column is +z).
        let mut pixels = vec![Rgb::ZERO; 8 * 4];
        pixels[0] = Rgb::new(1.0, 0.0, 0.0); // top left
        pixels[3 * 8 + 4] = Rgb::new(0.0, 1.0, 0.0); // bottom row, middle
        let e = Environment { scale: Rgb::ONE, map: EnvMap::new(8, 4, pixels).ok(), to_world: glam::Mat3::IDENTITY };
        let up_and_towards_minus_z = Vec3::new(0.01, 0.9, -0.3).normalize();
        assert_eq!(e.eval(up_and_towards_minus_z), Rgb::new(1.0, 0.0, 0.0));
        let down_and_towards_plus_z = Vec3::new(-0.01, -0.9, 0.3).normalize();
        assert_eq!(e.eval(down_and_towards_plus_z), Rgb::new(0.0, 1.0, 0.0));
    }

    #[test]
    fn spot_light_cone() {
        let l = Light::Spot {
            position: Vec3::new(0.0, 0.0, 1.0),
            direction: -Vec3::Z,
            intensity: Rgb::ONE,
            cos_inner: 20f32.to_radians().cos(),
            cos_outer: 30f32.to_radians().cos(),
        };
        assert!((l.sample(Vec3::ZERO, Vec2::ZERO).unwrap().value.x - 1.0).abs() < 1e-6);
        assert!(l.sample(Vec3::new(1.0, 0.0, 0.0), Vec2::ZERO).is_none()); // 45° off axis
    }
}
