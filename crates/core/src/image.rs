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
}
