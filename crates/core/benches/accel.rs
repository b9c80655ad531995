//! Build and traversal of every accelerator on a procedural bumpy icosphere (20·4^5 = 20,480
//! triangles; core has no file I/O, so the mesh is made here), with the benchmark workload's
//! camera at 128×128 and its diffuse bounce rays.
//!
//!   cargo bench -p snell-core --bench accel
//!
//! For the comparison with Embree on the real meshes, use `snell bench` (see the README).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::Vec3;
use snell_core::accel::{AccelKind, AccelParams};
use snell_core::camera::{Camera, Projection};
use snell_core::geometry::Ray;
use snell_core::material::Material;
use snell_core::scene::{Geometry, Object, Scene};
use snell_core::shape::Mesh;
use snell_core::{with_world, Rgb};

fn icosphere(subdiv: u32) -> Mesh {
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
        let mut cache = std::collections::HashMap::new();
        let mut mid = |a: u32, b: u32, p: &mut Vec<Vec3>| -> u32 {
            *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
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
    // A smooth bumpy displacement, so the surface is not convex.
    let p = p.iter().map(|v| *v * (1.0 + 0.15 * (5.0 * v.x).sin() * (7.0 * v.y).cos() * (3.0 * v.z).sin())).collect();
    Mesh { positions: p, normals: None, uvs: None, indices: f }
}

fn scene(mesh: Mesh) -> Scene {
    Scene {
        geometries: vec![Geometry::Mesh(mesh)],
        objects: vec![Object { geometry: 0, transform: None, material: 0, emission: Rgb::ZERO, light_samples: 1 }],
        materials: vec![Material::Diffuse { albedo: Rgb::ONE.into() }],
        lights: vec![],
        camera: Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 40.0 }).unwrap(),
        background: Rgb::ZERO,
        ambient: Rgb::ZERO,
    }
}

fn benches(c: &mut Criterion) {
    let s = scene(icosphere(5));
    let Geometry::Mesh(mesh) = &s.geometries[0] else { unreachable!() };
    let primary = snell_core::bench::primary_rays(&mesh.positions, 128, 128, 40.0);
    let params = AccelParams::default();
    let reference = AccelKind::DEFAULT.build_world(&s, &params);
    let hits: Vec<Option<(f32, Vec3)>> = with_world!(&reference, w => primary
        .iter()
        .map(|r| w.hit(r, f32::INFINITY).map(|h| {
            let [a, b, c] = mesh.triangle(h.prim as usize);
            (h.t, (b - a).cross(c - a))
        }))
        .collect());
    let bounce: Vec<Ray> = snell_core::bench::bounce_rays(&primary, &hits, snell_core::bench::radius(&mesh.positions));

    let mut g = c.benchmark_group("build");
    g.sample_size(10);
    for kind in AccelKind::ALL {
        g.bench_function(BenchmarkId::from_parameter(kind.name()), |b| b.iter(|| kind.build_world(&s, &params)));
    }
    g.finish();

    for (name, rays) in [("primary", &primary), ("bounce", &bounce)] {
        let mut g = c.benchmark_group(format!("closest/{name}"));
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.sample_size(10);
        for kind in AccelKind::ALL.into_iter().filter(|k| *k != AccelKind::Brute) {
            let world = kind.build_world(&s, &params);
            g.bench_function(BenchmarkId::from_parameter(kind.name()), |b| {
                b.iter(|| with_world!(&world, w => rays.iter().filter(|r| w.hit(r, f32::INFINITY).is_some()).count()))
            });
        }
        g.finish();
    }
    let mut g = c.benchmark_group("any/bounce");
    g.throughput(Throughput::Elements(bounce.len() as u64));
    g.sample_size(10);
    for kind in AccelKind::ALL.into_iter().filter(|k| *k != AccelKind::Brute) {
        let world = kind.build_world(&s, &params);
        g.bench_function(BenchmarkId::from_parameter(kind.name()), |b| {
            b.iter(|| with_world!(&world, w => bounce.iter().filter(|r| w.occluded(r, f32::INFINITY)).count()))
        });
    }
    g.finish();
}

criterion_group!(accel, benches);
criterion_main!(accel);
