//! `snell diff A B`: how far image A is from image B (the reference).

use std::path::PathBuf;

use anyhow::{bail, Result};
use snell_core::image::Image;
use snell_core::inspect::false_colour;
use snell_core::Rgb;

#[derive(clap::Args)]
pub struct DiffArgs {
    /// The image under test (.exr, .pfm, .hdr or .png; PNG is decoded from sRGB).
    pub test: PathBuf,
    /// The reference image.
    pub reference: PathBuf,
    /// Write a false-colour image of the per-pixel relative squared error, black = 0 ..
    /// pale yellow = the printed maximum of the scale (the 99th percentile).
    #[arg(long, value_name = "OUT")]
    pub error: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Relative squared error of one pixel, averaged over the channels: (t − r)² / (r² + 0.01), as
/// Mitsuba's and `imgdiff.py`'s relMSE define it.
fn rel_sq(t: Rgb, r: Rgb) -> f64 {
    let d = (t - r).as_dvec3();
    let r = r.as_dvec3();
    ((d * d) / (r * r + glam::DVec3::splat(1e-2))).element_sum() / 3.0
}

pub fn run(args: DiffArgs) -> Result<()> {
    let a = snell_io::image_in::read_rgb(&args.test)?;
    let b = snell_io::image_in::read_rgb(&args.reference)?;
    if (a.width, a.height) != (b.width, b.height) {
        bail!(
            "the images differ in size: {} is {}x{}, {} is {}x{}",
            args.test.display(),
            a.width,
            a.height,
            args.reference.display(),
            b.width,
            b.height
        );
    }
    let n = a.pixels.len();
    let finite: Vec<bool> = a.pixels.iter().zip(&b.pixels).map(|(t, r)| t.is_finite() && r.is_finite()).collect();
    let m = finite.iter().filter(|&&f| f).count().max(1) as f64;
    let mean =
        |img: &[Rgb]| img.iter().zip(&finite).filter(|(_, &f)| f).map(|(p, _)| p.as_dvec3()).sum::<glam::DVec3>() / m;
    let (mean_a, mean_b) = (mean(&a.pixels), mean(&b.pixels));
    let errs: Vec<f64> = a.pixels.iter().zip(&b.pixels).map(|(&t, &r)| rel_sq(t, r)).collect();
    let relmse = errs.iter().zip(&finite).filter(|(_, &f)| f).map(|(e, _)| e).sum::<f64>() / m;
    let mse = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .zip(&finite)
        .filter(|(_, &f)| f)
        .map(|((t, r), _)| ((*t - *r).as_dvec3() * (*t - *r).as_dvec3()).element_sum() / 3.0)
        .sum::<f64>()
        / m;
    let nonfinite = n - finite.iter().filter(|&&f| f).count();
    let mut sorted: Vec<f64> = errs.iter().copied().filter(|e| e.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    let p99 = sorted.get((sorted.len() as f64 * 0.99) as usize).copied().unwrap_or(0.0).max(1e-12);
    if let Some(out) = &args.error {
        let img = Image {
            width: a.width as u32,
            height: a.height as u32,
            pixels: errs.iter().map(|&e| false_colour((e / p99) as f32)).collect(),
        };
        snell_io::image_out::write_image(out, &img)?;
    }
    if args.json {
        println!(
            "{{\"mean_test\":[{},{},{}],\"mean_ref\":[{},{},{}],\"rmse\":{},\"relmse\":{},\"nonfinite\":{},\"p99_rel_sq\":{}}}",
            mean_a.x, mean_a.y, mean_a.z, mean_b.x, mean_b.y, mean_b.z, mse.sqrt(), relmse, nonfinite, p99
        );
    } else {
        println!("mean test  {:.6} {:.6} {:.6}", mean_a.x, mean_a.y, mean_a.z);
        println!("mean ref   {:.6} {:.6} {:.6}", mean_b.x, mean_b.y, mean_b.z);
        let rel = mean_a / mean_b - glam::DVec3::ONE;
        println!("mean diff  {:+.4} {:+.4} {:+.4} (relative)", rel.x, rel.y, rel.z);
        println!("rmse       {:.6}", mse.sqrt());
        println!("relmse     {relmse:.6}   (mean of (t - r)^2 / (r^2 + 0.01))");
        if nonfinite > 0 {
            println!("non-finite {nonfinite} pixels (left out of the numbers above)");
        }
        if let Some(out) = &args.error {
            println!(
                "{}: relative squared error, black = 0 .. pale yellow = {p99:.3e} (99th percentile)",
                out.display()
            );
        }
    }
    Ok(())
}
