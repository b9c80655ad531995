//! Writing images: `.png` (8-bit sRGB) and `.exr` (linear 32-bit float RGB), chosen by the
//! file's extension. The file is written whole or not at all: the bytes go to a temporary file
//! in the same directory, which is then renamed over the destination.

use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};

use snell_core::image::Image;

use crate::Error;

/// Output formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    Exr,
}

/// The format for a path, from its extension.
pub fn format_for(path: &Path) -> Result<ImageFormat, Error> {
    match path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("png") => Ok(ImageFormat::Png),
        Some("exr") => Ok(ImageFormat::Exr),
        _ => Err(Error::new(path, "unsupported image format (the output must end in .png or .exr)")),
    }
}

/// Encodes the image in memory.
pub fn encode(image: &Image, format: ImageFormat) -> Result<Vec<u8>, String> {
    match format {
        ImageFormat::Png => {
            let img = image::RgbImage::from_raw(image.width, image.height, image.to_srgb8())
                .ok_or("image size does not match its pixels")?;
            let mut buf = Cursor::new(Vec::new());
            img.write_to(&mut buf, image::ImageFormat::Png).map_err(|e| e.to_string())?;
            Ok(buf.into_inner())
        }
        ImageFormat::Exr => encode_exr(image, &[]),
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().ok_or_else(|| Error::new(path, "not a file name"))?;
    let tmp = dir.join(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// Encodes by extension and writes atomically.
pub fn write_image(path: &Path, image: &Image) -> Result<(), Error> {
    let format = format_for(path)?;
    let bytes = encode(image, format).map_err(|e| Error::new(path, e))?;
    write_atomic(path, &bytes)
}

/// Checks before rendering that the output can be written: known extension, existing directory.
pub fn check_output(path: &Path) -> Result<(), Error> {
    format_for(path)?;
    if let Some(d) = path.parent() {
        if !d.as_os_str().is_empty() && !d.is_dir() {
            return Err(Error::new(path, format!("the directory '{}' does not exist", d.display())));
        }
    }
    if path.is_dir() {
        return Err(Error::new(path, "is a directory"));
    }
    Ok(())
}

/// Writes a linear float OpenEXR with the image as `R`, `G`, `B` and further named channels
/// (`albedo.R`, `normal.X`, `Z`, …), each `width × height` values row by row from the top left.
/// Written whole or not at all, like [`write_image`].
pub fn write_exr_channels(path: &Path, image: &Image, extra: &[(&str, Vec<f32>)]) -> Result<(), Error> {
    if format_for(path)? != ImageFormat::Exr {
        return Err(Error::new(path, "extra layers (AOVs) need an .exr output"));
    }
    let n = (image.width * image.height) as usize;
    for (name, values) in extra {
        if values.len() != n {
            return Err(Error::new(path, format!("channel {name} has {} values for {n} pixels", values.len())));
        }
    }
    let bytes = encode_exr(image, extra).map_err(|e| Error::new(path, e))?;
    write_atomic(path, &bytes)
}

/// A linear float OpenEXR in memory: `R`, `G`, `B` and the `extra` channels (each one value
/// per pixel). Blocks are compressed one after another and stored top to bottom, so the same
/// image always gives the same bytes (a parallel writer stores them in the order they finish).
fn encode_exr(image: &Image, extra: &[(&str, Vec<f32>)]) -> Result<Vec<u8>, String> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes, LineOrder, WritableImage,
    };
    let mut list: Vec<AnyChannel<FlatSamples>> = Vec::new();
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        list.push(AnyChannel::new(*name, FlatSamples::F32(image.pixels.iter().map(|p| p[c]).collect())));
    }
    for (name, values) in extra {
        list.push(AnyChannel::new(*name, FlatSamples::F32(values.clone())));
    }
    let layer = Layer::new(
        (image.width as usize, image.height as usize),
        LayerAttributes::default(),
        Encoding { line_order: LineOrder::Increasing, ..Encoding::FAST_LOSSLESS },
        AnyChannels::sort(list.into()),
    );
    let mut buf = Cursor::new(Vec::new());
    exr::image::Image::from_layer(layer).write().non_parallel().to_buffered(&mut buf).map_err(|e| e.to_string())?;
    Ok(buf.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same image gives the same EXR bytes every time (a parallel writer stored the
    /// compressed blocks in the order they finished, so the files differed run to run), and
    /// the file reads back to the same pixels.
    #[test]
    fn exr_bytes_depend_only_on_the_image() {
        let mut rng = snell_core::sampling::Pcg32::new(1, 2);
        let mut image = Image::new(512, 384);
        for p in &mut image.pixels {
            *p = snell_core::Rgb::new(rng.next_f32(), rng.next_f32() * 4.0, rng.next_f32() * 0.1);
        }
        let first = encode(&image, ImageFormat::Exr).unwrap();
        for _ in 0..6 {
            assert!(encode(&image, ImageFormat::Exr).unwrap() == first, "the bytes changed");
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("noise.exr");
        write_atomic(&path, &first).unwrap();
        let back = crate::image_in::read_rgb(&path).unwrap();
        assert_eq!((back.width, back.height), (512, 384));
        for (a, b) in back.pixels.iter().zip(&image.pixels) {
            assert_eq!(a.to_array(), b.to_array());
        }
    }
}
