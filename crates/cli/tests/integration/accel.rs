//! Acceleration structures against the brute-force oracle, through the whole two-level world
//! (meshes, instances with transforms, spheres), plus watertightness and instance boxes.

use glam::{Affine3A, Quat, Vec3};
use snell_core::accel::{
    Accel, AccelKind, AccelParams, AnyWorld, Brute, Bvh, BvhParams, Grid, GridParams, KdParams, KdTree, SplitMethod,
};
use snell_core::camera::{Camera, Projection};
use snell_core::geometry::{Ray, Transform};
use snell_core::material::Material;
use snell_core::sampling::Pcg32;
use snell_core::scene::{Geometry, Object, RawHit, Scene, World};
use snell_core::shape::{intersect_triangle, Mesh, Sphere, WatertightRay};
use snell_core::Rgb;

fn rand_vec(rng: &mut Pcg32, scale: f32) -> Vec3 {
    Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5) * (2.0 * scale)
}

fn object(geometry: usize, transform: Option<Transform>) -> Object {
    Object { geometry, transform, material: 0, emission: Rgb::ZERO, light_samples: 1 }
}

pub fn scene_of(geometries: Vec<Geometry>, objects: Vec<Object>) -> Scene {
    Scene {
        geometries,
        objects,
        materials: vec![Material::Diffuse { albedo: Rgb::ONE.into() }],
        lights: vec![],
        camera: Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 40.0 }).unwrap(),
        background: Rgb::ZERO,
        ambient: Rgb::ZERO,
        light_selection: Default::default(),
    }
}

/// A random soup plus adversarial pieces: coplanar and axis-aligned triangles, zero-area
/// triangles, a cluster of triangles in one point, huge coordinates, a cube and its instances,
/// and spheres (one under a non-uniform scale).
fn adversarial_scene(seed: u64) -> Scene {
    let mut rng = Pcg32::new(seed, 7);
    let mut soup = Mesh::default();
    for _ in 0..300 {
        let c = rand_vec(&mut rng, 4.0);
        for _ in 0..3 {
            soup.positions.push(c + rand_vec(&mut rng, 0.6));
        }
    }
    // Coplanar, axis-aligned triangles in the plane z = 0.5.
    for i in 0..20 {
        let x = i as f32 * 0.2 - 2.0;
        soup.positions.extend([Vec3::new(x, -1.0, 0.5), Vec3::new(x + 0.3, -1.0, 0.5), Vec3::new(x, 1.0, 0.5)]);
    }
    // Zero-area triangles (a line and a point) and many triangles collapsed to one point.
    soup.positions.extend([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
    soup.positions.extend([Vec3::ONE; 3]);
    for _ in 0..20 {
        soup.positions.extend([Vec3::splat(-1.5); 3]);
    }
    soup.indices = (0..soup.positions.len() as u32 / 3).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    let cube = Mesh::cuboid(Vec3::splat(-0.5), Vec3::splat(0.5));
    let huge = Mesh::quad(Vec3::new(-1e6, -1e6, -20.0), Vec3::new(2e6, 0.0, 0.0), Vec3::new(0.0, 2e6, 0.0));
    let geometries = vec![
        Geometry::Mesh(soup),
        Geometry::Mesh(cube),
        Geometry::Sphere(Sphere { center: Vec3::ZERO, radius: 0.7 }),
        Geometry::Mesh(huge),
    ];
    let mut objects = vec![object(0, None), object(3, None)];
    for i in 0..12 {
        let m = Affine3A::from_scale_rotation_translation(
            Vec3::new(0.5 + rng.next_f32(), 0.5 + rng.next_f32(), 0.5 + rng.next_f32()),
            Quat::from_axis_angle(rand_vec(&mut rng, 1.0).normalize(), rng.next_f32() * 6.0),
            rand_vec(&mut rng, 5.0),
        );
        objects.push(object(if i % 3 == 0 { 2 } else { 1 }, Transform::try_new(m)));
    }
    objects.push(object(2, None));
    scene_of(geometries, objects)
}

fn rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Pcg32::new(seed, 3);
    let b = scene.aabb();
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let o = rand_vec(&mut rng, 8.0);
        let d = match i % 4 {
            // Aimed at a random point near the origin: mostly hits.
            0 | 1 => rand_vec(&mut rng, 3.0) - o,
            // Axis-aligned directions, including ±0 components.
            2 => [Vec3::X, -Vec3::Y, Vec3::Z, Vec3::new(-0.0, 0.0, -1.0)][(i / 4) % 4],
            _ => rand_vec(&mut rng, 1.0),
        };
        let _ = b;
        out.push(Ray::new(o, d));
    }
    // Rays starting inside boxes and along box faces.
    out.push(Ray::new(Vec3::ZERO, Vec3::X));
    out.push(Ray::new(Vec3::new(-0.5, 0.5, 3.0), -Vec3::Z));
    out
}

fn scene_scale(scene: &Scene) -> f32 {
    let b = scene.aabb();
    b.min.abs().max(b.max.abs()).max_element()
}

fn check_against_brute<A: Accel>(name: &str, scene: &Scene, params: &A::Params, rays: &[Ray]) {
    let oracle: World<Brute> = World::build(scene, &AccelParams::default());
    let world: World<A> = World::build(scene, params);
    let mut hits = 0;
    for (i, r) in rays.iter().enumerate() {
        let a = oracle.intersect(r, f32::INFINITY);
        let b = world.intersect(r, f32::INFINITY);
        match (a, b) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                hits += 1;
                let tol = 1e-5 * a.t.max(1.0);
                assert!((a.t - b.t).abs() <= tol, "{name} ray {i}: t {} vs brute {}", b.t, a.t);
                // Same object unless two surfaces are hit at the same distance (a tie).
                if a.object != b.object {
                    assert!((a.t - b.t).abs() <= tol, "{name} ray {i}: object {} vs brute {}", b.object, a.object);
                }
                // The same point, found from the hit triangle and its barycentrics (a tie
                // between triangles is the same point too).
                let p_tol = 1e-4 * a.t.max(1.0) + 1e-5 * scene_scale(scene);
                assert!((a.p - b.p).length() <= p_tol, "{name} ray {i}: p {} vs brute {}", b.p, a.p);
                // Any hit agrees with closest hit. The margin covers the triangle test's own
                // error, which grows with the coordinates (the ±1e6 quad reports t to ~1e-3).
                let margin = a.t * 1e-3 + 1e-6 * scene_scale(scene);
                assert!(world.occluded(r, a.t + margin), "{name} ray {i}: occluded misses the closest hit");
                assert!(!world.occluded(r, a.t * 0.999), "{name} ray {i}: occluded before the closest hit");
            }
            (a, b) => panic!("{name} ray {i} {r:?}: brute {:?} vs {:?}", a.map(|h| h.t), b.map(|h| h.t)),
        }
        assert_eq!(world.occluded(r, f32::INFINITY), a.is_some(), "{name} ray {i}: occluded(inf)");
    }
    assert!(hits > rays.len() / 3, "{name}: only {hits} of {} rays hit; the test is too easy", rays.len());
}

#[test]
fn every_accelerator_matches_brute_force_on_an_adversarial_scene() {
    for seed in [1, 2] {
        let scene = adversarial_scene(seed);
        let rays = rays(&scene, 3000, seed);
        for split in
            [SplitMethod::Center, SplitMethod::Median, SplitMethod::Sah, SplitMethod::Spatial, SplitMethod::Morton]
        {
            for max_leaf_prims in [1, 4] {
                let params = BvhParams { split, base: AccelParams { max_leaf_prims, ..AccelParams::default() } };
                check_against_brute::<Bvh>(&format!("{split:?}/{max_leaf_prims}"), &scene, &params, &rays);
            }
        }
        // A depth limit that forces big leaves.
        let params =
            BvhParams { split: SplitMethod::Sah, base: AccelParams { max_depth: 3, ..AccelParams::default() } };
        check_against_brute::<Bvh>("sah/depth3", &scene, &params, &rays);
        for (leaf, bonus) in [(1, 0.5), (4, 0.5), (4, 0.0), (8, 0.9)] {
            let base = AccelParams { max_leaf_prims: leaf, ..AccelParams::default() };
            let params = KdParams { empty_bonus: bonus, ..KdParams::new(base) };
            check_against_brute::<KdTree>(&format!("kdtree/{leaf}/{bonus}"), &scene, &params, &rays);
        }
        for lambda in [0.5, 3.0, 12.0] {
            let params = GridParams { base: AccelParams::default(), lambda };
            check_against_brute::<Grid>(&format!("grid/{lambda}"), &scene, &params, &rays);
        }
    }
}

#[test]
fn empty_and_single_primitive_scenes() {
    let empty = scene_of(vec![], vec![]);
    for kind in AccelKind::ALL {
        let w = kind.build_world(&empty, &AccelParams::default());
        let r = Ray::new(Vec3::ZERO, Vec3::X);
        snell_core::with_world!(&w, w => {
            assert!(w.intersect(&r, f32::INFINITY).is_none());
            assert!(!w.occluded(&r, f32::INFINITY));
        });
    }
    let one =
        Mesh { positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y], normals: None, uvs: None, indices: vec![[0, 1, 2]] };
    let scene = scene_of(vec![Geometry::Mesh(one)], vec![object(0, None)]);
    let r = Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z);
    for kind in AccelKind::ALL {
        let w = kind.build_world(&scene, &AccelParams::default());
        let hit = snell_core::with_world!(&w, w => w.intersect(&r, f32::INFINITY));
        assert!((hit.unwrap().t - 1.0).abs() < 1e-6, "{kind}");
        assert!(matches!(w, AnyWorld::Brute(_) | AnyWorld::Bvh(_) | AnyWorld::KdTree(_) | AnyWorld::Grid(_)));
    }
}

#[test]
fn bvh_statistics_are_sane() {
    let scene = adversarial_scene(3);
    let params = BvhParams { split: SplitMethod::Sah, base: AccelParams::default() };
    let world: World<Bvh> = World::build(&scene, &params);
    let (_, blas) = world.structures();
    let soup = blas[0].as_ref().unwrap().stats();
    let Geometry::Mesh(m) = &scene.geometries[0] else { unreachable!() };
    // Every non-degenerate-box triangle is referenced exactly once (a BVH never duplicates).
    assert_eq!(soup.prim_refs, m.indices.len());
    // Wide nodes: at least (leaves - 1) / (width - 1) of them, at most leaves - 1.
    let w = snell_core::accel::BVH_WIDTH;
    assert!(soup.nodes >= (soup.leaves - 1) / (w - 1) && soup.nodes < soup.leaves, "{soup:?}");
    assert!(soup.max_depth <= 24);
    assert!(soup.sah_cost > 1.0 && soup.sah_cost < m.indices.len() as f32);
}

/// Trees of a single wide node (a top level of at most eight objects, a mesh of at most eight
/// leaves) are queried without a stack, nearest child first: they give brute force's hits,
/// through edges, coplanar pieces and objects that overlap (ties), with one and with several
/// triangles per leaf.
#[test]
fn one_node_trees_match_brute_force() {
    let mut rng = Pcg32::new(11, 5);
    // 36 triangles: more than a mesh tested block by block, few enough for one node's leaves.
    let mut soup = Mesh::default();
    for _ in 0..36 {
        let c = rand_vec(&mut rng, 1.5);
        for _ in 0..3 {
            soup.positions.push(c + rand_vec(&mut rng, 0.8));
        }
    }
    soup.indices = (0..36).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    let quad = Mesh::quad(Vec3::new(-2.0, -2.0, 0.0), Vec3::X * 4.0, Vec3::Y * 4.0);
    let cube = Mesh::cuboid(Vec3::splat(-0.5), Vec3::splat(0.5));
    let geometries = vec![
        Geometry::Mesh(soup),
        Geometry::Mesh(quad),
        Geometry::Mesh(cube),
        Geometry::Sphere(Sphere { center: Vec3::ZERO, radius: 0.7 }),
    ];
    let moved = |x: f32, y: f32, z: f32| Transform::try_new(Affine3A::from_translation(Vec3::new(x, y, z)));
    // Seven objects: the soup, the quad twice in one plane (ties), cubes overlapping the sphere.
    let objects = vec![
        object(0, None),
        object(1, None),
        object(1, moved(1.0, 0.0, 0.0)),
        object(2, None),
        object(2, moved(0.3, 0.2, 0.1)),
        object(3, None),
        object(3, moved(2.0, 1.0, -1.0)),
    ];
    let scene = scene_of(geometries, objects);
    // Aimed at the objects from all around, and the shared adversarial rays.
    let mut rays: Vec<Ray> = (0..3000)
        .map(|_| {
            let o = rand_vec(&mut rng, 5.0);
            Ray::new(o, rand_vec(&mut rng, 1.5) - o)
        })
        .collect();
    rays.extend(self::rays(&scene, 1000, 4));
    for max_leaf_prims in [1, 4] {
        let params =
            BvhParams { split: SplitMethod::Sah, base: AccelParams { max_leaf_prims, ..AccelParams::default() } };
        let world: World<Bvh> = World::build(&scene, &params);
        let (top, blas) = world.structures();
        assert_eq!(top.stats().nodes, 1, "{:?}", top.stats());
        let soup = blas[0].as_ref().unwrap().stats();
        assert!(soup.nodes == 1 && soup.leaves > 1, "{soup:?}");
        check_against_brute::<Bvh>(&format!("one node/{max_leaf_prims}"), &scene, &params, &rays);
    }
}

/// A scene of one untransformed mesh in leaves (the bench's meshes, the bunny and dragon
/// renders) is queried by its own tree straight from `World::hit` and `World::occluded`,
/// past the object layers: closest and any-hit queries against brute force, on a displaced
/// icosphere and on a triangle soup whose triangles cross, for several leaf sizes and builds.
#[test]
fn one_mesh_scenes_match_brute_force() {
    let mut rng = Pcg32::new(17, 3);
    let ball = crate::common::bumpy_ball(&mut rng);
    let mut soup = Mesh::default();
    for i in 0..300u32 {
        let c = rand_vec(&mut rng, 1.5);
        soup.positions.extend((0..3).map(|_| c + rand_vec(&mut rng, 0.6)));
        soup.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    for (name, mesh) in [("ball", ball), ("soup", soup)] {
        let scene = scene_of(vec![Geometry::Mesh(mesh)], vec![object(0, None)]);
        // Aimed at the mesh from all around, and the shared adversarial rays.
        let mut rays: Vec<Ray> = (0..3000)
            .map(|_| {
                let o = rand_vec(&mut rng, 5.0);
                Ray::new(o, rand_vec(&mut rng, 1.0) - o)
            })
            .collect();
        rays.extend(self::rays(&scene, 1000, 8));
        for split in [SplitMethod::Sah, SplitMethod::Spatial] {
            for max_leaf_prims in [1, 4, 8] {
                let params = BvhParams { split, base: AccelParams { max_leaf_prims, ..AccelParams::default() } };
                let world: World<Bvh> = World::build(&scene, &params);
                assert!(world.structures().1[0].as_ref().unwrap().stats().leaves > 1);
                check_against_brute::<Bvh>(&format!("{name}/{split:?}/{max_leaf_prims}"), &scene, &params, &rays);
            }
        }
    }
}

/// `World::occluded_walk_only` (`snell bench --walk-only`) walks a one-mesh world's tree with no
/// triangle test, so it never answers "blocked" where the query does; a world of two objects has
/// no single tree to walk.
#[test]
fn the_walk_alone_tests_no_triangle() {
    let mut rng = Pcg32::new(5, 9);
    let scene = scene_of(vec![Geometry::Mesh(Mesh::icosphere(3))], vec![object(0, None)]);
    let params = BvhParams { split: SplitMethod::Sah, base: AccelParams::default() };
    let world: World<Bvh> = World::build(&scene, &params);
    assert!(world.structures().1[0].as_ref().unwrap().stats().leaves > 1);
    for _ in 0..200 {
        // From outside the sphere towards a point near its centre: blocked.
        let o = rand_vec(&mut rng, 1.0).normalize_or(Vec3::X) * 4.0;
        let r = Ray::new(o, rand_vec(&mut rng, 0.2) - o);
        assert!(world.occluded(&r, f32::INFINITY), "{r:?}");
        assert_eq!(world.occluded_walk_only(&r, f32::INFINITY), Some(false), "{r:?}");
    }
    let moved = Transform::try_new(Affine3A::from_translation(Vec3::new(3.0, 0.0, 0.0)));
    let two = scene_of(vec![Geometry::Mesh(Mesh::icosphere(3))], vec![object(0, None), object(0, moved)]);
    let world: World<Bvh> = World::build(&two, &params);
    assert_eq!(world.occluded_walk_only(&Ray::new(Vec3::new(0.0, 0.0, 4.0), -Vec3::Z), f32::INFINITY), None);
}

/// The top level keeps one object per leaf whatever the SAH would prefer: every object's box is
/// tested before its own structure is entered (merging small objects into one leaf made the
/// default scene 25 % slower).
#[test]
fn top_level_has_one_object_per_leaf() {
    let quad = Mesh::quad(Vec3::ZERO, Vec3::X, Vec3::Y);
    let objects: Vec<_> = (0..7)
        .map(|i| {
            let m = glam::Affine3A::from_translation(Vec3::new(i as f32 * 1.5, (i % 3) as f32, 0.0));
            object(0, Transform::try_new(m))
        })
        .collect();
    let scene = scene_of(vec![Geometry::Mesh(quad)], objects);
    let params = BvhParams { split: SplitMethod::Sah, base: AccelParams::default() };
    let world: World<Bvh> = World::build(&scene, &params);
    let (top, _) = world.structures();
    assert_eq!(top.stats().leaves, 7, "{:?}", top.stats());
}

/// The default accelerator takes at most 64 bytes per triangle, nodes and triangle blocks
/// counted (Embree: 66-72). Counting leaf cost in blocks of four in the SAH is what gets it
/// there: on this sphere the blocks are 96 % full (58 bytes per triangle), against 81 % (76
/// bytes) when the SAH counted triangles. Since the BVH frees its leaves' primitive lists once
/// they are relabelled with the blocks' ranges, it is 54.4.
#[test]
fn default_accelerator_fits_in_64_bytes_per_triangle() {
    let mesh = icosphere(6);
    let tris = mesh.indices.len();
    let scene = scene_of(vec![Geometry::Mesh(mesh)], vec![object(0, None)]);
    let world = AccelKind::DEFAULT.build_world(&scene, &AccelParams::default());
    let (bytes, blocks) = snell_core::with_world!(&world, w => (w.bytes(), w.triangle_blocks()));
    let per_tri = bytes as f64 / tris as f64;
    assert!(per_tri <= 64.0, "{per_tri:.1} bytes per triangle");
    let fill = tris as f64 / (4 * blocks) as f64;
    assert!(fill > 0.9, "blocks {:.1} % full", 100.0 * fill);
}

/// An icosphere (closed, every edge shared by two triangles, every vertex by five or six),
/// moved and scaled so that its coordinates are not round numbers.
pub fn icosphere(subdiv: u32) -> Mesh {
    let mut m = Mesh::icosphere(subdiv);
    for p in &mut m.positions {
        *p = *p * 1.37 + Vec3::new(0.1, -0.3, 0.7);
    }
    m
}

/// Rays that cross the surface exactly at every vertex and every edge midpoint of `mesh` must
/// hit it at or before that point: those are the rays that slip through shared edges and
/// vertices with a non-watertight test. Each ray arrives along the local inward normal (the
/// mean of the adjacent face normals), so it enters the surface there rather than grazing it.
/// Also rays from an interior point `inside` (if given) must hit the closed surface.
pub fn assert_watertight(mesh: &Mesh, inside: Option<Vec3>) -> usize {
    let scene = scene_of(vec![Geometry::Mesh(mesh.clone())], vec![object(0, None)]);
    let params = BvhParams { split: SplitMethod::Sah, base: AccelParams::default() };
    let world: World<Bvh> = World::build(&scene, &params);
    let dist = mesh.aabb().extent().length() * 2.0;
    let face_n: Vec<Vec3> = (0..mesh.indices.len())
        .map(|i| {
            let [a, b, c] = mesh.triangle(i);
            (b - a).cross(c - a).normalize_or_zero()
        })
        .collect();
    let mut vertex_n = vec![Vec3::ZERO; mesh.positions.len()];
    let mut edges: std::collections::HashMap<(u32, u32), Vec3> = std::collections::HashMap::new();
    for (t, n) in mesh.indices.iter().zip(&face_n) {
        for k in 0..3 {
            vertex_n[t[k] as usize] += *n;
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += *n;
        }
    }
    let mut targets: Vec<(Vec3, Vec3)> = mesh.positions.iter().copied().zip(vertex_n).collect();
    for ((a, b), n) in edges {
        targets.push(((mesh.positions[a as usize] + mesh.positions[b as usize]) * 0.5, n));
    }
    let mut tested = 0;
    for (i, &(q, n)) in targets.iter().enumerate() {
        let Some(n) = n.try_normalize() else { continue };
        let o = q + n * dist;
        let r = Ray::new(o, q - o);
        let hit = world.intersect(&r, f32::INFINITY);
        assert!(hit.is_some_and(|h| h.t <= 1.0 + 1e-4), "ray {i} slipped through the surface at {q}");
        assert!(world.occluded(&r, 1.0 + 1e-4), "any-hit ray {i} slipped through the surface at {q}");
        if let Some(c) = inside {
            let r = Ray::new(c, q - c);
            assert!(world.intersect(&r, 2.0).is_some(), "ray {i} from inside escaped through {q}");
            assert!(world.occluded(&r, 2.0), "any-hit ray {i} from inside escaped through {q}");
        }
        tested += 1;
    }
    tested
}

#[test]
fn watertight_closed_mesh_never_lets_rays_slip_through() {
    let m = icosphere(3);
    let n = assert_watertight(&m, Some(Vec3::new(0.1, -0.3, 0.7) + Vec3::new(0.013, 0.021, -0.017)));
    assert!(n > 2000);
}

#[test]
fn instance_boxes_contain_every_transformed_vertex() {
    let scene = adversarial_scene(4);
    for o in &scene.objects {
        let Some(t) = &o.transform else { continue };
        let b = scene.object_aabb(o);
        match &scene.geometries[o.geometry] {
            Geometry::Mesh(m) => {
                for p in &m.positions {
                    assert!(b.contains(t.point(*p)), "vertex {p} escapes its instance box");
                }
            }
            Geometry::Sphere(s) => {
                for i in 0..200 {
                    let th = i as f32 * 0.1;
                    let d =
                        Vec3::new(th.cos() * (i as f32 * 0.37).sin(), th.sin(), (i as f32 * 0.61).cos()).normalize();
                    assert!(b.contains(t.point(s.center + d * s.radius)));
                }
            }
        }
        // The box of the 8 transformed corners, no larger.
        let g = scene.geometries[o.geometry].aabb();
        assert_eq!(b, snell_core::geometry::Aabb::from_points(g.corners().map(|c| t.point(c))));
    }
}

#[test]
fn traversal_counts_and_structure_boxes() {
    let scene = adversarial_scene(5);
    let r = Ray::new(Vec3::new(-8.0, 0.1, 0.2), Vec3::X);
    // The oracle tests every object and every triangle of every mesh it enters.
    let brute: World<Brute> = World::build(&scene, &AccelParams::default());
    let c = snell_core::accel::Counts::default();
    brute.hit_counted(&r, f32::INFINITY, &c);
    let tris: u64 = scene
        .objects
        .iter()
        .map(|o| match &scene.geometries[o.geometry] {
            Geometry::Mesh(m) => m.indices.len() as u64,
            Geometry::Sphere(_) => 0,
        })
        .sum();
    assert_eq!(c.prims.get(), scene.objects.len() as u64 + tris);
    for kind in AccelKind::ALL {
        let w = kind.build_world(&scene, &AccelParams::default());
        snell_core::with_world!(&w, w => {
            let c = snell_core::accel::Counts::default();
            let h = w.hit_counted(&r, f32::INFINITY, &c);
            assert_eq!(h.map(|h| h.t), brute.hit(&r, f32::INFINITY).map(|h| h.t), "{kind}");
            assert!(c.nodes.get() >= 1 && c.prims.get() >= 1, "{kind}: {c:?}");
            if kind != AccelKind::Brute {
                assert!(c.prims.get() < scene.objects.len() as u64 + tris, "{kind} tested everything");
            }
            // Boxes at depth 0 bound everything; deeper boxes lie inside them.
            let root = snell_core::inspect::boxes_at_depth(w, 0);
            let deeper = snell_core::inspect::boxes_at_depth(w, 2);
            let all = root.iter().fold(snell_core::geometry::Aabb::EMPTY, |a, b| a.union(*b));
            assert!(!root.is_empty(), "{kind}");
            for b in &deeper {
                assert!(all.contains(b.min) && all.contains(b.max), "{kind}: {b:?} outside {all:?}");
            }
        });
    }
}

/// Whether a packet's hit `got` for ray `r` is the hit `want` the ray finds alone (distance,
/// object, triangle and barycentrics, bit for bit), or an exact tie: the same distance on
/// another triangle that the ray alone hits at exactly that distance (a ray through a vertex or
/// an edge that triangles in different leaves share; which of them comes first depends on the
/// order the leaves are visited in, which a packet's other rays can change).
fn same_or_tie(scene: &Scene, r: &Ray, want: Option<RawHit>, got: Option<RawHit>) -> bool {
    let key = |h: RawHit| (h.t.to_bits(), h.object, h.prim, h.b1.to_bits(), h.b2.to_bits());
    match (want, got) {
        (None, None) => true,
        (Some(a), Some(b)) if key(a) == key(b) => true,
        (Some(a), Some(b)) if a.t.to_bits() == b.t.to_bits() && (a.object, a.prim) != (b.object, b.prim) => {
            let o = &scene.objects[b.object as usize];
            match (&scene.geometries[o.geometry], &o.transform) {
                (Geometry::Mesh(m), None) => {
                    let [p0, p1, p2] = m.triangle(b.prim as usize);
                    let alone = intersect_triangle(&WatertightRay::new(r.o, r.d), p0, p1, p2, f32::INFINITY);
                    alone.is_some_and(|h| {
                        (h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits())
                            == (b.t.to_bits(), b.b1.to_bits(), b.b2.to_bits())
                    })
                }
                _ => false,
            }
        }
        _ => false,
    }
}

/// [`World::hit_packets`] on `P` groups of eight consecutive rays of `rays`: every fourth packet
/// with some lanes of each group only, every seventh with its last group idle, every fifth
/// with its first group idle; each active lane gets the hit the ray gets alone (or a tie).
fn check_groups<A: Accel, const P: usize>(w: &World<A>, scene: &Scene, rays: &[Ray], name: &str) {
    for (k, p) in rays.chunks_exact(8 * P).enumerate() {
        let groups: [[Ray; 8]; P] = std::array::from_fn(|g| std::array::from_fn(|i| p[8 * g + i]));
        let mut active: [u8; P] =
            std::array::from_fn(|g| if k % 4 == 3 { ((k * 37 + g * 54) % 255 + 1) as u8 } else { 0xff });
        if k % 7 == 6 {
            active[P - 1] = 0;
        }
        if k % 5 == 4 {
            active[0] = 0;
        }
        let mut got = [[None; 8]; P];
        w.hit_packets(&groups, active, &mut got);
        for (g, (rays, got)) in groups.iter().zip(got).enumerate() {
            for (lane, (r, h)) in rays.iter().zip(got).enumerate() {
                if active[g] & (1 << lane) == 0 {
                    assert!(h.is_none(), "{name}: {P} groups, lane {g}.{lane} is not active");
                    continue;
                }
                let want = w.hit(r, f32::INFINITY);
                assert!(
                    same_or_tie(scene, r, want, h),
                    "{name}: {P} groups, packet {k}, lane {g}.{lane}: {want:?} alone, {h:?}"
                );
            }
        }
    }
}

/// Packets of eight, sixteen and thirty-two rays (coherent camera rays, perspective and orthographic,
/// and incoherent random ones) get the hits that each ray gets alone (or an exact tie, see
/// [`same_or_tie`]), for every accelerator (the BVHs' AVX2 packet traversal where the
/// CPU has it, one by one elsewhere), on a single mesh (where packets are used) and on the
/// two-level adversarial scene and a small mesh (where they fall back to single rays), rays
/// grazing the mesh's box included.
#[test]
fn ray_packets_hit_what_single_rays_hit() {
    let mut mesh = Mesh::icosphere(4);
    let mut rng = Pcg32::new(21, 22);
    for p in mesh.positions.iter_mut() {
        *p *= 1.0 + 0.3 * rng.next_f32();
    }
    let single =
        Scene { geometries: vec![Geometry::Mesh(mesh)], objects: vec![object(0, None)], ..adversarial_scene(1) };
    let camera =
        Camera::look_at(Vec3::new(0.3, 0.4, 3.0), Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 45.0 })
            .unwrap();
    // Camera rays from one point and, orthographic, from a plane of points: packets whose
    // frustum (AVX2 packet traversal) spans one origin or a range of them.
    let ortho =
        Camera::look_at(Vec3::new(0.3, 0.4, 3.0), Vec3::ZERO, Vec3::Y, Projection::Orthographic { half_height: 1.5 })
            .unwrap();
    let coherent: Vec<Ray> = [camera, ortho]
        .iter()
        .flat_map(|c| {
            (0..64 * 64)
                .map(|i| c.ray(glam::Vec2::new((i % 64) as f32 + 0.5, (i / 64) as f32 + 0.5), 64, 64, glam::Vec2::ZERO))
        })
        .collect();
    // A small mesh (16 triangles or fewer) is tested as one leaf, without its tree.
    let small = Mesh::cuboid(Vec3::splat(-1.2), Vec3::new(1.0, 0.8, 1.1));
    let small =
        Scene { geometries: vec![Geometry::Mesh(small)], objects: vec![object(0, None)], ..adversarial_scene(1) };
    // A cube with a few triangles inside, too many for one leaf: its faces lie on its box.
    let mut cube = Mesh::cuboid(Vec3::new(-1.0, -0.75, -0.5), Vec3::new(1.25, 1.0, 0.75));
    for k in 0..8 {
        let c = Vec3::new(0.1 * k as f32 - 0.4, 0.05 * k as f32, -0.1);
        let n = cube.positions.len() as u32;
        cube.positions.extend([c, c + Vec3::new(0.2, 0.0, 0.0), c + Vec3::new(0.0, 0.2, 0.1)]);
        cube.indices.push([n, n + 1, n + 2]);
    }
    let cube = Scene { geometries: vec![Geometry::Mesh(cube)], objects: vec![object(0, None)], ..adversarial_scene(1) };
    for (name, scene) in [("mesh", single), ("cube", cube), ("small mesh", small), ("two-level", adversarial_scene(2))]
    {
        let mut all = coherent.clone();
        all.extend(rays(&scene, 800, 5));
        // Rays grazing the whole mesh's box (a packet that misses the box is not traced): aimed
        // from outside at the vertices on its faces, and touching it at one corner or at one
        // point of an edge only (where the cube's triangles meet the box).
        if let Geometry::Mesh(m) = &scene.geometries[0] {
            let b = m.aabb();
            for v in m.positions.iter().filter(|v| (0..3).any(|a| v[a] == b.min[a] || v[a] == b.max[a])) {
                for o in [Vec3::new(0.3, 0.4, 3.0), Vec3::new(-4.0, 0.1, 0.2), Vec3::new(0.5, -3.5, -2.0)] {
                    all.push(Ray::new(o, *v - o));
                }
            }
            for c in b.corners() {
                // +1 along an axis where the corner is on the box's max side.
                let out = Vec3::from_array(std::array::from_fn(|a| if c[a] == b.max[a] { 1.0 } else { -1.0 }));
                for leave in 0..3 {
                    // Inwards along two axes, outwards along the third: the ray meets the box at
                    // the corner only.
                    let d = Vec3::from_array(std::array::from_fn(|a| if a == leave { out[a] } else { -out[a] }));
                    all.push(Ray::new(c - d, d));
                    // Along an edge from the corner: touching it halfway, inwards along one
                    // axis and outwards along another.
                    let (i, o) = ((leave + 1) % 3, (leave + 2) % 3);
                    let mut p = c;
                    p[leave] = 0.5 * (b.min[leave] + b.max[leave]);
                    let mut d = Vec3::ZERO;
                    (d[i], d[o]) = (-out[i], out[o]);
                    all.push(Ray::new(p - d, d));
                }
            }
        }
        for kind in AccelKind::ALL {
            let world = kind.build_world(&scene, &AccelParams::default());
            let (hits, checked) = snell_core::with_world!(&world, w => {
                let (mut hits, mut checked) = (0, 0);
                for (k, p) in all.chunks_exact(8).enumerate() {
                    let p: &[Ray; 8] = p.try_into().unwrap();
                    // Every third packet traces some of its rays only.
                    let active = if k % 3 == 2 { (k * 53 % 255 + 1) as u8 } else { 0xff };
                    let got = w.hit_packet8(p, active);
                    for (lane, (r, g)) in p.iter().zip(got).enumerate() {
                        if active & (1 << lane) == 0 {
                            assert!(g.is_none(), "{name} {kind:?}: lane {lane} is not active");
                            continue;
                        }
                        let want = w.hit(r, f32::INFINITY);
                        assert!(same_or_tie(&scene, r, want, g), "{name} {kind:?}: {want:?} alone, {g:?} in a packet");
                        hits += usize::from(want.is_some());
                        checked += 1;
                    }
                }
                // Sixteen and thirty-two at once, as groups of eight under one frustum.
                check_groups::<_, 2>(w, &scene, &all, &format!("{name} {kind:?}"));
                check_groups::<_, 4>(w, &scene, &all, &format!("{name} {kind:?}"));
                (hits, checked)
            });
            assert!(hits > checked / 3, "{name} {kind:?}: {hits} of {checked}");
        }
    }
}

/// Shadow rays traced eight at a time (`World::occluded_packet8`, as Whitted traces an area
/// light's samples from one point) are blocked exactly where each one traced alone is
/// (`World::occluded_skipping`): from points on surfaces to points around a spot (close
/// together, as a small light's samples are, or spread out), each with its own `t_max`, or to
/// infinity, passing over the surface they leave where it cannot be met again; some lanes idle.
/// In the default scene (spheres, quads, a box, the light), a single mesh, a small mesh and
/// the two-level adversarial scene, for every accelerator.
#[test]
fn shadow_ray_packets_are_blocked_where_single_rays_are() {
    use snell_core::geometry::{spawn_ray, spawn_ray_to};
    let default = snell_io::scene::load(&crate::common::repo_scene("default.toml")).unwrap().scene;
    let mesh = Scene {
        geometries: vec![Geometry::Mesh(Mesh::icosphere(4))],
        objects: vec![object(0, None)],
        ..adversarial_scene(1)
    };
    let small = Mesh::cuboid(Vec3::splat(-1.2), Vec3::new(1.0, 0.8, 1.1));
    let small =
        Scene { geometries: vec![Geometry::Mesh(small)], objects: vec![object(0, None)], ..adversarial_scene(1) };
    // Each scene with the region its rays start from and aim at (centre, size).
    let scenes = [
        ("default", default, Vec3::new(0.0, 1.0, 0.0), 2.0),
        ("mesh", mesh, Vec3::ZERO, 2.5),
        ("small mesh", small, Vec3::ZERO, 2.5),
        ("two-level", adversarial_scene(3), Vec3::ZERO, 6.0),
    ];
    for (name, scene, centre, size) in scenes {
        for kind in AccelKind::ALL {
            let world = kind.build_world(&scene, &AccelParams::default());
            let (blocked, checked) = snell_core::with_world!(&world, w => {
                let mut rng = Pcg32::new(9, 10);
                let (mut blocked, mut checked) = (0, 0);
                // Points on surfaces: where rays from around the scene first meet one.
                let starts: Vec<Ray> = (0..600)
                    .map(|_| {
                        let o = centre + rand_vec(&mut rng, size);
                        Ray::new(o, centre + rand_vec(&mut rng, 0.3 * size) - o)
                    })
                    .collect();
                for (k, start) in starts.iter().enumerate() {
                    let Some(hit) = w.intersect(start, f32::INFINITY) else { continue };
                    let ng = if hit.ng.dot(start.d) > 0.0 { -hit.ng } else { hit.ng };
                    let spot = centre + rand_vec(&mut rng, 0.5 * size);
                    let spread = if k % 2 == 0 { 0.05 * size } else { 0.5 * size };
                    let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); 8];
                    let mut t_max = [0.0f32; 8];
                    let mut skip = [snell_core::scene::Skip::NONE; 8];
                    for lane in 0..8 {
                        let q = spot + rand_vec(&mut rng, spread);
                        let (r, t) = if k % 5 == 4 {
                            (spawn_ray(hit.p, ng, q - hit.p), f32::INFINITY)
                        } else {
                            spawn_ray_to(hit.p, ng, q, Vec3::ZERO)
                        };
                        (rays[lane], t_max[lane], skip[lane]) = (r, t, w.leaving(hit.object, hit.p, ng, r.d));
                    }
                    let active = if k % 3 == 2 { (k * 37 % 255 + 1) as u8 } else { 0xff };
                    let got = w.occluded_packet8(&rays, active, &t_max, &skip);
                    assert_eq!(got & !active, 0, "{name} {kind:?}: idle lanes reported blocked");
                    for lane in 0..8 {
                        if active & (1 << lane) == 0 {
                            continue;
                        }
                        let want = w.occluded_skipping(&rays[lane], t_max[lane], skip[lane]);
                        assert_eq!(got & (1 << lane) != 0, want, "{name} {kind:?}: ray {k}, lane {lane}");
                        blocked += usize::from(want);
                        checked += 1;
                    }
                }
                (blocked, checked)
            });
            assert!(
                blocked > checked / 10 && blocked < checked * 9 / 10,
                "{name} {kind:?}: {blocked} of {checked} blocked"
            );
        }
    }
}
