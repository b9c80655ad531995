//! Ray files as the Embree reference benchmark dumps them: little-endian float32, six per ray
//! (ox, oy, oz, dx, dy, dz), no header.

use std::path::Path;

use glam::Vec3;
use snell_core::geometry::Ray;

use crate::{Error, Location};

/// Reads a ray file.
pub fn read(path: &Path) -> Result<Vec<Ray>, Error> {
    let bytes = crate::read_file(path)?;
    if bytes.is_empty() {
        return Err(Error::new(path, "the file is empty"));
    }
    if bytes.len() % 24 != 0 {
        return Err(Error::at(
            path,
            Location::Byte((bytes.len() / 24 * 24) as u64),
            format!("{} bytes is not a whole number of rays (24 bytes each): truncated?", bytes.len()),
        ));
    }
    let mut rays = Vec::with_capacity(bytes.len() / 24);
    for (i, c) in bytes.chunks_exact(24).enumerate() {
        let f = |k: usize| f32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]]);
        let (o, d) = (Vec3::new(f(0), f(1), f(2)), Vec3::new(f(3), f(4), f(5)));
        if !o.is_finite() || !d.is_finite() || d == Vec3::ZERO {
            return Err(Error::at(
                path,
                Location::Byte(i as u64 * 24),
                format!("ray {i} is not finite or has no direction"),
            ));
        }
        rays.push(Ray::new(o, d));
    }
    Ok(rays)
}
