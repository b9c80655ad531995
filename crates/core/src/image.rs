//! A linear RGB image in memory.

use crate::Rgb;

/// Linear RGB pixels, row by row from the top left.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Rgb>,
}

impl Image {
    pub fn new(width: u32, height: u32) -> Image {
        Image { width, height, pixels: vec![Rgb::ZERO; width as usize * height as usize] }
    }

    #[inline]
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[(y * self.width + x) as usize]
    }

    /// 8-bit sRGB, 3 bytes per pixel (values clamped to `[0, 1]` before encoding).
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.pixels.iter().flat_map(|p| p.to_array().map(|c| (srgb_encode(c) * 255.0 + 0.5) as u8)).collect()
    }

    /// Mean of all pixels.
    pub fn mean(&self) -> Rgb {
        let s = self.pixels.iter().fold(glam::DVec3::ZERO, |a, p| a + p.as_dvec3());
        (s / self.pixels.len().max(1) as f64).as_vec3()
    }
}

/// Why pixels cannot make a texture or an environment map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BadPixels {
    /// No pixels, or not `width · height` of them.
    Size,
    /// The first pixel (in reading order, `(x, y)` from the top left) with a negative or
    /// non-finite channel.
    Value { x: usize, y: usize },
}

impl std::fmt::Display for BadPixels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BadPixels::Size => write!(f, "the image has no pixels"),
            BadPixels::Value { x, y } => {
                write!(f, "pixel ({x}, {y}) (from the top left) is negative or not finite")
            }
        }
    }
}

/// Checks that `pixels` are `width × height` (at least one) light or reflectance values: every
/// channel finite and not negative. (Such a value rendered black or poisoned its samples
/// without a word; a damaged or wrongly exported image should say so.)
pub fn check_pixels(width: usize, height: usize, pixels: &[Rgb]) -> Result<(), BadPixels> {
    if width == 0 || height == 0 || pixels.len() != width * height {
        return Err(BadPixels::Size);
    }
    match pixels.iter().position(|p| !p.is_finite() || p.min_element() < 0.0) {
        Some(i) => Err(BadPixels::Value { x: i % width, y: i / width }),
        None => Ok(()),
    }
}

/// Linear → sRGB transfer function, clamped to `[0, 1]`; NaN maps to 0.
pub fn srgb_encode(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB → linear.
pub fn srgb_decode(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_roundtrip_and_clamps() {
        for c in [0.0f32, 0.001, 0.2, 0.5, 1.0] {
            assert!((srgb_decode(srgb_encode(c)) - c).abs() < 1e-5);
        }
        assert!((srgb_encode(7.0) - 1.0).abs() < 1e-6);
        assert_eq!(srgb_encode(f32::NAN), 0.0);
    }

    #[test]
    fn check_pixels_finds_the_first_bad_value_in_reading_order() {
        let mut px = vec![Rgb::splat(0.5); 12];
        assert_eq!(check_pixels(4, 3, &px), Ok(()));
        assert_eq!(check_pixels(4, 2, &px), Err(BadPixels::Size));
        assert_eq!(check_pixels(0, 0, &[]), Err(BadPixels::Size));
        // Zero and negative zero are light values; tiny and huge finite ones too.
        px[1] = Rgb::new(0.0, -0.0, 1e-30);
        px[2] = Rgb::splat(3e38);
        assert_eq!(check_pixels(4, 3, &px), Ok(()));
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1e-7] {
            let mut p = px.clone();
            p[9] = Rgb::new(0.5, 0.5, bad);
            p[11] = Rgb::splat(bad);
            assert_eq!(check_pixels(4, 3, &p), Err(BadPixels::Value { x: 1, y: 2 }), "{bad}");
        }
    }
}
