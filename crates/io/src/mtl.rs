//! Wavefront MTL materials, mapped to Snell's materials for OBJ files rendered directly.
//!
//! | MTL | Snell |
//! |---|---|
//! | `illum` 4, 6, 7 or 9, or `d` < 1 or `Tr` > 0, or `Tf` ≠ 1 | `dielectric` of index `Ni` (`thindielectric` if `Ni` ≤ 1), transmittance `Tf` |
//! | `illum` 3, 5 or 8 (ray-traced reflection) | `mirror` with reflectance `Ks` |
//! | `Ks` > 0 | `plastic`: base `Kd`, coat reflection `Ks`, index `Ni` (1.5 if absent), roughness from the Phong exponent `Ns` (Beckmann α = √(2 / (Ns + 2)), Walter et al. 2007) |
//! | otherwise | `diffuse` with `Kd` |
//! | `map_Kd` | an image texture for the base |
//! | `Ke` | emission of the shapes that use the material |
//!
//! `Ka`, bump, displacement and the other maps are reported as ignored.

use std::path::Path;

use glam::Vec2;
use snell_core::material::microfacet::Distribution;
use snell_core::material::{ImageTexture, Material, Texture};
use snell_core::Rgb;

use crate::{Error, Location};

/// One `newmtl` block, as read.
#[derive(Clone, Debug, Default)]
struct Mtl {
    name: String,
    kd: Option<Rgb>,
    ks: Option<Rgb>,
    ke: Option<Rgb>,
    tf: Option<Rgb>,
    ns: Option<f32>,
    ni: Option<f32>,
    d: Option<f32>,
    illum: Option<i64>,
    map_kd: Option<(String, usize)>,
}

/// A material from an MTL file: Snell's material and the emission of the shapes using it.
pub struct MtlMaterial {
    pub name: String,
    pub material: Material,
    pub emission: Rgb,
}

/// Reads an MTL file. Unsupported statements are returned as warnings (with their line).
pub fn read(path: &Path) -> Result<(Vec<MtlMaterial>, Vec<String>), Error> {
    let text = String::from_utf8_lossy(&crate::read_file(path)?).into_owned();
    let mut warnings = Vec::new();
    let mut blocks: Vec<Mtl> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.split('#').next().unwrap_or("").trim();
        let mut it = l.split_whitespace();
        let Some(key) = it.next() else { continue };
        let rest: Vec<&str> = it.collect();
        let at = |m: String| Error::at(path, Location::Line(line), m);
        let nums = |n: usize| -> Result<Vec<f32>, Error> {
            let v: Option<Vec<f32>> = rest.iter().map(|t| t.parse::<f32>().ok().filter(|x| x.is_finite())).collect();
            match v {
                Some(v) if v.len() >= n => Ok(v),
                _ => Err(at(format!("'{key}' needs {n} number{}", if n > 1 { "s" } else { "" }))),
            }
        };
        let colour = || -> Result<Rgb, Error> {
            let v = nums(1)?;
            let c = if v.len() >= 3 { Rgb::new(v[0], v[1], v[2]) } else { Rgb::splat(v[0]) };
            if c.min_element() < 0.0 {
                return Err(at(format!("'{key}' must not be negative")));
            }
            Ok(c)
        };
        if key == "newmtl" {
            blocks.push(Mtl { name: rest.join(" "), ..Mtl::default() });
            continue;
        }
        let Some(m) = blocks.last_mut() else {
            return Err(at(format!("'{key}' before any 'newmtl'")));
        };
        match key {
            "Kd" => m.kd = Some(colour()?),
            "Ks" => m.ks = Some(colour()?),
            "Ke" => m.ke = Some(colour()?),
            "Tf" => m.tf = Some(colour()?),
            "Ns" => m.ns = Some(nums(1)?[0].max(0.0)),
            "Ni" => m.ni = Some(nums(1)?[0]),
            "d" => m.d = Some(nums(1)?[0].clamp(0.0, 1.0)),
            "Tr" => m.d = Some(1.0 - nums(1)?[0].clamp(0.0, 1.0)),
            "illum" => {
                m.illum = Some(
                    rest.first().and_then(|t| t.parse().ok()).ok_or_else(|| at("'illum' needs an integer".into()))?,
                )
            }
            "map_Kd" => {
                let f = rest.last().ok_or_else(|| at("'map_Kd' needs a file name".into()))?;
                if rest.len() > 1 {
                    warnings.push(format!("{}:{line}: options of 'map_Kd' are ignored", path.display()));
                }
                m.map_kd = Some((f.to_string(), line));
            }
            other => warnings.push(format!("{}:{line}: '{other}' is ignored", path.display())),
        }
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for m in blocks {
        let kd = m.kd.unwrap_or(Rgb::splat(0.8));
        let albedo = match &m.map_kd {
            None => Texture::Constant(kd),
            Some((f, line)) => {
                let img = crate::image_in::read_rgb(&dir.join(f))
                    .map_err(|e| Error::at(path, Location::Line(*line), format!("map_Kd '{f}': {}", e)))?;
                let image = ImageTexture::new(img.width, img.height, img.pixels)
                    .map_err(|e| Error::at(path, Location::Line(*line), format!("map_Kd '{f}': {e}")))?;
                Texture::Image { image: std::sync::Arc::new(image), scale: Vec2::ONE }
            }
        };
        let ks = m.ks.unwrap_or(Rgb::ZERO);
        let illum = m.illum.unwrap_or(if ks.max_element() > 0.0 { 2 } else { 1 });
        let transparent = matches!(illum, 4 | 6 | 7 | 9)
            || m.d.is_some_and(|d| d < 1.0)
            || m.tf.is_some_and(|t| t != Rgb::ONE && t != Rgb::ZERO);
        let ior = m.ni.filter(|n| *n > 0.0).unwrap_or(1.5);
        let material = if transparent {
            let transmittance = m.tf.filter(|t| t.max_element() > 0.0).unwrap_or(Rgb::ONE);
            if ior <= 1.0 {
                Material::ThinDielectric { ior: 1.5, transmittance }
            } else {
                Material::Dielectric { ior, transmittance, roughness: 0.0, distribution: Distribution::Ggx }
            }
        } else if matches!(illum, 3 | 5 | 8) {
            Material::Mirror { reflectance: if ks.max_element() > 0.0 { ks } else { Rgb::ONE } }
        } else if ks.max_element() > 0.0 {
            let alpha = (2.0 / (m.ns.unwrap_or(10.0) + 2.0)).sqrt();
            Material::plastic(albedo, ks, ior.max(1.0001), alpha, Distribution::Beckmann)
        } else {
            Material::Diffuse { albedo }
        };
        out.push(MtlMaterial { name: m.name, material, emission: m.ke.unwrap_or(Rgb::ZERO) });
    }
    Ok((out, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Vec<MtlMaterial> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("test.mtl");
        std::fs::write(&p, text).unwrap();
        match read(&p) {
            Ok((m, _)) => m,
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn mtl_statements_map_to_materials() {
        let m = load(
            "newmtl matte\nKd 0.5 0.4 0.3\n\
             newmtl shiny\nKd 0.1 0.1 0.1\nKs 0.5 0.5 0.5\nNs 100\n\
             newmtl glass\nillum 7\nNi 1.33\nTf 0.9 1 0.9\n\
             newmtl chrome\nillum 5\nKs 0.8 0.8 0.8\n\
             newmtl lamp\nKd 0 0 0\nKe 5 5 4\n",
        );
        assert_eq!(m.len(), 5);
        assert!(
            matches!(&m[0].material, Material::Diffuse { albedo: Texture::Constant(c) } if *c == Rgb::new(0.5, 0.4, 0.3))
        );
        match &m[1].material {
            Material::Plastic { roughness, distribution, .. } => {
                assert!((roughness - (2.0f32 / 102.0).sqrt()).abs() < 1e-6);
                assert_eq!(*distribution, Distribution::Beckmann);
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(&m[2].material, Material::Dielectric { ior, .. } if *ior == 1.33));
        assert!(matches!(&m[3].material, Material::Mirror { reflectance } if *reflectance == Rgb::splat(0.8)));
        assert_eq!(m[4].emission, Rgb::new(5.0, 5.0, 4.0));
    }
}
