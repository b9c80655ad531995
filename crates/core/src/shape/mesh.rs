use std::fmt;

use glam::{Vec2, Vec3};

use crate::geometry::Aabb;

/// An indexed triangle mesh: one shared vertex buffer, triangles as index triples.
/// Optional per-vertex shading normals and texture coordinates (same length as `positions`).
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<[u32; 3]>,
}

/// Whether a ray that leaves a surface can meet the same surface again, as a query may use to
/// pass over the surface it starts from (or the light it ends on) without testing it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reentry {
    /// Flat: every vertex in one plane (to the rounding of its coordinates). A ray leaving the
    /// surface, to either side, never meets it again.
    Never,
    /// Convex: every vertex on `centre`'s side of every triangle's plane (or, for a sphere, its
    /// centre). A ray leaving the surface to the side away from `centre` never meets it again.
    Inward { centre: Vec3 },
    /// A ray leaving the surface may meet it again (or the mesh was too large to check).
    Possible,
}

/// [`Mesh::reentry`] checks meshes of up to this many pairs of a triangle and a triangle
/// corner (about 1,200 triangles); it is meant for the small objects of rooms and boxes.
pub const REENTRY_MAX_CHECKS: usize = 1 << 22;

/// Why a mesh is invalid.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshError {
    NonFiniteVertex { vertex: usize },
    IndexOutOfRange { triangle: usize, index: u32, vertices: usize },
    AttributeLength { attribute: &'static str, len: usize, vertices: usize },
    TooManyVertices { vertices: usize },
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MeshError::NonFiniteVertex { vertex } => {
                write!(f, "vertex {vertex} has a NaN or infinite coordinate")
            }
            MeshError::IndexOutOfRange { triangle, index, vertices } => {
                write!(f, "triangle {triangle} uses vertex index {index}, but the mesh has {vertices} vertices")
            }
            MeshError::AttributeLength { attribute, len, vertices } => {
                write!(f, "{len} {attribute} for {vertices} vertices")
            }
            MeshError::TooManyVertices { vertices } => {
                write!(f, "{vertices} vertices do not fit 32-bit indices")
            }
        }
    }
}

impl std::error::Error for MeshError {}

impl Mesh {
    /// Checks the invariants every consumer relies on: finite positions, indices in range,
    /// attribute arrays as long as the position array. Non-finite or zero shading normals are
    /// dropped (the geometric normal is used instead) rather than rejected.
    pub fn validate(&mut self) -> Result<(), MeshError> {
        let n = self.positions.len();
        if n > u32::MAX as usize {
            return Err(MeshError::TooManyVertices { vertices: n });
        }
        if let Some(vertex) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFiniteVertex { vertex });
        }
        for (triangle, t) in self.indices.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange { triangle, index, vertices: n });
            }
        }
        if let Some(uv) = &self.uvs {
            if uv.len() != n {
                return Err(MeshError::AttributeLength {
                    attribute: "texture coordinates",
                    len: uv.len(),
                    vertices: n,
                });
            }
        }
        if let Some(nn) = &self.normals {
            if nn.len() != n {
                return Err(MeshError::AttributeLength { attribute: "normals", len: nn.len(), vertices: n });
            }
            if nn.iter().any(|v| !v.is_finite() || v.length_squared() == 0.0) {
                self.normals = None;
            }
        }
        Ok(())
    }

    #[inline]
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    pub fn aabb(&self) -> Aabb {
        // Only vertices that triangles use.
        self.indices.iter().flatten().fold(Aabb::EMPTY, |b, &i| b.grow(self.positions[i as usize]))
    }

    /// Whether a ray leaving this mesh's surface can meet the mesh again (see [`Reentry`]).
    /// Worked out for meshes of up to [`REENTRY_MAX_CHECKS`] triangle-vertex pairs (the check
    /// sets each triangle's plane against every vertex); larger ones are `Possible`.
    pub fn reentry(&self) -> Reentry {
        let corners = || self.indices.iter().flatten().map(|&i| self.positions[i as usize].as_dvec3());
        let n = self.indices.len() * 3;
        if n == 0 || self.indices.len() * n > REENTRY_MAX_CHECKS {
            return Reentry::Possible;
        }
        let b = self.aabb();
        let diag = f64::from(b.extent().length());
        let far = f64::from(b.min.abs().max(b.max.abs()).max_element());
        // How far off a plane a vertex may lie and still count as on it: the rounding of
        // coordinates (a flat quad's corners, stored as floats, are not exactly coplanar).
        let eps = f64::from(f32::EPSILON);
        let tol = 1e-6 * diag + 4.0 * eps * far;
        let normals: Vec<(glam::DVec3, glam::DVec3)> = self
            .indices
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize].as_dvec3());
                (a, (b - a).cross(c - a))
            })
            .collect();
        let Some(&(a, widest)) = normals.iter().max_by(|x, y| x.1.length_squared().total_cmp(&y.1.length_squared()))
        else {
            return Reentry::Possible;
        };
        if widest.length() <= 1e-12 * diag * diag {
            return Reentry::Possible;
        }
        let plane = widest.normalize();
        if corners().all(|v| plane.dot(v - a).abs() <= tol) {
            return Reentry::Never;
        }
        // Convex: every vertex on the centre's side of every triangle's plane, the centre
        // clearly inside (so that the side a hit point's normal gives is not lost to rounding).
        let centre = corners().sum::<glam::DVec3>() / n as f64;
        let margin = 1e-4 * diag + 64.0 * eps * far;
        let convex = normals.iter().all(|&(a, cross)| {
            let len = cross.length();
            if len <= 1e-12 * diag * diag {
                return false;
            }
            // Oriented away from the centre.
            let mut out = cross / len;
            let depth = out.dot(centre - a);
            if depth.abs() < margin {
                return false;
            }
            if depth > 0.0 {
                out = -out;
            }
            corners().all(|v| out.dot(v - a) <= tol)
        });
        if convex {
            Reentry::Inward { centre: centre.as_vec3() }
        } else {
            Reentry::Possible
        }
    }

    /// Whether every triangle lies in a face plane of the mesh's box: its three corners share
    /// the box's lowest or highest coordinate on some axis, exactly.
    pub fn on_box_faces(&self) -> bool {
        let b = self.aabb();
        self.indices.iter().all(|t| {
            let [p, q, r] = t.map(|i| self.positions[i as usize]);
            (0..3).any(|a| {
                let c = p[a];
                (c == b.min[a] || c == b.max[a]) && q[a] == c && r[a] == c
            })
        })
    }

    pub fn triangle_area(&self, i: usize) -> f32 {
        let [a, b, c] = self.triangle(i);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Drops triangles whose three indices are not all distinct; returns how many were dropped.
    pub fn drop_degenerate_indices(&mut self) -> usize {
        let before = self.indices.len();
        self.indices.retain(|[a, b, c]| a != b && b != c && a != c);
        before - self.indices.len()
    }

    /// An axis-aligned box `[min, max]` as 12 outward-facing triangles.
    pub fn cuboid(min: Vec3, max: Vec3) -> Mesh {
        let b = Aabb::new(min, max);
        let positions = b.corners().to_vec();
        // Corner index bits: x = 1, y = 2, z = 4. Faces wound counter-clockwise seen from outside.
        let quads: [[u32; 4]; 6] = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
        let indices = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        Mesh { positions, normals: None, uvs: None, indices }
    }

    /// The unit sphere as a subdivided icosahedron: closed, `20 · 4^subdiv` outward-facing
    /// triangles, every edge shared by two of them.
    pub fn icosphere(subdiv: u32) -> Mesh {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let mut p: Vec<Vec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .iter()
        .map(|v| Vec3::from(*v).normalize())
        .collect();
        let mut f: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdiv {
            let mut mids = std::collections::HashMap::new();
            let mut mid = |a: u32, b: u32, p: &mut Vec<Vec3>| -> u32 {
                *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                    p.len() as u32 - 1
                })
            };
            f = f
                .iter()
                .flat_map(|&[a, b, c]| {
                    let (ab, bc, ca) = (mid(a, b, &mut p), mid(b, c, &mut p), mid(c, a, &mut p));
                    [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
                })
                .collect();
        }
        Mesh { positions: p, normals: None, uvs: None, indices: f }
    }

    /// A parallelogram `corner + s·edge1 + t·edge2`, `s, t ∈ [0, 1]`, facing `edge1 × edge2`.
    pub fn quad(corner: Vec3, edge1: Vec3, edge2: Vec3) -> Mesh {
        Mesh {
            positions: vec![corner, corner + edge1, corner + edge1 + edge2, corner + edge2],
            normals: None,
            uvs: Some(vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y]),
            indices: vec![[0, 1, 2], [0, 2, 3]],
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn cuboid_faces_point_outwards() {
        let m = Mesh::cuboid(Vec3::ZERO, Vec3::ONE);
        let c = Vec3::splat(0.5);
        for i in 0..m.indices.len() {
            let [a, b, d] = m.triangle(i);
            let n = (b - a).cross(d - a);
            assert!(n.dot(a - c) > 0.0, "face {i} points inwards");
        }
    }

    #[test]
    fn icosphere_is_closed_and_faces_outwards() {
        let m = Mesh::icosphere(2);
        assert_eq!(m.indices.len(), 320);
        let mut edges = std::collections::HashMap::new();
        for (i, t) in m.indices.iter().enumerate() {
            let [a, b, c] = m.triangle(i);
            assert!((b - a).cross(c - a).dot(a) > 0.0);
            for k in 0..3 {
                *edges.entry((t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2));
    }

    /// Meshes of several triangles, joined from parts.
    fn joined(parts: &[Mesh]) -> Mesh {
        let mut m = Mesh::default();
        for p in parts {
            let base = m.positions.len() as u32;
            m.positions.extend(&p.positions);
            m.indices.extend(p.indices.iter().map(|t| t.map(|i| i + base)));
        }
        m
    }

    /// Shapes `Mesh::reentry` must tell apart, as they leave it: flat (whatever its place,
    /// its corners rounded to floats off the plane), convex (closed or not: a box without
    /// its lid, a sheet folded once), and neither (a step, two boxes apart, a degenerate
    /// triangle, an empty mesh).
    pub(crate) fn reentry_shapes() -> Vec<(&'static str, Mesh, Option<bool>)> {
        let mut lidless = Mesh::cuboid(Vec3::ZERO, Vec3::ONE);
        lidless.indices.retain(|t| !t.iter().all(|&i| i & 2 != 0)); // no triangle at y = 1
        let mut folded = Mesh::quad(Vec3::ZERO, Vec3::X * 4.0, Vec3::Z * 4.0);
        folded.positions[2].y = 0.3;
        let step = joined(&[
            Mesh::quad(Vec3::ZERO, Vec3::X, Vec3::Z),
            Mesh::quad(Vec3::X, Vec3::Y, Vec3::Z),
            Mesh::quad(Vec3::new(1.0, 1.0, 0.0), Vec3::X, Vec3::Z),
        ]);
        let two_boxes =
            joined(&[Mesh::cuboid(Vec3::ZERO, Vec3::ONE), Mesh::cuboid(Vec3::splat(3.0), Vec3::splat(4.0))]);
        let mut sliver = Mesh::cuboid(Vec3::ZERO, Vec3::ONE);
        sliver.indices.push([0, 1, 1]);
        // (name, mesh, Some(flat) where a ray leaving it (outwards, if convex) runs clear).
        vec![
            (
                "tilted quad far out",
                Mesh::quad(Vec3::new(1000.3, -200.7, 55.1), Vec3::new(3.1, 0.2, -1.7), Vec3::new(0.4, 2.9, 1.1)),
                Some(true),
            ),
            ("quad", Mesh::quad(Vec3::ZERO, Vec3::X, Vec3::Y), Some(true)),
            ("cuboid", Mesh::cuboid(Vec3::new(-1.0, 2.0, 0.5), Vec3::new(3.0, 2.5, 4.0)), Some(false)),
            ("icosphere", Mesh::icosphere(2), Some(false)),
            ("box without its lid", lidless, Some(false)),
            ("folded sheet", folded, Some(false)),
            ("step", step, None),
            ("two boxes", two_boxes, None),
            ("degenerate triangle", sliver, None),
            ("empty", Mesh::default(), None),
        ]
    }

    #[test]
    fn reentry_tells_flat_convex_and_other_meshes_apart() {
        for (name, m, want) in reentry_shapes() {
            let got = m.reentry();
            match (want, got) {
                (Some(true), Reentry::Never) | (None, Reentry::Possible) => {}
                (Some(false), Reentry::Inward { centre }) => {
                    // Inside every triangle's plane, as the vertices are.
                    assert!(m.aabb().contains(centre), "{name}: centre {centre} outside the box");
                }
                _ => panic!("{name}: {got:?}, expected {want:?}"),
            }
        }
        // Triangles on their box's faces: an axis-aligned quad or box, not a tilted one.
        let shapes = reentry_shapes();
        let on_faces: Vec<&str> = shapes.iter().filter(|s| s.1.on_box_faces()).map(|s| s.0).collect();
        assert_eq!(on_faces, ["quad", "cuboid", "box without its lid", "degenerate triangle", "empty"]);
        // Too large to check: left possible.
        assert_eq!(Mesh::icosphere(6).reentry(), Reentry::Possible);
    }

    #[test]
    fn validation_catches_bad_meshes() {
        let mut m = Mesh::cuboid(Vec3::ZERO, Vec3::ONE);
        m.indices.push([0, 1, 8]);
        assert!(matches!(m.validate(), Err(MeshError::IndexOutOfRange { index: 8, .. })));
        let mut m = Mesh::cuboid(Vec3::ZERO, Vec3::ONE);
        m.positions[3].y = f32::NAN;
        assert!(matches!(m.validate(), Err(MeshError::NonFiniteVertex { vertex: 3 })));
    }
}
