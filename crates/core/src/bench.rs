//! The ray-throughput workload of `../shared/bench` (identical to the Embree reference
//! benchmark `embree_bench.c`, down to the order of floating-point operations): a camera
//! framing the mesh, one primary ray per pixel centre, and a cosine-weighted diffuse bounce
//! ray from every primary hit.

use glam::Vec3;

use crate::geometry::{orthonormal_basis, Aabb, Ray};

/// `v / |v|` computed as `v * (1 / sqrt(x² + y² + z²))`, as the reference does.
#[inline]
fn norm3(v: Vec3) -> Vec3 {
    let l = 1.0 / (v.x * v.x + v.y * v.y + v.z * v.z).sqrt();
    v * l
}

/// Half the diagonal of the box of all vertices (the workload's length scale).
pub fn radius(positions: &[Vec3]) -> f32 {
    let b = Aabb::from_points(positions.iter().copied());
    let e = b.max - b.min;
    0.5 * (e.x * e.x + e.y * e.y + e.z * e.z).sqrt()
}

/// Primary rays, row major: the camera looks from direction (0.3, 0.4, 1) at the centre `c` of
/// the box of *all* vertices, from distance `0.8 r / tan(fov/2)`.
pub fn primary_rays(positions: &[Vec3], width: u32, height: u32, fov_deg: f32) -> Vec<Ray> {
    let b = Aabb::from_points(positions.iter().copied());
    let c = 0.5 * (b.min + b.max);
    let r = radius(positions);
    let dir = norm3(Vec3::new(0.3, 0.4, 1.0));
    let fov = fov_deg * std::f32::consts::PI / 180.0;
    let dist = 0.8 * r / (0.5 * fov).tan();
    let eye = c + dir * dist;
    let fwd = -dir;
    let right = norm3(fwd.cross(Vec3::Y));
    let u = right.cross(fwd);
    let th = (0.5 * fov).tan();
    let aspect = width as f32 / height as f32;
    let mut rays = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height {
        for x in 0..width {
            let px = (2.0 * (x as f32 + 0.5) / width as f32 - 1.0) * th * aspect;
            let py = (1.0 - 2.0 * (y as f32 + 0.5) / height as f32) * th;
            let d = Vec3::new(
                fwd.x + px * right.x + py * u.x,
                fwd.y + px * right.y + py * u.y,
                fwd.z + px * right.z + py * u.z,
            );
            rays.push(Ray::new(eye, norm3(d)));
        }
    }
    rays
}

/// The reference's PCG32 step (multiplier 6364136223846793005, increment 1442695040888963407).
#[inline]
fn pcg(s: &mut u64) -> u32 {
    let old = *s;
    *s = old.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
    let x = (((old >> 18) ^ old) >> 27) as u32;
    let rot = (old >> 59) as u32;
    x.rotate_right(rot)
}

#[inline]
fn rnd(s: &mut u64) -> f32 {
    (pcg(s) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Diffuse bounce rays: for primary ray `i` that hit at distance `t` a surface with geometric
/// normal `ng` (any length, either side), a ray from the hit point moved `1e-4 r` off the
/// surface towards the viewer, in a cosine-weighted direction about that normal.
pub fn bounce_rays(primary: &[Ray], hits: &[Option<(f32, Vec3)>], radius: f32) -> Vec<Ray> {
    let eps = 1e-4 * radius;
    let mut out = Vec::new();
    for (i, (pr, h)) in primary.iter().zip(hits).enumerate() {
        let Some((t, ng)) = h else { continue };
        let mut n = norm3(*ng);
        if n.dot(pr.d) > 0.0 {
            n = -n;
        }
        let o = Vec3::new(
            pr.o.x + t * pr.d.x + eps * n.x,
            pr.o.y + t * pr.d.y + eps * n.y,
            pr.o.z + t * pr.d.z + eps * n.z,
        );
        let (tt, bb) = orthonormal_basis(n);
        let mut s = 0x853c_49e6_748f_ea9b_u64 ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        pcg(&mut s);
        let u1 = rnd(&mut s);
        let u2 = rnd(&mut s);
        let r = u1.sqrt();
        let phi = 2.0 * std::f32::consts::PI * u2;
        let (lx, ly, lz) = (r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
        let d = Vec3::new(
            lx * tt.x + ly * bb.x + lz * n.x,
            lx * tt.y + ly * bb.y + lz * n.y,
            lx * tt.z + ly * bb.z + lz * n.z,
        );
        out.push(Ray::new(o, norm3(d)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primary_rays_are_unit_and_centred() {
        let pts = [Vec3::ZERO, Vec3::ONE];
        let rays = primary_rays(&pts, 4, 4, 40.0);
        assert_eq!(rays.len(), 16);
        assert!(rays.iter().all(|r| (r.d.length() - 1.0).abs() < 1e-6));
        // The four centre pixels surround the view axis, which points at the box centre.
        let axis = (Vec3::splat(0.5) - rays[0].o).normalize();
        let mean = (rays[5].d + rays[6].d + rays[9].d + rays[10].d).normalize();
        assert!((mean - axis).length() < 1e-5);
    }

    #[test]
    fn bounce_rays_leave_towards_the_viewer() {
        let pr = [Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z), Ray::new(Vec3::ZERO, Vec3::X)];
        let hits = [Some((5.0, Vec3::new(0.0, 0.0, -3.0))), None];
        let b = bounce_rays(&pr, &hits, 1.0);
        assert_eq!(b.len(), 1);
        assert!(b[0].o.z > 0.0 && b[0].d.z > 0.0);
    }
}
