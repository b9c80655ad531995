//! `snell`: the command-line front end. Exit status 0 on success, 1 for bad input (a scene or
//! mesh that cannot be read, an output that cannot be written), 2 for command-line misuse.

mod alloc;
mod bench;
mod diff;
mod info;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use snell_core::accel::{AccelKind, AccelParams};
use snell_core::integrator::{IntegratorKind, RayStats};
use snell_core::render::{render_with_aovs, RenderSettings};
use snell_core::with_world;
use snell_io::scene::LoadedScene;

#[global_allocator]
static ALLOCATOR: alloc::HugePages = alloc::HugePages::GLOBAL;

/// The built-in default scene (`snell render` with no scene file).
const DEFAULT_SCENE: &str = include_str!("../../../scenes/default.toml");

#[derive(Parser)]
#[command(name = "snell", version, about = "Snell: a physically based CPU ray tracer")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (.toml) or a bare mesh (.obj, .ply) to PNG or EXR.
    Render(RenderArgs),
    /// Measure acceleration structure build time and ray throughput on a mesh (the workload of
    /// the Embree reference benchmark).
    Bench(bench::BenchArgs),
    /// Compare an image with a reference: mean colours, RMSE, relative MSE, and optionally a
    /// false-colour error image.
    Diff(diff::DiffArgs),
    /// What a scene file contains (shapes, triangles, materials, lights, camera, film,
    /// integrator) and everything that was ignored or approximated.
    Info(info::InfoArgs),
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Scene file (.toml, or Mitsuba 3 .xml) or mesh (.obj, .ply). Without it, the built-in
    /// default scene.
    scene: Option<PathBuf>,
    /// Mitsuba scenes: set a parameter (`$name`), overriding the file's `<default>`.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    define: Vec<(String, String)>,
    /// Output image; the extension picks the format: .png (8-bit sRGB) or .exr (linear float).
    #[arg(short, long, default_value = "snell.png")]
    output: PathBuf,
    /// Samples per pixel.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1_048_576))]
    spp: Option<u32>,
    /// Image width in pixels.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    width: Option<u32>,
    /// Image height in pixels.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    height: Option<u32>,
    /// Random seed; the image depends only on scene, seed and sample count.
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads (default: one per core). Does not change the image.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    threads: Option<u32>,
    /// Integrator: whitted (the lecture's recursive ray tree) or path (path tracing with
    /// next-event estimation and MIS).
    #[arg(long, value_parser = parse_integrator)]
    integrator: Option<IntegratorKind>,
    /// Whitted: maximum depth of the ray tree (0: camera and shadow rays only; default 10).
    /// Path: longest path in segments (1: emitters only, 2: direct light; default unbounded).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=100_000))]
    max_depth: Option<u32>,
    /// Sample generator: independent (random, with stratified camera samples) or sobol
    /// (Owen-scrambled Sobol points in every dimension).
    #[arg(long, value_parser = parse_sampler)]
    sampler: Option<snell_core::sampling::SamplerKind>,
    /// Path: depth at which Russian roulette starts.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=100_000))]
    rr_depth: Option<u32>,
    /// Prune branches whose accumulated weight falls below this.
    #[arg(long, value_parser = parse_attenuation)]
    min_attenuation: Option<f32>,
    /// Acceleration structure: default, brute, bvh-center, bvh-median, bvh-sah, bvh-bottomup, kdtree, grid.
    #[arg(long, value_parser = parse_accel)]
    accel: Option<AccelKind>,
    /// Extra images. `albedo`, `normal`, `depth` (comma-separated): written as further channels
    /// of the EXR (`albedo.R/G/B`, `normal.X/Y/Z`, `Z`). Or, instead of shading, `heatmap`: one
    /// ray per pixel centre, coloured by the nodes it visits (written to OUT) and the primitives
    /// it tests (written to OUT with `-prims` added).
    #[arg(long, value_parser = parse_aov)]
    aov: Option<Aov>,
    /// Draw the boxes of the acceleration structure at this depth (0 = the root) over the image.
    #[arg(long, value_name = "DEPTH", value_parser = clap::value_parser!(u32).range(0..=64))]
    show_boxes: Option<u32>,
}

fn parse_attenuation(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be between 0 and 1, found {v}"))
    }
}

fn parse_accel(s: &str) -> Result<AccelKind, String> {
    s.parse()
}

fn parse_integrator(s: &str) -> Result<IntegratorKind, String> {
    s.parse()
}

fn parse_sampler(s: &str) -> Result<snell_core::sampling::SamplerKind, String> {
    s.parse()
}

/// What `--aov` asks for.
#[derive(Clone, Debug, PartialEq)]
enum Aov {
    Heatmap,
    /// Which of albedo, normal, depth.
    Layers {
        albedo: bool,
        normal: bool,
        depth: bool,
    },
}

fn parse_aov(s: &str) -> Result<Aov, String> {
    if s == "heatmap" {
        return Ok(Aov::Heatmap);
    }
    let (mut albedo, mut normal, mut depth) = (false, false, false);
    for part in s.split(',') {
        match part.trim() {
            "albedo" => albedo = true,
            "normal" => normal = true,
            "depth" => depth = true,
            other => {
                return Err(format!("unknown AOV '{other}' (expected heatmap, or a list of albedo, normal, depth)"))
            }
        }
    }
    Ok(Aov::Layers { albedo, normal, depth })
}

pub(crate) fn parse_define(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
        _ => Err(format!("'{s}': expected NAME=VALUE")),
    }
}

fn main() -> ExitCode {
    alloc::init();
    // Output piped into a reader that stops early (`snell info scene.xml | head`) ends the
    // program quietly, as it does `cat` or `grep`, instead of making the next `println!`
    // panic on the broken pipe (Rust ignores SIGPIPE by default).
    #[cfg(unix)]
    // SAFETY: called first thing, before any other thread exists; SIG_DFL is a valid handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => in_pool(args.threads, || cmd_render(args)),
        Command::Bench(args) => bench::run(args),
        Command::Diff(args) => diff::run(args),
        Command::Info(args) => info::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Runs `f` in a pool of `threads` workers (default: one per core), so that all a command does
/// in parallel (loading, building the accelerator, rendering) keeps to the count asked for, as
/// pbrt's `--nthreads` does. Without it the load and the build ran on every core whatever
/// `--threads` said.
fn in_pool<T: Send>(threads: Option<u32>, f: impl FnOnce() -> Result<T> + Send) -> Result<T> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.map_or(0, |n| n as usize))
        .build()
        .context("making the thread pool")?;
    pool.install(f)
}

pub(crate) fn load(scene: Option<&Path>, defines: &[(String, String)]) -> Result<LoadedScene> {
    let Some(path) = scene else {
        return Ok(snell_io::scene::parse(DEFAULT_SCENE, Path::new("<built-in default scene>"))?);
    };
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    if !defines.is_empty() && ext.as_deref() != Some("xml") {
        bail!("-D applies to Mitsuba scenes (.xml) only");
    }
    Ok(snell_io::load_scene(path, defines)?)
}

fn cmd_render(args: RenderArgs) -> Result<()> {
    snell_io::image_out::check_output(&args.output)?;
    let t_load = Instant::now();
    let loaded = load(args.scene.as_deref(), &args.define)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let load_s = t_load.elapsed().as_secs_f64();
    let mut scene = loaded.scene;
    let s = loaded.settings;

    let mut settings = RenderSettings {
        width: args.width.unwrap_or(s.width),
        height: args.height.unwrap_or(s.height),
        spp: args.spp.unwrap_or(s.spp),
        seed: args.seed.unwrap_or(s.seed),
        // The command's own pool (`in_pool`), which the render then works in.
        threads: rayon::current_num_threads(),
        filter: s.filter.clone(),
        reconstruction: s.reconstruction,
        sampler: args.sampler.unwrap_or(s.sampler),
        aovs: false,
    };
    settings.check().map_err(anyhow::Error::msg)?;
    if matches!(args.aov, Some(Aov::Layers { .. })) {
        if snell_io::image_out::format_for(&args.output)? != snell_io::image_out::ImageFormat::Exr {
            bail!("{}: AOVs are written as EXR channels; the output must end in .exr", args.output.display());
        }
        settings.aovs = true;
    }
    let integrator = snell_io::scene::SceneSettings {
        integrator: args.integrator.unwrap_or(s.integrator),
        max_depth: args.max_depth.or(s.max_depth),
        min_attenuation: args.min_attenuation.unwrap_or(s.min_attenuation),
        rr_depth: args.rr_depth.unwrap_or(s.rr_depth),
        ..s.clone()
    }
    .integrator();
    let accel = args.accel.unwrap_or(s.accel);
    // An automatic camera is framed for the final aspect ratio.
    if let Some(c) = loaded.frame.and_then(|b| snell_io::scene::auto_camera(b, settings.width, settings.height)) {
        scene.camera = c;
    }

    let t_build = Instant::now();
    let world = accel.build_world(&scene, &AccelParams::default());
    let build_s = t_build.elapsed().as_secs_f64();

    let boxes = args.show_boxes.map(|d| with_world!(&world, w => snell_core::inspect::boxes_at_depth(w, d as usize)));
    let overlay = |img: &mut snell_core::image::Image| {
        if let Some(b) = &boxes {
            snell_core::inspect::draw_boxes(img, &scene.camera, b, snell_core::Rgb::new(0.1, 1.0, 0.25));
        }
    };
    if args.aov == Some(Aov::Heatmap) {
        let t0 = Instant::now();
        let hm = with_world!(&world, w => snell_core::inspect::heat_map(w, &settings));
        let secs = t0.elapsed().as_secs_f64();
        let prims_path = suffixed(&args.output, "-prims");
        for (values, path, what) in
            [(&hm.nodes, &args.output, "nodes visited"), (&hm.prims, &prims_path, "primitives tested")]
        {
            let max = values.iter().copied().max().unwrap_or(0);
            let mean = values.iter().map(|&v| v as f64).sum::<f64>() / values.len().max(1) as f64;
            let mut img = snell_core::inspect::colourize(hm.width, hm.height, values, max);
            overlay(&mut img);
            snell_io::image_out::write_image(path, &img).with_context(|| format!("writing {}", path.display()))?;
            println!("{}: {what} per camera ray, black = 0 .. pale yellow = {max} (mean {mean:.1})", path.display());
        }
        println!("heat map with {accel}: {}x{} rays in {secs:.2} s", settings.width, settings.height);
        return Ok(());
    }

    let pixels = settings.width as u64 * settings.height as u64;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(pixels), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] [{wide_bar}] {percent:>3}% ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let progress = |n: u64| bar.inc(n);
    let t_render = Instant::now();
    let (mut image, aovs, stats) = with_world!(&world, w => render_with_aovs(w, &integrator, &settings, &progress));
    overlay(&mut image);
    let render_s = t_render.elapsed().as_secs_f64();
    bar.finish_and_clear();

    match (&args.aov, aovs) {
        (Some(Aov::Layers { albedo, normal, depth }), Some(a)) => {
            let mut extra: Vec<(&str, Vec<f32>)> = Vec::new();
            if *albedo {
                for (c, name) in ["albedo.R", "albedo.G", "albedo.B"].into_iter().enumerate() {
                    extra.push((name, a.albedo.iter().map(|v| v[c]).collect()));
                }
            }
            if *normal {
                for (c, name) in ["normal.X", "normal.Y", "normal.Z"].into_iter().enumerate() {
                    extra.push((name, a.normal.iter().map(|v| v[c]).collect()));
                }
            }
            if *depth {
                extra.push(("Z", a.depth.clone()));
            }
            snell_io::image_out::write_exr_channels(&args.output, &image, &extra)
        }
        _ => snell_io::image_out::write_image(&args.output, &image),
    }
    .with_context(|| format!("writing {}", args.output.display()))?;
    print_stats(&stats);
    let threads = settings.threads;
    println!(
        "{}: {}x{} at {} spp with {} ({} triangles): load {:.2} s, build {:.3} s, render {:.3} s, {:.2} Mrays/s, {} {}",
        args.output.display(),
        settings.width,
        settings.height,
        settings.spp,
        accel,
        scene.triangle_count(),
        load_s,
        build_s,
        render_s,
        stats.total_rays() as f64 / render_s.max(1e-9) / 1e6,
        threads,
        if threads == 1 { "thread" } else { "threads" }
    );
    Ok(())
}

/// `dir/name.ext` → `dir/name{suffix}.ext`.
fn suffixed(p: &Path, suffix: &str) -> PathBuf {
    let stem = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match p.extension() {
        Some(e) => format!("{stem}{suffix}.{}", e.to_string_lossy()),
        None => format!("{stem}{suffix}"),
    };
    p.with_file_name(name)
}

fn print_stats(s: &RayStats) {
    println!("ray tree:");
    println!("  camera rays         {:>12}", s.camera);
    println!("  shadow rays         {:>12}", s.shadow);
    println!("  reflection rays     {:>12}", s.reflection);
    println!("  refraction rays     {:>12}", s.refraction);
    println!("  pruned by depth     {:>12}", s.pruned_depth);
    println!("  pruned by weight    {:>12}", s.pruned_attenuation);
    println!("  total int. refl.    {:>12}", s.total_internal_reflections);
}
