//! Pictures of the acceleration structure, the lecture's "BVH ray-tracing example" and "BVH
//! construction example": per-pixel heat maps of the traversal work, and the boxes of the
//! hierarchy at a chosen depth drawn over an image.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::accel::{Accel, Counts};
use crate::camera::{Camera, Projection};
use crate::geometry::Aabb;
use crate::image::Image;
use crate::render::RenderSettings;
use crate::scene::{Geometry, World};
use crate::Rgb;

/// Traversal work per pixel for one camera ray through the pixel centre.
pub struct HeatMap {
    pub width: u32,
    pub height: u32,
    /// Nodes (or cells) visited, top and bottom level together.
    pub nodes: Vec<u32>,
    /// Primitives tested (objects in the top level, triangles and spheres below).
    pub prims: Vec<u32>,
}

/// Traces one ray through each pixel centre and counts its traversal work.
pub fn heat_map<A: Accel>(world: &World<A>, s: &RenderSettings) -> HeatMap {
    let run = || {
        (0..s.height)
            .into_par_iter()
            .flat_map_iter(|y| {
                (0..s.width).map(move |x| {
                    let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let ray = world.scene.camera.ray(film, s.width, s.height, Vec2::splat(0.5));
                    let c = Counts::default();
                    world.hit_counted(&ray, f32::INFINITY, &c);
                    (c.nodes.get() as u32, c.prims.get() as u32)
                })
            })
            .collect::<Vec<_>>()
    };
    let v = crate::render::on_threads(s.threads, run);
    HeatMap {
        width: s.width,
        height: s.height,
        nodes: v.iter().map(|p| p.0).collect(),
        prims: v.iter().map(|p| p.1).collect(),
    }
}

/// A perceptually ordered false-colour ramp (black, purple, red, orange, pale yellow) for
/// `t ∈ [0, 1]`.
pub fn false_colour(t: f32) -> Rgb {
    const STOPS: [[f32; 3]; 5] =
        [[0.0, 0.0, 0.02], [0.25, 0.02, 0.35], [0.75, 0.12, 0.2], [1.0, 0.55, 0.0], [1.0, 1.0, 0.75]];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 } * (STOPS.len() - 1) as f32;
    let i = (t as usize).min(STOPS.len() - 2);
    let f = t - i as f32;
    Rgb::from(STOPS[i]).lerp(Rgb::from(STOPS[i + 1]), f)
}

/// `values` as a false-colour image scaled so that `max` is the top of the ramp.
pub fn colourize(width: u32, height: u32, values: &[u32], max: u32) -> Image {
    let m = max.max(1) as f32;
    Image { width, height, pixels: values.iter().map(|&v| false_colour(v as f32 / m)).collect() }
}

/// World-space boxes of every object's structure at depth `depth` (objects without one, the
/// spheres, contribute their own box at depth 0).
pub fn boxes_at_depth<A: Accel>(world: &World<A>, depth: usize) -> Vec<Aabb> {
    let (_, blas) = world.structures();
    let scene = world.scene;
    let mut out = Vec::new();
    for o in &scene.objects {
        let local: Vec<Aabb> = match (&scene.geometries[o.geometry], &blas[o.geometry]) {
            (Geometry::Mesh(_), Some(a)) => a.boxes_at_depth(depth),
            (g, _) if depth == 0 => vec![g.aabb()],
            _ => Vec::new(),
        };
        out.extend(local.into_iter().map(|b| match &o.transform {
            Some(t) => t.aabb(&b),
            None => b,
        }));
    }
    out
}

/// Where `p` lands on the film (pixels), or `None` behind the camera.
fn project(cam: &Camera, p: Vec3, w: u32, h: u32) -> Option<Vec2> {
    let (right, up, fwd) = cam.frame();
    let d = p - cam.eye;
    let (x, y, z) = (d.dot(right), d.dot(up), d.dot(fwd));
    let aspect = w as f32 / h as f32;
    let (sx, sy) = match cam.projection() {
        Projection::Perspective { fov_y } | Projection::ThinLens { fov_y, .. } => {
            if z <= 1e-6 {
                return None;
            }
            let t = (fov_y.to_radians() * 0.5).tan();
            (x / (z * t), y / (z * t))
        }
        Projection::Orthographic { half_height } => (x / half_height, y / half_height),
    };
    Some(Vec2::new((sx / aspect + 1.0) * 0.5 * w as f32, (1.0 - sy) * 0.5 * h as f32))
}

/// Draws the 12 edges of each box over `img` in `colour`. Edges are clipped to the space in
/// front of a perspective camera.
pub fn draw_boxes(img: &mut Image, cam: &Camera, boxes: &[Aabb], colour: Rgb) {
    const EDGES: [(usize, usize); 12] =
        [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)];
    let (_, _, fwd) = cam.frame();
    let perspective = !matches!(cam.projection(), Projection::Orthographic { .. });
    for b in boxes {
        let c = b.corners();
        for (i, j) in EDGES {
            let (mut a, mut e) = (c[i], c[j]);
            if perspective {
                // Clip the segment to z > near.
                let near = 1e-3;
                let (za, ze) = ((a - cam.eye).dot(fwd), (e - cam.eye).dot(fwd));
                if za < near && ze < near {
                    continue;
                }
                if za < near {
                    a = e + (a - e) * ((ze - near) / (ze - za));
                } else if ze < near {
                    e = a + (e - a) * ((za - near) / (za - ze));
                }
            }
            if let (Some(p), Some(q)) = (project(cam, a, img.width, img.height), project(cam, e, img.width, img.height))
            {
                draw_line(img, p, q, colour);
            }
        }
    }
}

fn draw_line(img: &mut Image, p: Vec2, q: Vec2, colour: Rgb) {
    let n = (q - p).abs().max_element().ceil().min(1e5) as usize;
    for k in 0..=n {
        let s = p.lerp(q, if n == 0 { 0.0 } else { k as f32 / n as f32 });
        if s.x >= 0.0 && s.y >= 0.0 && (s.x as u32) < img.width && (s.y as u32) < img.height {
            let i = s.y as usize * img.width as usize + s.x as usize;
            img.pixels[i] = colour;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_monotone_in_brightness() {
        let mut prev = -1.0;
        for i in 0..=20 {
            let c = false_colour(i as f32 / 20.0);
            let l = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
            assert!(l > prev, "{i}");
            prev = l;
        }
    }

    #[test]
    fn projection_matches_the_camera_rays() {
        let cam =
            Camera::look_at(Vec3::new(1.0, 2.0, 5.0), Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 50.0 })
                .unwrap();
        let film = Vec2::new(30.5, 12.25);
        let r = cam.ray(film, 64, 48, Vec2::ZERO);
        let p = project(&cam, r.at(3.0), 64, 48).unwrap();
        assert!((p - film).length() < 1e-3, "{p} vs {film}");
    }
}
