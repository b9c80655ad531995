//! The render loop: the image is cut into tiles, rendered in parallel on a rayon pool.
//! Each pixel is computed from its own random streams (see [`crate::sampling`]), so the result
//! does not depend on how tiles are scheduled: it is bit-identical for any thread count.

use glam::Vec2;
use rayon::prelude::*;

use crate::accel::Accel;
use crate::filter::Filter;
use crate::image::Image;
use crate::integrator::{Integrator, RayStats};
use crate::sampling::{stratified_2d, Pcg32};
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
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings { width: 640, height: 480, spp: 16, seed: 0, threads: 0, filter: Filter::default() }
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

/// Renders the world. `progress(pixels)` is called as tiles finish (from worker threads).
/// Returns the image and the summed ray statistics.
pub fn render<A: Accel, I: Integrator>(
    world: &World<A>,
    integrator: &I,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> (Image, RayStats) {
    let (w, h) = (settings.width, settings.height);
    let tiles: Vec<(u32, u32)> =
        (0..h.div_ceil(TILE)).flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx * TILE, ty * TILE))).collect();
    let work = || {
        tiles
            .par_iter()
            .map(|&(x0, y0)| {
                let mut stats = RayStats::default();
                let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
                let mut px = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
                for y in y0..y1 {
                    for x in x0..x1 {
                        px.push(render_pixel(world, integrator, settings, x, y, &mut stats));
                    }
                }
                progress(px.len() as u64);
                (x0, y0, x1, px, stats)
            })
            .collect::<Vec<_>>()
    };
    let results = match rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build() {
        Ok(pool) => pool.install(work),
        Err(_) => work(),
    };
    let mut image = Image::new(w, h);
    let mut stats = RayStats::default();
    for (x0, y0, x1, px, s) in results {
        let tw = (x1 - x0) as usize;
        for (i, p) in px.into_iter().enumerate() {
            let (x, y) = (x0 as usize + i % tw, y0 as usize + i / tw);
            image.pixels[y * w as usize + x] = p;
        }
        stats.add(&s);
    }
    (image, stats)
}

fn render_pixel<A: Accel, I: Integrator>(
    world: &World<A>,
    integrator: &I,
    s: &RenderSettings,
    x: u32,
    y: u32,
    stats: &mut RayStats,
) -> Rgb {
    let pixel = y as u64 * s.width as u64 + x as u64;
    let key = (crate::sampling::mix64(s.seed ^ pixel) >> 32) as u32;
    let mut sum = Rgb::ZERO;
    for i in 0..s.spp {
        let mut rng = Pcg32::for_sample(s.seed, pixel, i as u64);
        let film_u = stratified_2d(i, s.spp, key, &mut rng);
        let lens_u = stratified_2d(i, s.spp, key ^ 0x5bd1_e995, &mut rng);
        let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + s.filter.sample(film_u);
        let ray = world.scene.camera.ray(film, s.width, s.height, lens_u);
        stats.camera += 1;
        let l = integrator.radiance(world, &ray, &mut rng, stats);
        // A non-finite sample (NaN from a degenerate configuration) would poison the pixel.
        if l.is_finite() {
            sum += l;
        }
    }
    sum / s.spp.max(1) as f32
}
