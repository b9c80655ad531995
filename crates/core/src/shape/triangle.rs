//! The watertight ray/triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1), 2013.
//!
//! The ray is sheared so that it runs along +z through the origin; the test then reduces to
//! 2D edge functions of the projected vertices. The projection depends only on the ray, so
//! neighbouring triangles share exactly the same projected edge and the same edge-function
//! value: a ray through a shared edge or vertex hits at least one of the triangles, never
//! neither. Edge functions that come out exactly zero are recomputed in `f64` so that the
//! sign is right. Edges count as inside (a ray through a shared edge may report either
//! triangle), which is what makes closed meshes watertight.

use glam::Vec3;

/// Per-ray data of the watertight test, computed once per ray and reused for every triangle.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    pub o: Vec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl WatertightRay {
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> WatertightRay {
        WatertightRay::of(&o, &d)
    }

    /// [`WatertightRay::new`] from the origin and direction where they lie: their components
    /// are read by axis from there. (Indexed in a copy of their own, they were stored to the
    /// stack and read back at once, a store-to-load round trip on the way to the first
    /// triangle test.)
    #[inline(always)]
    pub fn of(o: &Vec3, d: &Vec3) -> WatertightRay {
        // The dominant axis (x on ties, then y), and x, y swapped for a negative direction along
        // it, to keep the winding. Chosen by arithmetic, not branches: with directions spread
        // over the sphere, the branches were mispredicted about once per ray.
        let a = d.abs();
        let x_max = (a.x >= a.y) & (a.x >= a.z);
        let kz = (!x_max) as usize * (2 - (a.y >= a.z) as usize);
        let dm: &[f32; 3] = d.as_ref();
        // kx = (kz + 1) mod 3 and ky = (kz + 2) mod 3, two bits per kz in a constant (a table
        // indexed by kz was written to the stack and read back).
        let (kx, ky) = ((0b00_10_01 >> (2 * kz)) & 3, (0b01_00_10 >> (2 * kz)) & 3);
        let swap = (kx ^ ky) * (dm[kz] < 0.0) as usize;
        let (kx, ky) = (kx ^ swap, ky ^ swap);
        WatertightRay { o: *o, kx, ky, kz, sx: dm[kx] / dm[kz], sy: dm[ky] / dm[kz], sz: 1.0 / dm[kz] }
    }

    /// The permuted axes `[kx, ky, kz]`: `kz` is the dominant axis of the direction.
    #[inline]
    pub fn axes(&self) -> [usize; 3] {
        [self.kx, self.ky, self.kz]
    }

    /// The shear constants `[sx, sy, sz]`.
    #[inline]
    pub fn shear(&self) -> [f32; 3] {
        [self.sx, self.sy, self.sz]
    }
}

/// A triangle hit: distance and barycentric coordinates of vertices 1 and 2
/// (`p = (1-b1-b2)·p0 + b1·p1 + b2·p2`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriHit {
    pub t: f32,
    pub b1: f32,
    pub b2: f32,
}

/// Recomputes edge functions in `f64` when one came out exactly zero in `f32` (rare: the ray
/// passes through an edge or vertex to within rounding), so that the sign is right.
#[cold]
#[inline(never)]
fn edge_functions_f64(ax: f32, ay: f32, bx: f32, by: f32, cx: f32, cy: f32) -> (f32, f32, f32) {
    let (ax, ay, bx, by, cx, cy) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
    ((cx * by - cy * bx) as f32, (ax * cy - ay * cx) as f32, (bx * ay - by * ax) as f32)
}

/// Intersects the triangle `(p0, p1, p2)` with the ray, accepting `0 < t < t_max`.
#[inline(always)]
pub fn intersect_triangle(r: &WatertightRay, p0: Vec3, p1: Vec3, p2: Vec3, t_max: f32) -> Option<TriHit> {
    // Plain arrays: indexing a glam vector by a run-time axis is a `match`, i.e. branches.
    let a = (p0 - r.o).to_array();
    let b = (p1 - r.o).to_array();
    let c = (p2 - r.o).to_array();
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        (u, v, w) = edge_functions_f64(ax, ay, bx, by, cx, cy);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let az = r.sz * a[kz];
    let bz = r.sz * b[kz];
    let cz = r.sz * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    // Compare t = t_scaled / det against (0, t_max) without dividing.
    let (ts, d) = if det < 0.0 { (-t_scaled, -det) } else { (t_scaled, det) };
    if ts <= 0.0 || ts > t_max * d {
        return None;
    }
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t > 0.0 && t < t_max) {
        return None;
    }
    Some(TriHit { t, b1: v * inv, b2: w * inv })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(o: Vec3, d: Vec3, p: [Vec3; 3]) -> Option<TriHit> {
        intersect_triangle(&WatertightRay::new(o, d), p[0], p[1], p[2], f32::INFINITY)
    }

    const T: [Vec3; 3] = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];

    #[test]
    fn hits_inside_with_barycentrics() {
        let h = tri(Vec3::new(0.25, 0.5, 2.0), -Vec3::Z, T).unwrap();
        assert!((h.t - 2.0).abs() < 1e-6);
        assert!((h.b1 - 0.25).abs() < 1e-6 && (h.b2 - 0.5).abs() < 1e-6);
        // Both windings hit (no back-face culling).
        assert!(tri(Vec3::new(0.25, 0.5, -2.0), Vec3::Z, T).is_some());
    }

    #[test]
    fn misses_outside_behind_and_beyond() {
        assert!(tri(Vec3::new(0.75, 0.75, 2.0), -Vec3::Z, T).is_none());
        assert!(tri(Vec3::new(0.25, 0.25, 2.0), Vec3::Z, T).is_none());
        let r = WatertightRay::new(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z);
        assert!(intersect_triangle(&r, T[0], T[1], T[2], 1.5).is_none());
    }

    #[test]
    fn degenerate_triangles_never_hit() {
        let line = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        assert!(tri(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, line).is_none());
        let point = [Vec3::ONE; 3];
        assert!(tri(Vec3::new(1.0, 1.0, 2.0), -Vec3::Z, point).is_none());
    }

    #[test]
    fn shared_edge_is_never_slipped_through() {
        // Two triangles sharing the diagonal of the unit square; rays exactly along it.
        let a = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0)];
        let b = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        for i in 0..=100 {
            let s = i as f32 / 100.0;
            for d in [-Vec3::Z, Vec3::new(0.3, -0.1, -1.0), Vec3::new(-0.7, 0.9, -0.2)] {
                let o = Vec3::new(s, s, 0.0) - d * 3.0;
                assert!(tri(o, d, a).is_some() || tri(o, d, b).is_some(), "slipped at s={s} d={d}");
            }
        }
    }

    #[test]
    fn axes_are_chosen_as_by_the_branching_rule() {
        // Dominant axis: x on ties, then y; x and y swapped for a negative direction along it.
        let rule = |d: Vec3| {
            let a = d.abs();
            let kz = if a.x >= a.y && a.x >= a.z {
                0
            } else if a.y >= a.z {
                1
            } else {
                2
            };
            let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
            if d[kz] < 0.0 {
                [ky, kx, kz]
            } else {
                [kx, ky, kz]
            }
        };
        let v = [-1.0, -0.5, -0.0, 0.0, 0.5, 1.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        for x in v {
            for y in v {
                for z in v {
                    let d = Vec3::new(x, y, z);
                    assert_eq!(WatertightRay::new(Vec3::ZERO, d).axes(), rule(d), "d = {d}");
                }
            }
        }
    }
}
