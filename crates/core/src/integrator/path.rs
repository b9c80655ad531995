//! Unidirectional path tracing with next-event estimation and multiple importance sampling
//! (Veach 1997; the structure of pbrt-v4's `PathIntegrator` and Mitsuba 3's `path`).
//!
//! At every vertex: emission seen along the path (weighted against light sampling by the power
//! heuristic, unless it was reached through a delta lobe or straight from the camera); one
//! light chosen in proportion to its power and sampled, with a shadow ray (weighted against
//! BSDF sampling, unless the light or the BSDF is a delta); then the BSDF is sampled for the
//! next direction. Russian roulette from `rr_depth` on, with Mitsuba's survival probability
//! `min(max(β) η², 0.95)`.
//!
//! Depth counts path segments, as Mitsuba's `max_depth` does: 1 sees only emitters, 2 adds
//! direct light, and so on.

use super::{Integrator, RayStats};
use crate::accel::Accel;
use crate::geometry::{spawn_ray, Ray};
use crate::material::Frame;
use crate::sampling::Sampler;
use crate::scene::{Intersection, World};
use crate::Rgb;
use glam::{Vec3, Vec3A};

/// Path tracing with next-event estimation and MIS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Path {
    /// Longest path in segments (camera to light); `u32::MAX`: unbounded.
    pub max_depth: u32,
    /// Russian roulette starts at this depth.
    pub rr_depth: u32,
}

impl Default for Path {
    fn default() -> Self {
        Path { max_depth: u32::MAX, rr_depth: 5 }
    }
}

/// The power heuristic with β = 2.
#[inline]
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        1.0
    } else if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

impl Integrator for Path {
    fn radiance<A: Accel>(
        &self,
        world: &World<A>,
        camera_ray: &Ray,
        first: Option<Intersection>,
        rng: &mut Sampler,
        stats: &mut RayStats,
    ) -> Rgb {
        let scene = world.scene;
        // The sums run in 16-byte lanes (the same arithmetic per channel as `Rgb`): a 12-byte
        // value kept on the stack is stored in two pieces and, read back whole, stalls.
        let mut l = Vec3A::ZERO;
        let mut beta = Vec3A::ONE;
        // The direction of the path's current segment. Kept by itself: the segment's ray is
        // needed only to trace it, and a copy of the camera ray made here would be read back
        // in other pieces than it was written (a store-forwarding stall).
        let mut dir = camera_ray.d;
        // The BSDF pdf of the last bounce and whether it was a delta lobe (the camera counts
        // as one: what it sees directly is not light-sampled).
        let (mut prev_pdf, mut prev_delta) = (0.0f32, true);
        let mut prev_p = camera_ray.o;
        let mut eta_scale = 1.0f32;
        let mut depth = 0u32;
        // The camera ray's hit comes with it; each later one is found at the end of the loop.
        let mut next = first;
        loop {
            let Some(hit) = next else {
                l += beta * Vec3A::from(scene.background);
                if let Some((li, env)) = world.environment() {
                    // Radiance and density from one lookup of the direction's image coordinates.
                    let (radiance, w) = if prev_delta {
                        (env.eval(dir), 1.0)
                    } else {
                        let (radiance, pdf) = env.eval_pdf(dir);
                        (radiance, power_heuristic(prev_pdf, world.light_probability(li) * pdf))
                    };
                    l += beta * Vec3A::from(radiance) * w;
                }
                break;
            };
            let obj = &scene.objects[hit.object as usize];
            // Unit already (to rounding): cameras normalize their rays, and each later segment
            // is a BSDF sample's unit direction taken out of its frame. Normalizing it again put a
            // square root and a division on the chain from one hit to the next (Cornell box 1 %).
            // (A NaN direction passes: its sample comes out non-finite and is dropped.)
            debug_assert!(
                dir.is_nan() || (dir.length_squared() - 1.0).abs() < 1e-4,
                "segment direction {dir} is not unit"
            );
            let wo_world = -dir;
            let front = wo_world.dot(hit.ng) > 0.0;
            if front && obj.emission != Rgb::ZERO {
                let w = match (prev_delta, world.light_of(hit.object)) {
                    (false, Some(li)) => {
                        let light_pdf = world.light_probability(li) * world.lights[li].pdf(prev_p, hit.p, hit.ng);
                        power_heuristic(prev_pdf, light_pdf)
                    }
                    _ => 1.0,
                };
                l += beta * Vec3A::from(obj.emission) * w;
            }
            if depth + 1 >= self.max_depth {
                break;
            }
            let material = &scene.materials[obj.material];
            if !material.two_sided() && !front {
                break; // The back of a one-sided surface reflects nothing.
            }
            let bsdf = material.bsdf(hit.uv);
            // Opaque surfaces are two-sided: turn the frame to the side the path arrives from.
            // Dielectrics keep the outward normal, whose side tells inside from outside.
            let (mut ng, mut ns) = (hit.ng, hit.ns);
            if !bsdf.transmits() && !front {
                (ng, ns) = (-ng, -ns);
            }
            if !bsdf.transmits() && ns.dot(wo_world) <= 0.0 {
                ns = ng;
            }
            let frame = Frame::new(ns);
            let wo = frame.to_local(wo_world);

            // Next-event estimation.
            if !bsdf.is_delta() {
                if let Some((li, p_choose)) = world.choose_light(rng.next_f32()) {
                    let u = rng.next_2d();
                    if let Some(ls) = world.lights[li].sample(hit.p, u) {
                        let ls_wi = Vec3::from(ls.wi);
                        let wi = frame.to_local(ls_wi);
                        // Reflection must stay on the side of the geometric normal it started on,
                        // transmission must cross it.
                        let same_side = (ls_wi.dot(ng) > 0.0) == (wo_world.dot(ng) > 0.0);
                        let f = if same_side == (wi.z * wo.z > 0.0) { bsdf.eval(wo, wi) } else { Rgb::ZERO };
                        if f.max_element() > 0.0 && ls.value.max_element() > 0.0 {
                            stats.shadow += 1;
                            let blocked = world.shadowed(&hit, ng, li, &ls);
                            if !blocked {
                                let w = if ls.pdf > 0.0 {
                                    power_heuristic(ls.pdf * p_choose, bsdf.pdf(wo, wi))
                                } else {
                                    1.0
                                };
                                l += beta * Vec3A::from(f) * ls.value * (w / p_choose);
                            }
                        }
                    }
                }
            }

            // BSDF sampling.
            let uc = rng.next_f32();
            let u = rng.next_2d();
            let Some(bs) = bsdf.sample(wo, uc, u) else { break };
            let wi_world = frame.to_world(bs.wi);
            // Shading normals can send a sample through the geometric surface the wrong way.
            let crosses = (wi_world.dot(ng) > 0.0) != (wo_world.dot(ng) > 0.0);
            if crosses != (bs.wi.z * wo.z < 0.0) {
                break;
            }
            beta *= Vec3A::from(bs.weight);
            // Russian roulette takes the 1/η² of refraction back out of the throughput, so that
            // paths inside glass are not killed for it.
            let eta = bsdf.eta_across(wo, bs.wi);
            eta_scale *= eta * eta;
            (prev_pdf, prev_delta, prev_p) = (bs.pdf, bs.delta, hit.p);
            if crosses {
                stats.refraction += 1;
            } else {
                stats.reflection += 1;
            }
            let ray = spawn_ray(hit.p, ng, wi_world);
            dir = ray.d;
            depth += 1;
            if depth >= self.rr_depth {
                let q = (beta.max_element() * eta_scale).min(0.95);
                if rng.next_f32() >= q {
                    break;
                }
                beta /= q;
            }
            if beta.max_element() <= 0.0 || !beta.is_finite() {
                break;
            }
            next = world.intersect_skipping(&ray, f32::INFINITY, world.leaving(hit.object, hit.p, ng, ray.d));
        }
        l.into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_heuristic_weights_sum_to_one() {
        for (a, b) in [(1.0f32, 2.0f32), (0.3, 0.0), (5.0, 5.0)] {
            assert!((power_heuristic(a, b) + power_heuristic(b, a) - 1.0).abs() < 1e-6);
        }
        assert_eq!(power_heuristic(f32::INFINITY, 1.0), 1.0);
    }
}
