//! Integrators: how radiance along a camera ray is computed.

mod whitted;

pub use whitted::Whitted;

use crate::accel::Accel;
use crate::geometry::Ray;
use crate::sampling::Pcg32;
use crate::scene::World;
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
    fn radiance<A: Accel>(&self, world: &World<A>, ray: &Ray, rng: &mut Pcg32, stats: &mut RayStats) -> Rgb;
}
