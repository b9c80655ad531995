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
use crate::geometry::{offset_ray_origin_lanewise, spawn_ray, spawn_ray_lanewise, spawn_ray_to_lanewise, Ray};
use crate::light::LightSample;
use crate::material::bsdf::{cosine_hemisphere, diffuse_eval, diffuse_pdf, diffuse_sampled, Bsdf};
use crate::material::Frame;
use crate::sampling::Sampler;
use crate::scene::{Intersection, Skip, World};
use crate::Rgb;
use glam::{Vec2, Vec3, Vec3A};

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

/// Whether a light sample's direction `ls_wi` (`wi` in the shading frame) can bring light to
/// `wo_world` (`wo`): reflection must stay on the side of the geometric normal `ng` it started
/// on, transmission must cross it. ([`Path::finish`] and [`DiffuseLanes::run`] alike.)
#[inline(always)]
fn light_reaches(ng: Vec3, wo_world: Vec3, ls_wi: Vec3, wo: Vec3, wi: Vec3) -> bool {
    let same_side = (ls_wi.dot(ng) > 0.0) == (wo_world.dot(ng) > 0.0);
    same_side == (wi.z * wo.z > 0.0)
}

/// A light sample's MIS weight against BSDF sampling (power heuristic), its light chosen with
/// probability `p_choose`; 1 for a delta light (`ls_pdf` 0), whose `bsdf_pdf` is not asked for.
#[inline(always)]
fn light_weight(ls_pdf: f32, p_choose: f32, bsdf_pdf: impl FnOnce() -> f32) -> f32 {
    if ls_pdf > 0.0 {
        power_heuristic(ls_pdf * p_choose, bsdf_pdf())
    } else {
        1.0
    }
}

/// Whether a direction `wi_world` leaving the surface crosses its geometric normal `ng`'s
/// plane (relative to `wo_world`, where the path came from).
#[inline(always)]
fn crosses(ng: Vec3, wo_world: Vec3, wi_world: Vec3) -> bool {
    (wi_world.dot(ng) > 0.0) != (wo_world.dot(ng) > 0.0)
}

/// What a path carries from one vertex to the next.
#[derive(Clone, Copy, Debug)]
struct PathState {
    /// The radiance gathered so far. The sums run in 16-byte lanes (the same arithmetic per
    /// channel as `Rgb`): a 12-byte value kept on the stack is stored in two pieces and, read
    /// back whole, stalls.
    l: Vec3A,
    beta: Vec3A,
    /// The direction of the path's current segment. Kept by itself: the segment's ray is
    /// needed only to trace it, and a copy of the camera ray made here would be read back in
    /// other pieces than it was written (a store-forwarding stall).
    dir: Vec3,
    /// The BSDF pdf of the last bounce and whether it was a delta lobe (the camera counts as
    /// one: what it sees directly is not light-sampled).
    prev_pdf: f32,
    prev_delta: bool,
    prev_p: Vec3,
    eta_scale: f32,
    depth: u32,
    /// Where the current segment's direction looks up the environment's image, made as the
    /// segment set out ([`Environment::lookup_ahead`]); `None` for the camera's segment and
    /// without an image.
    ///
    /// [`Environment::lookup_ahead`]: crate::light::Environment::lookup_ahead
    env_uv: Option<Vec2>,
}

impl PathState {
    #[inline(always)]
    fn new(camera_ray: &Ray) -> PathState {
        PathState {
            l: Vec3A::ZERO,
            beta: Vec3A::ONE,
            dir: camera_ray.d,
            prev_pdf: 0.0,
            prev_delta: true,
            prev_p: camera_ray.o,
            eta_scale: 1.0,
            depth: 0,
            env_uv: None,
        }
    }
}

/// A vertex's surface, ready to shade: what [`Path::begin`] finds. The hit is borrowed where
/// the query left it: copied into the vertex, it was read back in other pieces than it had
/// just been written in, a store-forwarding stall on every vertex.
struct Shade<'a, 'h> {
    hit: &'h Intersection,
    bsdf: Bsdf<'a>,
    /// The geometric and shading normals, an opaque surface's turned to the side the path
    /// arrives from.
    ng: Vec3,
    ns: Vec3,
    /// Towards where the path came from.
    wo_world: Vec3,
}

/// The random numbers a vertex draws, in the order it draws them (the light sampled with its
/// pair), drawn before anything is traced from the vertex.
struct Draws {
    /// The light chosen (its index and the probability of the choice) and its sample.
    light: Option<(usize, f32, LightSample)>,
    /// The BSDF sample's lobe choice and direction numbers.
    uc: f32,
    u: Vec2,
}

impl Draws {
    #[inline(always)]
    fn take<A: Accel>(world: &World<A>, shade: &Shade, rng: &mut Sampler) -> Draws {
        let mut light = None;
        // Next-event estimation, where the BSDF has a lobe to evaluate.
        if !shade.bsdf.is_delta() {
            if let Some((li, p_choose)) = world.choose_light(rng.next_f32()) {
                let u = rng.next_2d();
                // A Lambertian surface reflects nothing of a light sample from the other side
                // of its geometric normal than the path (`light_reaches` is then false, or the
                // directions lie in opposite hemispheres, where `diffuse_eval` is zero): the
                // light may drop such a sample early. (Not for a NaN direction of arrival,
                // whose sample `light_reaches` judges otherwise.)
                let side = match shade.bsdf {
                    Bsdf::Diffuse { .. } => {
                        let c = shade.wo_world.dot(shade.ng);
                        (!c.is_nan()).then_some((shade.ng, c > 0.0))
                    }
                    _ => None,
                };
                light = world.lights[li].sample_facing(shade.hit.p, u, side).map(|ls| (li, p_choose, ls));
            }
        }
        let uc = rng.next_f32();
        Draws { light, uc, u: rng.next_2d() }
    }
}

/// Eight Lambertian vertices, structure of arrays (`[axis][lane]`): the inputs written lane by
/// lane, then [`DiffuseLanes::run`] works out every lane's light-sample contribution, shadow
/// ray, BSDF sample and next ray with the scalar functions, in a loop the compiler turns into
/// vector instructions (the same operations, so the same bits as the one-path loop).
#[derive(Default)]
struct DiffuseLanes {
    p: [[f32; 8]; 3],
    ng: [[f32; 8]; 3],
    ns: [[f32; 8]; 3],
    wo_world: [[f32; 8]; 3],
    albedo: [[f32; 8]; 3],
    beta: [[f32; 8]; 3],
    light_wi: [[f32; 8]; 3],
    light_value: [[f32; 8]; 3],
    light_q: [[f32; 8]; 3],
    light_n: [[f32; 8]; 3],
    light_pdf: [f32; 8],
    p_choose: [f32; 8],
    /// A light sample whose value is positive somewhere, and whether its light is at infinity.
    light_ok: [bool; 8],
    light_inf: [bool; 8],
    u: [[f32; 8]; 2],
    // Out: the light sample's contribution, if its shadow ray (to trace) finds it unblocked;
    // whether the BSDF sample goes on (`ok`), its density, direction and the next ray's origin.
    contrib: [[f32; 8]; 3],
    shadow: [bool; 8],
    /// Each lane's shadow ray, whole (`occluded_skipping` reads it from here: put together
    /// from the lanes just before the query, its pieces stalled the query's first loads).
    shadow_ray: [Ray; 8],
    shadow_t: [f32; 8],
    ok: [bool; 8],
    pdf: [f32; 8],
    wi_world: [[f32; 8]; 3],
    origin: [[f32; 8]; 3],
}

#[inline(always)]
fn get(a: &[[f32; 8]; 3], i: usize) -> Vec3 {
    Vec3::new(a[0][i], a[1][i], a[2][i])
}

#[inline(always)]
fn put(a: &mut [[f32; 8]; 3], i: usize, v: Vec3) {
    (a[0][i], a[1][i], a[2][i]) = (v.x, v.y, v.z);
}

impl DiffuseLanes {
    /// Every lane: what [`Path::finish`] works out for a Lambertian vertex before it traces.
    #[inline(always)]
    fn run(&mut self) {
        for i in 0..8 {
            let (p, ng, wo_world) = (get(&self.p, i), get(&self.ng, i), get(&self.wo_world, i));
            let albedo = get(&self.albedo, i);
            let frame = Frame::new(get(&self.ns, i));
            let wo = frame.to_local(wo_world);
            // The light sample: as `Path::finish`.
            let ls_wi = get(&self.light_wi, i);
            let wi = frame.to_local(ls_wi);
            let f = if light_reaches(ng, wo_world, ls_wi, wo, wi) { diffuse_eval(albedo, wo, wi) } else { Rgb::ZERO };
            self.shadow[i] = self.light_ok[i] && f.max_element() > 0.0;
            let p_choose = self.p_choose[i];
            let w = light_weight(self.light_pdf[i], p_choose, || diffuse_pdf(wo, wi));
            put(&mut self.contrib, i, get(&self.beta, i) * f * get(&self.light_value, i) * (w / p_choose));
            // `World::shadow_ray`'s ray.
            let (r, t) = if self.light_inf[i] {
                (spawn_ray_lanewise(p, ng, ls_wi), f32::INFINITY)
            } else {
                spawn_ray_to_lanewise(p, ng, get(&self.light_q, i), get(&self.light_n, i))
            };
            self.shadow_ray[i] = r;
            self.shadow_t[i] = t;
            // The BSDF sample: as `Path::finish`.
            let wi = cosine_hemisphere(Vec2::new(self.u[0][i], self.u[1][i]));
            let bs = diffuse_sampled(albedo, wo, wi);
            let wi_world = frame.to_world(wi);
            self.ok[i] = bs.is_some() && crosses(ng, wo_world, wi_world) == (wi.z * wo.z < 0.0);
            self.pdf[i] = bs.map_or(0.0, |b| b.pdf);
            // `spawn_ray`'s ray, kept in lanes (written whole, as the shadow ray is, it cost the
            // loop its vector stores: 0.75 % more instructions on the Cornell box).
            put(&mut self.wi_world, i, wi_world);
            put(&mut self.origin, i, offset_ray_origin_lanewise(p, ng, wi_world));
        }
    }

    /// [`DiffuseLanes::run`] in AVX2's eight lanes.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    unsafe fn run_avx2(&mut self) {
        self.run()
    }
}

impl Path {
    /// One vertex of a path: `next` is the closest hit of its current segment (`None`: the
    /// segment left the scene). Adds what the vertex contributes to `st.l` and returns the
    /// next segment's query (its ray and what it passes over), or `None` where the path ends.
    #[inline(always)]
    fn vertex<A: Accel>(
        &self,
        world: &World<A>,
        st: &mut PathState,
        next: Option<&Intersection>,
        rng: &mut Sampler,
        stats: &mut RayStats,
    ) -> Option<(Ray, Skip)> {
        let shade = self.begin(world, st, next)?;
        let draws = Draws::take(world, &shade, rng);
        self.finish(world, st, &shade, &draws, rng, stats)
    }

    /// A vertex up to its shading: the environment where the path left the scene, emission
    /// seen along the path, the depth limit, and the surface's BSDF and normals. `None` where
    /// the path ends.
    #[inline(always)]
    fn begin<'a, 'h, A: Accel>(
        &self,
        world: &World<'a, A>,
        st: &mut PathState,
        next: Option<&'h Intersection>,
    ) -> Option<Shade<'a, 'h>> {
        let scene = world.scene;
        let Some(hit) = next else {
            st.l += st.beta * Vec3A::from(scene.background);
            if let Some((li, env)) = world.environment() {
                // Radiance and density from one lookup of the direction's image coordinates.
                let (radiance, w) = if st.prev_delta {
                    (env.eval_at(st.dir, st.env_uv), 1.0)
                } else {
                    let (radiance, pdf) = env.eval_pdf_at(st.dir, st.env_uv);
                    (radiance, power_heuristic(st.prev_pdf, world.light_probability(li) * pdf))
                };
                st.l += st.beta * Vec3A::from(radiance) * w;
            }
            return None;
        };
        let surface = &world.surfaces[hit.object as usize];
        // Unit already (to rounding): cameras normalize their rays, and each later segment
        // is a BSDF sample's unit direction taken out of its frame. Normalizing it again put a
        // square root and a division on the chain from one hit to the next (Cornell box 1 %).
        // (A NaN direction passes: its sample comes out non-finite and is dropped.)
        debug_assert!(
            st.dir.is_nan() || (st.dir.length_squared() - 1.0).abs() < 1e-4,
            "segment direction {} is not unit",
            st.dir
        );
        let wo_world = -st.dir;
        let front = wo_world.dot(hit.ng) > 0.0;
        if front && surface.emission != Rgb::ZERO {
            let w = match (st.prev_delta, world.light_of(hit.object)) {
                (false, Some(li)) => {
                    let light_pdf = world.light_probability(li) * world.lights[li].pdf(st.prev_p, hit.p, hit.ng);
                    power_heuristic(st.prev_pdf, light_pdf)
                }
                _ => 1.0,
            };
            st.l += st.beta * Vec3A::from(surface.emission) * w;
        }
        if st.depth + 1 >= self.max_depth {
            return None;
        }
        if !surface.two_sided && !front {
            return None; // The back of a one-sided surface reflects nothing.
        }
        let bsdf = match surface.diffuse {
            Some(albedo) => Bsdf::Diffuse { albedo },
            None => scene.materials[surface.material].bsdf(hit.uv),
        };
        // Opaque surfaces are two-sided: turn the frame to the side the path arrives from.
        // Dielectrics keep the outward normal, whose side tells inside from outside.
        let (mut ng, mut ns) = (hit.ng, hit.ns);
        if !bsdf.transmits() && !front {
            (ng, ns) = (-ng, -ns);
        }
        if !bsdf.transmits() && ns.dot(wo_world) <= 0.0 {
            ns = ng;
        }
        Some(Shade { hit, bsdf, ng, ns, wo_world })
    }

    /// A vertex from its random numbers on: the light sample's shadow ray and contribution, the
    /// BSDF sample, Russian roulette. Returns the next segment's query, or `None` where the
    /// path ends. ([`DiffuseLanes`] does the same for eight Lambertian vertices at once.)
    #[inline(always)]
    fn finish<A: Accel>(
        &self,
        world: &World<A>,
        st: &mut PathState,
        shade: &Shade,
        draws: &Draws,
        rng: &mut Sampler,
        stats: &mut RayStats,
    ) -> Option<(Ray, Skip)> {
        let Shade { hit, bsdf, ng, ns, wo_world } = shade;
        let (ng, wo_world) = (*ng, *wo_world);
        let frame = Frame::new(*ns);
        let wo = frame.to_local(wo_world);
        if let Some((li, p_choose, ls)) = &draws.light {
            let ls_wi = Vec3::from(ls.wi);
            let wi = frame.to_local(ls_wi);
            // The BSDF's density is needed for MIS wherever the light's is not a delta: then
            // both come from one evaluation.
            let (f, pdf) = match light_reaches(ng, wo_world, ls_wi, wo, wi) {
                false => (Rgb::ZERO, 0.0),
                true if ls.pdf > 0.0 => bsdf.eval_and_pdf(wo, wi),
                true => (bsdf.eval(wo, wi), 0.0),
            };
            if f.max_element() > 0.0 && ls.value.max_element() > 0.0 {
                stats.shadow += 1;
                let blocked = world.shadowed(hit, ng, *li, ls);
                if !blocked {
                    let w = light_weight(ls.pdf, *p_choose, || pdf);
                    st.l += st.beta * Vec3A::from(f) * ls.value * (w / p_choose);
                }
            }
        }

        // BSDF sampling.
        let bs = bsdf.sample(wo, draws.uc, draws.u)?;
        let wi_world = frame.to_world(bs.wi);
        // Shading normals can send a sample through the geometric surface the wrong way.
        let crosses = crosses(ng, wo_world, wi_world);
        if crosses != (bs.wi.z * wo.z < 0.0) {
            return None;
        }
        st.beta *= Vec3A::from(bs.weight);
        // Russian roulette takes the 1/η² of refraction back out of the throughput, so that
        // paths inside glass are not killed for it.
        let eta = bsdf.eta_across(wo, bs.wi);
        st.eta_scale *= eta * eta;
        (st.prev_pdf, st.prev_delta, st.prev_p) = (bs.pdf, bs.delta, hit.p);
        if crosses {
            stats.refraction += 1;
        } else {
            stats.reflection += 1;
        }
        self.roulette(world, st, rng, hit.object, hit.p, ng, spawn_ray(hit.p, ng, wi_world))
    }

    /// The end of a vertex whose next segment is `ray` (from `p` on object `obj`, geometric
    /// normal `ng`): the depth, Russian roulette, the throughput's check. Returns the next
    /// segment's query, or `None` where the path ends.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn roulette<A: Accel>(
        &self,
        world: &World<A>,
        st: &mut PathState,
        rng: &mut Sampler,
        obj: u32,
        p: Vec3,
        ng: Vec3,
        ray: Ray,
    ) -> Option<(Ray, Skip)> {
        st.dir = ray.d;
        st.depth += 1;
        if st.depth >= self.rr_depth {
            let q = (st.beta.max_element() * st.eta_scale).min(0.95);
            if rng.next_f32() >= q {
                return None;
            }
            st.beta /= q;
        }
        if st.beta.max_element() <= 0.0 || !st.beta.is_finite() {
            return None;
        }
        st.env_uv = world.environment().and_then(|(_, e)| e.lookup_ahead(ray.d));
        Some((ray, world.leaving(obj, p, ng, ray.d)))
    }
}

/// [`Path`]'s working memory between calls of [`Integrator::radiance8`]: its lanes, whose
/// inputs are written only for the lanes that take part in a step (the others keep earlier
/// values, worked out and then left unread), so that they are zeroed once per tile rather
/// than once per call.
#[derive(Default)]
pub struct PathScratch {
    lanes: DiffuseLanes,
}

impl Integrator for Path {
    type Scratch = PathScratch;

    fn radiance<A: Accel>(
        &self,
        world: &World<A>,
        camera_ray: &Ray,
        first: Option<Intersection>,
        rng: &mut Sampler,
        stats: &mut RayStats,
    ) -> Rgb {
        let mut st = PathState::new(camera_ray);
        // The camera ray's hit comes with it; each later one is found here.
        let mut next = first;
        while let Some((ray, skip)) = self.vertex(world, &mut st, next.as_ref(), rng, stats) {
            next = world.intersect_skipping(&ray, f32::INFINITY, skip);
        }
        st.l.into()
    }

    /// The paths of up to eight camera samples in lockstep: each live path's vertex up to its
    /// random numbers, then the Lambertian vertices' light samples, shadow rays and BSDF
    /// samples worked out together in vector lanes (`DiffuseLanes`, where the CPU has AVX2)
    /// and the other vertices one by one, then every live path's next segment traced. Each
    /// path draws its numbers and does its arithmetic as [`Integrator::radiance`] does, so the
    /// image is the same bits (and thread counts still do not change it).
    fn radiance8<A: Accel>(
        &self,
        world: &World<A>,
        rays: &[Ray; 8],
        next: &mut [Option<Intersection>; 8],
        samplers: &mut [Sampler],
        stats: &mut RayStats,
        scratch: &mut PathScratch,
    ) -> [Rgb; 8] {
        let n = samplers.len().min(8);
        let samplers = &mut samplers[..n];
        // Every camera ray left the scene (the sky around a single object, most of a packet's
        // samples there): each path is its one vertex, `begin`'s, which draws no number; path
        // by path, without the lockstep's arrays.
        if next[..n].iter().all(Option::is_none) {
            let mut out = [Rgb::ZERO; 8];
            for (i, rng) in samplers.iter_mut().enumerate() {
                out[i] = self.radiance(world, &rays[i], None, rng, stats);
            }
            return out;
        }
        let mut st: [PathState; 8] = std::array::from_fn(|i| PathState::new(&rays[i]));
        let mut queries = [(rays[0], Skip::NONE); 8];
        let mut live = (1u32 << samplers.len()) - 1;
        let lanes = &mut scratch.lanes;
        // Per lane in `lanes`: its object and light.
        let mut objs = [0u32; 8];
        let mut lights = [0usize; 8];
        while live != 0 {
            // Each live path's vertex up to its random numbers; Lambertian vertices wait for the
            // lanes, the others are finished one by one.
            let mut wide = 0u32;
            // The live lanes as of now, visited by their bits (a test of every lane's bit was a
            // branch mispredicted as paths end); a lane leaves `live` only on its own turn.
            for lane in crate::accel::lanes(live) {
                let rng = &mut samplers[lane];
                let Some(shade) = self.begin(world, &mut st[lane], next[lane].as_ref()) else {
                    live &= !(1 << lane);
                    continue;
                };
                let draws = Draws::take(world, &shade, rng);
                match (shade.bsdf, &draws.light) {
                    (Bsdf::Diffuse { albedo }, light) if world.avx2 => {
                        put(&mut lanes.p, lane, shade.hit.p);
                        put(&mut lanes.ng, lane, shade.ng);
                        put(&mut lanes.ns, lane, shade.ns);
                        put(&mut lanes.wo_world, lane, shade.wo_world);
                        put(&mut lanes.albedo, lane, albedo);
                        put(&mut lanes.beta, lane, st[lane].beta.into());
                        (lanes.u[0][lane], lanes.u[1][lane]) = (draws.u.x, draws.u.y);
                        objs[lane] = shade.hit.object;
                        lanes.light_ok[lane] = false;
                        if let Some((li, p_choose, ls)) = light {
                            put(&mut lanes.light_wi, lane, ls.wi.into());
                            put(&mut lanes.light_value, lane, ls.value.into());
                            put(&mut lanes.light_q, lane, ls.p.into());
                            put(&mut lanes.light_n, lane, ls.n.into());
                            (lanes.light_pdf[lane], lanes.p_choose[lane]) = (ls.pdf, *p_choose);
                            lanes.light_ok[lane] = ls.value.max_element() > 0.0;
                            lanes.light_inf[lane] = ls.infinite;
                            lights[lane] = *li;
                        }
                        wide |= 1 << lane;
                    }
                    _ => match self.finish(world, &mut st[lane], &shade, &draws, rng, stats) {
                        Some(q) => queries[lane] = q,
                        None => live &= !(1 << lane),
                    },
                }
            }
            if wide != 0 {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `world.avx2` (checked for every lane of `wide`) says the CPU has AVX2.
                unsafe {
                    lanes.run_avx2()
                };
                // (Elsewhere `world.avx2` is false and no vertex waits for the lanes.)
                #[cfg(not(target_arch = "x86_64"))]
                lanes.run();
                for lane in crate::accel::lanes(wide) {
                    let s = &mut st[lane];
                    let (p, ng, obj) = (get(&lanes.p, lane), get(&lanes.ng, lane), objs[lane]);
                    if lanes.shadow[lane] {
                        stats.shadow += 1;
                        let r = &lanes.shadow_ray[lane];
                        let end =
                            (!lanes.light_inf[lane]).then(|| (get(&lanes.light_q, lane), get(&lanes.light_n, lane)));
                        let skip = world.shadow_skip(obj, p, ng, lights[lane], end, r.d);
                        if !world.occluded_skipping(r, lanes.shadow_t[lane], skip) {
                            s.l += Vec3A::from(get(&lanes.contrib, lane));
                        }
                    }
                    if !lanes.ok[lane] {
                        live &= !(1 << lane);
                        continue;
                    }
                    // The Lambertian sample's weight is its albedo; its η is 1, which leaves
                    // `eta_scale` as it is; and a sample that goes on reflects (`ok` says it
                    // does not cross the surface, as its lobe's directions never do).
                    s.beta *= Vec3A::from(get(&lanes.albedo, lane));
                    (s.prev_pdf, s.prev_delta, s.prev_p) = (lanes.pdf[lane], false, p);
                    stats.reflection += 1;
                    let ray = Ray::new(get(&lanes.origin, lane), get(&lanes.wi_world, lane));
                    match self.roulette(world, s, &mut samplers[lane], obj, p, ng, ray) {
                        Some(q) => queries[lane] = q,
                        None => live &= !(1 << lane),
                    }
                }
            }
            for lane in crate::accel::lanes(live) {
                let (ray, skip) = &queries[lane];
                world.intersect_skipping_into(ray, f32::INFINITY, *skip, &mut next[lane]);
            }
        }
        st.map(|s| s.l.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What lets `Draws::take` drop a Lambertian vertex's light samples from the other side
    /// of its geometric normal than the path: for every such direction the vertex's light
    /// contribution is zero (`light_reaches` false, or `diffuse_eval` zero), whatever the
    /// shading normal. Over random geometric and shading normals, directions of arrival and
    /// light directions.
    #[test]
    fn lambertian_light_from_the_other_side_contributes_nothing() {
        let mut rng = crate::sampling::Pcg32::new(41, 42);
        let unit = |rng: &mut crate::sampling::Pcg32| crate::light::Environment::direction(rng.next_2d());
        let mut checked = 0;
        for _ in 0..200_000 {
            let (ng, wo_world, ls_wi) = (unit(&mut rng), unit(&mut rng), unit(&mut rng));
            // A shading normal near the geometric one, as interpolated normals are.
            let ns = (ng + 0.5 * unit(&mut rng)).normalize();
            let front = wo_world.dot(ng) > 0.0;
            let c = ls_wi.dot(ng);
            if (front && c > 0.0) || (!front && c <= 0.0) {
                continue;
            }
            let frame = Frame::new(ns);
            let (wo, wi) = (frame.to_local(wo_world), frame.to_local(ls_wi));
            let f = if light_reaches(ng, wo_world, ls_wi, wo, wi) { diffuse_eval(Rgb::ONE, wo, wi) } else { Rgb::ZERO };
            assert_eq!(f, Rgb::ZERO, "ng {ng} wo {wo_world} wi {ls_wi} ns {ns}");
            checked += 1;
        }
        assert!(checked > 50_000);
    }

    #[test]
    fn power_heuristic_weights_sum_to_one() {
        for (a, b) in [(1.0f32, 2.0f32), (0.3, 0.0), (5.0, 5.0)] {
            assert!((power_heuristic(a, b) + power_heuristic(b, a) - 1.0).abs() < 1e-6);
        }
        assert_eq!(power_heuristic(f32::INFINITY, 1.0), 1.0);
    }
}
