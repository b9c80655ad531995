//! Reading images as linear RGB: Radiance HDR and OpenEXR as they are, PNG (8 or 16 bit)
//! decoded from sRGB.

use std::path::Path;

use snell_core::Rgb;

use crate::Error;

/// A linear RGB image, row by row from the top.
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Reads `.hdr`, `.exr` or `.png` into linear RGB (alpha dropped).
pub fn read_rgb(path: &Path) -> Result<RgbImage, Error> {
    let bytes = crate::read_file(path)?;
    let format = image::ImageFormat::from_path(path)
        .map_err(|_| Error::new(path, "unknown image format (expected .hdr, .exr or .png)"))?;
    if !matches!(format, image::ImageFormat::Hdr | image::ImageFormat::OpenExr | image::ImageFormat::Png) {
        return Err(Error::new(path, "unsupported image format (expected .hdr, .exr or .png)"));
    }
    let img = image::load_from_memory_with_format(&bytes, format)
        .map_err(|e| Error::new(path, format!("cannot decode the image: {e}")))?;
    let integer = !matches!(img, image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_));
    let rgb = img.to_rgb32f();
    let (width, height) = (rgb.width() as usize, rgb.height() as usize);
    let pixels = rgb
        .pixels()
        .map(|p| {
            let c = Rgb::from(p.0);
            if integer && format == image::ImageFormat::Png {
                Rgb::new(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z))
            } else {
                c
            }
        })
        .collect();
    Ok(RgbImage { width, height, pixels })
}
