//! Whole renders: determinism across thread counts, analytic radiometry, the ray tree's energy
//! balance, pruning statistics, and small golden images.

use std::path::{Path, PathBuf};

use snell_core::accel::AccelParams;
use snell_core::image::Image;
use snell_core::integrator::RayStats;
use snell_core::render::{render, RenderSettings};
use snell_core::with_world;
use snell_io::scene::LoadedScene;

use crate::common::{repo_scene, run, stderr};

pub struct Opts {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub threads: usize,
    pub max_depth: Option<u32>,
    pub min_attenuation: Option<f32>,
}

impl Default for Opts {
    fn default() -> Self {
        Opts { width: 32, height: 32, spp: 4, threads: 0, max_depth: None, min_attenuation: None }
    }
}

pub fn render_loaded(l: &LoadedScene, o: &Opts) -> (Image, RayStats) {
    let mut scene = l.scene.clone();
    if let Some(c) = l.frame.and_then(|b| snell_io::scene::auto_camera(b, o.width, o.height)) {
        scene.camera = c;
    }
    let settings = RenderSettings {
        width: o.width,
        height: o.height,
        spp: o.spp,
        seed: l.settings.seed,
        threads: o.threads,
        filter: l.settings.filter.clone(),
        reconstruction: l.settings.reconstruction,
        sampler: l.settings.sampler,
        aovs: false,
    };
    let integrator = snell_io::scene::SceneSettings {
        max_depth: o.max_depth.or(l.settings.max_depth),
        min_attenuation: o.min_attenuation.unwrap_or(l.settings.min_attenuation),
        ..l.settings.clone()
    }
    .integrator();
    let world = l.settings.accel.build_world(&scene, &AccelParams::default());
    with_world!(&world, w => render(w, &integrator, &settings, &|_| {}))
}

fn render_src(src: &str, o: &Opts) -> (Image, RayStats) {
    let l = snell_io::scene::parse(src, Path::new("test.toml")).unwrap_or_else(|e| panic!("{e}"));
    render_loaded(&l, o)
}

#[test]
fn image_is_bit_identical_with_one_and_two_threads() {
    let l = snell_io::scene::load(&repo_scene("default.toml")).unwrap();
    let o1 = Opts { width: 40, height: 30, spp: 4, threads: 1, ..Opts::default() };
    let o2 = Opts { threads: 2, ..o1 };
    let (a, sa) = render_loaded(&l, &o1);
    let (b, sb) = render_loaded(&l, &o2);
    let bits = |i: &Image| i.pixels.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(sa, sb);
    // And the seed does change it.
    let mut l2 = l.clone();
    l2.settings.seed = 1;
    let (c, _) = render_loaded(&l2, &o1);
    assert_ne!(bits(&a), bits(&c));
}

#[test]
fn cli_output_is_identical_across_thread_counts() {
    let dir = tempfile::tempdir().unwrap();
    let common = ["render", "--width", "24", "--height", "16", "--spp", "2"];
    let a = run(&[&common[..], &["-o", "a.exr", "--threads", "1"]].concat(), dir.path());
    let b = run(&[&common[..], &["-o", "b.exr", "--threads", "2"]].concat(), dir.path());
    assert!(a.status.success() && b.status.success(), "{}{}", stderr(&a), stderr(&b));
    let ra = image::open(dir.path().join("a.exr")).unwrap().to_rgb32f();
    let rb = image::open(dir.path().join("b.exr")).unwrap().to_rgb32f();
    assert_eq!(ra.as_raw(), rb.as_raw());
    // The summary line reports time and throughput, and the threads the whole command (load,
    // build and render) ran on: the pool `--threads` asked for.
    let out = String::from_utf8_lossy(&a.stdout);
    assert!(out.contains("Mrays/s") && out.contains("camera rays"), "{out}");
    assert!(out.trim_end().ends_with("Mrays/s, 1 thread"), "{out}");
    assert!(
        String::from_utf8_lossy(&b.stdout).trim_end().ends_with("Mrays/s, 2 threads"),
        "{}",
        String::from_utf8_lossy(&b.stdout)
    );
}

const PLANE: &str = r#"
[render]
filter = "box"
[camera]
type = "orthographic"
eye = [0, 0, 5]
look_at = [0, 0, 0]
scale = 0.5
[materials.m]
type = "diffuse"
albedo = 0.5
[[shapes]]
type = "quad"
corner = [-10, -10, 0]
edge1 = [20, 0, 0]
edge2 = [0, 20, 0]
material = "m"
"#;

#[test]
fn diffuse_plane_under_directional_light_is_albedo_times_e_over_pi() {
    // Light arriving at 60° from the normal: E·cos 60° = 1.
    let src = format!(
        "{PLANE}[[lights]]\ntype = \"directional\"\ndirection = [0, {}, -0.5]\nirradiance = 2\n",
        -(0.75f32).sqrt()
    );
    let (img, stats) = render_src(&src, &Opts::default());
    let expect = 0.5 * 1.0 / std::f32::consts::PI;
    for p in &img.pixels {
        assert!((p.x - expect).abs() < 1e-5 && (p.z - expect).abs() < 1e-5, "{p} vs {expect}");
    }
    assert_eq!(stats.shadow, stats.camera);
}

#[test]
fn point_light_falls_off_with_inverse_square() {
    let src = format!("{PLANE}[[lights]]\ntype = \"point\"\nposition = [0, 0, 2]\nintensity = 8\n");
    let (img, _) = render_src(&src, &Opts { width: 33, height: 33, ..Opts::default() });
    // Centre pixel: L = albedo/π · I/d² · cos θ (θ ≈ 0); the pixel spans ±1/66 in x and y.
    let expect = 0.5 / std::f32::consts::PI * 8.0 / 4.0;
    let c = img.get(16, 16).x;
    assert!((c - expect).abs() < 2e-3 * expect, "{c} vs {expect}");
    // Edge pixel, at x = 0.5 - 1/66: cos θ / d² with d² = 4 + x².
    let x = 0.5 - 1.0 / 66.0;
    let d2 = 4.0 + x * x;
    let expect = 0.5 / std::f32::consts::PI * 8.0 / d2 * (2.0 / d2.sqrt());
    let e = img.get(32, 16).x;
    assert!((e - expect).abs() < 1e-2 * expect, "{e} vs {expect}");
}

#[test]
fn area_light_soft_shadow_is_partial() {
    // A sphere between a quad light and the plane casts umbra and penumbra.
    let src = format!(
        "{PLANE}[[shapes]]\ntype = \"quad\"\ncorner = [-0.5, -0.5, 3]\nedge1 = [0, 1, 0]\nedge2 = [1, 0, 0]\nemission = 5\nlight_samples = 64\n\
         [[shapes]]\ntype = \"sphere\"\ncenter = [0, 0, 1.5]\nradius = 0.25\n"
    )
    .replace("eye = [0, 0, 5]", "eye = [0, 0, 1]")
    .replace("scale = 0.5", "scale = 1.5");
    let (img, _) = render_src(&src, &Opts { width: 64, height: 64, spp: 1, ..Opts::default() });
    let v: Vec<f32> = (0..64).map(|x| img.get(x, 32).x).collect();
    let max = v.iter().cloned().fold(0.0, f32::max);
    let centre = v[32];
    let partial = v.iter().filter(|&&x| x > 0.1 * max && x < 0.9 * max).count();
    assert!(centre < 0.5 * max, "no shadow under the sphere: {centre} vs {max}");
    assert!(partial >= 6, "no penumbra: {v:?}");
}

/// Glass in a uniform white environment: every path ends in the environment, and Fresnel
/// splits energy without loss (R + T = 1, the 1/η² radiance scaling cancels on the way out),
/// so with no pruning the image is white everywhere, to the precision of the deepest branches.
#[test]
fn glass_in_a_white_furnace_is_invisible() {
    for shape in [
        "type = \"sphere\"\nradius = 1",
        "type = \"box\"\nmin = [-0.7, -0.7, -0.7]\nmax = [0.7, 0.7, 0.7]\ntransform = [{ rotate = { axis = [1, 1, 0], angle = 30 } }]",
    ] {
        for ior in ["1.33", "1.5", "2.42"] {
            let src = format!(
                "[render]\nbackground = 1\n[camera]\neye = [0, 0, 4]\nfov = 40\n[materials.g]\ntype = \"dielectric\"\nior = {ior}\n[[shapes]]\n{shape}\nmaterial = \"g\"\n"
            );
            let o = Opts { max_depth: Some(60), min_attenuation: Some(0.0), ..Opts::default() };
            let (img, stats) = render_src(&src, &o);
            for p in &img.pixels {
                assert!((p.x - 1.0).abs() < 2e-3, "{shape} ior {ior}: pixel {p}");
            }
            assert!(stats.refraction > 0 && stats.reflection > 0);
            if shape.contains("box") {
                assert!(stats.total_internal_reflections > 0, "a glass cube shows TIR");
            } else {
                // A ray refracted into a sphere meets the surface at its entry angle: no TIR.
                assert_eq!(stats.total_internal_reflections, 0);
            }
        }
    }
}

#[test]
fn constant_mirror_and_fresnel_conductor() {
    let src = "[render]\nbackground = 1\nfilter = \"box\"\n[camera]\neye = [0, 0, 4]\nfov = 5\n[materials.m]\ntype = \"mirror\"\nreflectance = 0.5\n[[shapes]]\ntype = \"sphere\"\nmaterial = \"m\"\n";
    let (img, _) = render_src(src, &Opts::default());
    assert!(img.pixels.iter().all(|p| (p.x - 0.5).abs() < 1e-6));
    // Gold at (nearly) normal incidence reflects its R0 per channel.
    let src = src.replace("type = \"mirror\"\nreflectance = 0.5", "type = \"conductor\"\nmetal = \"gold\"");
    let (img, _) = render_src(&src, &Opts::default());
    let (eta, k) = snell_core::material::metal("gold").unwrap();
    let r0 = snell_core::material::conductor_fresnel(1.0, eta, k);
    let c = img.get(16, 16);
    assert!((c - r0).abs().max_element() < 1e-3, "{c} vs {r0}");
}

#[test]
fn ray_tree_is_pruned_by_depth_and_attenuation() {
    let src = std::fs::read_to_string(repo_scene("ray-tree.toml")).unwrap();
    let mut prev = 0;
    for depth in [1u32, 2, 5, 10] {
        let o = Opts { max_depth: Some(depth), min_attenuation: Some(0.0), spp: 1, ..Opts::default() };
        let (_, s) = render_src(&src, &o);
        let secondary = s.reflection + s.refraction;
        assert!(secondary > prev, "depth {depth}: {secondary} secondary rays, not more than {prev}");
        assert!(s.pruned_depth > 0, "depth {depth}: nothing pruned by depth");
        assert_eq!(s.pruned_attenuation, 0);
        prev = secondary;
    }
    // Depth 0: camera and shadow rays only.
    let (_, s) = render_src(&src, &Opts { max_depth: Some(0), spp: 1, ..Opts::default() });
    assert_eq!(s.reflection + s.refraction, 0);
    // A high attenuation limit cuts branches that depth alone would trace.
    let o = Opts { max_depth: Some(10), min_attenuation: Some(0.3), spp: 1, ..Opts::default() };
    let (_, s) = render_src(&src, &o);
    assert!(s.pruned_attenuation > 0);
}

#[test]
fn bare_mesh_renders_with_automatic_camera() {
    let dir = tempfile::tempdir().unwrap();
    let obj = crate::common::data("tetra.obj");
    let o = run(
        &["render", obj.to_str().unwrap(), "-o", "m.png", "--width", "40", "--height", "30", "--spp", "2"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(dir.path().join("m.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (40, 30));
    // The mesh is framed: the centre pixel differs from the background in the corner.
    let (c, corner) = (img.get_pixel(20, 15), img.get_pixel(0, 0));
    assert_ne!(c, corner);
}

// ---------------------------------------------------------------------------------------------
// Golden images: small renders of the example scenes, compared with images in
// `tests/golden`. `SNELL_BLESS=1 cargo test golden` rewrites them (check the diff by eye).

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

fn check_golden(name: &str, img: &Image) {
    let path = golden_dir().join(format!("{name}.exr"));
    if std::env::var_os("SNELL_BLESS").is_some() {
        snell_io::image_out::write_image(&path, img).unwrap();
        return;
    }
    let gold =
        image::open(&path).unwrap_or_else(|e| panic!("{}: {e} (bless with SNELL_BLESS=1)", path.display())).to_rgb32f();
    assert_eq!(gold.dimensions(), (img.width, img.height), "{name}: size");
    let mut sum = 0.0f64;
    let mut max = 0.0f32;
    for (a, b) in img.pixels.iter().zip(gold.pixels()) {
        let d = (*a - glam::Vec3::from(b.0)).abs().max_element();
        sum += d as f64;
        max = max.max(d);
    }
    let mean = sum / img.pixels.len() as f64;
    if mean > 1e-4 || max > 2e-2 {
        let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("golden-{name}"));
        let _ = std::fs::create_dir_all(&out);
        let _ = snell_io::image_out::write_image(&out.join("actual.exr"), img);
        let diff = Image {
            width: img.width,
            height: img.height,
            pixels: img
                .pixels
                .iter()
                .zip(gold.pixels())
                .map(|(a, b)| (*a - glam::Vec3::from(b.0)).abs() * 10.0)
                .collect(),
        };
        let _ = snell_io::image_out::write_image(&out.join("diff-x10.png"), &diff);
        panic!("{name}: mean abs difference {mean:.2e}, max {max:.2e}; actual and diff in {}", out.display());
    }
}

#[test]
fn golden_images_of_the_example_scenes() {
    for name in ["default", "ior-row", "fresnel-vs-constant", "total-internal-reflection", "glazed", "ray-tree"] {
        let l = snell_io::scene::load(&repo_scene(&format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"));
        let (img, _) = render_loaded(&l, &Opts { width: 64, height: 48, spp: 4, ..Opts::default() });
        check_golden(name, &img);
    }
}

#[test]
fn heat_map_and_box_overlay_from_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let obj = crate::common::data("two-tetra.obj");
    let o = run(
        &["render", obj.to_str().unwrap(), "--aov", "heatmap", "-o", "hm.exr", "--width", "32", "--height", "24"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("nodes visited per camera ray") && out.contains("primitives tested per camera ray"), "{out}");
    assert!(dir.path().join("hm.exr").is_file() && dir.path().join("hm-prims.exr").is_file());
    let a = run(
        &["render", obj.to_str().unwrap(), "-o", "a.png", "--width", "32", "--height", "24", "--spp", "1"],
        dir.path(),
    );
    let b = run(
        &[
            "render",
            obj.to_str().unwrap(),
            "-o",
            "b.png",
            "--width",
            "32",
            "--height",
            "24",
            "--spp",
            "1",
            "--show-boxes",
            "1",
            // The median split always divides 8 triangles (the SAH keeps them in one leaf).
            "--accel",
            "bvh-median",
        ],
        dir.path(),
    );
    assert!(a.status.success() && b.status.success());
    let (a, b) = (image::open(dir.path().join("a.png")).unwrap(), image::open(dir.path().join("b.png")).unwrap());
    let differ = a.to_rgb8().pixels().zip(b.to_rgb8().pixels()).filter(|(p, q)| p != q).count();
    assert!(differ > 20, "the boxes were not drawn ({differ} pixels differ)");
    let bad = run(&["render", "--aov", "normals"], dir.path());
    assert_eq!(bad.status.code(), Some(2));
}

/// Every light and camera type, end to end through a scene file.
#[test]
fn lights_and_cameras_through_the_scene_format() {
    let room = r#"
[render]
filter = "box"
[materials.m]
type = "diffuse"
albedo = 0.5
[[shapes]]
type = "quad"
corner = [-10, 0, 10]
edge1 = [20, 0, 0]
edge2 = [0, 0, -20]
material = "m"
"#;
    let top = "[camera]\ntype = \"orthographic\"\neye = [0, 5, 0]\nlook_at = [0, 0, 0]\nup = [0, 0, -1]\nscale = 2\n";
    // An emissive sphere above the floor: the floor below it is lit, and matches the analytic
    // irradiance of a sphere light, E = π L sin²α = π L (r/d)², within the sampling noise.
    let src = format!("{room}{top}[[shapes]]\ntype = \"sphere\"\ncenter = [0, 2, 0]\nradius = 0.5\nemission = 4\nlight_samples = 64\n");
    let (img, _) = render_src(&src, &Opts { width: 33, height: 33, spp: 4, ..Opts::default() });
    let centre = img.get(16, 16).x;
    // The orthographic camera looks straight down through the sphere at the centre pixel, so
    // check a pixel beside the sphere's silhouette: x = 0.85 (pixel 23 of 33 over [-2, 2]).
    let x: f32 = (23.5 / 33.0) * 4.0 - 2.0;
    let d2 = 4.0 + x * x;
    let cos_floor = 2.0 / d2.sqrt();
    let sin2a = 0.25 / d2;
    let expect = 0.5 / std::f32::consts::PI * std::f32::consts::PI * 4.0 * sin2a * cos_floor;
    let v = img.get(23, 16).x;
    assert!((v - expect).abs() < 0.05 * expect, "beside the sphere: {v} vs {expect}");
    assert!(centre > 1.0, "the sphere itself is seen from above: {centre}");
    // A spot light: lit inside its cone, dark outside.
    let src = format!("{room}{top}[[lights]]\ntype = \"spot\"\nposition = [0, 2, 0]\nlook_at = [0, 0, 0]\nintensity = 10\ncone_angle = 20\nfalloff_start = 15\n");
    let (img, _) = render_src(&src, &Opts { width: 33, height: 33, spp: 1, ..Opts::default() });
    assert!((img.get(16, 16).x - 0.5 / std::f32::consts::PI * 10.0 / 4.0).abs() < 1e-3);
    assert_eq!(img.get(0, 16).x, 0.0);
    // A thin lens focused on the floor sees it sharply; the same lens focused far away blurs a
    // checkerboard into grey.
    let checker = room.replace("albedo = 0.5", "albedo = { checker = [1, 0], scale = 40 }");
    let lens = |focus: f32| {
        format!("{checker}[camera]\ntype = \"thinlens\"\neye = [0, 4, 0.001]\nlook_at = [0, 0, 0]\nfov = 30\naperture = 0.3\nfocus_distance = {focus}\n[[lights]]\ntype = \"directional\"\ndirection = [0, -1, 0]\nirradiance = 3.14159265\n")
    };
    let contrast = |img: &Image| {
        let v: Vec<f32> = img.pixels.iter().map(|p| p.x).collect();
        let m = v.iter().sum::<f32>() / v.len() as f32;
        (v.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / v.len() as f32).sqrt()
    };
    let o = Opts { width: 32, height: 32, spp: 16, ..Opts::default() };
    let (sharp, _) = render_src(&lens(4.0), &o);
    let (blurred, _) = render_src(&lens(40.0), &o);
    assert!(contrast(&sharp) > 2.0 * contrast(&blurred), "{} vs {}", contrast(&sharp), contrast(&blurred));
}

// ---- Path tracing -------------------------------------------------------------------------

fn mean(img: &Image) -> snell_core::Rgb {
    img.pixels.iter().copied().sum::<snell_core::Rgb>() / img.pixels.len() as f32
}

/// Furnaces for the path tracer: in a uniform environment of radiance 1, a convex diffuse
/// object of albedo ρ has radiance ρ everywhere (it sees only the environment), and lossless
/// glass, smooth or thin, is invisible. The environment is reached only by BSDF sampling.
#[test]
fn path_tracer_furnaces() {
    let cases = [
        ("type = \"diffuse\"\nalbedo = 0.5", 0.5, 0.02f32),
        ("type = \"diffuse\"\nalbedo = 1", 1.0, 1e-4),
        ("type = \"dielectric\"\nior = 1.5", 1.0, 1e-4),
        ("type = \"thindielectric\"\nior = 1.5", 1.0, 1e-4),
    ];
    // The environment as an unsampled background, and as a light sampled with MIS.
    let envs = ["[render]\nbackground = 1\n", "[[lights]]\ntype = \"environment\"\nradiance = 1\n[render]\n"];
    for ((material, expect, tol), env) in cases.iter().flat_map(|c| envs.iter().map(move |e| (*c, *e))) {
        let src = format!(
            "{env}integrator = \"path\"\nrr_depth = 1000\nmax_depth = 200\n[camera]\neye = [0, 0, 4]\nfov = 20\n\
             [materials.m]\n{material}\n[[shapes]]\ntype = \"sphere\"\nradius = 1\nmaterial = \"m\"\n"
        );
        let (img, stats) = render_src(&src, &Opts { width: 16, height: 16, spp: 64, ..Opts::default() });
        // The sphere fills the centre of the image.
        let mut sum = 0.0f64;
        let mut n = 0;
        for y in 5..11 {
            for x in 5..11 {
                sum += img.get(x, y).x as f64;
                n += 1;
            }
        }
        let m = (sum / n as f64) as f32;
        // Light sampling makes single paths vary even in a furnace: then only the mean is exact.
        let tol = if env.contains("environment") { tol.max(0.01) } else { tol.max(1e-4) };
        assert!((m - expect).abs() <= tol * expect, "{material} ({env:?}): mean {m}, expected {expect}");
        assert!(stats.reflection + stats.refraction > 0);
    }
}

/// Direct light only (paths of two segments): the path tracer's MIS of light sampling and
/// BSDF sampling must give what the Whitted integrator's light sampling alone gives.
#[test]
fn path_tracer_direct_light_matches_light_sampling() {
    let scene = |integrator: &str, depth: u32| {
        format!(
            "[render]\nintegrator = \"{integrator}\"\nmax_depth = {depth}\n[camera]\neye = [0, -3, 2]\nlook_at = [0, 0, 0]\nfov = 50\n\
             [materials.floor]\ntype = \"diffuse\"\nalbedo = 0.6\n\
             [materials.shiny]\ntype = \"glossy\"\nalbedo = 0.3\nroughness = 0.3\n\
             [[shapes]]\ntype = \"quad\"\ncorner = [-3, -3, 0]\nedge1 = [6, 0, 0]\nedge2 = [0, 6, 0]\nmaterial = \"floor\"\n\
             [[shapes]]\ntype = \"sphere\"\ncenter = [0.6, 0.5, 0.5]\nradius = 0.5\nmaterial = \"shiny\"\n\
             [[shapes]]\ntype = \"quad\"\ncorner = [-0.5, -0.5, 2]\nedge1 = [0, 1, 0]\nedge2 = [1, 0, 0]\nemission = 4\nlight_samples = 16\n\
             [[shapes]]\ntype = \"sphere\"\ncenter = [-1, 0.5, 1.2]\nradius = 0.1\nemission = 30\n"
        )
    };
    // Enough samples that the tiny emitter seen directly (a fraction of a pixel) averages out:
    // at 1024 / 256 spp the two agree to 0.1 %.
    let o = Opts { width: 24, height: 24, spp: 256, ..Opts::default() };
    let (path, _) = render_src(&scene("path", 2), &Opts { spp: 1024, ..o });
    let (whitted, _) = render_src(&scene("whitted", 0), &o);
    let (a, b) = (mean(&path), mean(&whitted));
    assert!((a - b).abs().max_element() < 0.01 * b.max_element(), "path {a} vs light sampling {b}");
}

/// Global illumination with an exact answer: inside a closed box whose walls all emit `Le` and
/// reflect diffusely with albedo ρ, radiance is the same everywhere and `L = Le + ρ L`, so
/// `L = Le / (1 - ρ)`: every bounce matters (ρ = 0.5: half the light has bounced at least once).
#[test]
fn path_tracer_emissive_enclosure_converges_to_le_over_one_minus_albedo() {
    let walls = [
        ("[-1, -1, -1]", "[2, 0, 0]", "[0, 2, 0]"),
        ("[-1, -1, 1]", "[0, 2, 0]", "[2, 0, 0]"),
        ("[-1, -1, -1]", "[0, 2, 0]", "[0, 0, 2]"),
        ("[1, -1, -1]", "[0, 0, 2]", "[0, 2, 0]"),
        ("[-1, -1, -1]", "[0, 0, 2]", "[2, 0, 0]"),
        ("[-1, 1, -1]", "[2, 0, 0]", "[0, 0, 2]"),
    ];
    let mut src = String::from(
        "[render]\nintegrator = \"path\"\n[camera]\neye = [0.2, -0.3, 0.1]\nlook_at = [1, 0.5, 0.3]\nfov = 90\n\
         [materials.wall]\ntype = \"diffuse\"\nalbedo = 0.5\n",
    );
    for (c, e1, e2) in walls {
        src += &format!(
            "[[shapes]]\ntype = \"quad\"\ncorner = {c}\nedge1 = {e1}\nedge2 = {e2}\nmaterial = \"wall\"\nemission = 1\n"
        );
    }
    let (img, stats) = render_src(&src, &Opts { width: 16, height: 16, spp: 64, ..Opts::default() });
    let m = mean(&img);
    assert!((m.x - 2.0).abs() < 0.02, "mean radiance {m}, expected 2");
    // Bounded paths see less: max_depth 2 (emission + one bounce) gives Le (1 + ρ) = 1.5.
    let l = snell_io::scene::parse(&src.replace("[camera]", "max_depth = 2\n[camera]"), Path::new("t.toml")).unwrap();
    let (img2, _) = render_loaded(&l, &Opts { width: 16, height: 16, spp: 64, ..Opts::default() });
    assert!((mean(&img2).x - 1.5).abs() < 0.02, "max_depth 2: {}", mean(&img2));
    assert!(stats.shadow > 0 && stats.reflection > 0);
}

#[test]
fn path_tracer_is_bit_identical_across_thread_counts() {
    let mut l = snell_io::scene::load(&repo_scene("default.toml")).unwrap();
    l.settings.integrator = snell_core::integrator::IntegratorKind::Path;
    let o1 = Opts { width: 24, height: 16, spp: 4, threads: 1, ..Opts::default() };
    let (a, sa) = render_loaded(&l, &o1);
    let (b, sb) = render_loaded(&l, &Opts { threads: 2, ..o1 });
    let bits = |i: &Image| i.pixels.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(sa, sb);
}

#[test]
fn aovs_are_extra_exr_channels() {
    use exr::prelude::{read_all_flat_layers_from_file, FlatSamples};
    let dir = tempfile::tempdir().unwrap();
    let scene = "[render]\nintegrator = \"path\"\n[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\nfov = 10\n\
                 [materials.m]\ntype = \"diffuse\"\nalbedo = [0.2, 0.4, 0.6]\n\
                 [[shapes]]\ntype = \"quad\"\ncorner = [-10, -10, 0]\nedge1 = [20, 0, 0]\nedge2 = [0, 20, 0]\nmaterial = \"m\"\n\
                 [[lights]]\ntype = \"directional\"\ndirection = [0, 0, -1]\nirradiance = 1\n";
    std::fs::write(dir.path().join("s.toml"), scene).unwrap();
    let args = ["render", "s.toml", "--width", "9", "--height", "7", "--spp", "4", "--aov", "albedo,normal,depth"];
    let o = run(&[&args[..], &["-o", "a.exr"]].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let img = read_all_flat_layers_from_file(dir.path().join("a.exr")).unwrap();
    let layer = &img.layer_data[0];
    let channel = |name: &str| -> Vec<f32> {
        let c = layer.channel_data.list.iter().find(|c| c.name.to_string() == name).unwrap_or_else(|| panic!("{name}"));
        match &c.sample_data {
            FlatSamples::F32(v) => v.clone(),
            other => panic!("{other:?}"),
        }
    };
    let centre = 3 * 9 + 4;
    for (name, want) in [
        ("albedo.R", 0.2),
        ("albedo.G", 0.4),
        ("albedo.B", 0.6),
        ("normal.X", 0.0),
        ("normal.Z", 1.0),
        ("R", 0.2 / std::f32::consts::PI),
    ] {
        let v = channel(name)[centre];
        assert!((v - want).abs() < 1e-3, "{name}: {v} vs {want}");
    }
    // Depth: the distance along the ray, 5 at the centre and a little more off-centre.
    let z = channel("Z");
    assert!((z[centre] - 5.0).abs() < 0.01, "{}", z[centre]);
    assert!(z[0] > z[centre]);
    // AOVs do not change the image.
    let o = run(&[&args[..8], &["-o", "b.exr"]].concat(), dir.path());
    assert!(o.status.success());
    let (a, b) = (image::open(dir.path().join("a.exr")).unwrap(), image::open(dir.path().join("b.exr")).unwrap());
    assert_eq!(a.to_rgb32f().into_raw(), b.to_rgb32f().into_raw());
    // PNG cannot hold them.
    let o = run(&[&args[..], &["-o", "a.png"]].concat(), dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains(".exr"), "{}", stderr(&o));
    let o = run(&["render", "--aov", "colour", "-o", "x.exr"], dir.path());
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn image_textures_map_with_v_up() {
    // An 8×8 PNG: top half red | green, bottom half blue | white (sRGB 255 = linear 1).
    let dir = tempfile::tempdir().unwrap();
    let png = image::RgbImage::from_fn(8, 8, |x, y| match (x < 4, y < 4) {
        (true, true) => image::Rgb([255, 0, 0]),
        (false, true) => image::Rgb([0, 255, 0]),
        (true, false) => image::Rgb([0, 0, 255]),
        (false, false) => image::Rgb([255, 255, 255]),
    });
    png.save(dir.path().join("t.png")).unwrap();
    // A box filter keeps each sample inside its pixel, so inside its texel's neighbourhood.
    let src = "[render]\nspp = 1\nfilter = \"box\"\n[camera]\ntype = \"orthographic\"\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\nscale = 1\n\
               [materials.m]\ntype = \"diffuse\"\nalbedo = { image = \"t.png\" }\n\
               [[shapes]]\ntype = \"quad\"\ncorner = [-1, -1, 0]\nedge1 = [2, 0, 0]\nedge2 = [0, 2, 0]\nmaterial = \"m\"\n\
               [[lights]]\ntype = \"directional\"\ndirection = [0, 0, -1]\nirradiance = 3.14159265\n";
    std::fs::write(dir.path().join("s.toml"), src).unwrap();
    let l = snell_io::scene::load(&dir.path().join("s.toml")).unwrap_or_else(|e| panic!("{e}"));
    let (img, _) = render_loaded(&l, &Opts { width: 8, height: 8, spp: 1, ..Opts::default() });
    // The image's top left (v near 1) shows the texture's top left.
    for (x, y, want) in
        [(1, 1, [1.0, 0.0, 0.0]), (6, 1, [0.0, 1.0, 0.0]), (1, 6, [0.0, 0.0, 1.0]), (6, 6, [1.0, 1.0, 1.0])]
    {
        let p = img.get(x, y);
        assert!((p - snell_core::Rgb::from(want)).abs().max_element() < 0.02, "({x}, {y}): {p}");
    }
    let e = snell_io::scene::parse(
        "[materials.m]\ntype = \"diffuse\"\nalbedo = { image = \"missing.png\" }\n",
        &dir.path().join("x.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("missing.png"), "{e}");
}

#[test]
fn obj_with_mtl_gets_its_materials() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("m.mtl"),
        "newmtl red\nKd 0.8 0.1 0.1\nnewmtl glass\nillum 7\nNi 1.5\nnewmtl lamp\nKd 0 0 0\nKe 4 4 4\nmap_Bump b.png\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("m.obj"),
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\n\
         usemtl red\nf 1 2 3\nusemtl glass\nf 1 3 4\nusemtl lamp\nf 5 6 7\nusemtl nothing\nf 1 2 5\n",
    )
    .unwrap();
    let l = snell_io::scene::from_mesh(&dir.path().join("m.obj")).unwrap_or_else(|e| panic!("{e}"));
    let kinds: Vec<String> = l.scene.objects[2..]
        .iter()
        .map(|o| format!("{:?}", l.scene.materials[o.material]).split([' ', '{']).next().unwrap().to_string())
        .collect();
    assert_eq!(kinds, ["Diffuse", "Dielectric", "Diffuse", "Plastic"], "{kinds:?}");
    assert_eq!(l.scene.objects[4].emission, snell_core::Rgb::splat(4.0));
    assert_eq!(l.scene.triangle_count(), 4 + 2 + 2, "four faces, the floor and the light");
    assert!(l.warnings.iter().any(|w| w.contains("map_Bump") && w.contains("m.mtl:9:")), "{:?}", l.warnings);
    assert!(l.warnings.iter().any(|w| w.contains("'nothing'")), "{:?}", l.warnings);
    let (img, _) = render_loaded(&l, &Opts { width: 8, height: 8, spp: 1, ..Opts::default() });
    assert!(img.pixels.iter().all(|p| p.is_finite()));
}

#[test]
fn two_sided_false_makes_the_back_black() {
    // The camera looks at the back of a quad facing away, lit by an environment on both sides.
    let scene = |two_sided: &str| {
        format!(
            "[render]\nintegrator = \"path\"\n[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\nfov = 10\n\
             [[lights]]\ntype = \"environment\"\n\
             [materials.m]\ntype = \"diffuse\"\nalbedo = 0.5\n{two_sided}\n\
             [[shapes]]\ntype = \"quad\"\ncorner = [-10, -10, 0]\nedge1 = [0, 20, 0]\nedge2 = [20, 0, 0]\nmaterial = \"m\"\n"
        )
    };
    let o = Opts { width: 4, height: 4, spp: 16, ..Opts::default() };
    let (one, _) = render_src(&scene("two_sided = false"), &o);
    let (two, _) = render_src(&scene(""), &o);
    assert_eq!(one.get(2, 2), snell_core::Rgb::ZERO);
    assert!((two.get(2, 2).x - 0.5).abs() < 0.05, "{}", two.get(2, 2));
    let e = snell_io::scene::parse("[materials.g]\ntype = \"dielectric\"\ntwo_sided = false\n", Path::new("g.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("'two_sided' does not apply"), "{e}");
}

#[test]
fn every_light_sample_is_traced_whatever_their_number() {
    // Whitted draws a light's samples four at a time, the last one to three on their own:
    // every count from 1 to 9 must trace one shadow ray per sample at every point. The plane
    // fills the view and a rectangle light behind the camera sees all of it: large and near
    // (sampled by solid angle, two at a time in SSE2 lanes) or small (sampled by area).
    for (size, offset) in [(4.0f32, -2.0f32), (0.2, -0.1)] {
        for n in 1..=9u32 {
            let light = format!(
                "[[shapes]]\ntype = \"quad\"\ncorner = [{offset}, {offset}, 6]\nedge1 = [0, {size}, 0]\n\
                 edge2 = [{size}, 0, 0]\nmaterial = \"m\"\nemission = [1, 1, 1]\nlight_samples = {n}\n"
            );
            let (img, s) =
                render_src(&format!("{PLANE}{light}"), &Opts { width: 8, height: 6, spp: 1, ..Opts::default() });
            assert_eq!(s.camera, 48);
            assert_eq!(s.shadow, 48 * n as u64, "light of size {size}, {n} samples");
            assert!(
                img.pixels.iter().all(|p| p.min_element() > 0.0),
                "light of size {size}, {n} samples: a dark pixel"
            );
        }
    }
}
