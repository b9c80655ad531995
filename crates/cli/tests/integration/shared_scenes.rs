//! Tests on the shared real meshes (`SNELL_SCENES`, set by `.ci/run`).

use glam::Vec3;
use snell_core::accel::{AccelParams, Brute, Bvh, BvhParams, SplitMethod};
use snell_core::geometry::Ray;
use snell_core::scene::{Geometry, Object, World};
use snell_core::Rgb;

use crate::accel::{assert_watertight, scene_of};
use crate::common::{run, shared_scene, stderr};

#[test]
fn bunny_obj_and_ply_give_identical_geometry() {
    let (Some(obj), Some(ply)) = (shared_scene("stanford/bunny.obj"), shared_scene("stanford/bunny.ply")) else {
        return;
    };
    let a = snell_io::read_mesh(&obj).unwrap();
    let b = snell_io::read_mesh(&ply).unwrap();
    assert_eq!(a.indices.len(), 69_451);
    assert_eq!(a.indices.len(), b.indices.len());
    // The OBJ prints 6 significant digits, so positions agree to about 1e-7 (coordinates ~0.1).
    let close = |p: Vec3, q: Vec3| (p - q).abs().max_element() <= 1e-6;
    assert!(close(a.aabb().min, b.aabb().min) && close(a.aabb().max, b.aabb().max));
    // Triangle by triangle, the same corners (the OBJ keeps the PLY's face order).
    let mismatches =
        (0..a.indices.len()).filter(|&i| !a.triangle(i).iter().zip(b.triangle(i)).all(|(p, q)| close(*p, q))).count();
    assert_eq!(mismatches, 0);
}

#[test]
fn dragon_loads_with_every_triangle() {
    let Some(p) = shared_scene("stanford/dragon_vrip_res4.ply") else {
        return;
    };
    let m = snell_io::read_mesh(&p).unwrap();
    assert!(m.indices.len() >= 11_000 && m.indices.len() <= 11_102, "{}", m.indices.len());
    let b = m.aabb();
    assert!((b.min - Vec3::new(-0.1076, 0.0528, -0.0498)).abs().max_element() < 1e-4, "{b:?}");
}

#[test]
fn bvh_matches_brute_force_on_the_bunny() {
    let Some(p) = shared_scene("stanford/bunny.ply") else {
        return;
    };
    let mesh = snell_io::read_mesh(&p).unwrap();
    let b = mesh.aabb();
    let scene = scene_of(
        vec![Geometry::Mesh(mesh)],
        vec![Object { geometry: 0, transform: None, material: 0, emission: Rgb::ZERO, light_samples: 1 }],
    );
    let brute: World<Brute> = World::build(&scene, &AccelParams::default());
    let bvh: World<Bvh> = World::build(&scene, &BvhParams { split: SplitMethod::Sah, base: AccelParams::default() });
    // The benchmark's camera, on a coarse grid of pixels.
    let c = b.center();
    let r = b.extent().length() * 0.5;
    let eye = c + Vec3::new(0.3, 0.4, 1.0).normalize() * (0.8 * r / 20f32.to_radians().tan());
    let cam = snell_core::camera::Camera::look_at(
        eye,
        c,
        Vec3::Y,
        snell_core::camera::Projection::Perspective { fov_y: 40.0 },
    )
    .unwrap();
    let mut hits = 0;
    for y in 0..16 {
        for x in 0..16 {
            let ray: Ray =
                cam.ray(glam::Vec2::new(x as f32 * 64.0 + 32.0, y as f32 * 64.0 + 32.0), 1024, 1024, glam::Vec2::ZERO);
            let a = brute.intersect(&ray, f32::INFINITY);
            let h = bvh.intersect(&ray, f32::INFINITY);
            assert_eq!(a.is_some(), h.is_some(), "pixel {x},{y}");
            if let (Some(a), Some(h)) = (a, h) {
                assert!((a.t - h.t).abs() < 1e-6 * a.t.max(1.0));
                hits += 1;
            }
        }
    }
    assert!(hits > 40, "{hits}");
    // The default accelerator's memory target (Embree: 66-72 bytes per triangle).
    let per_tri = bvh.bytes() as f64 / scene.triangle_count() as f64;
    assert!(per_tri <= 64.0, "{per_tri:.1} bytes per triangle");
}

#[test]
fn spot_is_watertight() {
    let Some(p) = shared_scene("misc/spot.obj") else {
        return;
    };
    let m = snell_io::read_mesh(&p).unwrap();
    assert!(assert_watertight(&m, None) > 10_000);
}

#[test]
fn bunny_renders_as_a_bare_mesh() {
    let Some(p) = shared_scene("stanford/bunny.ply") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let o = run(
        &["render", p.to_str().unwrap(), "-o", "bunny.png", "--width", "32", "--height", "32", "--spp", "1"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("bunny.png").is_file());
}

#[test]
fn a_thousand_instanced_bunnies_share_one_mesh() {
    let Some(bunny) = shared_scene("stanford/bunny.ply") else { return };
    let src = format!(
        "[render]\nbackground = 0.5\n[[lights]]\ntype = \"directional\"\ndirection = [0, -1, 0]\n[[shapes]]\ntype = \"mesh\"\nfile = {:?}\ntransform = [{{ rotate = {{ axis = [0, 1, 0], angle = 30 }} }}]\narray = {{ count = [10, 10, 10], step = [0.2, 0.2, 0.2] }}\n",
        bunny.to_str().unwrap()
    );
    let l = snell_io::scene::parse(&src, std::path::Path::new("instances.toml")).unwrap();
    assert_eq!(l.scene.geometries.len(), 1, "the mesh must be stored once");
    assert_eq!(l.scene.objects.len(), 1000);
    assert_eq!(l.scene.triangle_count(), 1000 * 69_451);
    // Every instance is boxed by its own transformed corners, and renders.
    let b0 = l.scene.object_aabb(&l.scene.objects[0]);
    let b999 = l.scene.object_aabb(&l.scene.objects[999]);
    assert!(((b999.min - b0.min) - Vec3::splat(1.8)).abs().max_element() < 1e-4);
    let o = crate::images::Opts { width: 24, height: 24, spp: 1, ..Default::default() };
    let (img, stats) = crate::images::render_loaded(&l, &o);
    // Some pixels show the background, some show lit bunnies.
    assert!(img.pixels.iter().any(|p| (p.x - 0.5).abs() < 1e-6));
    assert!(img.pixels.iter().any(|p| (p.x - 0.5).abs() > 1e-3));
    assert_eq!(stats.camera, 24 * 24);
}

#[test]
fn the_bunnies_example_scene_loads() {
    if shared_scene("stanford/bunny.ply").is_none() {
        return;
    }
    // scenes/bunnies.toml reads the bunny from ../shared beside the checkout.
    let p = crate::common::repo_scene("bunnies.toml");
    if std::fs::metadata(p.parent().unwrap().join("../../shared/scenes/stanford/bunny.ply")).is_err() {
        eprintln!("../shared is not beside this checkout: skipping scenes/bunnies.toml");
        return;
    }
    let l = snell_io::scene::load(&p).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(l.scene.objects.len(), 1001);
    assert_eq!(l.scene.geometries.len(), 2);
}

#[test]
fn hdr_and_exr_environment_maps_light_the_path_tracer() {
    for rel in ["envmaps/spiaggia_di_mondello_1k.hdr", "envmaps/museum.exr"] {
        let Some(p) = shared_scene(rel) else { return };
        let src = format!(
            "[render]\nintegrator = \"path\"\n[camera]\neye = [0, 0, 4]\nfov = 30\n\
             [[lights]]\ntype = \"environment\"\nfile = {:?}\nrotate_y = 45\n\
             [[shapes]]\ntype = \"sphere\"\nradius = 1\n",
            p.to_str().unwrap()
        );
        let l = snell_io::scene::parse(&src, std::path::Path::new("/env.toml")).unwrap_or_else(|e| panic!("{e}"));
        match &l.scene.lights[0] {
            snell_core::light::Light::Environment(e) => {
                let m = e.map.as_ref().unwrap();
                assert_eq!(m.width, 2 * m.height, "{rel}: equirectangular");
            }
            other => panic!("{other:?}"),
        }
        let (img, _) = crate::images::render_loaded(
            &l,
            &crate::images::Opts { width: 16, height: 16, spp: 4, ..Default::default() },
        );
        assert!(img.pixels.iter().all(|p| p.is_finite() && p.max_element() > 0.0), "{rel}");
    }
    let e = snell_io::scene::parse(
        "[[lights]]\ntype = \"environment\"\nfile = \"nowhere.hdr\"\n",
        std::path::Path::new("/tmp/x.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("nowhere.hdr") && e.contains("no such file"), "{e}");
}
