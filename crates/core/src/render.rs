//! The render loop: the image is cut into tiles, rendered in parallel on a rayon pool.
//! Each pixel is computed from its own random streams (see [`crate::sampling`]), so the result
//! does not depend on how tiles are scheduled: it is bit-identical for any thread count.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::accel::Accel;
use crate::filter::Filter;
use crate::geometry::Ray;
use crate::image::Image;
use crate::integrator::{Integrator, RayStats};
use crate::sampling::{Sampler, SamplerKind, Strata};
use crate::scene::World;
use crate::Rgb;

/// How the image is sampled.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel, stratified over the pixel (and the lens).
    pub spp: u32,
    pub seed: u64,
    /// Worker threads; 0 means one per core.
    pub threads: usize,
    pub filter: Filter,
    pub reconstruction: Reconstruction,
    pub sampler: SamplerKind,
    /// Also compute the albedo, normal and depth AOVs (one more camera-ray intersection per
    /// sample).
    pub aovs: bool,
}

/// Auxiliary images of the first surface each camera sample sees, filtered like the image:
/// albedo ([`crate::material::Material::albedo`]), world-space shading normal (facing the
/// camera), and depth (distance along the camera ray). Misses contribute zero.
#[derive(Clone, Debug, PartialEq)]
pub struct Aovs {
    pub albedo: Vec<Rgb>,
    pub normal: Vec<Vec3>,
    pub depth: Vec<f32>,
}

/// What one sample adds to a pixel: `Σ w·L`, `Σ w`, and the AOVs weighted alike.
#[derive(Clone, Copy, Debug, Default)]
struct Accum {
    l: Rgb,
    w: f32,
    albedo: Rgb,
    normal: Vec3,
    depth: f32,
}

impl Accum {
    /// Adds the sums of another accumulator (weights included).
    fn merge(&mut self, o: &Accum) {
        self.l += o.l;
        self.w += o.w;
        self.albedo += o.albedo;
        self.normal += o.normal;
        self.depth += o.depth;
    }

    /// Adds one sample with filter weight `w`; `aovs`: its AOVs too (without them, only the
    /// radiance and the weight are summed, the rest staying zero).
    #[inline(always)]
    fn add(&mut self, s: &Accum, w: f32, aovs: bool) {
        self.l += s.l * w;
        self.w += w;
        if aovs {
            self.albedo += s.albedo * w;
            self.normal += s.normal * w;
            self.depth += s.depth * w;
        }
    }
}

/// How samples become pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Reconstruction {
    /// Filter importance sampling (pbrt-v4): each sample lands at an offset distributed like the
    /// filter and counts for its own pixel only; pixels are plain averages.
    #[default]
    ImportanceSampled,
    /// Splatting (Mitsuba 3, pbrt-v3): samples are uniform over their pixel and add to every pixel
    /// whose filter covers them, weighted by the filter; pixels are `Σ w L / Σ w`. Neighbouring
    /// pixels share samples, so wide filters give smoother (correlated) noise.
    Splat,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 640,
            height: 480,
            spp: 16,
            seed: 0,
            threads: 0,
            filter: Filter::default(),
            reconstruction: Reconstruction::default(),
            sampler: SamplerKind::default(),
            aovs: false,
        }
    }
}

/// The largest image [`RenderSettings::check`] accepts: 2^28 pixels (3 GiB of float RGB).
pub const MAX_PIXELS: u64 = 1 << 28;

impl RenderSettings {
    /// Rejects settings that cannot be rendered: a zero-sized image, one too large to hold in
    /// memory, or zero samples.
    pub fn check(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!("the image is {}x{} pixels; both sizes must be at least 1", self.width, self.height));
        }
        let pixels = self.width as u64 * self.height as u64;
        if pixels > MAX_PIXELS {
            return Err(format!(
                "the image is {}x{} = {pixels} pixels; at most {MAX_PIXELS} are supported",
                self.width, self.height
            ));
        }
        if self.spp == 0 {
            return Err("the sample count must be at least 1".into());
        }
        Ok(())
    }
}

const TILE: u32 = 16;
/// Splatting reaches at most this many pixels beyond a sample's own (filter radius 16.5).
const MAX_SPLAT_MARGIN: u32 = 16;
/// The most pixels a splatted sample reaches along one axis.
const SPLAT_SPAN: usize = 2 * MAX_SPLAT_MARGIN as usize + 1;

/// The pixels along one axis (of `n`) within `m` of pixel `c` that a sample at film coordinate
/// `f` reaches through `filter`, written to `out` in increasing order with their weights; returns
/// how many there are. Pixels of weight zero are left out.
#[inline]
fn splat_weights(filter: &Filter, f: f32, c: u32, m: u32, n: u32, out: &mut [(u32, f32); SPLAT_SPAN]) -> usize {
    let (lo, hi) = (c.saturating_sub(m), (c + m).min(n - 1));
    let mut k = 0;
    // Eight pixels at a time, their weights worked out in lanes ([`Filter::eval_1d_8`]). (A
    // pixel's index converts through `i32`, the same value below 2^31, as SSE2 converts only
    // signed integers.)
    for p0 in (lo..=hi).step_by(8) {
        let x: [f32; 8] = std::array::from_fn(|j| f - ((p0 + j as u32) as i32 as f32 + 0.5));
        let wt = filter.eval_1d_8(&x);
        for (j, &wt) in wt.iter().enumerate().take((hi - p0 + 1) as usize) {
            if wt != 0.0 {
                out[k] = (p0 + j as u32, wt);
                k += 1;
            }
        }
    }
    k
}

/// Renders the world. `progress(pixels)` is called as tiles finish (from worker threads).
/// Returns the image and the summed ray statistics.
pub fn render<A: Accel, I: Integrator>(
    world: &World<A>,
    integrator: &I,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> (Image, RayStats) {
    let (image, _, stats) = render_with_aovs(world, integrator, settings, progress);
    (image, stats)
}

/// [`render`], also returning the AOVs when `settings.aovs` asks for them.
pub fn render_with_aovs<A: Accel, I: Integrator>(
    world: &World<A>,
    integrator: &I,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> (Image, Option<Aovs>, RayStats) {
    let (w, h) = (settings.width, settings.height);
    let tiles: Vec<(u32, u32)> =
        (0..h.div_ceil(TILE)).flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx * TILE, ty * TILE))).collect();
    let splat = settings.reconstruction == Reconstruction::Splat;
    // Splatting: how far beyond its tile a sample's filter reaches, in pixels.
    let m = if splat { ((settings.filter.radius() - 0.5).max(0.0).ceil() as u32).min(MAX_SPLAT_MARGIN) } else { 0 };
    let strata = Strata::new(settings.spp);
    // Splatting through a box at least a pixel wide (Mitsuba's default `box`): every sample
    // lies in its own pixel, within the box's reach on both axes (`|film − centre| ≤ 0.5`
    // exactly, for coordinates below 2^22, where `x + 0.5` and the sum with an offset in
    // `[−0.5, 0.5]` round within `[x, x + 1]`), so its weight is 1, as the loops would find.
    let unit_splat =
        splat && m == 0 && matches!(settings.filter, Filter::Box { radius } if radius >= 0.5) && w.max(h) <= 1 << 22;
    let work = || {
        tiles
            .par_iter()
            .map(|&(x0, y0)| {
                let mut stats = RayStats::default();
                let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
                // The tile's pixels plus a margin of m: Σ w·L and Σ w per pixel.
                let bw = (x1 - x0 + 2 * m) as usize;
                let mut acc = vec![Accum::default(); bw * (y1 - y0 + 2 * m) as usize];
                let mut packets = CameraPackets::new();
                let mut scratch = I::Scratch::default();
                // A splatted sample's columns and rows with their weights.
                let (mut cols, mut rows) = ([(0, 0.0); SPLAT_SPAN], [(0, 0.0); SPLAT_SPAN]);
                let aovs = settings.aovs;
                for y in y0..y1 {
                    for x in x0..x1 {
                        // The pixel's own accumulator.
                        let own = (y + m - y0) as usize * bw + (x + m - x0) as usize;
                        render_pixel(
                            world,
                            integrator,
                            settings,
                            &strata,
                            x,
                            y,
                            &mut stats,
                            &mut packets,
                            &mut scratch,
                            &mut |film, sample| {
                                if !splat || unit_splat {
                                    acc[own].add(&sample, 1.0, aovs);
                                    return;
                                }
                                // The filter is separable: one weight per column and per row,
                                // and only those it reaches are visited (a filter within the
                                // pixel, `m` = 0, weighs the sample's own pixel only).
                                let nc = splat_weights(&settings.filter, film.x, x, m, w, &mut cols);
                                let nr = splat_weights(&settings.filter, film.y, y, m, h, &mut rows);
                                for &(py, wy) in &rows[..nr] {
                                    let row = (py + m - y0) as usize * bw;
                                    for &(px, wx) in &cols[..nc] {
                                        let wt = wx * wy;
                                        if wt != 0.0 {
                                            acc[row + (px + m - x0) as usize].add(&sample, wt, aovs);
                                        }
                                    }
                                }
                            },
                        );
                    }
                }
                progress(((x1 - x0) * (y1 - y0)) as u64);
                (x0, y0, acc, stats)
            })
            .collect::<Vec<_>>()
    };
    let results = on_threads(settings.threads, work);
    // Tiles are merged in a fixed order, so the sums (and the image) do not depend on threads.
    let mut sums = vec![Accum::default(); (w * h) as usize];
    let mut stats = RayStats::default();
    for (x0, y0, acc, s) in results {
        let bw = (TILE.min(w - x0) + 2 * m) as usize;
        for (i, a) in acc.iter().enumerate() {
            let (bx, by) = ((i % bw) as i64, (i / bw) as i64);
            let (x, y) = (x0 as i64 + bx - m as i64, y0 as i64 + by - m as i64);
            if a.w != 0.0 && (0..w as i64).contains(&x) && (0..h as i64).contains(&y) {
                sums[y as usize * w as usize + x as usize].merge(a);
            }
        }
        stats.add(&s);
    }
    let mut image = Image::new(w, h);
    for (p, a) in image.pixels.iter_mut().zip(&sums) {
        *p = if a.w > 0.0 { a.l / a.w } else { Rgb::ZERO };
    }
    let aovs = settings.aovs.then(|| Aovs {
        albedo: sums.iter().map(|a| if a.w > 0.0 { a.albedo / a.w } else { Rgb::ZERO }).collect(),
        normal: sums.iter().map(|a| if a.w > 0.0 { a.normal / a.w } else { Vec3::ZERO }).collect(),
        depth: sums.iter().map(|a| if a.w > 0.0 { a.depth / a.w } else { 0.0 }).collect(),
    });
    (image, aovs, stats)
}

/// Runs `f` on `threads` workers (0: one per core). Called from a pool of that many (the CLI
/// runs each command in one), `f` works in it; otherwise in a pool of its own (or, where no
/// pool can be made, in the caller's).
pub(crate) fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    if rayon::current_thread_index().is_some() && rayon::current_num_threads() == threads {
        return f();
    }
    match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
        Ok(pool) => pool.install(f),
        Err(_) => f(),
    }
}

/// Samples of a pixel whose camera rays are traced together: packets of eight, `CHUNK / 8`
/// of them under one frustum.
const CHUNK: usize = 32;

/// Room for `CHUNK` camera samples (their samplers, film and lens positions, rays and hits),
/// made once per tile and filled afresh for each pixel's samples: set up per pixel, these
/// arrays cost up to 27 % at 8 samples a pixel. Only the entries of the samples being traced
/// are read.
struct CameraPackets {
    samplers: [Sampler; CHUNK],
    film: [[Vec2; 8]; CHUNK / 8],
    lens: [[Vec2; 8]; CHUNK / 8],
    rays: [[Ray; 8]; CHUNK / 8],
    hits: [[Option<crate::scene::RawHit>; 8]; CHUNK / 8],
    /// One packet's hits with their interactions, handed to the integrator (filled in place:
    /// built as a new array and moved here, they were copied through `memcpy`).
    firsts: [Option<crate::scene::Intersection>; 8],
}

impl CameraPackets {
    fn new() -> CameraPackets {
        CameraPackets {
            samplers: std::array::from_fn(|_| Sampler::new(SamplerKind::Independent, 0, 0, 0, 1)),
            film: [[Vec2::ZERO; 8]; CHUNK / 8],
            lens: [[Vec2::ZERO; 8]; CHUNK / 8],
            rays: [[Ray::new(Vec3::ZERO, Vec3::Z); 8]; CHUNK / 8],
            hits: [[None; 8]; CHUNK / 8],
            firsts: [None; 8],
        }
    }
}

/// Traces the samples of pixel `(x, y)`, handing each one's film position and radiance to
/// `sink`. Camera rays go `CHUNK` at a time, in packets of eight traced together
/// ([`World::hit_packets`]), which find for each ray the hit it finds alone (but for exact
/// ties between triangles, see [`World::hit_packet8`]). A hit's
/// [`Intersection`](crate::scene::Intersection) is made only when its sample is shaded.
#[allow(clippy::too_many_arguments)]
fn render_pixel<A: Accel, I: Integrator>(
    world: &World<A>,
    integrator: &I,
    s: &RenderSettings,
    strata: &Strata,
    x: u32,
    y: u32,
    stats: &mut RayStats,
    packets: &mut CameraPackets,
    scratch: &mut I::Scratch,
    sink: &mut impl FnMut(Vec2, Accum),
) {
    const GROUPS: usize = CHUNK / 8;
    let pixel = y as u64 * s.width as u64 + x as u64;
    let key = (crate::sampling::mix64(s.seed ^ pixel) >> 32) as u32;
    // Film and lens samples, rays and hits by packet of eight.
    let CameraPackets { samplers, film, lens, rays, hits, firsts } = packets;
    for first in (0..s.spp).step_by(CHUNK) {
        let n = (s.spp - first).min(CHUNK as u32) as usize;
        for k in 0..n {
            let (sampler, f, l) = camera_film(world, s, strata, x, y, pixel, key, first + k as u32);
            (samplers[k], film[k / 8][k % 8], lens[k / 8][k % 8]) = (sampler, f, l);
        }
        // Eight rays at once (`Camera::rays8`, the same rays as one at a time); lanes past
        // the pixel's last sample repeat its first and are not traced.
        for k in n..n.next_multiple_of(8) {
            (film[k / 8][k % 8], lens[k / 8][k % 8]) = (film[0][0], lens[0][0]);
        }
        for (g, rays) in rays.iter_mut().enumerate().take(n.div_ceil(8)) {
            world.scene.camera.rays8(&film[g], s.width, s.height, &lens[g], rays);
        }
        let active: [u8; GROUPS] = std::array::from_fn(|g| (0xffu32 >> (8 - n.saturating_sub(8 * g).min(8))) as u8);
        // One packet where the samples fill one; otherwise four under one frustum, idle ones
        // included. (Sixteen-ray packets are the bench's: tracing them here as well changed how
        // the bench's copy was compiled, and cost it 5 %.)
        if n <= 8 {
            hits[0] = world.hit_packet8(&rays[0], active[0]);
        } else {
            world.hit_packets(rays, active, hits);
        }
        for g in 0..n.div_ceil(8) {
            let m = (n - 8 * g).min(8);
            let (film, rays) = (&film[g], &rays[g]);
            for (i, first) in firsts.iter_mut().enumerate() {
                match hits[g][i].as_ref().filter(|_| i < m) {
                    Some(h) => world.interaction_into(&rays[i], h, first),
                    None => *first = None,
                }
            }
            stats.camera += m as u64;
            // The AOVs of the camera hits, where asked for (built before the integrator takes
            // the hits over).
            let aovs: Option<[Accum; 8]> = s.aovs.then(|| {
                std::array::from_fn(|i| {
                    let mut sample = Accum::default();
                    if let Some(hit) = &firsts[i] {
                        let (o, ray) = (&world.scene.objects[hit.object as usize], &rays[i]);
                        sample.albedo = world.scene.materials[o.material].albedo(hit.uv);
                        sample.normal = if hit.ns.dot(ray.d) > 0.0 { -hit.ns } else { hit.ns };
                        sample.depth = hit.t * ray.d.length();
                    }
                    sample
                })
            });
            let ls = integrator.radiance8(world, rays, firsts, &mut samplers[8 * g..8 * g + m], stats, scratch);
            for i in 0..m {
                let mut sample = aovs.as_ref().map_or_else(Accum::default, |a| a[i]);
                // Tested in 16-byte lanes, as the path tracer sums (see `Path::radiance`).
                let l = glam::Vec3A::from(ls[i]);
                // A non-finite sample (NaN from a degenerate configuration) would poison the
                // pixel; it still counts (as black), so that the estimate stays unbiased where
                // it is finite.
                sample.l = if l.is_finite() { l.into() } else { Rgb::ZERO };
                sink(film[i], sample);
            }
        }
    }
}

/// Camera sample `i` of a pixel without its ray: its sampler (past the camera's dimensions),
/// film position and lens sample.
#[allow(clippy::too_many_arguments)]
fn camera_film<A: Accel>(
    world: &World<A>,
    s: &RenderSettings,
    strata: &Strata,
    x: u32,
    y: u32,
    pixel: u64,
    key: u32,
    i: u32,
) -> (Sampler, Vec2, Vec2) {
    let mut sampler = Sampler::new(s.sampler, s.seed, pixel, i, s.spp);
    let (film_u, lens_u) = match s.sampler {
        SamplerKind::Independent => {
            let rng = sampler.rng();
            // The film's strata in order (sample `i` in cell `i`): no permutation to compute,
            // and a packet's eight rays cross one row of cells, which keeps it coherent. The
            // lens's strata are shuffled, so that film and lens cells are paired at random.
            let film = strata.sample_in_order(i, key, rng);
            // Cameras without a lens ignore the lens sample: its draw only advances the stream
            // (by the one 2D draw a stratified sample makes), without stratifying it.
            let lens = if world.scene.camera.has_lens() {
                strata.sample(i, key ^ 0x5bd1_e995, rng)
            } else {
                rng.next_2d();
                Vec2::ZERO
            };
            (film, lens)
        }
        SamplerKind::Sobol => (sampler.next_2d(), sampler.next_2d()),
    };
    let offset = match s.reconstruction {
        Reconstruction::ImportanceSampled => s.filter.sample(film_u),
        Reconstruction::Splat => film_u - Vec2::splat(0.5),
    };
    let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + offset;
    (sampler, film, lens_u)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{AccelKind, AccelParams};
    use crate::camera::{Camera, Projection};
    use crate::geometry::Transform;
    use crate::integrator::Path;
    use crate::light::{Environment, Light};
    use crate::material::microfacet::Distribution;
    use crate::material::{Material, Texture};
    use crate::scene::{Geometry, LightSelection, Object, Scene};
    use crate::shape::Mesh;

    /// Camera rays traced in packets (up to four packets of eight under one frustum, where the
    /// scene is one mesh) give exactly the image of each sample traced alone: one partial
    /// packet (5 samples), a full and a partial one (11), three with the last partial and
    /// the fourth idle (21), and 32 then a partial one (37), through a pinhole, a thin lens and
    /// an orthographic camera. Samples land by filter importance sampling (the default) and
    /// are splatted through Mitsuba's one-pixel box (each sample weighs 1 in its own pixel
    /// only); either way a pixel is the plain average of its own samples.
    #[test]
    fn camera_packets_render_what_single_rays_render() {
        for projection in [
            Projection::Perspective { fov_y: 40.0 },
            Projection::ThinLens { fov_y: 40.0, aperture: 0.3, focus_distance: 2.5 },
            Projection::Orthographic { half_height: 1.2 },
        ] {
            for spp in [5, 11, 21, 37] {
                for (reconstruction, filter) in [
                    (Reconstruction::ImportanceSampled, Filter::default()),
                    (Reconstruction::Splat, Filter::Box { radius: 0.5 }),
                ] {
                    packets_match_single_rays(
                        Camera::look_at(Vec3::new(0.4, 0.3, 3.0), Vec3::ZERO, Vec3::Y, projection).unwrap(),
                        spp,
                        reconstruction,
                        filter,
                    );
                }
            }
        }
    }

    fn packets_match_single_rays(camera: Camera, spp: u32, reconstruction: Reconstruction, filter: Filter) {
        let settings = RenderSettings {
            width: 12,
            height: 10,
            spp,
            threads: 1,
            reconstruction,
            filter,
            ..RenderSettings::default()
        };
        renders_match_single_paths(lit_sphere(camera), &settings, Path { max_depth: 4, rr_depth: 2 });
    }

    /// The paths of a packet's samples run in lockstep (`Path::radiance8`, Lambertian vertices
    /// in vector lanes where the CPU has them) give exactly what each sample's path gives alone
    /// (`Path::radiance`): a scene of diffuse, rough metal, glass and one-sided surfaces lit by
    /// a rectangle, a sphere light, a point light and the sky, with Russian roulette from the
    /// second bounce; partial packets and full ones, both samplers.
    #[test]
    fn paths_in_lockstep_render_what_single_paths_render() {
        let camera =
            Camera::look_at(Vec3::new(0.3, 0.9, 3.5), Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 50.0 })
                .unwrap();
        for (spp, sampler) in [(5, SamplerKind::Independent), (37, SamplerKind::Independent), (16, SamplerKind::Sobol)]
        {
            let settings =
                RenderSettings { width: 12, height: 10, spp, threads: 1, sampler, ..RenderSettings::default() };
            renders_match_single_paths(mixed_scene(camera), &settings, Path { max_depth: 6, rr_depth: 2 });
        }
    }

    /// Renders `scene` and checks every pixel against the average of its samples' radiance,
    /// each path traced alone.
    fn renders_match_single_paths(scene: Scene, settings: &RenderSettings, integrator: Path) {
        let camera = scene.camera;
        let spp = settings.spp;
        let world = AccelKind::DEFAULT.build_world(&scene, &AccelParams::default());
        crate::with_world!(&world, w => {
            let (image, _) = render(w, &integrator, settings, &|_| {});
            // Samples that hit something, and pixels none of whose samples do (their packets
            // take the path tracer's way for packets that all leave the scene).
            let (mut lit, mut sky_pixels) = (0, 0);
            for y in 0..settings.height {
                for x in 0..settings.width {
                    let pixel = y as u64 * settings.width as u64 + x as u64;
                    let key = (crate::sampling::mix64(settings.seed ^ pixel) >> 32) as u32;
                    let (mut sum, mut n, lit_before) = (Rgb::ZERO, 0.0f32, lit);
                    for i in 0..settings.spp {
                        let (mut sampler, film, lens) = camera_film(w, settings, &Strata::new(settings.spp), x, y, pixel, key, i);
                        let ray = w.scene.camera.ray(film, settings.width, settings.height, lens);
                        let hit = w.intersect(&ray, f32::INFINITY);
                        lit += usize::from(hit.is_some());
                        let mut stats = RayStats::default();
                        sum += integrator.radiance(w, &ray, hit, &mut sampler, &mut stats) * 1.0;
                        n += 1.0;
                    }
                    // The renderer's arithmetic: Σ 1·L, added to an empty sum, over Σ 1.
                    let want = (Rgb::ZERO + sum) / n;
                    assert_eq!(image.pixels[pixel as usize], want, "{camera:?}, {spp} spp: pixel ({x}, {y})");
                    sky_pixels += usize::from(lit == lit_before && want != Rgb::ZERO);
                }
            }
            assert!(lit > 20 * spp as usize, "{camera:?}: {lit} camera samples hit the sphere");
            assert!(sky_pixels > 0, "{camera:?}: no pixel sees only the (lit) sky");
        });
    }

    /// Splatting through a Gaussian wider than a pixel (Mitsuba's default filter) gives each
    /// pixel `Σ w L / Σ w` over every sample of every pixel whose filter reaches it, here worked
    /// out sample by sample over the whole image (the renderer sums by tile, with margins, in
    /// another order: hence the tolerance). The image spans two tiles each way, so samples
    /// reach across tile edges and are cut off at the image's.
    #[test]
    fn gaussian_splatting_weighs_every_pixel_the_filter_reaches() {
        let camera =
            Camera::look_at(Vec3::new(0.4, 0.3, 3.0), Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 40.0 })
                .unwrap();
        let scene = lit_sphere(camera);
        let filter = Filter::gaussian(2.0, 0.5);
        let settings = RenderSettings {
            width: TILE + 5,
            height: TILE + 3,
            spp: 3,
            threads: 2,
            reconstruction: Reconstruction::Splat,
            filter: filter.clone(),
            ..RenderSettings::default()
        };
        let integrator = Path { max_depth: 3, rr_depth: 2 };
        let world = AccelKind::DEFAULT.build_world(&scene, &AccelParams::default());
        crate::with_world!(&world, w => {
            let (image, _) = render(w, &integrator, &settings, &|_| {});
            let (width, height) = (settings.width as usize, settings.height as usize);
            let (mut sum, mut weight) = (vec![Rgb::ZERO; width * height], vec![0.0f32; width * height]);
            let strata = Strata::new(settings.spp);
            for y in 0..settings.height {
                for x in 0..settings.width {
                    let pixel = y as u64 * settings.width as u64 + x as u64;
                    let key = (crate::sampling::mix64(settings.seed ^ pixel) >> 32) as u32;
                    for i in 0..settings.spp {
                        let (mut sampler, film, lens) = camera_film(w, &settings, &strata, x, y, pixel, key, i);
                        let ray = w.scene.camera.ray(film, settings.width, settings.height, lens);
                        let hit = w.intersect(&ray, f32::INFINITY);
                        let l = integrator.radiance(w, &ray, hit, &mut sampler, &mut RayStats::default());
                        for (j, (s, wt)) in sum.iter_mut().zip(&mut weight).enumerate() {
                            let centre = Vec2::new((j % width) as f32 + 0.5, (j / width) as f32 + 0.5);
                            let f = filter.eval(film - centre);
                            *s += l * f;
                            *wt += f;
                        }
                    }
                }
            }
            let mut reached = 0;
            for (j, (s, wt)) in sum.iter().zip(&weight).enumerate() {
                let want = *s / *wt;
                let got = image.pixels[j];
                assert!((got - want).abs().max_element() <= 1e-5 * want.max_element().max(1.0), "pixel {j}: {got} against {want}");
                reached += usize::from(want.max_element() > 0.0);
            }
            assert!(reached > width * height / 4, "{reached} pixels lit");
        });
    }

    /// A diffuse icosphere on a diffuse floor between a rough gold sphere and a glass one,
    /// under a downward-facing square light, a sphere light, a point light and a dim sky.
    fn mixed_scene(camera: Camera) -> Scene {
        let at = |x: f32, y: f32, z: f32, scale: f32| {
            Transform::try_new(glam::Affine3A::from_scale_rotation_translation(
                Vec3::splat(scale),
                glam::Quat::IDENTITY,
                Vec3::new(x, y, z),
            ))
        };
        let object = |geometry, transform, material, emission| Object {
            geometry,
            transform,
            material,
            emission,
            light_samples: 1,
        };
        let constant = |r, g, b| Texture::Constant(Rgb::new(r, g, b));
        let mut scene = lit_sphere(camera);
        scene.geometries.extend([
            Geometry::Mesh(Mesh::quad(Vec3::new(-4.0, -1.0, 4.0), Vec3::new(8.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -8.0))),
            Geometry::Mesh(Mesh::quad(Vec3::new(-0.5, 2.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0))),
            Geometry::Sphere(crate::shape::Sphere { center: Vec3::new(-1.0, 1.2, 0.8), radius: 0.2 }),
        ]);
        scene.materials.extend([
            Material::Diffuse { albedo: constant(0.5, 0.5, 0.4) },
            Material::Conductor {
                eta: Rgb::new(0.143, 0.375, 1.442),
                k: Rgb::new(3.983, 2.386, 1.603),
                roughness: 0.3,
                distribution: Distribution::Ggx,
            },
            Material::Dielectric { ior: 1.5, transmittance: Rgb::ONE, roughness: 0.0, distribution: Distribution::Ggx },
            Material::OneSided(Box::new(Material::Diffuse { albedo: constant(0.8, 0.8, 0.8) })),
        ]);
        scene.objects.extend([
            object(1, None, 1, Rgb::ZERO),
            object(2, None, 4, Rgb::splat(6.0)),
            object(3, None, 4, Rgb::new(4.0, 3.0, 2.0)),
            object(0, at(1.4, -0.5, 0.3, 0.5), 2, Rgb::ZERO),
            object(0, at(-1.3, -0.4, 0.2, 0.6), 3, Rgb::ZERO),
        ]);
        scene.lights.push(Light::Point { position: Vec3::new(2.0, 2.5, 2.0), intensity: Rgb::splat(3.0) });
        if let Light::Environment(sky) = &mut scene.lights[0] {
            sky.scale = Rgb::splat(0.2);
        }
        scene
    }

    /// A diffuse icosphere under a white sky, seen by `camera`.
    fn lit_sphere(camera: Camera) -> Scene {
        Scene {
            geometries: vec![Geometry::Mesh(Mesh::icosphere(3))],
            objects: vec![Object { geometry: 0, transform: None, material: 0, emission: Rgb::ZERO, light_samples: 1 }],
            materials: vec![Material::Diffuse { albedo: Texture::Constant(Rgb::new(0.7, 0.6, 0.5)) }],
            lights: vec![Light::Environment(Environment {
                scale: Rgb::ONE,
                map: None,
                to_world: glam::Mat3::IDENTITY,
            })],
            camera,
            background: Rgb::ZERO,
            ambient: Rgb::ZERO,
            light_selection: LightSelection::Power,
        }
    }
}
