//! pbrt-v4 scene files, mapped to Snell's scene.
//!
//! The tokenizer reads pbrt's syntax: `#` comments, quoted strings (with `\` escapes), numbers,
//! bare words and `[ ]` arrays; `Include` and `Import` splice in another file (relative to the
//! main file's directory, as pbrt resolves them; cycles are errors). Parameters are
//! `"type name" value` or `"type name" [ values ]`.
//!
//! What is mapped: the transforms (`Identity`, `Translate`, `Scale`, `Rotate`, `LookAt`,
//! `Transform`, `ConcatTransform`, `CoordinateSystem`, `CoordSysTransform`), `AttributeBegin/End`
//! (and the older `TransformBegin/End`), `Attribute` defaults, `ReverseOrientation`,
//! `ObjectBegin/End` and `ObjectInstance`; `Camera` `perspective` (`fov` on the shorter image
//! axis, `lensradius`, `focaldistance`) and `orthographic`; `Film "rgb"` resolution; `Sampler`
//! sample counts and seed; `Integrator "path"` / `"volpath"` (`maxdepth`); `PixelFilter`;
//! shapes `trianglemesh`, `plymesh`, `bilinearmesh`, `sphere`, `disk`, `cylinder`; materials
//! `diffuse`, `coateddiffuse`, `conductor`, `dielectric`, `thindielectric`,
//! `diffusetransmission`, `interface`, named or not; textures `imagemap`, `checkerboard`,
//! `constant`, `scale`; lights `point`, `spot`, `distant`, `infinite` (constant, or an
//! equal-area image resampled to latitude-longitude); `AreaLightSource "diffuse"`; `rgb`,
//! `spectrum` (pairs, files, pbrt's named metal and glass spectra) and `blackbody` values.
//!
//! pbrt's camera space is left-handed (`+x` is the image's right), and its `maxdepth` counts
//! bounces, so `maxdepth 5` is Snell's (Mitsuba's) `max_depth = 6`. Every parameter that was not
//! used and every construct that was approximated is reported with file, line and column in
//! [`LoadedScene::warnings`].

use std::cell::Cell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Mat3, Mat4, Vec2, Vec3, Vec4};

use snell_core::camera::{Camera, Projection};
use snell_core::filter::Filter;
use snell_core::integrator::IntegratorKind;
use snell_core::light::{EnvMap, Environment, Light};
use snell_core::material::microfacet::Distribution;
use snell_core::material::{self, ImageTexture, Material, Texture};
use snell_core::render::Reconstruction;
use snell_core::sampling::SamplerKind;
use snell_core::scene::{Geometry, LightSelection, Object, Scene};
use snell_core::shape::{Mesh, Sphere};
use snell_core::Rgb;

use crate::scene::{LoadedScene, SceneSettings};
use crate::{shapes, spectrum, Error, Location};

// ---------------------------------------------------------------------------------------------
// Tokens

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Word,
    Str,
    Num,
    Open,
    Close,
}

/// Where a token is: file index, line, column (1-based).
#[derive(Clone, Copy, Debug)]
struct At(usize, usize, usize);

#[derive(Clone, Debug)]
struct Tok {
    kind: Kind,
    text: String,
    at: At,
}

fn tokenize(text: &str, file: usize, path: &Path) -> Result<Vec<Tok>, Error> {
    let mut toks = Vec::new();
    let mut it = text.char_indices().peekable();
    let (mut line, mut col) = (1usize, 1usize);
    let bump = |c: char, line: &mut usize, col: &mut usize| {
        if c == '\n' {
            *line += 1;
            *col = 1;
        } else {
            *col += 1;
        }
    };
    while let Some(&(_, c)) = it.peek() {
        let at = At(file, line, col);
        match c {
            c if c.is_whitespace() => {
                it.next();
                bump(c, &mut line, &mut col);
            }
            '#' => {
                while let Some(&(_, c)) = it.peek() {
                    if c == '\n' {
                        break;
                    }
                    it.next();
                    bump(c, &mut line, &mut col);
                }
            }
            '[' | ']' => {
                it.next();
                bump(c, &mut line, &mut col);
                toks.push(Tok { kind: if c == '[' { Kind::Open } else { Kind::Close }, text: c.to_string(), at });
            }
            '"' => {
                it.next();
                bump(c, &mut line, &mut col);
                let mut s = String::new();
                loop {
                    let Some((_, c)) = it.next() else {
                        return Err(Error::at(path, Location::LineCol(at.1, at.2), "unterminated string"));
                    };
                    bump(c, &mut line, &mut col);
                    match c {
                        '"' => break,
                        '\n' => {
                            return Err(Error::at(path, Location::LineCol(at.1, at.2), "string runs past the line"))
                        }
                        '\\' => {
                            let Some((_, e)) = it.next() else { continue };
                            bump(e, &mut line, &mut col);
                            s.push(match e {
                                'n' => '\n',
                                't' => '\t',
                                other => other,
                            });
                        }
                        c => s.push(c),
                    }
                }
                toks.push(Tok { kind: Kind::Str, text: s, at });
            }
            _ => {
                let mut s = String::new();
                while let Some(&(_, c)) = it.peek() {
                    if c.is_whitespace() || matches!(c, '[' | ']' | '"' | '#') {
                        break;
                    }
                    s.push(c);
                    it.next();
                    bump(c, &mut line, &mut col);
                }
                let numeric = s.starts_with(|c: char| c.is_ascii_digit() || matches!(c, '-' | '+' | '.'));
                if numeric && s.parse::<f64>().is_err() {
                    return Err(Error::at(path, Location::LineCol(at.1, at.2), format!("'{s}' is not a number")));
                }
                toks.push(Tok { kind: if numeric { Kind::Num } else { Kind::Word }, text: s, at });
            }
        }
    }
    Ok(toks)
}

// ---------------------------------------------------------------------------------------------
// Parameters

#[derive(Clone, Debug)]
enum Vals {
    Num(Vec<f64>),
    Str(Vec<String>),
    Bool(Vec<bool>),
}

#[derive(Clone, Debug)]
struct Param {
    ty: String,
    name: String,
    vals: Vals,
    at: At,
    used: Cell<bool>,
}

/// A directive's parameter list, with the attribute defaults that apply to it.
#[derive(Clone, Debug, Default)]
struct Params {
    list: Vec<Param>,
    defaults: Vec<Param>,
}

impl Params {
    fn get(&self, name: &str) -> Option<&Param> {
        let p = self.list.iter().find(|p| p.name == name).or_else(|| self.defaults.iter().find(|p| p.name == name))?;
        p.used.set(true);
        Some(p)
    }
}

// ---------------------------------------------------------------------------------------------
// The token stream over included files

struct Frame {
    toks: Vec<Tok>,
    pos: usize,
    canon: PathBuf,
}

struct Files {
    paths: Vec<PathBuf>,
}

impl Files {
    fn err(&self, at: At, msg: impl Into<String>) -> Error {
        Error::at(&self.paths[at.0], Location::LineCol(at.1, at.2), msg)
    }

    fn note(&self, at: At, msg: impl AsRef<str>) -> String {
        format!("{}:{}:{}: {}", self.paths[at.0].display(), at.1, at.2, msg.as_ref())
    }
}

struct Stream {
    frames: Vec<Frame>,
    /// Where the last token came from (for errors at the end of a file).
    last: At,
}

impl Stream {
    fn peek(&mut self) -> Option<&Tok> {
        while let Some(f) = self.frames.last() {
            if f.pos < f.toks.len() {
                break;
            }
            self.frames.pop();
        }
        let f = self.frames.last()?;
        f.toks.get(f.pos)
    }

    fn next(&mut self) -> Option<Tok> {
        self.peek()?;
        let f = self.frames.last_mut()?;
        let t = f.toks[f.pos].clone();
        f.pos += 1;
        self.last = t.at;
        Some(t)
    }
}

// ---------------------------------------------------------------------------------------------
// Graphics state

#[derive(Clone, Copy, Debug, PartialEq)]
enum CurrentMaterial {
    Index(usize),
    /// pbrt's `interface`: the shape only bounds a medium and is not rendered.
    Interface,
}

#[derive(Clone)]
struct State {
    ctm: Mat4,
    reverse: bool,
    material: CurrentMaterial,
    emission: Option<Rgb>,
    /// `Attribute "target"` defaults, by target (`shape`, `light`, `material`, `texture`).
    attributes: HashMap<String, Vec<Param>>,
}

/// A shape inside an `ObjectBegin` block, ready to be instanced.
#[derive(Clone)]
struct Part {
    geometry: usize,
    transform: Option<Affine3A>,
    material: usize,
}

struct Ctx {
    files: Files,
    base: PathBuf,
    warnings: Vec<String>,
    materials: Vec<Material>,
    named_materials: HashMap<String, CurrentMaterial>,
    textures: HashMap<String, Texture>,
    float_textures: HashMap<String, f32>,
    geometries: Vec<Geometry>,
    objects: Vec<Object>,
    lights: Vec<Light>,
    instances: HashMap<String, Vec<Part>>,
    defining: Option<(String, Vec<Part>)>,
    coordinate_systems: HashMap<String, Mat4>,
    camera: Option<(Mat4, String, Params, At)>,
    film: Option<(String, Params, At)>,
    sampler: Option<(String, Params, At)>,
    integrator: Option<(String, Params, At)>,
    filter: Option<(String, Params, At)>,
}

const DIRECTIVES_WITH_PARAMS: [&str; 11] = [
    "Camera",
    "Film",
    "Sampler",
    "Integrator",
    "PixelFilter",
    "Accelerator",
    "Shape",
    "Material",
    "LightSource",
    "AreaLightSource",
    "ColorSpace",
];

impl Ctx {
    fn warn(&mut self, at: At, msg: impl AsRef<str>) {
        let s = self.files.note(at, msg);
        self.warnings.push(s);
    }

    /// Warns about every parameter of a directive that nothing read.
    fn unused(&mut self, what: &str, p: &Params) {
        for q in &p.list {
            if !q.used.get() {
                let s = self.files.note(q.at, format!("parameter '{} {}' of {what} is ignored", q.ty, q.name));
                self.warnings.push(s);
            }
        }
    }

    fn nums<'a>(&self, p: &'a Param) -> Result<&'a [f64], Error> {
        match &p.vals {
            Vals::Num(v) => Ok(v),
            _ => Err(self.files.err(p.at, format!("'{}' needs numbers", p.name))),
        }
    }

    fn float(&self, p: &Params, name: &str, default: f32) -> Result<f32, Error> {
        let Some(q) = p.get(name) else { return Ok(default) };
        if q.ty == "texture" {
            let Vals::Str(s) = &q.vals else { return Err(self.files.err(q.at, "a texture parameter needs a name")) };
            let n = s.first().map(String::as_str).unwrap_or("");
            return self
                .float_textures
                .get(n)
                .copied()
                .ok_or_else(|| self.files.err(q.at, format!("unknown float texture '{n}'")));
        }
        match self.nums(q)? {
            [v] if v.is_finite() => Ok(*v as f32),
            _ => Err(self.files.err(q.at, format!("'{name}' needs one finite number"))),
        }
    }

    fn int(&self, p: &Params, name: &str, default: i64) -> Result<i64, Error> {
        let Some(q) = p.get(name) else { return Ok(default) };
        match self.nums(q)? {
            [v] if v.fract() == 0.0 && v.abs() < 1e15 => Ok(*v as i64),
            _ => Err(self.files.err(q.at, format!("'{name}' needs one integer"))),
        }
    }

    fn boolean(&self, p: &Params, name: &str, default: bool) -> Result<bool, Error> {
        let Some(q) = p.get(name) else { return Ok(default) };
        match &q.vals {
            Vals::Bool(v) if v.len() == 1 => Ok(v[0]),
            _ => Err(self.files.err(q.at, format!("'{name}' needs one bool (true or false)"))),
        }
    }

    fn string<'a>(&self, p: &'a Params, name: &str) -> Result<Option<&'a str>, Error> {
        let Some(q) = p.get(name) else { return Ok(None) };
        match &q.vals {
            Vals::Str(v) if v.len() == 1 => Ok(Some(&v[0])),
            _ => Err(self.files.err(q.at, format!("'{name}' needs one string"))),
        }
    }

    /// A list of 3-vectors (points, normals).
    fn vec3s(&self, p: &Params, name: &str) -> Result<Option<Vec<Vec3>>, Error> {
        let Some(q) = p.get(name) else { return Ok(None) };
        let v = self.nums(q)?;
        if v.len() % 3 != 0 || v.iter().any(|x| !x.is_finite()) {
            return Err(self.files.err(q.at, format!("'{name}' needs finite numbers in threes")));
        }
        Ok(Some(v.chunks(3).map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).collect()))
    }

    fn vec3(&self, p: &Params, name: &str, default: Vec3) -> Result<Vec3, Error> {
        match self.vec3s(p, name)?.as_deref() {
            None => Ok(default),
            Some([v]) => Ok(*v),
            Some(_) => Err(self
                .files
                .err(p.get(name).map(|q| q.at).unwrap_or(At(0, 0, 0)), format!("'{name}' needs one point"))),
        }
    }

    fn indices(&self, p: &Params, name: &str, per: usize, count: usize) -> Result<Option<Vec<u32>>, Error> {
        let Some(q) = p.get(name) else { return Ok(None) };
        let v = self.nums(q)?;
        if v.len() % per != 0 {
            return Err(self.files.err(q.at, format!("'{name}' needs a multiple of {per} indices")));
        }
        v.iter()
            .map(|&i| {
                if i.fract() == 0.0 && i >= 0.0 && (i as usize) < count {
                    Ok(i as u32)
                } else {
                    Err(self.files.err(q.at, format!("index {i} in '{name}' is not a vertex (there are {count})")))
                }
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    fn path(&self, at: At, f: &str) -> PathBuf {
        let p = Path::new(f);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        let main = self.base.join(p);
        if main.exists() {
            return main;
        }
        // pbrt resolves relative to the main file; fall back to the including file's directory.
        let including = self.files.paths[at.0].parent().unwrap_or(Path::new(".")).join(p);
        if including.exists() {
            including
        } else {
            main
        }
    }

    /// A named pbrt spectrum as RGB: metals' `eta` and `k`, glasses' indices, illuminants (white).
    fn named_spectrum(&mut self, at: At, name: &str) -> Result<Rgb, Error> {
        if let Some(rest) = name.strip_prefix("metal-") {
            let (metal, part) = rest.rsplit_once('-').unwrap_or((rest, ""));
            if let (Some((eta, k)), "eta" | "k") = (material::metal(metal), part) {
                return Ok(if part == "eta" { eta } else { k });
            }
        }
        if let Some(ior) = glass_ior(name) {
            return Ok(Rgb::splat(ior));
        }
        if name.starts_with("stdillum-") || name.starts_with("illum-") {
            self.warn(at, format!("illuminant '{name}' is taken as white (Snell renders in RGB)"));
            return Ok(Rgb::ONE);
        }
        Err(self
            .files
            .err(at, format!("unknown named spectrum '{name}' (known: metal-{{Au,Ag,Cu,Al}}-{{eta,k}}, glass-*)")))
    }

    /// A spectrum-valued parameter as RGB, if present.
    fn color(&mut self, p: &Params, name: &str, kind: spectrum::Kind) -> Result<Option<Rgb>, Error> {
        let Some(q) = p.get(name).cloned() else { return Ok(None) };
        let c = match (q.ty.as_str(), &q.vals) {
            ("rgb" | "color", Vals::Num(v)) => match v.as_slice() {
                [r, g, b] => Rgb::new(*r as f32, *g as f32, *b as f32),
                _ => return Err(self.files.err(q.at, format!("'{name}' needs three numbers"))),
            },
            ("float", Vals::Num(v)) if v.len() == 1 => Rgb::splat(v[0] as f32),
            ("blackbody", Vals::Num(v)) => {
                let t = v.first().copied().unwrap_or(f64::NAN) as f32;
                let c = spectrum::blackbody_normalised(t)
                    .ok_or_else(|| self.files.err(q.at, "a blackbody needs a positive temperature in kelvin"))?;
                if kind == spectrum::Kind::Emission {
                    c
                } else {
                    // As a reflectance, the colour scaled to a maximum of 1.
                    c / c.max_element()
                }
            }
            ("spectrum", Vals::Str(v)) if v.len() == 1 => {
                let s = &v[0];
                if s.starts_with("metal-") || s.starts_with("glass-") || s.contains("illum") {
                    self.named_spectrum(q.at, s)?
                } else {
                    let path = self.path(q.at, s);
                    let text = crate::read_text(&path)?;
                    let mut nums = Vec::new();
                    for (i, line) in text.lines().enumerate() {
                        let t = line.split('#').next().unwrap_or("");
                        for w in t.split(|c: char| c.is_whitespace() || c == ',').filter(|w| !w.is_empty()) {
                            nums.push(w.parse::<f32>().map_err(|_| {
                                Error::at(&path, Location::Line(i + 1), format!("'{w}' is not a number"))
                            })?);
                        }
                    }
                    self.spectrum_pairs(q.at, &nums, kind)?
                }
            }
            ("spectrum", Vals::Num(v)) => {
                let nums: Vec<f32> = v.iter().map(|&x| x as f32).collect();
                if let [x] = nums.as_slice() {
                    Rgb::splat(*x)
                } else {
                    self.spectrum_pairs(q.at, &nums, kind)?
                }
            }
            _ => return Err(self.files.err(q.at, format!("'{} {name}' is not a colour", q.ty))),
        };
        if !c.is_finite() || c.min_element() < 0.0 {
            return Err(self.files.err(q.at, format!("'{name}' must be finite and not negative")));
        }
        Ok(Some(c))
    }

    fn spectrum_pairs(&mut self, at: At, nums: &[f32], kind: spectrum::Kind) -> Result<Rgb, Error> {
        if nums.len() < 2 || !nums.len().is_multiple_of(2) {
            return Err(self.files.err(at, "a spectrum needs (wavelength, value) pairs"));
        }
        let pairs: Vec<(f32, f32)> = nums.chunks(2).map(|c| (c[0], c[1])).collect();
        let c = spectrum::to_rgb(&pairs, kind)
            .ok_or_else(|| self.files.err(at, "the spectrum's wavelengths must increase"))?;
        self.warn(at, "spectrum converted to RGB through the CIE 1931 observer (rendered in RGB)");
        Ok(c)
    }

    /// A spectrum texture parameter: a named texture or a constant colour.
    fn texture(&mut self, p: &Params, name: &str, default: Rgb) -> Result<Texture, Error> {
        if let Some(q) = p.get(name).filter(|q| q.ty == "texture").cloned() {
            let Vals::Str(s) = &q.vals else { return Err(self.files.err(q.at, "a texture parameter needs a name")) };
            let n = s.first().map(String::as_str).unwrap_or("");
            if let Some(t) = self.textures.get(n) {
                return Ok(t.clone());
            }
            if let Some(&f) = self.float_textures.get(n) {
                return Ok(Texture::Constant(Rgb::splat(f)));
            }
            return Err(self.files.err(q.at, format!("unknown texture '{n}'")));
        }
        Ok(Texture::Constant(self.color(p, name, spectrum::Kind::Reflectance)?.unwrap_or(default)))
    }

    /// pbrt-v4's roughness: `uroughness` / `vroughness` (default `roughness`), remapped to the
    /// GGX `alpha` by a square root unless `remaproughness` is false.
    fn roughness(&mut self, p: &Params, at: At) -> Result<f32, Error> {
        let r = self.float(p, "roughness", 0.0)?;
        let (u, v) = (self.float(p, "uroughness", r)?, self.float(p, "vroughness", r)?);
        if u != v {
            self.warn(at, format!("anisotropic roughness ({u}, {v}) rendered isotropic ({})", 0.5 * (u + v)));
        }
        let r = (0.5 * (u + v)).max(0.0);
        Ok(if self.boolean(p, "remaproughness", true)? { r.sqrt() } else { r })
    }

    fn eta(&mut self, p: &Params, default: f32) -> Result<f32, Error> {
        let Some(q) = p.get("eta").cloned() else { return Ok(default) };
        let eta = match (&q.vals, q.ty.as_str()) {
            (Vals::Num(v), "float") if v.len() == 1 => v[0] as f32,
            _ => {
                let c = self.color(p, "eta", spectrum::Kind::Reflectance)?.unwrap_or(Rgb::splat(default));
                if c.max_element() - c.min_element() > 1e-4 {
                    self.warn(q.at, "dispersion is not rendered: the index is averaged over RGB");
                }
                (c.x + c.y + c.z) / 3.0
            }
        };
        if !(eta > 0.0 && eta.is_finite()) {
            return Err(self.files.err(q.at, "'eta' must be positive"));
        }
        Ok(eta)
    }

    fn material(&mut self, ty: &str, p: &Params, at: At) -> Result<CurrentMaterial, Error> {
        let m = match ty {
            "diffuse" => Material::Diffuse { albedo: self.texture(p, "reflectance", Rgb::splat(0.5))? },
            "coateddiffuse" => {
                let diffuse = self.texture(p, "reflectance", Rgb::splat(0.5))?;
                let alpha = self.roughness(p, at)?;
                let eta = self.eta(p, 1.5)?;
                for ignored in ["thickness", "albedo", "g", "maxdepth", "nsamples"] {
                    p.get(ignored);
                }
                self.warn(at, "coateddiffuse rendered as Snell's plastic (a Fresnel coat over Lambert; no layer thickness or albedo)");
                Material::plastic(diffuse, Rgb::ONE, eta, alpha, Distribution::Ggx)
            }
            "conductor" | "coatedconductor" => {
                if ty == "coatedconductor" {
                    self.warn(at, "coatedconductor rendered as its conductor, without the coat");
                }
                let alpha = self.roughness(p, at)?;
                let (eta, k) = if let Some(r) = self.color(p, "reflectance", spectrum::Kind::Reflectance)? {
                    // pbrt's artist-friendly conductor: eta 1 and k giving reflectance r at normal incidence.
                    let r = r.clamp(Rgb::ZERO, Rgb::splat(0.9999));
                    (Rgb::ONE, (r / (Rgb::ONE - r)).map(|x| 2.0 * x.sqrt()))
                } else {
                    let (cu_eta, cu_k) = material::metal("Cu").unwrap_or((Rgb::ONE, Rgb::ONE));
                    let eta = self.color(p, "eta", spectrum::Kind::Reflectance)?.unwrap_or(cu_eta);
                    let k = self.color(p, "k", spectrum::Kind::Reflectance)?.unwrap_or(cu_k);
                    (eta, k)
                };
                Material::Conductor { eta, k, roughness: alpha, distribution: Distribution::Ggx }
            }
            "dielectric" => {
                let ior = self.eta(p, 1.5)?;
                let roughness = self.roughness(p, at)?;
                Material::Dielectric { ior, transmittance: Rgb::ONE, roughness, distribution: Distribution::Ggx }
            }
            "thindielectric" => Material::ThinDielectric { ior: self.eta(p, 1.5)?, transmittance: Rgb::ONE },
            "diffusetransmission" => {
                let r = self.texture(p, "reflectance", Rgb::splat(0.25))?;
                p.get("transmittance");
                self.warn(at, "diffusetransmission rendered as diffuse reflection only (its transmission is dropped)");
                Material::Diffuse { albedo: r }
            }
            "interface" => return Ok(CurrentMaterial::Interface),
            "" => return Err(self.files.err(at, "the material needs a type")),
            other => {
                self.warn(at, format!("material '{other}' is not supported; using diffuse grey 0.5"));
                Material::Diffuse { albedo: Texture::Constant(Rgb::splat(0.5)) }
            }
        };
        for ignored in ["displacement", "normalmap"] {
            if let Some(q) = p.get(ignored) {
                let at = q.at;
                self.warn(at, format!("'{ignored}' is not supported"));
            }
        }
        self.materials.push(m);
        Ok(CurrentMaterial::Index(self.materials.len() - 1))
    }

    fn texture_def(&mut self, name: &str, ty: &str, class: &str, p: &Params, at: At) -> Result<(), Error> {
        let t = match class {
            "constant" => self.texture(p, "value", Rgb::ONE)?,
            "scale" => {
                let s = self.texture(p, "scale", Rgb::ONE)?;
                let t = self.texture(p, "tex", Rgb::ONE)?;
                match (t, s) {
                    (Texture::Constant(a), Texture::Constant(b)) => Texture::Constant(a * b),
                    (Texture::Image { image, scale }, Texture::Constant(b))
                    | (Texture::Constant(b), Texture::Image { image, scale }) => {
                        let pixels = image.pixels.iter().map(|&c| c * b).collect();
                        let image = ImageTexture::new(image.width, image.height, pixels)
                            .map_err(|e| self.files.err(at, format!("the scaled image: {e}")))?;
                        Texture::Image { image: std::sync::Arc::new(image), scale }
                    }
                    (t, _) => {
                        self.warn(at, "a 'scale' of two textures keeps the first only");
                        t
                    }
                }
            }
            "checkerboard" => {
                if self.int(p, "dimension", 2)? != 2 {
                    self.warn(at, "3D checkerboards are rendered as 2D");
                }
                let a = self.texture(p, "tex1", Rgb::ONE)?;
                let b = self.texture(p, "tex2", Rgb::ZERO)?;
                let (u, v) = (self.float(p, "uscale", 1.0)?, self.float(p, "vscale", 1.0)?);
                if u != v {
                    self.warn(at, format!("checkerboard uscale {u} and vscale {v} differ; using {u}"));
                }
                if !matches!((&a, &b), (Texture::Constant(_), Texture::Constant(_))) {
                    self.warn(at, "checkerboard squares of textures are rendered with their mean colours");
                }
                Texture::Checker { a: a.mean(), b: b.mean(), scale: u }
            }
            "imagemap" => {
                let f = self.string(p, "filename")?.ok_or_else(|| self.files.err(at, "imagemap needs 'filename'"))?;
                let path = self.path(at, f);
                let img = crate::image_in::read_rgb(&path)?;
                // The file's own values first (`invert` would clamp a NaN away), where its
                // pixels are; then `scale`, which must keep them light values.
                let bad = |e: snell_core::image::BadPixels| format!("imagemap '{f}': {e}");
                snell_core::image::check_pixels(img.width, img.height, &img.pixels)
                    .map_err(|e| self.files.err(at, bad(e)))?;
                let scale = self.float(p, "scale", 1.0)?;
                if scale < 0.0 {
                    let at = p.get("scale").map_or(at, |q| q.at);
                    return Err(self.files.err(at, "'scale' must not be negative"));
                }
                let invert = self.boolean(p, "invert", false)?;
                let pixels = img
                    .pixels
                    .iter()
                    .map(|&c| {
                        let c = c * scale;
                        if invert {
                            (Rgb::ONE - c).max(Rgb::ZERO)
                        } else {
                            c
                        }
                    })
                    .collect();
                if let Some(e) = self.string(p, "encoding")? {
                    if e != "sRGB" {
                        let at = p.get("encoding").map(|q| q.at).unwrap_or(at);
                        self.warn(at, format!("encoding '{e}' is ignored: 8-bit images are decoded from sRGB"));
                    }
                }
                let image = ImageTexture::new(img.width, img.height, pixels).map_err(|e| self.files.err(at, bad(e)))?;
                let uv = Vec2::new(self.float(p, "uscale", 1.0)?, self.float(p, "vscale", 1.0)?);
                Texture::Image { image: std::sync::Arc::new(image), scale: uv }
            }
            other => {
                self.warn(at, format!("texture '{other}' is not supported; using grey 0.5"));
                Texture::Constant(Rgb::splat(0.5))
            }
        };
        if ty == "float" {
            let v = match &t {
                Texture::Constant(c) => c.x,
                other => {
                    self.warn(at, "a float texture that varies is rendered with its mean");
                    other.mean().x
                }
            };
            self.float_textures.insert(name.to_string(), v);
        } else {
            self.textures.insert(name.to_string(), t);
        }
        Ok(())
    }

    /// A shape in object space: a mesh, or a sphere.
    fn shape_geometry(&mut self, ty: &str, p: &Params, at: At) -> Result<Option<Geometry>, Error> {
        let mesh = match ty {
            "trianglemesh" => {
                let pos = self.vec3s(p, "P")?.ok_or_else(|| self.files.err(at, "trianglemesh needs 'point3 P'"))?;
                let idx = match self.indices(p, "indices", 3, pos.len())? {
                    Some(i) => i,
                    None if pos.len() == 3 => vec![0, 1, 2],
                    None => {
                        return Err(self.files.err(at, "trianglemesh needs 'integer indices' (more than 3 points)"))
                    }
                };
                let normals = self.per_vertex(p, "N", pos.len())?;
                let uvs = self.uvs(p, pos.len())?;
                for ignored in ["S", "faceIndices"] {
                    p.get(ignored);
                }
                Mesh { positions: pos, normals, uvs, indices: idx.chunks(3).map(|c| [c[0], c[1], c[2]]).collect() }
            }
            "bilinearmesh" => {
                let pos = self.vec3s(p, "P")?.ok_or_else(|| self.files.err(at, "bilinearmesh needs 'point3 P'"))?;
                let idx = match self.indices(p, "indices", 4, pos.len())? {
                    Some(i) => i,
                    None if pos.len() == 4 => vec![0, 1, 2, 3],
                    None => {
                        return Err(self.files.err(at, "bilinearmesh needs 'integer indices' (more than 4 points)"))
                    }
                };
                let normals = self.per_vertex(p, "N", pos.len())?;
                let uvs = self.uvs(p, pos.len())?;
                let patches: Vec<[u32; 4]> = idx.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
                let m = shapes::bilinear(&pos, normals.as_deref(), uvs.as_deref(), &patches, 8);
                if m.indices.len() > 2 * patches.len() {
                    self.warn(at, "curved bilinear patches tessellated into 8 × 8 quads");
                }
                m
            }
            "plymesh" => {
                let f = self.string(p, "filename")?.ok_or_else(|| self.files.err(at, "plymesh needs 'filename'"))?;
                let path = self.path(at, f);
                if path.extension().is_some_and(|e| e == "gz") {
                    return Err(Error::new(&path, "compressed PLY (.ply.gz) is not supported; decompress it"));
                }
                for ignored in ["displacement", "edgelength"] {
                    if let Some(q) = p.get(ignored) {
                        let at = q.at;
                        self.warn(at, format!("plymesh '{ignored}' is not supported"));
                    }
                }
                crate::ply::read(&path)?
            }
            "sphere" => {
                let radius = self.float(p, "radius", 1.0)?;
                if radius <= 0.0 {
                    return Err(self.files.err(at, "the sphere's radius must be positive"));
                }
                let (zmin, zmax, phimax) =
                    (self.float(p, "zmin", -radius)?, self.float(p, "zmax", radius)?, self.float(p, "phimax", 360.0)?);
                if zmin > -radius || zmax < radius || phimax < 360.0 {
                    self.warn(at, "partial spheres (zmin, zmax, phimax) are rendered whole");
                }
                return Ok(Some(Geometry::Sphere(Sphere { center: Vec3::ZERO, radius })));
            }
            "disk" => {
                let (h, r) = (self.float(p, "height", 0.0)?, self.float(p, "radius", 1.0)?);
                if self.float(p, "innerradius", 0.0)? > 0.0 || self.float(p, "phimax", 360.0)? < 360.0 {
                    self.warn(at, "disk 'innerradius' and 'phimax' are ignored");
                }
                self.warn(at, "disk tessellated into 128 triangles");
                let mut m = shapes::disk(128);
                m.positions.iter_mut().for_each(|v| *v = Vec3::new(v.x * r, v.y * r, h));
                m
            }
            "cylinder" => {
                let r = self.float(p, "radius", 1.0)?;
                let (z0, z1) = (self.float(p, "zmin", -1.0)?, self.float(p, "zmax", 1.0)?);
                if r <= 0.0 || z0 == z1 {
                    return Err(self.files.err(at, "the cylinder needs a positive radius and zmin != zmax"));
                }
                if self.float(p, "phimax", 360.0)? < 360.0 {
                    self.warn(at, "cylinder 'phimax' is ignored");
                }
                self.warn(at, "cylinder tessellated into 128 quads with smooth normals");
                shapes::cylinder(Vec3::new(0.0, 0.0, z0), Vec3::new(0.0, 0.0, z1), r, 128)
            }
            other => {
                p.list.iter().for_each(|q| q.used.set(true));
                self.warn(at, format!("shape '{other}' is not supported; skipped"));
                return Ok(None);
            }
        };
        for ignored in ["alpha", "emissionfilename"] {
            if let Some(q) = p.get(ignored) {
                let at = q.at;
                self.warn(at, format!("'{ignored}' is not supported"));
            }
        }
        let mut mesh = mesh;
        mesh.drop_degenerate_indices();
        mesh.validate().map_err(|e| self.files.err(at, e.to_string()))?;
        if mesh.indices.is_empty() {
            self.warn(at, "the shape has no triangles; skipped");
            return Ok(None);
        }
        Ok(Some(Geometry::Mesh(mesh)))
    }

    fn per_vertex(&self, p: &Params, name: &str, n: usize) -> Result<Option<Vec<Vec3>>, Error> {
        let v = self.vec3s(p, name)?;
        if let Some(v) = &v {
            if v.len() != n {
                let at = p.get(name).map(|q| q.at).unwrap_or(At(0, 0, 0));
                return Err(self.files.err(at, format!("'{name}' has {} entries for {n} points", v.len())));
            }
        }
        Ok(v)
    }

    fn uvs(&self, p: &Params, n: usize) -> Result<Option<Vec<Vec2>>, Error> {
        let Some(q) = p.get("uv").or_else(|| p.get("st")) else { return Ok(None) };
        let v = self.nums(q)?;
        if v.len() != 2 * n {
            return Err(self.files.err(q.at, format!("'{}' has {} numbers for {n} points", q.name, v.len())));
        }
        Ok(Some(v.chunks(2).map(|c| Vec2::new(c[0] as f32, c[1] as f32)).collect()))
    }

    fn shape(&mut self, ty: &str, p: &Params, at: At, s: &State) -> Result<(), Error> {
        let Some(mut geometry) = self.shape_geometry(ty, p, at)? else { return Ok(()) };
        let material = match s.material {
            CurrentMaterial::Index(m) => m,
            CurrentMaterial::Interface => return Ok(()),
        };
        let m = affine(&self.files, s.ctm, at)?;
        let transform = match &mut geometry {
            Geometry::Mesh(mesh) => {
                if s.reverse {
                    shapes::flip(mesh, true);
                }
                // Meshes are placed in world space (instances keep their transform).
                shapes::bake(mesh, m).ok_or_else(|| self.files.err(at, "the transform is not invertible"))?;
                None
            }
            Geometry::Sphere(_) => {
                if s.reverse {
                    self.warn(at, "ReverseOrientation on a sphere is ignored");
                }
                Some(m)
            }
        };
        let g = self.geometries.len();
        self.geometries.push(geometry);
        if let Some((_, parts)) = self.defining.as_mut() {
            parts.push(Part { geometry: g, transform, material });
            if s.emission.is_some() {
                self.warn(at, "area lights inside an object (instanced) emit nothing, as in pbrt");
            }
            return Ok(());
        }
        let emission = s.emission.unwrap_or(Rgb::ZERO);
        self.place(&Part { geometry: g, transform, material }, None, emission, at)
    }

    fn place(&mut self, part: &Part, outer: Option<Affine3A>, emission: Rgb, at: At) -> Result<(), Error> {
        let o = shapes::object(&self.geometries, part.geometry, outer, part.transform, part.material, emission)
            .map_err(|e| self.files.err(at, e))?;
        self.objects.push(o);
        Ok(())
    }

    /// A light's `from` (object space) and its unit world direction towards `to`.
    fn light_direction(&self, p: &Params, m: Affine3A, at: At) -> Result<(Vec3, Vec3), Error> {
        let from = self.vec3(p, "from", Vec3::ZERO)?;
        let to = self.vec3(p, "to", Vec3::Z)?;
        let dir = m.transform_vector3(to - from);
        if dir.length_squared() == 0.0 || !dir.is_finite() {
            return Err(self.files.err(at, "the light's 'from' and 'to' coincide"));
        }
        Ok((from, dir.normalize()))
    }

    fn light(&mut self, ty: &str, p: &Params, at: At, s: &State) -> Result<(), Error> {
        let m = affine(&self.files, s.ctm, at)?;
        let scale = self.float(p, "scale", 1.0)?;
        if let Some(q) = p.get("power").or_else(|| p.get("illuminance")) {
            let at = q.at;
            let name = q.name.clone();
            self.warn(at, format!("'{name}' is ignored: the light keeps its given radiance or intensity"));
        }
        let emission = spectrum::Kind::Emission;
        match ty {
            "point" => {
                let i = self.color(p, "I", emission)?.unwrap_or(Rgb::ONE) * scale;
                let from = self.vec3(p, "from", Vec3::ZERO)?;
                self.lights.push(Light::Point { position: m.transform_point3(from), intensity: i });
            }
            "spot" => {
                let i = self.color(p, "I", emission)?.unwrap_or(Rgb::ONE) * scale;
                let (from, dir) = self.light_direction(p, m, at)?;
                let cone = self.float(p, "coneangle", 30.0)?;
                let delta = self.float(p, "conedelta", 5.0)?;
                self.lights.push(Light::Spot {
                    position: m.transform_point3(from),
                    direction: dir,
                    intensity: i,
                    cos_inner: (cone - delta).max(0.0).to_radians().cos(),
                    cos_outer: cone.to_radians().cos(),
                });
            }
            "distant" => {
                let l = self.color(p, "L", emission)?.unwrap_or(Rgb::ONE) * scale;
                let (_, dir) = self.light_direction(p, m, at)?;
                self.lights.push(Light::Directional { direction: dir, irradiance: l });
            }
            "infinite" => {
                if self.lights.iter().any(|l| matches!(l, Light::Environment(_))) {
                    self.warn(at, "a second infinite light is ignored");
                    return Ok(());
                }
                let to_world = shapes::rotation(m);
                p.get("portal");
                let env = if let Some(f) = self.string(p, "filename")? {
                    let path = self.path(at, f);
                    let img = crate::image_in::read_rgb(&path)?;
                    if img.width != img.height {
                        return Err(Error::new(
                            &path,
                            "pbrt's infinite light needs a square image in the equal-area octahedral mapping",
                        ));
                    }
                    let map = equal_area_to_latlong(&img).map_err(|e| Error::new(&path, e.to_string()))?;
                    Environment { scale: Rgb::splat(scale), map: Some(map), to_world }
                } else {
                    let l = self.color(p, "L", emission)?.unwrap_or(Rgb::ONE);
                    Environment { scale: l * scale, map: None, to_world: Mat3::IDENTITY }
                };
                self.lights.push(Light::Environment(env));
            }
            "goniometric" | "projection" => {
                self.warn(at, format!("'{ty}' light rendered as a point light"));
                let i = self.color(p, "I", emission)?.unwrap_or(Rgb::ONE) * scale;
                self.lights.push(Light::Point { position: m.transform_point3(Vec3::ZERO), intensity: i });
            }
            other => self.warn(at, format!("light '{other}' is not supported; ignored")),
        }
        Ok(())
    }
}

/// The affine part of a pbrt transform (projective ones are rejected).
fn affine(files: &Files, m: Mat4, at: At) -> Result<Affine3A, Error> {
    if (m.row(3) - Vec4::W).abs().max_element() > 1e-6 || !m.is_finite() {
        return Err(files.err(at, "the current transform is not affine"));
    }
    Ok(Affine3A::from_mat4(m))
}

/// Indices of refraction (at the d line) of pbrt's named glasses.
fn glass_ior(name: &str) -> Option<f32> {
    Some(match name {
        "glass-BK7" => 1.5168,
        "glass-BAF10" => 1.6700,
        "glass-FK51A" => 1.4866,
        "glass-LASF9" => 1.8503,
        "glass-F5" => 1.6034,
        "glass-F10" => 1.6200,
        "glass-F11" => 1.6209,
        _ => return None,
    })
}

/// pbrt-v4's equal-area octahedral mapping (Clarberg): a unit direction to `[0, 1]²`.
fn equal_area_square(d: Vec3) -> Vec2 {
    let (x, y, z) = (d.x.abs(), d.y.abs(), d.z.abs());
    let r = (1.0 - z).max(0.0).sqrt();
    let (a, b) = (x.max(y), x.min(y));
    let b = if a == 0.0 { 0.0 } else { b / a };
    let mut phi = b.atan() * std::f32::consts::FRAC_2_PI;
    if x < y {
        phi = 1.0 - phi;
    }
    let mut v = phi * r;
    let mut u = r - v;
    if d.z < 0.0 {
        std::mem::swap(&mut u, &mut v);
        u = 1.0 - u;
        v = 1.0 - v;
    }
    u = u.copysign(d.x);
    v = v.copysign(d.y);
    Vec2::new(0.5 * (u + 1.0), 0.5 * (v + 1.0))
}

/// Resamples a square equal-area image (pbrt's environment maps, `+z` up) into the
/// latitude-longitude image Snell samples, in the same frame, at twice the width. Its pixels
/// are checked as given (a bad one is reported where it is in the file).
fn equal_area_to_latlong(img: &crate::image_in::RgbImage) -> Result<EnvMap, snell_core::image::BadPixels> {
    snell_core::image::check_pixels(img.width, img.height, &img.pixels)?;
    let n = img.width;
    let (w, h) = (2 * n, n);
    let at = |x: i64, y: i64| img.pixels[(y.clamp(0, n as i64 - 1) as usize) * n + x.clamp(0, n as i64 - 1) as usize];
    let mut pixels = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let uv = Vec2::new((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32);
            let d = Environment::direction(uv);
            let s = equal_area_square(d) * n as f32 - Vec2::splat(0.5);
            let (x0, y0) = (s.x.floor(), s.y.floor());
            let (fx, fy) = (s.x - x0, s.y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            let c = (at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx) * (1.0 - fy)
                + (at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx) * fy;
            pixels.push(c);
        }
    }
    EnvMap::new(w, h, pixels)
}

/// pbrt's `LookAt`: the world-to-camera matrix (camera looks down `+z`, `+y` up, `+x` right).
fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (target - eye).normalize_or_zero();
    let right = up.normalize_or_zero().cross(dir).normalize_or_zero();
    if dir == Vec3::ZERO || right == Vec3::ZERO {
        return None;
    }
    let new_up = dir.cross(right);
    let world_from_camera = Mat4::from_cols(right.extend(0.0), new_up.extend(0.0), dir.extend(0.0), eye.extend(1.0));
    Some(world_from_camera.inverse())
}

/// Loads a pbrt-v4 scene.
pub fn load(path: &Path) -> Result<LoadedScene, Error> {
    let text = crate::read_text(path)?;
    let canon = path.canonicalize().map_err(|e| Error::io(path, e))?;
    let mut cx = Ctx {
        files: Files { paths: vec![path.to_path_buf()] },
        base: path.parent().unwrap_or(Path::new(".")).to_path_buf(),
        warnings: Vec::new(),
        materials: vec![Material::Diffuse { albedo: Texture::Constant(Rgb::splat(0.5)) }],
        named_materials: HashMap::new(),
        textures: HashMap::new(),
        float_textures: HashMap::new(),
        geometries: Vec::new(),
        objects: Vec::new(),
        lights: Vec::new(),
        instances: HashMap::new(),
        defining: None,
        coordinate_systems: HashMap::new(),
        camera: None,
        film: None,
        sampler: None,
        integrator: None,
        filter: None,
    };
    let toks = tokenize(&text, 0, path)?;
    let mut stream = Stream { frames: vec![Frame { toks, pos: 0, canon }], last: At(0, 1, 1) };
    let mut state = State {
        ctm: Mat4::IDENTITY,
        reverse: false,
        material: CurrentMaterial::Index(0),
        emission: None,
        attributes: HashMap::new(),
    };
    let mut stack: Vec<(State, At, bool)> = Vec::new();
    while let Some(t) = stream.next() {
        if t.kind != Kind::Word {
            return Err(cx.files.err(t.at, format!("expected a directive, found '{}'", t.text)));
        }
        let at = t.at;
        let d = t.text.as_str();
        match d {
            "Include" | "Import" => {
                let f = string_arg(&cx, &mut stream, d)?;
                let p = cx.path(at, &f);
                let canon = p.canonicalize().map_err(|e| {
                    Error::at(
                        &cx.files.paths[at.0],
                        Location::LineCol(at.1, at.2),
                        format!("{d} '{f}': {}", Error::io(&p, e).message),
                    )
                })?;
                if stream.frames.iter().any(|fr| fr.canon == canon) {
                    return Err(cx.files.err(at, format!("{d} '{f}' includes itself (a cycle)")));
                }
                let text = crate::read_text(&p)?;
                let idx = cx.files.paths.len();
                cx.files.paths.push(p.clone());
                let toks = tokenize(&text, idx, &p)?;
                stream.frames.push(Frame { toks, pos: 0, canon });
            }
            "Identity" => state.ctm = Mat4::IDENTITY,
            "Translate" => {
                let v = nums_arg::<3>(&cx, &mut stream, d)?;
                state.ctm *= Mat4::from_translation(Vec3::from(v));
            }
            "Scale" => {
                let v = nums_arg::<3>(&cx, &mut stream, d)?;
                state.ctm *= Mat4::from_scale(Vec3::from(v));
            }
            "Rotate" => {
                let [a, x, y, z] = nums_arg::<4>(&cx, &mut stream, d)?;
                let axis = Vec3::new(x, y, z).normalize_or_zero();
                if axis == Vec3::ZERO {
                    return Err(cx.files.err(at, "Rotate needs a non-zero axis"));
                }
                state.ctm *= Mat4::from_axis_angle(axis, a.to_radians());
            }
            "LookAt" => {
                let v = nums_arg::<9>(&cx, &mut stream, d)?;
                let m = look_at(Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]), Vec3::new(v[6], v[7], v[8]))
                    .ok_or_else(|| cx.files.err(at, "LookAt: the eye, target and up vector give no frame"))?;
                state.ctm *= m;
            }
            "Transform" | "ConcatTransform" => {
                let v = array_arg(&cx, &mut stream, d, 16)?;
                let m = Mat4::from_cols_array(&v.try_into().unwrap_or([0.0; 16]));
                state.ctm = if d == "Transform" { m } else { state.ctm * m };
            }
            "CoordinateSystem" => {
                let n = string_arg(&cx, &mut stream, d)?;
                cx.coordinate_systems.insert(n, state.ctm);
            }
            "CoordSysTransform" => {
                let n = string_arg(&cx, &mut stream, d)?;
                match cx.coordinate_systems.get(&n) {
                    Some(m) => state.ctm = *m,
                    None => cx.warn(at, format!("unknown coordinate system '{n}'; ignored")),
                }
            }
            "ReverseOrientation" => state.reverse = !state.reverse,
            "AttributeBegin" | "TransformBegin" => {
                if d == "TransformBegin" {
                    cx.warn(at, "TransformBegin is deprecated in pbrt-v4 (treated as a transform-only AttributeBegin)");
                }
                stack.push((state.clone(), at, d == "TransformBegin"));
            }
            "AttributeEnd" | "TransformEnd" => {
                let Some((saved, _, transform_only)) = stack.pop() else {
                    return Err(cx.files.err(at, format!("{d} without a matching begin")));
                };
                if transform_only != (d == "TransformEnd") {
                    return Err(cx.files.err(at, format!("{d} closes a block its kind did not open")));
                }
                if transform_only {
                    state.ctm = saved.ctm;
                } else {
                    state = saved;
                }
            }
            "Attribute" => {
                let target = string_arg(&cx, &mut stream, d)?;
                let p = params(&cx, &mut stream)?;
                if !matches!(target.as_str(), "shape" | "light" | "material" | "medium" | "texture") {
                    return Err(cx.files.err(at, format!("unknown Attribute target '{target}'")));
                }
                state.attributes.entry(target).or_default().extend(p.list);
            }
            "ActiveTransform" => {
                let w =
                    stream.next().ok_or_else(|| cx.files.err(at, "ActiveTransform needs All, StartTime or EndTime"))?;
                if w.text != "All" {
                    cx.warn(at, "motion blur is not supported: only the start transform is used");
                }
            }
            "TransformTimes" => {
                nums_arg::<2>(&cx, &mut stream, d)?;
            }
            "WorldBegin" => {
                state.ctm = Mat4::IDENTITY;
                cx.coordinate_systems.insert("world".into(), Mat4::IDENTITY);
            }
            "WorldEnd" => {}
            "Option" => {
                let p = params(&cx, &mut stream)?;
                cx.unused("Option", &p);
            }
            "MakeNamedMaterial" => {
                let name = string_arg(&cx, &mut stream, d)?;
                let mut p = params(&cx, &mut stream)?;
                p.defaults = state.attributes.get("material").cloned().unwrap_or_default();
                let ty = cx.string(&p, "type")?.unwrap_or("").to_string();
                let m = cx.material(&ty, &p, at)?;
                cx.unused(&format!("material '{name}'"), &p);
                cx.named_materials.insert(name, m);
            }
            "NamedMaterial" => {
                let name = string_arg(&cx, &mut stream, d)?;
                state.material = *cx
                    .named_materials
                    .get(&name)
                    .ok_or_else(|| cx.files.err(at, format!("unknown material '{name}'")))?;
            }
            "Texture" => {
                let name = string_arg(&cx, &mut stream, d)?;
                let ty = string_arg(&cx, &mut stream, d)?;
                let class = string_arg(&cx, &mut stream, d)?;
                let mut p = params(&cx, &mut stream)?;
                p.defaults = state.attributes.get("texture").cloned().unwrap_or_default();
                if ty != "spectrum" && ty != "float" {
                    return Err(cx.files.err(at, format!("texture type '{ty}' (expected \"spectrum\" or \"float\")")));
                }
                cx.texture_def(&name, &ty, &class, &p, at)?;
                cx.unused(&format!("texture '{name}'"), &p);
            }
            "ObjectBegin" => {
                let name = string_arg(&cx, &mut stream, d)?;
                if cx.defining.is_some() {
                    return Err(cx.files.err(at, "ObjectBegin inside another object"));
                }
                stack.push((state.clone(), at, false));
                cx.defining = Some((name, Vec::new()));
            }
            "ObjectEnd" => {
                let Some((name, parts)) = cx.defining.take() else {
                    return Err(cx.files.err(at, "ObjectEnd without ObjectBegin"));
                };
                let Some((saved, _, _)) = stack.pop() else {
                    return Err(cx.files.err(at, "ObjectEnd without ObjectBegin"));
                };
                state = saved;
                cx.instances.insert(name, parts);
            }
            "ObjectInstance" => {
                let name = string_arg(&cx, &mut stream, d)?;
                let parts = cx
                    .instances
                    .get(&name)
                    .cloned()
                    .ok_or_else(|| cx.files.err(at, format!("unknown object '{name}'")))?;
                let m = affine(&cx.files, state.ctm, at)?;
                for part in &parts {
                    cx.place(part, Some(m), Rgb::ZERO, at)?;
                }
            }
            "MakeNamedMedium" | "MediumInterface" => {
                if d == "MakeNamedMedium" {
                    string_arg(&cx, &mut stream, d)?;
                    params(&cx, &mut stream)?;
                } else {
                    string_arg(&cx, &mut stream, d)?;
                    if stream.peek().is_some_and(|t| t.kind == Kind::Str) {
                        string_arg(&cx, &mut stream, d)?;
                    }
                }
                cx.warn(at, "participating media are not supported; ignored");
            }
            _ if DIRECTIVES_WITH_PARAMS.contains(&d) => {
                let ty = string_arg(&cx, &mut stream, d)?;
                let mut p = params(&cx, &mut stream)?;
                let what = format!("{d} \"{ty}\"");
                match d {
                    "Camera" => {
                        cx.coordinate_systems.insert("camera".into(), state.ctm.inverse());
                        cx.camera = Some((state.ctm, ty, p, at));
                        continue;
                    }
                    "Film" => cx.film = Some((ty, p, at)),
                    "Sampler" => cx.sampler = Some((ty, p, at)),
                    "Integrator" => cx.integrator = Some((ty, p, at)),
                    "PixelFilter" => cx.filter = Some((ty, p, at)),
                    "Accelerator" => {
                        cx.warn(at, "the Accelerator is chosen by Snell (--accel); ignored");
                    }
                    "ColorSpace" if ty != "srgb" => {
                        cx.warn(at, format!("color space '{ty}' is ignored: colours are taken as linear sRGB"));
                    }
                    "Material" => {
                        p.defaults = state.attributes.get("material").cloned().unwrap_or_default();
                        state.material = cx.material(&ty, &p, at)?;
                        cx.unused(&what, &p);
                    }
                    "Shape" => {
                        p.defaults = state.attributes.get("shape").cloned().unwrap_or_default();
                        cx.shape(&ty, &p, at, &state)?;
                        cx.unused(&what, &p);
                    }
                    "LightSource" => {
                        p.defaults = state.attributes.get("light").cloned().unwrap_or_default();
                        cx.light(&ty, &p, at, &state)?;
                        cx.unused(&what, &p);
                    }
                    "AreaLightSource" => {
                        p.defaults = state.attributes.get("light").cloned().unwrap_or_default();
                        if ty != "diffuse" {
                            cx.warn(at, format!("area light '{ty}' is not supported; ignored"));
                            continue;
                        }
                        let l = cx.color(&p, "L", spectrum::Kind::Emission)?.unwrap_or(Rgb::ONE);
                        let scale = cx.float(&p, "scale", 1.0)?;
                        if cx.boolean(&p, "twosided", false)? {
                            cx.warn(at, "two-sided area lights emit on the front side only");
                        }
                        state.emission = Some(l * scale);
                        cx.unused(&what, &p);
                    }
                    _ => {}
                }
            }
            other => return Err(cx.files.err(at, format!("unknown directive '{other}'"))),
        }
    }
    if let Some((_, at, _)) = stack.last() {
        return Err(cx.files.err(*at, "this block is never closed (missing AttributeEnd or ObjectEnd)"));
    }
    finish(cx, path)
}

fn string_arg(cx: &Ctx, s: &mut Stream, d: &str) -> Result<String, Error> {
    match s.next() {
        Some(t) if t.kind == Kind::Str => Ok(t.text),
        Some(t) => Err(cx.files.err(t.at, format!("{d} needs a quoted string here, not '{}'", t.text))),
        None => Err(cx.files.err(s.last, format!("{d}: the file ends before its string argument"))),
    }
}

fn number(cx: &Ctx, s: &mut Stream, d: &str) -> Result<f32, Error> {
    match s.next() {
        Some(t) if t.kind == Kind::Num => {
            let v: f64 = t.text.parse().map_err(|_| cx.files.err(t.at, format!("'{}' is not a number", t.text)))?;
            if !v.is_finite() {
                return Err(cx.files.err(t.at, format!("'{}' is not finite", t.text)));
            }
            Ok(v as f32)
        }
        Some(t) => Err(cx.files.err(t.at, format!("{d} needs a number here, not '{}'", t.text))),
        None => Err(cx.files.err(s.last, format!("{d}: the file ends before its numbers"))),
    }
}

fn nums_arg<const N: usize>(cx: &Ctx, s: &mut Stream, d: &str) -> Result<[f32; N], Error> {
    let mut v = [0.0; N];
    for x in v.iter_mut() {
        *x = number(cx, s, d)?;
    }
    Ok(v)
}

/// `[ n numbers ]` (or the numbers without brackets).
fn array_arg(cx: &Ctx, s: &mut Stream, d: &str, n: usize) -> Result<Vec<f32>, Error> {
    let bracket = s.peek().is_some_and(|t| t.kind == Kind::Open);
    if bracket {
        s.next();
    }
    let v = (0..n).map(|_| number(cx, s, d)).collect::<Result<Vec<_>, _>>()?;
    if bracket {
        match s.next() {
            Some(t) if t.kind == Kind::Close => {}
            Some(t) => return Err(cx.files.err(t.at, format!("{d} needs exactly {n} numbers"))),
            None => return Err(cx.files.err(s.last, format!("{d}: missing ']'"))),
        }
    }
    Ok(v)
}

/// The `"type name" value` list after a directive.
fn params(cx: &Ctx, s: &mut Stream) -> Result<Params, Error> {
    let mut list = Vec::new();
    while let Some(t) = s.peek() {
        if t.kind != Kind::Str {
            break;
        }
        let Some(t) = s.next() else { break };
        let mut words = t.text.split_whitespace();
        let (Some(ty), Some(name), None) = (words.next(), words.next(), words.next()) else {
            return Err(cx.files.err(t.at, format!("'{}' is not a parameter declaration (\"type name\")", t.text)));
        };
        let ty = match ty {
            "point" => "point3",
            "vector" => "vector3",
            "normal" => "normal3",
            "color" => "rgb",
            other => other,
        };
        const TYPES: [&str; 14] = [
            "integer",
            "float",
            "point2",
            "vector2",
            "point3",
            "vector3",
            "normal3",
            "spectrum",
            "rgb",
            "blackbody",
            "bool",
            "string",
            "texture",
            "normal3",
        ];
        if !TYPES.contains(&ty) {
            return Err(cx.files.err(t.at, format!("unknown parameter type '{ty}'")));
        }
        let mut raw = Vec::new();
        match s.next() {
            Some(v) if v.kind == Kind::Open => loop {
                match s.next() {
                    Some(v) if v.kind == Kind::Close => break,
                    Some(v) if v.kind == Kind::Open => return Err(cx.files.err(v.at, "nested '[' in a parameter")),
                    Some(v) => raw.push(v),
                    None => return Err(cx.files.err(t.at, format!("'{name}': missing ']'"))),
                }
            },
            Some(v) if matches!(v.kind, Kind::Num | Kind::Str | Kind::Word) => raw.push(v),
            Some(v) => return Err(cx.files.err(v.at, format!("'{name}' has no value"))),
            None => return Err(cx.files.err(t.at, format!("'{name}' has no value"))),
        }
        let wrong = |v: &Tok, want: &str| cx.files.err(v.at, format!("'{ty} {name}' needs {want}, not '{}'", v.text));
        let vals = match ty {
            "string" | "texture" => Vals::Str(
                raw.iter()
                    .map(|v| if v.kind == Kind::Str { Ok(v.text.clone()) } else { Err(wrong(v, "strings")) })
                    .collect::<Result<_, _>>()?,
            ),
            "bool" => Vals::Bool(
                raw.iter()
                    .map(|v| match (v.kind, v.text.as_str()) {
                        (Kind::Str | Kind::Word, "true") => Ok(true),
                        (Kind::Str | Kind::Word, "false") => Ok(false),
                        _ => Err(wrong(v, "true or false")),
                    })
                    .collect::<Result<_, _>>()?,
            ),
            "spectrum" if raw.first().is_some_and(|v| v.kind == Kind::Str) => Vals::Str(
                raw.iter()
                    .map(|v| if v.kind == Kind::Str { Ok(v.text.clone()) } else { Err(wrong(v, "a name")) })
                    .collect::<Result<_, _>>()?,
            ),
            _ => Vals::Num(
                raw.iter()
                    .map(|v| {
                        if v.kind == Kind::Num {
                            v.text.parse::<f64>().map_err(|_| wrong(v, "numbers"))
                        } else {
                            Err(wrong(v, "numbers"))
                        }
                    })
                    .collect::<Result<_, _>>()?,
            ),
        };
        if let Vals::Num(v) = &vals {
            let per = match ty {
                "point2" | "vector2" => 2,
                "point3" | "vector3" | "normal3" | "rgb" => 3,
                _ => 1,
            };
            if v.len() % per != 0 || v.is_empty() {
                return Err(cx.files.err(t.at, format!("'{ty} {name}' needs numbers in groups of {per}")));
            }
            if ty == "integer" && v.iter().any(|x| x.fract() != 0.0) {
                return Err(cx.files.err(t.at, format!("'{ty} {name}' needs whole numbers")));
            }
        }
        list.push(Param { ty: ty.to_string(), name: name.to_string(), vals, at: t.at, used: Cell::new(false) });
    }
    Ok(Params { list, defaults: Vec::new() })
}

/// Camera, film, sampler, integrator and filter, once the whole file is read.
fn finish(mut cx: Ctx, path: &Path) -> Result<LoadedScene, Error> {
    let mut settings = SceneSettings { integrator: IntegratorKind::Path, ..SceneSettings::default() };
    settings.reconstruction = Reconstruction::ImportanceSampled;
    // pbrt-v4's defaults: 1280 × 720, zsobol 16 spp, volpath maxdepth 5, Gaussian radius 1.5.
    let (mut width, mut height) = (1280u32, 720u32);
    settings.spp = 16;
    settings.sampler = SamplerKind::Sobol;
    settings.max_depth = Some(6);
    // pbrt plays Russian roulette from the second bounce on.
    settings.rr_depth = 2;
    settings.filter = Filter::gaussian(1.5, 0.5);
    if let Some((ty, p, at)) = cx.film.take() {
        if ty != "rgb" {
            cx.warn(at, format!("film '{ty}' is written as an RGB image"));
        }
        width = cx.int(&p, "xresolution", 1280)?.clamp(1, 65536) as u32;
        height = cx.int(&p, "yresolution", 720)?.clamp(1, 65536) as u32;
        p.get("filename");
        cx.unused(&format!("Film \"{ty}\""), &p);
    }
    if let Some((ty, p, at)) = cx.sampler.take() {
        settings.spp = match ty.as_str() {
            "stratified" => cx.int(&p, "xsamples", 4)? * cx.int(&p, "ysamples", 4)?,
            _ => cx.int(&p, "pixelsamples", 16)?,
        }
        .clamp(1, 1 << 20) as u32;
        p.get("jitter");
        p.get("randomization");
        settings.seed = cx.int(&p, "seed", 0)?.max(0) as u64;
        settings.sampler = match ty.as_str() {
            "independent" => SamplerKind::Independent,
            "sobol" | "zsobol" | "paddedsobol" => SamplerKind::Sobol,
            other => {
                cx.warn(at, format!("sampler '{other}' is rendered with Owen-scrambled Sobol points"));
                SamplerKind::Sobol
            }
        };
        cx.unused(&format!("Sampler \"{ty}\""), &p);
    }
    if let Some((ty, p, at)) = cx.integrator.take() {
        if !matches!(ty.as_str(), "path" | "volpath") {
            cx.warn(at, format!("integrator '{ty}' is not supported; using path tracing"));
        } else if ty == "volpath" {
            cx.warn(at, "volpath is rendered as path tracing (no participating media)");
        }
        let d = cx.int(&p, "maxdepth", 5)?;
        settings.max_depth = Some((d.max(0) + 1) as u32);
        if cx.boolean(&p, "regularize", false)? {
            cx.warn(at, "'regularize' is not supported");
        }
        p.get("lightsampler");
        cx.unused(&format!("Integrator \"{ty}\""), &p);
    }
    if let Some((ty, p, at)) = cx.filter.take() {
        let r = |cx: &Ctx, d: f32| -> Result<f32, Error> {
            let (x, y) = (cx.float(&p, "xradius", d)?, cx.float(&p, "yradius", d)?);
            Ok(0.5 * (x + y))
        };
        settings.filter = match ty.as_str() {
            "box" => Filter::Box { radius: r(&cx, 0.5)? },
            "triangle" => Filter::Tent { radius: r(&cx, 2.0)? },
            "gaussian" => Filter::gaussian(r(&cx, 1.5)?, cx.float(&p, "sigma", 0.5)?.max(1e-3)),
            other => {
                cx.warn(at, format!("filter '{other}' is not supported; using a Gaussian"));
                Filter::gaussian(1.5, 0.5)
            }
        };
        cx.unused(&format!("PixelFilter \"{ty}\""), &p);
    }
    settings.width = width;
    settings.height = height;
    let Some((ctm, ty, p, at)) = cx.camera.take() else {
        return Err(Error::new(path, "the scene has no Camera"));
    };
    let w = affine(&cx.files, ctm, at)?.inverse();
    if !w.is_finite() {
        return Err(cx.files.err(at, "the camera transform is not invertible"));
    }
    let aspect = width as f32 / height as f32;
    let projection = match ty.as_str() {
        "orthographic" => {
            p.get("screenwindow");
            Projection::Orthographic { half_height: if aspect >= 1.0 { 1.0 } else { 1.0 / aspect } }
        }
        other => {
            if other != "perspective" {
                cx.warn(at, format!("camera '{other}' is rendered as a perspective camera"));
            }
            let fov = cx.float(&p, "fov", 90.0)?;
            if !(fov > 0.0 && fov < 180.0) {
                return Err(cx.files.err(at, format!("field of view {fov} degrees is out of range")));
            }
            // pbrt's fov spans the shorter image axis.
            let fov_y =
                if aspect >= 1.0 { fov } else { 2.0 * ((fov.to_radians() * 0.5).tan() / aspect).atan().to_degrees() };
            let lens = cx.float(&p, "lensradius", 0.0)?;
            if lens > 0.0 {
                Projection::ThinLens { fov_y, aperture: lens, focus_distance: cx.float(&p, "focaldistance", 1e6)? }
            } else {
                Projection::Perspective { fov_y }
            }
        }
    };
    cx.unused(&format!("Camera \"{ty}\""), &p);
    let eye = w.transform_point3(Vec3::ZERO);
    let camera = Camera::with_frame(
        eye,
        w.transform_vector3(Vec3::X),
        w.transform_vector3(Vec3::Y),
        w.transform_vector3(Vec3::Z),
        projection,
    )
    .ok_or_else(|| cx.files.err(at, "the camera transform has no valid view direction"))?;
    let scene = Scene {
        geometries: cx.geometries,
        objects: cx.objects,
        materials: cx.materials,
        lights: cx.lights,
        camera,
        background: Rgb::ZERO,
        ambient: Rgb::ZERO,
        light_selection: LightSelection::Power,
    };
    scene.check().map_err(|e| Error::new(path, e))?;
    Ok(LoadedScene { scene, settings, frame: None, warnings: cx.warnings })
}
