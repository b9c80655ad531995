//! # snell-core
//!
//! The renderer itself, with no file I/O and no command-line concerns: geometry, acceleration
//! structures, cameras, lights, materials, samplers, integrators and the tiled render loop.
//!
//! Data flow: a [`scene::Scene`] (geometry, objects, materials, lights, camera) is handed to
//! [`accel::AccelKind::build_world`], which builds the chosen acceleration structure over it once;
//! [`render::render`] then traces camera rays through that [`scene::World`] with an
//! [`integrator`] and accumulates them into an [`image::Image`].
//!
//! Conventions used everywhere (see ARCHITECTURE.md):
//! - right-handed world space, y up by convention of the scene formats (nothing depends on it);
//! - directions `wo` and `wi` point *away* from the surface point;
//! - colours are linear RGB [`Rgb`] (a `glam::Vec3`), radiance in arbitrary consistent units;
//! - `f32` everywhere except where the watertight triangle test falls back to `f64`.

pub mod accel;
pub mod bench;
pub mod camera;
pub mod filter;
pub mod geometry;
pub mod image;
pub mod inspect;
pub mod integrator;
pub mod lanes;
pub mod light;
pub mod material;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod shape;

pub use glam::{Vec2, Vec3};

/// Linear RGB colour or spectral quantity sampled at three primaries.
pub type Rgb = glam::Vec3;
