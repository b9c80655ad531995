//! Integrators: how radiance along a camera ray is computed.

mod path;
mod whitted;

pub use path::Path;
pub use whitted::Whitted;

use crate::accel::Accel;
use crate::geometry::Ray;
use crate::sampling::Sampler;
use crate::scene::{Intersection, World};
use crate::Rgb;

/// Counts of what the ray tree did, summed over the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    pub camera: u64,
    pub shadow: u64,
    pub reflection: u64,
    pub refraction: u64,
    /// Branches not traced because they would exceed the maximum depth.
    pub pruned_depth: u64,
    /// Branches not traced because their accumulated weight fell below the minimum attenuation.
    pub pruned_attenuation: u64,
    pub total_internal_reflections: u64,
}

impl RayStats {
    pub fn total_rays(&self) -> u64 {
        self.camera + self.shadow + self.reflection + self.refraction
    }

    pub fn add(&mut self, o: &RayStats) {
        self.camera += o.camera;
        self.shadow += o.shadow;
        self.reflection += o.reflection;
        self.refraction += o.refraction;
        self.pruned_depth += o.pruned_depth;
        self.pruned_attenuation += o.pruned_attenuation;
        self.total_internal_reflections += o.total_internal_reflections;
    }
}

/// Computes the radiance arriving along a camera ray.
pub trait Integrator: Sync {
    /// Working memory [`Integrator::radiance8`] keeps from one call to the next, made once
    /// per tile (so that no call pays for setting it up).
    type Scratch: Default;

    /// `first` is the ray's closest hit, `world.intersect(ray, f32::INFINITY)`, which the
    /// caller has found already (camera rays are traced in packets).
    fn radiance<A: Accel>(
        &self,
        world: &World<A>,
        ray: &Ray,
        first: Option<Intersection>,
        sampler: &mut Sampler,
        stats: &mut RayStats,
    ) -> Rgb;

    /// The radiance along the camera rays `rays[i]` for the lanes `i` whose sampler is
    /// `samplers[i]` (the lanes past `samplers` give black): lane by lane what
    /// [`Integrator::radiance`] gives, with each sampler's numbers drawn in the same order.
    /// `hits[i]` holds camera ray `i`'s hit; the integrator may overwrite it (the path tracer
    /// keeps each path's next hit there, which spares copying the eight hits). `scratch` holds
    /// whatever an earlier call left there. Integrators that gain from running paths together
    /// override it.
    fn radiance8<A: Accel>(
        &self,
        world: &World<A>,
        rays: &[Ray; 8],
        hits: &mut [Option<Intersection>; 8],
        samplers: &mut [Sampler],
        stats: &mut RayStats,
        _scratch: &mut Self::Scratch,
    ) -> [Rgb; 8] {
        let mut out = [Rgb::ZERO; 8];
        for (i, sampler) in samplers.iter_mut().enumerate().take(8) {
            out[i] = self.radiance(world, &rays[i], hits[i], sampler, stats);
        }
        out
    }
}

/// The integrator a render uses, chosen once per render (enum dispatch, no virtual calls).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnyIntegrator {
    Whitted(Whitted),
    Path(Path),
}

impl Integrator for AnyIntegrator {
    type Scratch = (<Whitted as Integrator>::Scratch, <Path as Integrator>::Scratch);

    fn radiance<A: Accel>(
        &self,
        world: &World<A>,
        ray: &Ray,
        first: Option<Intersection>,
        sampler: &mut Sampler,
        stats: &mut RayStats,
    ) -> Rgb {
        match self {
            AnyIntegrator::Whitted(w) => w.radiance(world, ray, first, sampler, stats),
            AnyIntegrator::Path(p) => p.radiance(world, ray, first, sampler, stats),
        }
    }

    fn radiance8<A: Accel>(
        &self,
        world: &World<A>,
        rays: &[Ray; 8],
        hits: &mut [Option<Intersection>; 8],
        samplers: &mut [Sampler],
        stats: &mut RayStats,
        scratch: &mut Self::Scratch,
    ) -> [Rgb; 8] {
        match self {
            AnyIntegrator::Whitted(w) => w.radiance8(world, rays, hits, samplers, stats, &mut scratch.0),
            AnyIntegrator::Path(p) => p.radiance8(world, rays, hits, samplers, stats, &mut scratch.1),
        }
    }
}

/// Which integrator: the names `whitted` and `path` of scene files and `--integrator`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntegratorKind {
    Whitted,
    Path,
}

impl std::str::FromStr for IntegratorKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "whitted" => Ok(IntegratorKind::Whitted),
            "path" => Ok(IntegratorKind::Path),
            _ => Err(format!("unknown integrator '{s}' (expected whitted or path)")),
        }
    }
}

impl std::fmt::Display for IntegratorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            IntegratorKind::Whitted => "whitted",
            IntegratorKind::Path => "path",
        })
    }
}
