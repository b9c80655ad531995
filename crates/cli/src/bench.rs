//! `snell bench`: build and ray-throughput measurements on a mesh, with the workload of
//! `../shared/bench` (the same camera, primary and bounce rays as the Embree reference), or
//! replaying the rays the Embree tool dumped.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use rayon::prelude::*;
use snell_core::accel::{Accel, AccelKind, AccelParams, AnyWorld};
use snell_core::geometry::Ray;
use snell_core::scene::{Geometry, Object, Scene, World};
use snell_core::shape::Mesh;
use snell_core::{with_world, Rgb};

#[derive(clap::Args)]
pub struct BenchArgs {
    /// The mesh (.ply or .obj).
    mesh: PathBuf,
    /// Accelerators to measure, comma-separated (their traces alternate round by round), or `all`.
    #[arg(long, default_value = "default", value_parser = parse_accels)]
    accel: Accels,
    /// Worker threads for building and tracing (default: one per core); a comma-separated list
    /// measures each count, their runs alternating round by round.
    #[arg(long, value_parser = parse_threads)]
    threads: Option<ThreadCounts>,
    /// Replay PREFIX_primary.f32 and PREFIX_bounce.f32 (as `embree_bench --dump-rays` writes them).
    #[arg(long, value_name = "PREFIX")]
    rays: Option<PathBuf>,
    /// One JSON object per accelerator and workload, one per line.
    #[arg(long)]
    json: bool,
    /// Timed repetitions (after one warm-up); the median is reported.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=64))]
    reps: u32,
    /// Primary ray image size.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..=16384))]
    width: u32,
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..=16384))]
    height: u32,
    /// Largest leaf of the top-down builds.
    #[arg(long, default_value_t = AccelParams::default().max_leaf_prims as u32, value_parser = clap::value_parser!(u32).range(1..=255))]
    max_leaf: u32,
    /// Depth limit of the top-down builds (the lecture's 24 by default).
    #[arg(long, default_value_t = AccelParams::default().max_depth as u32, value_parser = clap::value_parser!(u32).range(1..=63))]
    max_depth: u32,
    /// Also time workload `bounce-walk`: the bounce rays' any-hit walk with every leaf answering
    /// "not blocked" at once, without its triangle tests (the walk's own cost, a diagnostic).
    /// BVH accelerators only.
    #[arg(long)]
    walk_only: bool,
}

/// The accelerators `--accel` names, each once, in the order given.
#[derive(Clone, Debug)]
pub struct Accels(Vec<AccelKind>);

fn parse_accels(s: &str) -> Result<Accels, String> {
    if s == "all" {
        return Ok(Accels(AccelKind::ALL.to_vec()));
    }
    parse_list(s, |name| name.parse()).map(Accels)
}

/// The thread counts `--threads` names, each once, in the order given.
#[derive(Clone, Debug)]
pub struct ThreadCounts(Vec<usize>);

fn parse_threads(s: &str) -> Result<ThreadCounts, String> {
    parse_list(s, |part| match part.parse() {
        Ok(n) if (1..=4096).contains(&n) => Ok(n),
        _ => Err(format!("'{part}' is not a thread count (1 to 4096)")),
    })
    .map(ThreadCounts)
}

/// A comma-separated list, each item parsed by `one` (trimmed), each kept once in the order given.
fn parse_list<T: PartialEq>(s: &str, one: impl Fn(&str) -> Result<T, String>) -> Result<Vec<T>, String> {
    let mut items = Vec::new();
    for part in s.split(',') {
        let item = one(part.trim())?;
        if !items.contains(&item) {
            items.push(item);
        }
    }
    Ok(items)
}

/// One line of results.
struct Row {
    accel: AccelKind,
    threads: usize,
    build_ms: f64,
    accel_bytes: usize,
    workload: &'static str,
    rays: usize,
    hits: usize,
    mrays_per_s: f64,
    sah_cost: f32,
    /// Mean nodes (cells) visited and primitives tested per ray (an untimed counting pass).
    nodes_per_ray: f64,
    prims_per_ray: f64,
    nodes: usize,
    leaves: usize,
    depth: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn count_closest<A: Accel>(w: &World<A>, rays: &[Ray]) -> usize {
    dynamic(rays, |c| c.iter().filter(|r| w.hit(r, f32::INFINITY).is_some()).count())
}

/// `f` summed over the rays in pieces of 1024 (64 packets of sixteen), handed out as Embree's
/// benchmark hands them to its threads (OpenMP's `schedule(dynamic, 1024)`, `(dynamic, 64)`
/// for packets): each of the pool's threads takes the next piece until none is left. Rayon's
/// `par_chunks` split the bounce rays unevenly: two threads traced them 1.56–1.59× as fast as
/// one, against 2.0× this way (and Embree's 1.99×).
fn dynamic(rays: &[Ray], f: impl Fn(&[Ray]) -> usize + Sync) -> usize {
    use std::sync::atomic::{AtomicUsize, Ordering};
    const PIECE: usize = 1024;
    let next = AtomicUsize::new(0);
    let total = AtomicUsize::new(0);
    rayon::broadcast(|_| {
        let mut n = 0;
        loop {
            let i = next.fetch_add(PIECE, Ordering::Relaxed);
            if i >= rays.len() {
                break;
            }
            n += f(&rays[i..(i + PIECE).min(rays.len())]);
        }
        total.fetch_add(n, Ordering::Relaxed);
    });
    total.into_inner()
}

/// [`count_closest`] with the rays traced in packets of sixteen consecutive ones (the rest one
/// by one); primary rays come in 4×4 tiles ([`tiles_of_sixteen`]).
fn count_closest_packets<A: Accel>(w: &World<A>, rays: &[Ray]) -> usize {
    dynamic(rays, |c| {
        let mut packets = c.chunks_exact(16);
        let mut n = 0;
        for p in packets.by_ref() {
            let groups: [[Ray; 8]; 2] = std::array::from_fn(|g| std::array::from_fn(|i| p[8 * g + i]));
            let mut hits = [[None; 8]; 2];
            w.hit_packets(&groups, [0xff; 2], &mut hits);
            n += hits.iter().flatten().filter(|h| h.is_some()).count();
        }
        n + packets.remainder().iter().filter(|r| w.hit(r, f32::INFINITY).is_some()).count()
    })
}

/// Primary rays (one per pixel, row by row) reordered so that each sixteen consecutive rays
/// are a 4×4 pixel tile, row by row, the packets Embree's benchmark traces with
/// `rtcIntersect16`. Rays that are not a `width × height` image, or tiles cut by the image's
/// edge, keep their order.
fn tiles_of_sixteen(rays: &[Ray], width: usize, height: usize) -> Vec<Ray> {
    const TW: usize = 4;
    const TH: usize = 4;
    if rays.len() != width * height || !width.is_multiple_of(TW) || !height.is_multiple_of(TH) {
        return rays.to_vec();
    }
    let mut out = Vec::with_capacity(rays.len());
    for ty in (0..height).step_by(TH) {
        for tx in (0..width).step_by(TW) {
            for y in ty..ty + TH {
                out.extend_from_slice(&rays[y * width + tx..y * width + tx + TW]);
            }
        }
    }
    out
}

/// Mean traversal work per ray, counted in an untimed pass (closest hit for every workload).
fn work_per_ray<A: Accel>(w: &World<A>, rays: &[Ray]) -> (f64, f64) {
    let (n, p) = rays
        .par_chunks(1024)
        .map(|c| {
            let counts = snell_core::accel::Counts::default();
            for r in c {
                w.hit_counted(r, f32::INFINITY, &counts);
            }
            (counts.nodes.get(), counts.prims.get())
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let k = rays.len().max(1) as f64;
    (n as f64 / k, p as f64 / k)
}

fn count_occluded<A: Accel>(w: &World<A>, rays: &[Ray]) -> usize {
    dynamic(rays, |c| c.iter().filter(|r| w.occluded(r, f32::INFINITY)).count())
}

/// `bounce-walk`: the rays' any-hit walks without triangle tests ([`World::occluded_walk_only`]),
/// counted as `count_occluded` counts (never blocked, so 0). `run` has checked that the world
/// has such a walk.
fn count_walk_only<A: Accel>(w: &World<A>, rays: &[Ray]) -> usize {
    dynamic(rays, |c| c.iter().filter(|r| w.occluded_walk_only(r, f32::INFINITY) == Some(true)).count())
}

/// The brute-force oracle is far too slow for a million rays: it traces every `stride`-th
/// ray, at most 2,048 and at most as many as keep it near 10^8 triangle tests per pass.
fn subset(rays: &[Ray], kind: AccelKind, tris: usize) -> Vec<Ray> {
    if kind == AccelKind::Brute {
        let max = (100_000_000 / tris.max(1)).clamp(16, 2048);
        let stride = rays.len().div_ceil(max).max(1);
        rays.iter().step_by(stride).copied().collect()
    } else {
        rays.to_vec()
    }
}

/// One workload traced once on `world`: the rays that hit (closest hit), or are blocked.
fn trace(world: &AnyWorld, workload: &str, rays: &[Ray]) -> usize {
    with_world!(world, w => match workload {
        "bounce-occluded" => count_occluded(w, rays),
        "bounce-walk" => count_walk_only(w, rays),
        "primary-packets" => count_closest_packets(w, rays),
        _ => count_closest(w, rays),
    })
}

/// A structure as built: its kind, the world, and its build time (ms) with each pool.
type Built<'s> = (AccelKind, AnyWorld<'s>, Vec<f64>);

/// Times every workload on every built structure with every pool: per workload, one untimed
/// pass on each structure with each pool, then `reps` rounds that trace it on each in turn.
/// Taken round by round, the structures and thread counts share whatever the machine does
/// meanwhile (on a shared machine, whose speed drifts from one second to the next, their
/// ratios steady); one alone is simply timed `reps` times after a warm-up. Rows come structure
/// by structure, thread count by thread count, each the median of its rounds.
fn measure(
    built: &[Built<'_>],
    pools: &[(usize, rayon::ThreadPool)],
    work: &[(&'static str, Vec<Ray>)],
    reps: u32,
) -> Vec<Row> {
    struct Job {
        rays: Vec<Ray>,
        hits: Vec<usize>,
        secs: Vec<Vec<f64>>,
        work: (f64, f64),
    }
    let first = &pools[0].1;
    let mut jobs: Vec<Vec<Job>> = built
        .iter()
        .map(|(kind, world, _)| {
            let tris = with_world!(world, w => w.scene.triangle_count());
            work.iter()
                .map(|(_, rays)| {
                    let rays = subset(rays, *kind, tris);
                    let work = first.install(|| with_world!(world, w => work_per_ray(w, &rays)));
                    Job { rays, hits: vec![0; pools.len()], secs: vec![Vec::new(); pools.len()], work }
                })
                .collect()
        })
        .collect();
    for (k, (name, _)) in work.iter().enumerate() {
        for round in 0..=reps {
            for (a, (_, world, _)) in built.iter().enumerate() {
                for (p, (_, pool)) in pools.iter().enumerate() {
                    let job = &mut jobs[a][k];
                    let t0 = Instant::now();
                    job.hits[p] = pool.install(|| trace(world, name, &job.rays));
                    // Round 0 warms up.
                    if round > 0 {
                        job.secs[p].push(t0.elapsed().as_secs_f64());
                    }
                }
            }
        }
    }
    let mut rows = Vec::new();
    for ((kind, world, build_ms), jobs) in built.iter().zip(jobs) {
        let (stats, bytes) = with_world!(world, w => {
            let (_, blas) = w.structures();
            // Like Embree's figure: the structures and the triangle data their leaves point to.
            (blas.first().and_then(|b| b.as_ref()).map(|b| b.stats()).unwrap_or_default(), w.bytes())
        });
        for (p, (threads, _)) in pools.iter().enumerate() {
            for ((name, _), job) in work.iter().zip(&jobs) {
                let (nodes_per_ray, prims_per_ray) = job.work;
                rows.push(Row {
                    accel: *kind,
                    threads: *threads,
                    build_ms: build_ms[p],
                    accel_bytes: bytes,
                    workload: name,
                    rays: job.rays.len(),
                    hits: job.hits[p],
                    mrays_per_s: job.rays.len() as f64 / median(job.secs[p].clone()) / 1e6,
                    sah_cost: stats.sah_cost,
                    nodes_per_ray,
                    prims_per_ray,
                    nodes: stats.nodes,
                    leaves: stats.leaves,
                    depth: stats.max_depth,
                });
            }
        }
    }
    rows
}

/// Builds the workload: the reference's primary rays, and bounce rays from their hits.
fn workload(mesh: &Mesh, scene: &Scene, args: &BenchArgs) -> Result<Vec<(&'static str, Vec<Ray>)>> {
    let (primary, bounce) = match &args.rays {
        Some(prefix) => {
            let p = |suffix: &str| PathBuf::from(format!("{}_{suffix}.f32", prefix.display()));
            (snell_io::rays::read(&p("primary"))?, snell_io::rays::read(&p("bounce"))?)
        }
        None => {
            let primary = snell_core::bench::primary_rays(&mesh.positions, args.width, args.height, 40.0);
            let world = AccelKind::DEFAULT.build_world(scene, &AccelParams::default());
            let hits: Vec<Option<(f32, glam::Vec3)>> = with_world!(&world, w => primary
                .par_iter()
                .map(|r| {
                    w.hit(r, f32::INFINITY).map(|h| {
                        let [a, b, c] = mesh.triangle(h.prim as usize);
                        (h.t, (b - a).cross(c - a))
                    })
                })
                .collect());
            let radius = snell_core::bench::radius(&mesh.positions);
            let bounce = snell_core::bench::bounce_rays(&primary, &hits, radius);
            (primary, bounce)
        }
    };
    let tiled = tiles_of_sixteen(&primary, args.width as usize, args.height as usize);
    let mut work = vec![("primary", primary), ("primary-packets", tiled), ("bounce", bounce.clone())];
    if args.walk_only {
        work.push(("bounce-walk", bounce.clone()));
    }
    work.push(("bounce-occluded", bounce));
    Ok(work)
}

pub fn run(args: BenchArgs) -> Result<()> {
    let mesh = snell_io::read_mesh(&args.mesh)?;
    let name = args.mesh.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tris = mesh.indices.len();
    let scene = Scene {
        geometries: vec![Geometry::Mesh(mesh)],
        objects: vec![Object { geometry: 0, transform: None, material: 0, emission: Rgb::ZERO, light_samples: 1 }],
        materials: vec![snell_core::material::Material::Diffuse { albedo: Rgb::ONE.into() }],
        lights: vec![],
        camera: snell_core::camera::Camera::look_at(
            glam::Vec3::Z,
            glam::Vec3::ZERO,
            glam::Vec3::Y,
            snell_core::camera::Projection::Perspective { fov_y: 40.0 },
        )
        .context("internal: camera")?,
        background: Rgb::ZERO,
        ambient: Rgb::ZERO,
        light_selection: Default::default(),
    };
    let Geometry::Mesh(mesh) = &scene.geometries[0] else { unreachable!("built above") };
    // One pool per thread count (0: one thread per core).
    let counts = args.threads.as_ref().map_or(vec![0], |t| t.0.clone());
    let pools = counts
        .iter()
        .map(|&n| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().context("thread pool")?;
            Ok((pool.current_num_threads(), pool))
        })
        .collect::<Result<Vec<_>>>()?;
    if args.walk_only {
        if let Some(kind) = args.accel.0.iter().find(|k| !matches!(k, AccelKind::Bvh(_))) {
            clap::Error::raw(
                clap::error::ErrorKind::ArgumentConflict,
                format!("--walk-only times a BVH's walk; --accel names {}, which is not a BVH\n", kind.name()),
            )
            .exit();
        }
    }
    let work = pools[0].1.install(|| workload(mesh, &scene, &args))?;
    if !args.json {
        let threads: Vec<String> = pools.iter().map(|(n, _)| n.to_string()).collect();
        // By name: the workloads' order depends on the flags (the packets' count once stood
        // here for the bounce rays').
        let rays = |name| work.iter().find(|(w, _)| *w == name).map_or(0, |(_, r)| r.len());
        println!(
            "{name}: {tris} triangles, {} primary and {} bounce rays, {} threads, median of {} runs",
            rays("primary"),
            rays("bounce"),
            threads.join(" and "),
            args.reps
        );
        println!(
            "{:<12} {:>7} {:>9} {:>8} {:>16} {:>8} {:>8} {:>8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>5}",
            "accel",
            "threads",
            "build ms",
            "MiB",
            "workload",
            "rays",
            "hits",
            "Mrays/s",
            "SAH",
            "nodes/ray",
            "prims/ray",
            "nodes",
            "leaves",
            "depth"
        );
    }
    let params = AccelParams {
        max_leaf_prims: args.max_leaf as usize,
        max_depth: args.max_depth as usize,
        ..AccelParams::default()
    };
    // Every structure is built (and its build timed with each pool, the pools alternating
    // round by round, as the traces do) first, so that their traces can alternate.
    let built: Vec<Built> = args
        .accel
        .0
        .iter()
        .map(|&kind| {
            let mut secs = vec![Vec::new(); pools.len()];
            let mut world = None;
            for round in 0..=args.reps {
                for (p, (_, pool)) in pools.iter().enumerate() {
                    // The previous structure is released outside the timing (as Embree's
                    // benchmark releases its scene).
                    drop(world.take());
                    let t0 = Instant::now();
                    world = Some(pool.install(|| kind.build_world(&scene, &params)));
                    if round > 0 {
                        secs[p].push(t0.elapsed().as_secs_f64());
                    }
                }
            }
            let world = world.expect("built in the rounds above");
            (kind, world, secs.into_iter().map(|s| median(s) * 1e3).collect())
        })
        .collect();
    if args.walk_only {
        let probe = Ray::new(glam::Vec3::ZERO, glam::Vec3::Z);
        for (kind, world, _) in &built {
            if with_world!(world, w => w.occluded_walk_only(&probe, 1.0)).is_none() {
                anyhow::bail!(
                    "--walk-only: {} gives this mesh no tree to walk (its triangles are tested as one range)",
                    kind.name()
                );
            }
        }
    }
    let rows = measure(&built, &pools, &work, args.reps);
    for r in rows {
        if args.json {
            println!(
                "{{\"mesh\":\"{name}\",\"tris\":{tris},\"accel\":\"{}\",\"threads\":{},\"build_ms\":{:.3},\"accel_bytes\":{},\"workload\":\"{}\",\"rays\":{},\"hits\":{},\"mrays_per_s\":{:.6},\"sah_cost\":{:.3},\"nodes_per_ray\":{:.2},\"prims_per_ray\":{:.2},\"nodes\":{},\"leaves\":{},\"depth\":{}}}",
                r.accel,
                r.threads,
                r.build_ms,
                r.accel_bytes,
                r.workload,
                r.rays,
                r.hits,
                r.mrays_per_s,
                r.sah_cost,
                r.nodes_per_ray,
                r.prims_per_ray,
                r.nodes,
                r.leaves,
                r.depth
            );
        } else {
            println!(
                "{:<12} {:>7} {:>9.1} {:>8.2} {:>16} {:>8} {:>8} {:>8.2} {:>7.1} {:>8.1} {:>8.1} {:>8} {:>8} {:>5}",
                r.accel.name(),
                r.threads,
                r.build_ms,
                r.accel_bytes as f64 / (1024.0 * 1024.0),
                r.workload,
                r.rays,
                r.hits,
                r.mrays_per_s,
                r.sah_cost,
                r.nodes_per_ray,
                r.prims_per_ray,
                r.nodes,
                r.leaves,
                r.depth
            );
        }
    }
    Ok(())
}
