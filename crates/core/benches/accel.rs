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

/// The icosphere with a smooth bumpy displacement, so that the surface is not convex.
fn bumpy_icosphere(subdiv: u32) -> Mesh {
    let mut m = Mesh::icosphere(subdiv);
    for v in &mut m.positions {
        *v *= 1.0 + 0.15 * (5.0 * v.x).sin() * (7.0 * v.y).cos() * (3.0 * v.z).sin();
    }
    m
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
        light_selection: Default::default(),
    }
}

fn benches(c: &mut Criterion) {
    let s = scene(bumpy_icosphere(5));
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
