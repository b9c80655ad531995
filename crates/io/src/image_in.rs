//! Reading images as linear RGB: Radiance HDR and OpenEXR as they are, PNG (8 or 16 bit)
//! decoded from sRGB.

use std::path::Path;

use snell_core::image::srgb_decode;
use snell_core::Rgb;

use crate::{Error, Location};

/// A linear RGB image, row by row from the top.
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

/// Reads `.hdr`, `.exr`, `.pfm` or `.png` into linear RGB (alpha dropped).
pub fn read_rgb(path: &Path) -> Result<RgbImage, Error> {
    let bytes = crate::read_file(path)?;
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("pfm")) {
        return read_pfm(path, &bytes);
    }
    let format = image::ImageFormat::from_path(path)
        .map_err(|_| Error::new(path, "unknown image format (expected .hdr, .exr, .pfm or .png)"))?;
    if !matches!(format, image::ImageFormat::Hdr | image::ImageFormat::OpenExr | image::ImageFormat::Png) {
        return Err(Error::new(path, "unsupported image format (expected .hdr, .exr, .pfm or .png)"));
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
                c.map(srgb_decode)
            } else {
                c
            }
        })
        .collect();
    Ok(RgbImage { width, height, pixels })
}

/// Portable float map: `PF` (RGB) or `Pf` (grey), size, scale (negative: little endian), then
/// rows of floats from the bottom up.
fn read_pfm(path: &Path, bytes: &[u8]) -> Result<RgbImage, Error> {
    // Three whitespace-separated header tokens, then one whitespace byte, then the data.
    let mut tokens = Vec::new();
    let mut i = 0;
    while tokens.len() < 4 {
        while i < bytes.len() && bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        if start == i {
            return Err(Error::at(path, Location::Byte(i as u64), "truncated PFM header"));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..i]).into_owned());
    }
    i += 1; // the single whitespace byte after the scale
    let channels = match tokens[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        t => return Err(Error::at(path, Location::Byte(0), format!("not a PFM file (magic '{t}')"))),
    };
    let parse = |t: &str, what: &str| -> Result<f64, Error> {
        t.parse::<f64>().map_err(|_| Error::new(path, format!("PFM header: bad {what} '{t}'")))
    };
    let (w, h, scale) = (parse(&tokens[1], "width")?, parse(&tokens[2], "height")?, parse(&tokens[3], "scale")?);
    if w < 1.0 || h < 1.0 || w.fract() != 0.0 || h.fract() != 0.0 || w * h > (1u64 << 28) as f64 {
        return Err(Error::new(path, format!("PFM header: bad size {w} x {h}")));
    }
    let (width, height) = (w as usize, h as usize);
    let need = width * height * channels * 4;
    let data = bytes.get(i..i + need).ok_or_else(|| {
        Error::at(path, Location::Byte(bytes.len() as u64), format!("truncated: {need} bytes of pixels expected"))
    })?;
    let f = |k: usize| {
        let b = [data[4 * k], data[4 * k + 1], data[4 * k + 2], data[4 * k + 3]];
        if scale < 0.0 {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut pixels = vec![Rgb::ZERO; width * height];
    for y in 0..height {
        for x in 0..width {
            let k = (y * width + x) * channels;
            let c = if channels == 3 { Rgb::new(f(k), f(k + 1), f(k + 2)) } else { Rgb::splat(f(k)) };
            pixels[(height - 1 - y) * width + x] = c;
        }
    }
    Ok(RgbImage { width, height, pixels })
}
