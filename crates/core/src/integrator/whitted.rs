//! The lecture's recursive ray tracer (Whitted 1980), with physically based ingredients.
//!
//! At each hit: emission (if the object is a light) + direct light from every light through
//! shadow rays (several, stratified, for area lights) + the ambient term + the delta lobes,
//! each of which spawns a child ray of the ray tree:
//! - mirrors and smooth conductors spawn a reflected ray weighted by Fresnel (or the constant
//!   reflectance);
//! - dielectrics spawn *both* a reflected ray (weight `F`) and a refracted ray (weight `1 - F`,
//!   times `1/η²` for the change of radiance across the boundary); beyond the critical angle
//!   only the reflected ray, with weight 1 (total internal reflection);
//! - smooth plastics (glazed) spawn the coat's reflection (`F`); the base's share is direct light;
//! - thin dielectrics spawn a reflected ray and a straight-through ray;
//! - rough surfaces (rough conductors, plastics and dielectrics) get direct light only.
//!
//! A branch is pruned when it would go deeper than `max_depth` or when the product of weights
//! from the camera down to it falls below `min_attenuation` (in every channel).
//! Shadow rays are blocked by any surface, glass included (no caustics: that is Whitted).

use glam::Vec3;

use super::{Integrator, RayStats};
use crate::accel::Accel;
use crate::geometry::{spawn_ray, Ray};
use crate::material::bsdf::Bsdf;
use crate::material::{conductor_fresnel, fresnel, Frame, Material};
use crate::sampling::{Pcg32, Sampler, Strata};
use crate::scene::{Intersection, Skip, World};
use crate::Rgb;

/// Whitted-style recursive ray tracing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Whitted {
    /// Maximum depth of the ray tree: 0 traces only camera (and shadow) rays.
    pub max_depth: u32,
    /// Branches whose accumulated weight falls below this (in every channel) are pruned.
    pub min_attenuation: f32,
}

impl Default for Whitted {
    fn default() -> Self {
        Whitted { max_depth: 10, min_attenuation: 1e-3 }
    }
}

#[derive(Clone, Copy)]
enum Kind {
    Reflection,
    Refraction,
}

/// Up to eight shadow rays waiting to be traced together, with what each brings if unblocked.
struct ShadowBatch {
    rays: [Ray; 8],
    t_max: [f32; 8],
    skip: [Skip; 8],
    light: [Rgb; 8],
    n: usize,
}

impl ShadowBatch {
    fn new() -> ShadowBatch {
        ShadowBatch {
            rays: [Ray::new(Vec3::ZERO, Vec3::Z); 8],
            t_max: [0.0; 8],
            skip: [Skip::NONE; 8],
            light: [Rgb::ZERO; 8],
            n: 0,
        }
    }

    #[inline]
    fn push(&mut self, ray: Ray, t_max: f32, skip: Skip, light: Rgb) {
        let i = self.n;
        (self.rays[i], self.t_max[i], self.skip[i], self.light[i]) = (ray, t_max, skip, light);
        self.n += 1;
    }

    /// Traces the waiting rays and adds the light of the unblocked ones to `acc`, in order.
    fn flush<A: Accel>(&mut self, world: &World<A>, acc: &mut Rgb) {
        if self.n == 0 {
            return;
        }
        let active = (0xffu32 >> (8 - self.n)) as u8;
        let blocked = world.occluded_packet8(&self.rays, active, &self.t_max, &self.skip);
        for i in 0..self.n {
            if blocked & (1 << i) == 0 {
                *acc += self.light[i];
            }
        }
        self.n = 0;
    }
}

struct Ctx<'a, 'w, A: Accel> {
    world: &'a World<'w, A>,
    rng: &'a mut Pcg32,
    stats: &'a mut RayStats,
}

impl Integrator for Whitted {
    type Scratch = ();

    fn radiance<A: Accel>(
        &self,
        world: &World<A>,
        ray: &Ray,
        first: Option<Intersection>,
        sampler: &mut Sampler,
        stats: &mut RayStats,
    ) -> Rgb {
        // The ray tree stratifies its shadow rays itself, from the independent stream.
        let mut ctx = Ctx { world, rng: sampler.rng(), stats };
        self.shade(&mut ctx, ray, first, 0, Rgb::ONE)
    }
}

impl Whitted {
    /// The radiance along `ray`, which passes over the objects of `skip`.
    fn trace<A: Accel>(&self, cx: &mut Ctx<A>, ray: &Ray, skip: Skip, depth: u32, throughput: Rgb) -> Rgb {
        let hit = cx.world.intersect_skipping(ray, f32::INFINITY, skip);
        self.shade(cx, ray, hit, depth, throughput)
    }

    /// The radiance along `ray`, whose closest hit is `hit`.
    fn shade<A: Accel>(
        &self,
        cx: &mut Ctx<A>,
        ray: &Ray,
        hit: Option<Intersection>,
        depth: u32,
        throughput: Rgb,
    ) -> Rgb {
        let Some(hit) = hit else {
            return cx.world.escaped(ray.d);
        };
        let scene = cx.world.scene;
        let obj = &scene.objects[hit.object as usize];
        let material = &scene.materials[obj.material];
        let wo = (-ray.d).normalize();
        let front = wo.dot(hit.ng) > 0.0;
        if !material.two_sided() && !front {
            return Rgb::ZERO; // The back of a one-sided surface: black (and it emits only in front).
        }
        let material = material.surface();
        let mut l = Rgb::ZERO;
        if front && obj.emission != Rgb::ZERO {
            l += obj.emission;
        }
        // Opaque surfaces shade on the side the ray arrives from (two-sided).
        let (ng, mut ns) = if front { (hit.ng, hit.ns) } else { (-hit.ng, -hit.ns) };
        if ns.dot(wo) <= 0.0 {
            ns = ng;
        }
        let bsdf = material.bsdf(hit.uv);
        if !bsdf.is_delta() {
            l += self.direct(cx, &hit, &bsdf, ng, ns, wo);
            l += scene.ambient * material.diffuse_albedo(hit.uv);
        }
        let cos_o = ns.dot(wo).clamp(0.0, 1.0);
        match *material {
            Material::Mirror { reflectance } => {
                l += self.child(
                    cx,
                    &hit,
                    ng,
                    fresnel::reflect(wo, ns),
                    reflectance,
                    Kind::Reflection,
                    depth,
                    throughput,
                );
            }
            Material::Conductor { eta, k, roughness: 0.0, .. } => {
                let f = conductor_fresnel(cos_o, eta, k);
                l += self.child(cx, &hit, ng, fresnel::reflect(wo, ns), f, Kind::Reflection, depth, throughput);
            }
            Material::Plastic { ior, specular, roughness: 0.0, .. } => {
                let f = fresnel::dielectric(cos_o, ior);
                l += self.child(
                    cx,
                    &hit,
                    ng,
                    fresnel::reflect(wo, ns),
                    specular * f,
                    Kind::Reflection,
                    depth,
                    throughput,
                );
            }
            Material::ThinDielectric { ior, transmittance } => {
                let r = fresnel::thin_slab(cos_o, ior);
                l += self.child(
                    cx,
                    &hit,
                    ng,
                    fresnel::reflect(wo, ns),
                    Rgb::splat(r),
                    Kind::Reflection,
                    depth,
                    throughput,
                );
                let t = transmittance * (1.0 - r);
                l += self.child(cx, &hit, ng, -wo, t, Kind::Refraction, depth, throughput);
            }
            Material::Dielectric { ior, transmittance, roughness: 0.0, .. } => {
                // `front`: arriving from outside (the side the geometric normal points to).
                let eta = if front { ior } else { 1.0 / ior };
                let cos = ns.dot(wo).clamp(-1.0, 1.0).max(0.0);
                let r = fresnel::reflect(wo, ns);
                match fresnel::refract(wo, ns, eta) {
                    None => {
                        cx.stats.total_internal_reflections += 1;
                        l += self.child(cx, &hit, ng, r, Rgb::ONE, Kind::Reflection, depth, throughput);
                    }
                    Some(t) => {
                        let f = fresnel::dielectric(cos, eta);
                        l += self.child(cx, &hit, ng, r, Rgb::splat(f), Kind::Reflection, depth, throughput);
                        let w = transmittance * ((1.0 - f) / (eta * eta));
                        l += self.child(cx, &hit, ng, t, w, Kind::Refraction, depth, throughput);
                    }
                }
            }
            _ => {}
        }
        l
    }

    /// Traces one branch of the ray tree, unless it is pruned.
    #[allow(clippy::too_many_arguments)]
    fn child<A: Accel>(
        &self,
        cx: &mut Ctx<A>,
        hit: &Intersection,
        ng: Vec3,
        dir: Vec3,
        weight: Rgb,
        kind: Kind,
        depth: u32,
        throughput: Rgb,
    ) -> Rgb {
        if weight.max_element() <= 0.0 {
            return Rgb::ZERO;
        }
        if depth >= self.max_depth {
            cx.stats.pruned_depth += 1;
            return Rgb::ZERO;
        }
        let tp = throughput * weight;
        if tp.max_element() < self.min_attenuation {
            cx.stats.pruned_attenuation += 1;
            return Rgb::ZERO;
        }
        match kind {
            Kind::Reflection => cx.stats.reflection += 1,
            Kind::Refraction => cx.stats.refraction += 1,
        }
        let ray = spawn_ray(hit.p, ng, dir);
        weight * self.trace(cx, &ray, cx.world.leaving(hit.object, hit.p, ng, ray.d), depth + 1, tp)
    }

    /// Direct light from every light source, with shadow rays.
    fn direct<A: Accel>(&self, cx: &mut Ctx<A>, hit: &Intersection, bsdf: &Bsdf, ng: Vec3, ns: Vec3, wo: Vec3) -> Rgb {
        // A dielectric's frame keeps its outward normal: which side the path is on sets η.
        let frame = Frame::new(if bsdf.transmits() { hit.ns } else { ns });
        let wo_local = frame.to_local(wo);
        let mut sum = Rgb::ZERO;
        for (li, light) in cx.world.lights.iter().enumerate() {
            if matches!(light, crate::light::Light::Environment(_)) {
                continue; // Whitted sees the environment only along its rays (and the ambient term).
            }
            let n = light.samples();
            // The strata, made once for the light's samples. Sample `s` takes cell `s`: every
            // cell is drawn here and the jitters are independent, so a hash permutation of the
            // cells (a dozen dependent multiplies a sample, as `Strata::sample` runs) would
            // change the bits of the estimate but not its distribution.
            let strata = Strata::new(n);
            // What the light's samples from this point share (a rectangle's spherical
            // rectangle) is worked out once for all of them.
            let from = light.from_point(hit.p);
            let mut acc = Rgb::ZERO;
            // Several samples' shadow rays leave one point for one light, close together:
            // they are traced eight at a time as a packet, and the unblocked ones summed in
            // sample order (the same sum, bit for bit, as each traced alone).
            // Made only for a light with several samples (a point light's one would pay for it).
            let mut batch: Option<ShadowBatch> = None;
            // Samples are drawn four at a time, their strata in order, and used in order: the
            // same sum as one at a time. Four light samples' chains of square roots and
            // divisions overlap (a spherical rectangle draws two at once in SSE2 lanes,
            // `LightFrom::sample_pair`); a light of one sample (a point light) takes it alone.
            let draw = |s: u32, rng: &mut _| strata.sample_in_order(s, li as u32 ^ 0x9e37_79b9, rng);
            for s in (0..n).step_by(4) {
                let u = draw(s, cx.rng);
                let group = if s + 3 < n {
                    let (u1, u2, u3) = (draw(s + 1, cx.rng), draw(s + 2, cx.rng), draw(s + 3, cx.rng));
                    let ([a, b], [c, d]) = (from.sample_pair([u, u1]), from.sample_pair([u2, u3]));
                    [a, b, c, d]
                } else if s + 1 == n {
                    [from.sample(u), None, None, None]
                } else {
                    // The last two or three of a light's samples. (Indexed: the iterator form
                    // clippy prefers compiled to code 6 % slower on scenes that never run it.)
                    let mut q = [from.sample(u), None, None, None];
                    #[allow(clippy::needless_range_loop)]
                    for i in 1..(n - s) as usize {
                        q[i] = from.sample(draw(s + i as u32, cx.rng));
                    }
                    q
                };
                // By reference: moving the group into an iterator copied it (`memcpy`).
                for ls in group.iter().flatten() {
                    let ls_wi = Vec3::from(ls.wi);
                    if ls_wi.dot(ng) <= 0.0 {
                        continue; // Light below the geometric surface.
                    }
                    let f = bsdf.eval(wo_local, frame.to_local(ls_wi));
                    if f.max_element() <= 0.0 || ls.value.max_element() <= 0.0 {
                        continue;
                    }
                    cx.stats.shadow += 1;
                    if n == 1 {
                        if !cx.world.shadowed(hit, ng, li, ls) {
                            acc += f * Vec3::from(ls.value);
                        }
                        continue;
                    }
                    let (ray, t_max, skip) = cx.world.shadow_ray(hit, ng, li, ls);
                    let b = batch.get_or_insert_with(ShadowBatch::new);
                    b.push(ray, t_max, skip, f * Vec3::from(ls.value));
                    if b.n == 8 {
                        b.flush(cx.world, &mut acc);
                    }
                }
            }
            if let Some(b) = &mut batch {
                b.flush(cx.world, &mut acc);
            }
            sum += acc / n as f32;
        }
        sum
    }
}
