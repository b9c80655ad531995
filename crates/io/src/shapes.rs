//! What the scene readers share about shapes: tessellated disks, cylinders and bilinear
//! patches, baking a transform into a mesh, checked objects, and the rotation of a transform.

use glam::{Vec2, Vec3};

use snell_core::shape::Mesh;

/// The unit disk in the `z = 0` plane, facing `+z`.
pub(crate) fn disk(n: u32) -> Mesh {
    let mut positions = vec![Vec3::ZERO];
    let mut uvs = vec![Vec2::splat(0.5)];
    for i in 0..n {
        let a = i as f32 / n as f32 * std::f32::consts::TAU;
        positions.push(Vec3::new(a.cos(), a.sin(), 0.0));
        uvs.push(Vec2::new(0.5 + 0.5 * a.cos(), 0.5 + 0.5 * a.sin()));
    }
    let indices = (0..n).map(|i| [0, 1 + i, 1 + (i + 1) % n]).collect();
    Mesh { positions, normals: None, uvs: Some(uvs), indices }
}

/// An open cylinder around the segment `p0`–`p1`, normals outward.
pub(crate) fn cylinder(p0: Vec3, p1: Vec3, radius: f32, n: u32) -> Mesh {
    let axis = p1 - p0;
    let (s, t) = snell_core::geometry::orthonormal_basis(axis.normalize());
    let (mut positions, mut normals, mut uvs) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let a = i as f32 / n as f32 * std::f32::consts::TAU;
        let radial = s * a.cos() + t * a.sin();
        for (end, v) in [(p0, 0.0), (p1, 1.0)] {
            positions.push(end + radial * radius);
            normals.push(radial);
            uvs.push(Vec2::new(i as f32 / n as f32, v));
        }
    }
    let mut indices = Vec::new();
    for i in 0..n {
        let (a0, a1) = (2 * i, 2 * i + 1);
        let (b0, b1) = (2 * ((i + 1) % n), 2 * ((i + 1) % n) + 1);
        indices.push([a0, b0, b1]);
        indices.push([a0, b1, a1]);
    }
    // Wind so that the faces look outward (the winding normal agrees with the radial one).
    let tri = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        (b - a).cross(c - a)
    };
    if tri(&indices[0]).dot(normals[0] + normals[2]) < 0.0 {
        indices.iter_mut().for_each(|t| t.swap(1, 2));
    }
    Mesh { positions, normals: Some(normals), uvs: Some(uvs), indices }
}

/// Moves a mesh into world space by `m`, keeping its orientation: a transform that mirrors
/// (negative determinant) would turn the winding inside out, so the winding is swapped back.
/// `None` if `m` is not invertible.
pub(crate) fn bake(mesh: &mut Mesh, m: glam::Affine3A) -> Option<()> {
    let t = snell_core::geometry::Transform::try_new(m)?;
    for p in mesh.positions.iter_mut() {
        *p = t.point(*p);
    }
    if let Some(n) = mesh.normals.as_mut() {
        n.iter_mut().for_each(|v| *v = t.normal(*v));
    }
    if m.matrix3.determinant() < 0.0 {
        flip(mesh, false);
    }
    Some(())
}

/// Turns a mesh's faces around: swaps the winding and, if `normals`, negates the normals.
pub(crate) fn flip(mesh: &mut Mesh, normals: bool) {
    mesh.indices.iter_mut().for_each(|t| t.swap(1, 2));
    if normals {
        if let Some(n) = mesh.normals.as_mut() {
            n.iter_mut().for_each(|v| *v = -*v);
        }
    }
}

/// A mesh of bilinear patches, each given by four vertex indices `p00, p10, p01, p11` (pbrt's
/// order). A flat patch becomes two triangles; a curved one a grid of `n × n` quads.
pub(crate) fn bilinear(
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    uvs: Option<&[Vec2]>,
    patches: &[[u32; 4]],
    n: u32,
) -> Mesh {
    let mut out = Mesh { positions: Vec::new(), normals: normals.map(|_| Vec::new()), uvs: None, indices: Vec::new() };
    let mut out_uvs = Vec::new();
    for q in patches {
        let p = q.map(|i| positions[i as usize]);
        let flat = {
            let nrm = (p[1] - p[0]).cross(p[2] - p[0]);
            let scale = (p[3] - p[0]).length().max(1e-20);
            nrm.length() == 0.0 || (nrm.normalize().dot(p[3] - p[0]) / scale).abs() < 1e-5
        };
        let k = if flat { 1 } else { n };
        let base = out.positions.len() as u32;
        for j in 0..=k {
            for i in 0..=k {
                let (s, t) = (i as f32 / k as f32, j as f32 / k as f32);
                let lerp4 =
                    |a: [Vec3; 4]| (a[0] * (1.0 - s) + a[1] * s) * (1.0 - t) + (a[2] * (1.0 - s) + a[3] * s) * t;
                out.positions.push(lerp4(p));
                if let (Some(ns), Some(o)) = (normals, out.normals.as_mut()) {
                    o.push(lerp4(q.map(|i| ns[i as usize])).normalize_or_zero());
                }
                let uv = match uvs {
                    Some(uv) => {
                        let u = q.map(|i| uv[i as usize].extend(0.0));
                        lerp4(u).truncate()
                    }
                    None => Vec2::new(s, t),
                };
                out_uvs.push(uv);
            }
        }
        let row = k + 1;
        for j in 0..k {
            for i in 0..k {
                let a = base + j * row + i;
                // Winding p00 → p10 → p11, so the normal is (p10 - p00) × (p01 - p00), as pbrt's.
                out.indices.push([a, a + 1, a + row + 1]);
                out.indices.push([a, a + row + 1, a + row]);
            }
        }
    }
    out.uvs = Some(out_uvs);
    out
}

/// An object placing `geometry` by `outer · inner` (either may be absent), checked: the
/// transform must be invertible, and an emitting sphere may only be scaled uniformly (its
/// light is sampled as a sphere).
pub(crate) fn object(
    geometries: &[snell_core::scene::Geometry],
    geometry: usize,
    outer: Option<glam::Affine3A>,
    inner: Option<glam::Affine3A>,
    material: usize,
    emission: snell_core::Rgb,
) -> Result<snell_core::scene::Object, &'static str> {
    use snell_core::geometry::Transform;
    let m = match (outer, inner) {
        (Some(a), Some(b)) => Some(a * b),
        (a, b) => a.or(b),
    };
    let transform = match m {
        Some(m) => Some(Transform::try_new(m).ok_or("the transform is not invertible")?),
        None => None,
    };
    if emission != snell_core::Rgb::ZERO {
        if let (Some(snell_core::scene::Geometry::Sphere(_)), Some(t)) = (geometries.get(geometry), &transform) {
            if t.uniform_scale().is_none() {
                return Err("an emitting sphere may only be scaled uniformly");
            }
        }
    }
    Ok(snell_core::scene::Object { geometry, transform, material, emission, light_samples: 1 })
}

/// The rotation part of `m` (its axes normalised), for environments, which turn but do not scale.
pub(crate) fn rotation(m: glam::Affine3A) -> glam::Mat3 {
    glam::Mat3::from_cols(
        Vec3::from(m.matrix3.x_axis).normalize_or_zero(),
        Vec3::from(m.matrix3.y_axis).normalize_or_zero(),
        Vec3::from(m.matrix3.z_axis).normalize_or_zero(),
    )
}
