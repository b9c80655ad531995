//! Spectra to RGB, for the readers of formats that allow spectral values (Mitsuba's `spectrum`
//! and `blackbody`, pbrt's `spectrum` and `blackbody` parameters).
//!
//! Snell renders in linear sRGB, so a spectrum becomes the linear sRGB colour of its CIE 1931
//! tristimulus values. The colour-matching functions are Wyman, Sloan and Shirley's
//! piecewise-Gaussian fit (JCGT 2013), within about 1 % of the tabulated CIE 1931 observer.
//! Two normalisations, as Mitsuba's RGB variants have them:
//! - [`Kind::Reflectance`]: white-balanced, so that a constant spectrum `v` gives `(v, v, v)`
//!   (reflectances and indices of refraction);
//! - [`Kind::Emission`]: `XYZ = ∫ L(λ) x̄(λ) dλ / ∫ ȳ(λ) dλ`, so that a constant radiance `v`
//!   has luminance `v` (and, being equal-energy white, is slightly pink in sRGB).

use snell_core::Rgb;

/// What a spectrum measures, which decides its normalisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Reflectance,
    Emission,
}

const LAMBDA_MIN: f64 = 360.0;
const LAMBDA_MAX: f64 = 830.0;

fn lobe(l: f64, mu: f64, s1: f64, s2: f64) -> f64 {
    let t = (l - mu) / if l < mu { s1 } else { s2 };
    (-0.5 * t * t).exp()
}

/// CIE 1931 2° colour-matching functions at wavelength `l` (nm), fitted.
pub fn cie_xyz(l: f64) -> [f64; 3] {
    let x =
        1.056 * lobe(l, 599.8, 37.9, 31.0) + 0.362 * lobe(l, 442.0, 16.0, 26.7) - 0.065 * lobe(l, 501.1, 20.4, 26.2);
    let y = 0.821 * lobe(l, 568.8, 46.9, 40.5) + 0.286 * lobe(l, 530.9, 16.3, 31.1);
    let z = 1.217 * lobe(l, 437.0, 11.8, 36.0) + 0.681 * lobe(l, 459.0, 26.0, 13.8);
    [x, y, z]
}

/// Linear sRGB (D65) of CIE XYZ.
pub fn xyz_to_srgb([x, y, z]: [f64; 3]) -> Rgb {
    Rgb::new(
        (3.2404542 * x - 1.5371385 * y - 0.4985314 * z) as f32,
        (-0.9692660 * x + 1.8760108 * y + 0.0415560 * z) as f32,
        (0.0556434 * x - 0.2040259 * y + 1.0572252 * z) as f32,
    )
}

/// `∫ f(λ) (x̄, ȳ, z̄)(λ) dλ` over the visible range, 1 nm steps.
fn integrate(f: impl Fn(f64) -> f64) -> [f64; 3] {
    let mut acc = [0.0; 3];
    let n = (LAMBDA_MAX - LAMBDA_MIN) as usize;
    for i in 0..n {
        let l = LAMBDA_MIN + i as f64 + 0.5;
        let v = f(l);
        let c = cie_xyz(l);
        for k in 0..3 {
            acc[k] += v * c[k];
        }
    }
    acc
}

fn normalised(xyz: [f64; 3], by: f64) -> [f64; 3] {
    xyz.map(|c| c / by)
}

/// The RGB of a spectrum given as `(wavelength in nm, value)` pairs in increasing wavelength,
/// interpolated linearly and held constant beyond its ends. `None` if the list is empty or not
/// increasing.
pub fn to_rgb(pairs: &[(f32, f32)], kind: Kind) -> Option<Rgb> {
    if pairs.is_empty() || pairs.windows(2).any(|w| w[1].0 <= w[0].0) {
        return None;
    }
    let xyz = integrate(|l| interpolate(pairs, l as f32) as f64);
    let white = integrate(|_| 1.0);
    Some(match kind {
        Kind::Emission => xyz_to_srgb(normalised(xyz, white[1])),
        Kind::Reflectance => {
            let w = xyz_to_srgb(normalised(white, white[1]));
            xyz_to_srgb(normalised(xyz, white[1])) / w
        }
    })
}

/// Linear interpolation in `(λ, value)` pairs, constant beyond the ends.
pub fn interpolate(pairs: &[(f32, f32)], l: f32) -> f32 {
    if l <= pairs[0].0 {
        return pairs[0].1;
    }
    for w in pairs.windows(2) {
        if l <= w[1].0 {
            let t = (l - w[0].0) / (w[1].0 - w[0].0).max(1e-6);
            return w[0].1 + t * (w[1].1 - w[0].1);
        }
    }
    pairs[pairs.len() - 1].1
}

/// Planck's spectral radiance of a black body at `kelvin`, in W / (m² sr nm), at `l` nm.
pub fn planck(l: f64, kelvin: f64) -> f64 {
    const H: f64 = 6.626_070_15e-34;
    const C: f64 = 299_792_458.0;
    const K: f64 = 1.380_649e-23;
    let lm = l * 1e-9;
    let e = (H * C / (lm * K * kelvin)).exp_m1();
    2.0 * H * C * C / (lm.powi(5) * e) * 1e-9
}

/// The RGB radiance of a black body at `kelvin`, in absolute units (Mitsuba's `blackbody`:
/// W / (m² sr nm) integrated against the colour-matching functions over `∫ ȳ`). `None` for a
/// temperature that is not positive and finite.
pub fn blackbody(kelvin: f32) -> Option<Rgb> {
    let t = kelvin as f64;
    if !(t > 0.0 && t.is_finite()) {
        return None;
    }
    let white = integrate(|_| 1.0);
    Some(xyz_to_srgb(normalised(integrate(|l| planck(l, t)), white[1])))
}

/// The colour of a black body at `kelvin` with luminance 1 (pbrt-v4's normalised `blackbody`).
pub fn blackbody_normalised(kelvin: f32) -> Option<Rgb> {
    let t = kelvin as f64;
    if !(t > 0.0 && t.is_finite()) {
        return None;
    }
    let xyz = integrate(|l| planck(l, t));
    (xyz[1] > 0.0).then(|| xyz_to_srgb(normalised(xyz, xyz[1])))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fitted_observer_integrates_like_the_tabulated_one() {
        // ∫ȳ = 106.857 for the tabulated CIE 1931 observer; x̄ and z̄ integrate alike.
        let w = integrate(|_| 1.0);
        assert!((w[1] - 106.857).abs() < 1.5, "{w:?}");
        assert!((w[0] / w[1] - 1.0).abs() < 0.02 && (w[2] / w[1] - 1.0).abs() < 0.02, "{w:?}");
    }

    #[test]
    fn spectra_match_mitsubas_rgb_conversion() {
        // Values printed by Mitsuba 3.9.1 (scalar_rgb) for the same spectra.
        let close = |a: Rgb, b: [f32; 3], tol: f32| (0..3).all(|i| (a[i] - b[i]).abs() <= tol * b[i].max(0.1));
        let refl = to_rgb(&[(400.0, 0.2), (550.0, 0.8), (700.0, 0.3)], Kind::Reflectance).unwrap();
        assert!(close(refl, [0.561923, 0.744912, 0.377663], 0.04), "{refl:?}");
        let flat = to_rgb(&[(360.0, 0.5), (830.0, 0.5)], Kind::Reflectance).unwrap();
        assert!(close(flat, [0.5, 0.5, 0.5], 1e-3), "{flat:?}");
        let white = to_rgb(&[(360.0, 1.0), (830.0, 1.0)], Kind::Emission).unwrap();
        assert!(close(white, [1.20488, 0.948228, 0.909267], 0.02), "{white:?}");
        let e = to_rgb(&[(400.0, 2.0), (550.0, 8.0), (700.0, 3.0)], Kind::Emission).unwrap();
        assert!(close(e, [6.79281, 7.11634, 3.33954], 0.04), "{e:?}");
        assert!(to_rgb(&[], Kind::Emission).is_none());
        assert!(to_rgb(&[(500.0, 1.0), (400.0, 1.0)], Kind::Emission).is_none());
    }

    #[test]
    fn black_bodies_redden_as_they_cool() {
        let warm = blackbody_normalised(2700.0).unwrap();
        let d65ish = blackbody_normalised(6504.0).unwrap();
        let hot = blackbody_normalised(12000.0).unwrap();
        assert!(warm[0] > warm[1] && warm[1] > warm[2], "{warm:?}");
        assert!(hot[2] > hot[0], "{hot:?}");
        // About white near 6500 K (D65 is not a black body; within a few per cent).
        assert!((d65ish[0] / d65ish[2] - 1.0).abs() < 0.1, "{d65ish:?}");
        // Luminance 1.
        let y = 0.2126 * warm[0] + 0.7152 * warm[1] + 0.0722 * warm[2];
        assert!((y - 1.0).abs() < 1e-3, "{y}");
        // Stefan–Boltzmann-ish sanity: radiance at 500 nm of a 5000 K body is about 12 100 W/(m² sr nm).
        assert!((planck(500.0, 5000.0) - 12_100.0).abs() < 200.0, "{}", planck(500.0, 5000.0));
        assert!(blackbody(0.0).is_none() && blackbody(f32::NAN).is_none());
        assert!(blackbody(5000.0).unwrap().min_element() > 1000.0);
    }
}
