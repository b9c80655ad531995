//! Surfaces: triangle meshes (watertight ray/triangle test), spheres.

mod mesh;
mod sphere;
mod tri4;
mod triangle;

#[cfg(test)]
pub(crate) use mesh::tests::reentry_shapes;
pub use mesh::{Mesh, MeshError, Reentry, REENTRY_MAX_CHECKS};
pub use sphere::{intersect_sphere, Sphere};
#[cfg(target_arch = "x86_64")]
pub use tri4::Rays8;
pub use tri4::{BlockHit, Corners, Ray4, Tri4};
pub use triangle::{intersect_triangle, TriHit, WatertightRay};
