//! Surfaces: triangle meshes (watertight ray/triangle test), spheres.

mod mesh;
mod sphere;
mod triangle;

pub use mesh::{Mesh, MeshError};
pub use sphere::{intersect_sphere, Sphere};
pub use triangle::{intersect_triangle, TriHit, WatertightRay};
