//! The pbrt-v4 reader: each construct on a small file, bad files, and the repository's pbrt
//! Cornell box against Mitsuba's reference of the XML one.

use snell_core::camera::Projection;
use snell_core::light::Light;
use snell_core::material::{Material, Texture};
use snell_core::sampling::SamplerKind;
use snell_core::scene::Geometry;
use snell_core::Vec3;
use snell_io::scene::LoadedScene;

use crate::common::{repo_scene, run, stderr};
use crate::mitsuba::compare_with_mitsuba;

const HEAD: &str = r#"LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" [ 45 ]
Film "rgb" "integer xresolution" [ 32 ] "integer yresolution" [ 24 ]
WorldBegin
"#;

/// Writes `files` (name, contents) into a temporary directory and loads the first.
fn load_files(files: &[(&str, &str)]) -> (tempfile::TempDir, Result<LoadedScene, String>) {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        let p = dir.path().join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    let r = snell_io::pbrt::load(&dir.path().join(files[0].0)).map_err(|e| e.to_string());
    (dir, r)
}

/// Loads `HEAD` (4 lines) followed by `body`.
fn load(body: &str) -> Result<LoadedScene, String> {
    load_files(&[("scene.pbrt", &format!("{HEAD}{body}\n"))]).1
}

fn mesh(l: &LoadedScene, object: usize) -> &snell_core::shape::Mesh {
    match &l.scene.geometries[l.scene.objects[object].geometry] {
        Geometry::Mesh(m) => m,
        other => panic!("{other:?}"),
    }
}

const TRI: &str = r#"Shape "trianglemesh" "point3 P" [ 0 0 0  1 0 0  0 1 0 ] "integer indices" [ 0 1 2 ]"#;

#[test]
fn transforms_and_attribute_blocks() {
    let l = load(&format!(
        r#"AttributeBegin
             Translate 10 0 0
             Scale 2 2 2
             {TRI}
           AttributeEnd
           {TRI}
           AttributeBegin
             Rotate 90 0 0 1
             {TRI}
             CoordinateSystem "turned"
           AttributeEnd
           AttributeBegin
             ConcatTransform [ 1 0 0 0  0 1 0 0  0 0 1 0  0 0 7 1 ]
             {TRI}
             Transform [ 1 0 0 0  0 1 0 0  0 0 1 0  0 5 0 1 ]
             {TRI}
             CoordSysTransform "turned"
             {TRI}
           AttributeEnd"#
    ))
    .unwrap();
    let p = |i: usize| mesh(&l, i).positions.clone();
    // Translate then Scale: scaled first, then moved (pbrt post-multiplies).
    assert_eq!(p(0)[1], Vec3::new(12.0, 0.0, 0.0));
    // The block restored the transform.
    assert_eq!(p(1)[1], Vec3::new(1.0, 0.0, 0.0));
    // Rotate 90 about z takes x to y.
    assert!((p(2)[1] - Vec3::Y).length() < 1e-6, "{:?}", p(2));
    // ConcatTransform and Transform list the matrix column by column (translation last).
    assert_eq!(p(3)[0], Vec3::new(0.0, 0.0, 7.0));
    assert_eq!(p(4)[0], Vec3::new(0.0, 5.0, 0.0));
    assert!((p(5)[1] - Vec3::Y).length() < 1e-6, "CoordSysTransform: {:?}", p(5));
}

#[test]
fn camera_film_sampler_integrator_and_filter() {
    let l = load_files(&[(
        "s.pbrt",
        r#"# a comment
Scale -1 1 1
LookAt 1 2 3  1 2 0  0 1 0 # eye, target, up
Camera "perspective" "float fov" 30 "float lensradius" 0.1 "float focaldistance" 4
Film "rgb" "integer xresolution" [ 40 ] "integer yresolution" [ 80 ] "string filename" "out.exr"
Sampler "halton" "integer pixelsamples" 7 "integer seed" 3
Integrator "volpath" "integer maxdepth" [ 2 ]
PixelFilter "triangle"
WorldBegin
"#,
    )])
    .1
    .unwrap();
    let s = &l.settings;
    assert_eq!((s.width, s.height, s.spp, s.seed, s.max_depth), (40, 80, 7, 3, Some(3)));
    assert_eq!(s.sampler, SamplerKind::Sobol);
    assert!(matches!(s.filter, snell_core::filter::Filter::Tent { radius } if radius == 2.0));
    let c = &l.scene.camera;
    assert_eq!(c.eye, Vec3::new(1.0, 2.0, 3.0));
    let (right, up, forward) = c.frame();
    assert!((forward - -Vec3::Z).length() < 1e-6 && (up - Vec3::Y).length() < 1e-6);
    // pbrt's camera has +x to the right: LookAt down -z would put world -x on the right; the
    // mirror in front of it puts +x there.
    assert!((right - Vec3::X).length() < 1e-6, "{right:?}");
    match c.projection() {
        // fov is on the shorter axis, here x: the vertical field is wider.
        Projection::ThinLens { fov_y, aperture, focus_distance } => {
            let expect = 2.0 * ((15f32).to_radians().tan() * 2.0).atan().to_degrees();
            assert!((fov_y - expect).abs() < 1e-3 && aperture == 0.1 && focus_distance == 4.0, "{fov_y}");
        }
        other => panic!("{other:?}"),
    }
    assert!(l.warnings.iter().any(|w| w.contains("halton")), "{:?}", l.warnings);
    // Without the mirror, the image's right is world -x when looking down -z (left-handed).
    let l = load("").unwrap();
    assert!((l.scene.camera.frame().0 - -Vec3::X).length() < 1e-6);
    let o = load_files(&[(
        "o.pbrt",
        "LookAt 0 0 5 0 0 0 0 1 0\nCamera \"orthographic\"\nFilm \"rgb\" \"integer xresolution\" 20 \"integer yresolution\" 10\nWorldBegin\n",
    )])
    .1
    .unwrap();
    assert_eq!(o.scene.camera.projection(), Projection::Orthographic { half_height: 1.0 });
}

#[test]
fn shapes_map_to_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    std::fs::write(dir.path().join("t.ply"), ply).unwrap();
    let body = r#"
Shape "trianglemesh" "point3 P" [ 0 0 0  1 0 0  1 1 0  0 1 0 ] "integer indices" [ 0 1 2  0 2 3 ]
    "normal N" [ 0 0 1  0 0 1  0 0 1  0 0 1 ] "point2 uv" [ 0 0  1 0  1 1  0 1 ]
Shape "bilinearmesh" "point3 P" [ 0 0 0  1 0 0  0 1 0  1 1 0 ]
Shape "bilinearmesh" "point3 P" [ 0 0 0  1 0 0  0 1 0  1 1 1 ]
Translate 0 0 -3
Shape "sphere" "float radius" 0.5
Shape "plymesh" "string filename" "t.ply"
Shape "disk" "float radius" 2
Shape "cylinder"
Shape "curve" "point3 P" [ 0 0 0 1 1 1 2 2 2 3 3 3 ]
"#;
    std::fs::write(dir.path().join("s.pbrt"), format!("{HEAD}{body}")).unwrap();
    let l = snell_io::pbrt::load(&dir.path().join("s.pbrt")).unwrap();
    assert_eq!(l.scene.objects.len(), 7, "the curve is skipped");
    let m = mesh(&l, 0);
    assert_eq!(m.indices.len(), 2);
    assert!(m.normals.is_some() && m.uvs.is_some());
    // A flat bilinear patch is two triangles facing (p10 - p00) × (p01 - p00) = +z; a curved one is tessellated.
    let flat = mesh(&l, 1);
    assert_eq!(flat.indices.len(), 2);
    let [a, b, c] = flat.triangle(0);
    assert!((b - a).cross(c - a).z > 0.0);
    assert_eq!(mesh(&l, 2).indices.len(), 128);
    match &l.scene.geometries[l.scene.objects[3].geometry] {
        Geometry::Sphere(s) => assert_eq!(s.radius, 0.5),
        other => panic!("{other:?}"),
    }
    assert!(l.scene.objects[3].transform.is_some());
    assert_eq!(mesh(&l, 4).positions[1], Vec3::new(1.0, 0.0, -3.0));
    assert!((mesh(&l, 5).aabb().max.x - 2.0).abs() < 1e-5);
    assert!(l.warnings.iter().any(|w| w.contains("s.pbrt:15:") && w.contains("curve")), "{:?}", l.warnings);
}

#[test]
fn materials_and_textures_map_to_snells() {
    let l = load(&format!(
        r#"Texture "checks" "spectrum" "checkerboard" "rgb tex1" [ 1 0 0 ] "rgb tex2" [ 0 0 1 ] "float uscale" 4 "float vscale" 4
Texture "rough" "float" "constant" "float value" 0.04
Material "diffuse" "texture reflectance" "checks"
{TRI}
Material "conductor" "spectrum eta" "metal-Au-eta" "spectrum k" "metal-Au-k" "texture roughness" "rough"
{TRI}
Material "conductor" "rgb reflectance" [ 0.9 0.5 0.1 ]
{TRI}
Material "dielectric" "spectrum eta" "glass-BK7"
{TRI}
Material "thindielectric"
{TRI}
Material "coateddiffuse" "rgb reflectance" [ 0.2 0.3 0.4 ] "float roughness" 0.01
{TRI}
MakeNamedMaterial "water" "string type" "dielectric" "float eta" 1.33
NamedMaterial "water"
{TRI}
Material "interface"
{TRI}
Material "diffuse" "spectrum reflectance" [ 400 0.2 550 0.8 700 0.3 ] "float sparkle" 2
{TRI}"#
    ))
    .unwrap();
    let m = |i: usize| &l.scene.materials[l.scene.objects[i].material];
    assert_eq!(l.scene.objects.len(), 8, "the interface shape is not rendered");
    match m(0) {
        Material::Diffuse { albedo: Texture::Checker { a, b, scale } } => {
            assert_eq!((*a, *b, *scale), (Vec3::X, Vec3::Z, 4.0))
        }
        other => panic!("{other:?}"),
    }
    let (au_eta, au_k) = snell_core::material::metal("Au").unwrap();
    match m(1) {
        // Roughness 0.04 remapped to alpha 0.2, as pbrt-v4 does.
        Material::Conductor { eta, k, roughness, .. } => {
            assert!(*eta == au_eta && *k == au_k && (roughness - 0.2).abs() < 1e-6)
        }
        other => panic!("{other:?}"),
    }
    match m(2) {
        // eta 1 and k = 2 sqrt(r / (1 - r)) reflect r at normal incidence.
        Material::Conductor { eta, k, .. } => {
            let r0 = ((*eta - Vec3::ONE) * (*eta - Vec3::ONE) + *k * *k)
                / ((*eta + Vec3::ONE) * (*eta + Vec3::ONE) + *k * *k);
            assert!((r0 - Vec3::new(0.9, 0.5, 0.1)).abs().max_element() < 1e-4, "{r0:?}");
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(m(3), Material::Dielectric { ior, roughness, .. } if *ior == 1.5168 && *roughness == 0.0));
    assert!(matches!(m(4), Material::ThinDielectric { ior, .. } if *ior == 1.5));
    assert!(matches!(m(5), Material::Plastic { ior, roughness, .. } if *ior == 1.5 && (roughness - 0.1).abs() < 1e-6));
    assert!(matches!(m(6), Material::Dielectric { ior, .. } if *ior == 1.33));
    match m(7) {
        Material::Diffuse { albedo: Texture::Constant(c) } => assert!((c.y - 0.745).abs() < 0.03, "{c:?}"),
        other => panic!("{other:?}"),
    }
    // pbrt's materials reflect on both sides.
    assert!(!l.scene.materials.iter().any(|m| matches!(m, Material::OneSided(_))));
    let w = l.warnings.join("\n");
    assert!(w.contains("scene.pbrt:24:") && w.contains("'float sparkle'"), "{w}");
    assert!(w.contains("coateddiffuse"), "{w}");
}

#[test]
fn lights_area_lights_and_instances() {
    let dir = tempfile::tempdir().unwrap();
    // A 2 × 2 equal-area environment, bright in the +z half (the top in pbrt's frame).
    let mut img = image::Rgb32FImage::new(2, 2);
    img.put_pixel(0, 0, image::Rgb([1.0, 1.0, 1.0]));
    img.save(dir.path().join("env.exr")).unwrap();
    let body = format!(
        r#"LightSource "point" "rgb I" [ 1 2 3 ] "point3 from" [ 1 1 1 ]
LightSource "spot" "blackbody I" [ 3000 ] "float scale" 2 "float coneangle" 40 "float conedelta" 10
LightSource "distant" "point3 from" [ 0 10 0 ] "point3 to" [ 0 0 0 ] "rgb L" [ 3 3 3 ]
LightSource "infinite" "string filename" "env.exr"
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [ 4 5 6 ] "float scale" 0.5
  ReverseOrientation
  {TRI}
AttributeEnd
{TRI}
ObjectBegin "thing"
  Shape "sphere"
  {TRI}
ObjectEnd
Translate 5 0 0
ObjectInstance "thing"
Translate 5 0 0
ObjectInstance "thing"
"#
    );
    std::fs::write(dir.path().join("s.pbrt"), format!("{HEAD}{body}")).unwrap();
    let l = snell_io::pbrt::load(&dir.path().join("s.pbrt")).unwrap_or_else(|e| panic!("{e}"));
    let lights = &l.scene.lights;
    assert!(
        matches!(lights[0], Light::Point { position, intensity } if position == Vec3::ONE && intensity == Vec3::new(1.0, 2.0, 3.0))
    );
    match lights[1] {
        Light::Spot { intensity, cos_inner, cos_outer, direction, .. } => {
            assert!(intensity.x > intensity.z, "a 3000 K black body is red: {intensity:?}");
            let y = 0.2126 * intensity.x + 0.7152 * intensity.y + 0.0722 * intensity.z;
            assert!((y - 2.0).abs() < 1e-2, "luminance 1 times scale 2: {y}");
            assert!(
                (cos_inner - 30f32.to_radians().cos()).abs() < 1e-6
                    && (cos_outer - 40f32.to_radians().cos()).abs() < 1e-6
            );
            assert_eq!(direction, Vec3::Z);
        }
        ref other => panic!("{other:?}"),
    }
    assert!(
        matches!(lights[2], Light::Directional { direction, irradiance } if direction == -Vec3::Y && irradiance == Vec3::splat(3.0))
    );
    match &lights[3] {
        Light::Environment(e) => {
            let m = e.map.as_ref().unwrap();
            assert_eq!((m.width, m.height), (4, 2));
            // Pixel (0, 0) of the equal-area square holds directions with x < 0 and y < 0 (on
            // either hemisphere); it lands in the lat-long image where those directions are.
            assert!(e.eval(Vec3::new(-1.0, -1.0, 0.3).normalize()).max_element() > 0.5);
            assert!(e.eval(Vec3::new(1.0, 1.0, 0.3).normalize()).max_element() < 0.5);
        }
        other => panic!("{other:?}"),
    }
    let o = &l.scene.objects;
    assert_eq!(o.len(), 6);
    assert_eq!(o[0].emission, Vec3::new(2.0, 2.5, 3.0));
    assert_eq!(o[1].emission, Vec3::ZERO, "the area light ends with its block");
    // ReverseOrientation turned the first triangle around (it emits towards -z).
    let [a, b, c] = mesh(&l, 0).triangle(0);
    assert!((b - a).cross(c - a).z < 0.0);
    assert_eq!(o[2].geometry, o[4].geometry, "instances share the object's geometry");
    let t = o[4].transform.as_ref().unwrap();
    assert_eq!(t.point(Vec3::ZERO), Vec3::new(10.0, 0.0, 0.0));
}

#[test]
fn includes_imports_and_cycles() {
    let (_d, l) = load_files(&[
        ("main.pbrt", &format!("{HEAD}Include \"parts/a.pbrt\"\nImport \"b.pbrt\"\n")),
        ("parts/a.pbrt", &format!("{TRI}\n")),
        ("b.pbrt", &format!("Translate 0 0 1\n{TRI}\n")),
    ]);
    let l = l.unwrap();
    assert_eq!(l.scene.objects.len(), 2);
    let (_d, e) = load_files(&[
        ("main.pbrt", &format!("{HEAD}Include \"a.pbrt\"\n")),
        ("a.pbrt", "Include \"b.pbrt\"\n"),
        ("b.pbrt", "\n\nInclude \"a.pbrt\"\n"),
    ]);
    let e = e.unwrap_err();
    assert!(e.contains("b.pbrt:3:1") && e.contains("cycle"), "{e}");
}

#[test]
fn bad_files_name_file_line_and_column() {
    let cases: &[(&str, &str)] = &[
        // Truncated.
        ("Shape \"trianglemesh\" \"point3 P\" [ 0 0 0", "scene.pbrt:5:"),
        ("Shape \"sphere\" \"float radius", "string runs past the line"),
        ("AttributeBegin\n", "never closed"),
        // Wrong types.
        ("Shape \"sphere\" \"float radius\" \"big\"", "needs numbers"),
        ("Shape \"sphere\" \"float radius\" 1x", "not a number"),
        ("Shape \"sphere\" \"bool radius\" 1", "true or false"),
        ("Shape \"sphere\" \"colour radius\" 1", "unknown parameter type"),
        ("Shape \"trianglemesh\" \"point3 P\" [ 0 0 0 1 0 0 0 1 ] \"integer indices\" [ 0 1 2 ]", "groups of 3"),
        ("Shape \"trianglemesh\" \"point3 P\" [ 0 0 0 1 0 0 0 1 0 ] \"integer indices\" [ 0 1 3 ]", "not a vertex"),
        ("Translate 1 2", "ends before its numbers"),
        ("Translate 1 2 Scale", "needs a number here"),
        // Unknown references and directives.
        ("NamedMaterial \"nothing\"", "unknown material 'nothing'"),
        ("ObjectInstance \"nothing\"", "unknown object 'nothing'"),
        ("Material \"diffuse\" \"texture reflectance\" \"nothing\"", "unknown texture 'nothing'"),
        ("Material \"conductor\" \"spectrum eta\" \"metal-Unobtainium-eta\"", "unknown named spectrum"),
        ("Shape \"plymesh\" \"string filename\" \"missing.ply\"", "missing.ply"),
        ("Frobnicate 1", "unknown directive 'Frobnicate'"),
        ("AttributeEnd", "without a matching begin"),
    ];
    for (body, want) in cases {
        let e = load(body).expect_err(body);
        assert!(e.contains(want), "{body}: {e}");
        if !want.contains(".ply") {
            assert!(e.contains("scene.pbrt:5:") || e.contains("scene.pbrt:6:"), "{body}: {e}");
        }
    }
    let e = load_files(&[("n.pbrt", "WorldBegin\n")]).1.unwrap_err();
    assert!(e.contains("no Camera"), "{e}");
}

#[test]
fn cli_renders_pbrt_and_reports_bad_files_with_status_1() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.pbrt"), format!("{HEAD}LightSource \"infinite\"\nShape \"sphere\"\n")).unwrap();
    let o = run(&["render", "s.pbrt", "--spp", "1", "-o", "out.exr"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(dir.path().join("out.exr")).unwrap();
    assert_eq!((img.width(), img.height()), (32, 24));
    std::fs::write(dir.path().join("bad.pbrt"), format!("{HEAD}Shape \"sphere\" \"float radius\" [ 1\n")).unwrap();
    let o = run(&["render", "bad.pbrt", "-o", "x.exr"], dir.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("bad.pbrt:5:"), "{}", stderr(&o));
    assert!(!dir.path().join("x.exr").exists());
}

/// The repository's pbrt-v4 Cornell box (scenes/cornell-box.pbrt, written from the Mitsuba
/// scene's meshes) converges to Mitsuba's reference of cbox-rgb.xml. Russian roulette as the
/// Mitsuba scene plays it, so that both are judged at the same noise.
#[test]
fn pbrt_cornell_box_matches_mitsuba() {
    let mut l = snell_io::pbrt::load(&repo_scene("cornell-box.pbrt")).unwrap_or_else(|e| panic!("{e}"));
    assert!(l.warnings.is_empty(), "{:?}", l.warnings);
    assert_eq!(l.settings.max_depth, Some(6));
    l.settings.rr_depth = 5;
    compare_with_mitsuba("cornell-box.pbrt", &l, "cbox-rgb", 256, 256, 6, 1.2);
}
