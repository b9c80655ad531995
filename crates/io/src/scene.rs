//! Snell's native scene format (TOML). The README documents it with an example per feature.
//!
//! Parsing is strict: unknown keys, keys that do not apply to the chosen `type`, wrong types
//! and out-of-range values are errors that name the file, line and column. Mesh files are
//! resolved relative to the scene file and loaded once per path, however many shapes use them
//! (the shapes become instances of one shared mesh).

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Quat, Vec3};
use serde::{Deserialize, Deserializer};
use snell_core::accel::AccelKind;
use snell_core::camera::{Camera, Projection};
use snell_core::filter::Filter;
use snell_core::geometry::{Aabb, Transform};
use snell_core::integrator::{AnyIntegrator, IntegratorKind, Path as PathTracer, Whitted};
use snell_core::light::{EnvMap, Environment, Light};
use snell_core::material::microfacet::Distribution;
use snell_core::material::{self, Material};
use snell_core::render::Reconstruction;
use snell_core::sampling::SamplerKind;
use snell_core::scene::{Geometry, LightSelection, Object, Scene};
use snell_core::shape::{Mesh, Sphere};
use snell_core::Rgb;
use toml::Spanned;

use crate::{Error, Location};

/// Render settings a scene file can carry; the command line overrides each of them.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSettings {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u64,
    pub integrator: IntegratorKind,
    /// Whitted: depth of the ray tree (default 10). Path: longest path in segments (default
    /// unbounded, as Mitsuba's `max_depth = -1`).
    pub max_depth: Option<u32>,
    pub min_attenuation: f32,
    /// Path: depth at which Russian roulette starts (Mitsuba's `rr_depth`, default 5).
    pub rr_depth: u32,
    pub accel: AccelKind,
    pub filter: Filter,
    pub reconstruction: Reconstruction,
    pub sampler: SamplerKind,
}

impl Default for SceneSettings {
    fn default() -> Self {
        SceneSettings {
            width: 640,
            height: 480,
            spp: 16,
            seed: 0,
            integrator: IntegratorKind::Whitted,
            max_depth: None,
            min_attenuation: 1e-3,
            rr_depth: 5,
            accel: AccelKind::DEFAULT,
            filter: Filter::default(),
            reconstruction: Reconstruction::default(),
            sampler: SamplerKind::default(),
        }
    }
}

impl SceneSettings {
    /// The reconstruction filter, as a short description.
    pub fn filter_name(&self) -> String {
        match &self.filter {
            Filter::Box { radius } => format!("box radius {radius}"),
            Filter::Tent { radius } => format!("tent radius {radius}"),
            Filter::Gaussian { radius, sigma, .. } => format!("gaussian sigma {sigma} radius {radius}"),
        }
    }

    /// The integrator these settings describe, with each one's defaults filled in.
    pub fn integrator(&self) -> AnyIntegrator {
        match self.integrator {
            IntegratorKind::Whitted => AnyIntegrator::Whitted(Whitted {
                max_depth: self.max_depth.unwrap_or(Whitted::default().max_depth),
                min_attenuation: self.min_attenuation,
            }),
            IntegratorKind::Path => AnyIntegrator::Path(PathTracer {
                max_depth: self.max_depth.unwrap_or(u32::MAX),
                rr_depth: self.rr_depth,
            }),
        }
    }
}

/// A loaded scene with its settings.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    pub scene: Scene,
    pub settings: SceneSettings,
    /// When the camera was placed automatically: the box it frames, so that a caller that
    /// changes the image size can re-frame it with [`auto_camera`] for the new aspect ratio.
    pub frame: Option<Aabb>,
    /// What the reader ignored or approximated, each with file, line and column.
    pub warnings: Vec<String>,
}

// ---------------------------------------------------------------------------------------------
// Validated values

/// A finite 3-vector.
#[derive(Clone, Copy, Debug)]
struct V3(Vec3);
impl<'de> Deserialize<'de> for V3 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let a = <[f32; 3]>::deserialize(d)?;
        let v = Vec3::from(a);
        if !v.is_finite() {
            return Err(serde::de::Error::custom("expected three finite numbers"));
        }
        Ok(V3(v))
    }
}

/// A colour: three finite non-negative numbers, or one number for grey.
#[derive(Clone, Copy, Debug)]
struct Color(Rgb);
impl<'de> Deserialize<'de> for Color {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum C {
            One(f32),
            Three([f32; 3]),
        }
        let c =
            C::deserialize(d).map_err(|_| serde::de::Error::custom("expected a colour: [r, g, b] or one number"))?;
        let v = match c {
            C::One(x) => Rgb::splat(x),
            C::Three(a) => Rgb::from(a),
        };
        if !v.is_finite() || v.min_element() < 0.0 {
            return Err(serde::de::Error::custom("colour components must be finite and not negative"));
        }
        Ok(Color(v))
    }
}

/// A colour or a texture: `[r, g, b]`, one number, `{ checker = [colour, colour], scale = n }`,
/// or `{ image = "file", scale = n }` (read when the material is built, relative to the scene).
#[derive(Clone, Debug)]
enum Tex {
    Ready(material::Texture),
    Image { file: String, scale: f32 },
}
impl<'de> Deserialize<'de> for Tex {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Checker {
            checker: [Color; 2],
            scale: Option<f32>,
        }
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Img {
            image: String,
            scale: Option<f32>,
        }
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum T {
            C(Color),
            Checker(Checker),
            Img(Img),
        }
        let positive = |scale: f32| -> Result<f32, D::Error> {
            if scale.is_finite() && scale > 0.0 {
                Ok(scale)
            } else {
                Err(serde::de::Error::custom("a texture's scale must be a positive number"))
            }
        };
        match T::deserialize(d).map_err(|_| {
            serde::de::Error::custom(
                "expected a colour ([r, g, b] or one number), { checker = [colour, colour], scale = n } or \
                 { image = \"file\", scale = n }",
            )
        })? {
            T::C(c) => Ok(Tex::Ready(material::Texture::Constant(c.0))),
            T::Checker(c) => {
                let scale = positive(c.scale.unwrap_or(8.0))?;
                Ok(Tex::Ready(material::Texture::Checker { a: c.checker[0].0, b: c.checker[1].0, scale }))
            }
            T::Img(i) => Ok(Tex::Image { file: i.image, scale: positive(i.scale.unwrap_or(1.0))? }),
        }
    }
}

/// A finite number in a range, checked by the newtype's constructor below.
#[derive(Clone, Copy, Debug)]
struct Num(f32);
impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = f32::deserialize(d)?;
        if !v.is_finite() {
            return Err(serde::de::Error::custom(format!("expected a finite number, found {v}")));
        }
        Ok(Num(v))
    }
}

/// An index of refraction: a number ≥ 1 or a preset name.
#[derive(Clone, Copy, Debug)]
struct Ior(f32);
impl<'de> Deserialize<'de> for Ior {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum I {
            N(f32),
            S(String),
        }
        let names = || material::IORS.iter().map(|p| p.0).collect::<Vec<_>>().join(", ");
        let v = match I::deserialize(d).map_err(|_| {
            serde::de::Error::custom(format!("expected an index of refraction: a number or one of {}", names()))
        })? {
            I::N(v) => v,
            I::S(s) => material::named_ior(&s)
                .ok_or_else(|| serde::de::Error::custom(format!("unknown IOR preset '{s}' (known: {})", names())))?,
        };
        if !(v.is_finite() && v > 0.0) {
            return Err(serde::de::Error::custom(format!(
                "an index of refraction must be a positive finite number, found {v}"
            )));
        }
        Ok(Ior(v))
    }
}

type S<T> = Option<Spanned<T>>;

// ---------------------------------------------------------------------------------------------
// The file's structure

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    render: Option<RenderDef>,
    camera: Option<Spanned<CameraDef>>,
    #[serde(default)]
    materials: BTreeMap<String, Spanned<MaterialDef>>,
    #[serde(default)]
    lights: Vec<Spanned<LightDef>>,
    #[serde(default)]
    shapes: Vec<Spanned<ShapeDef>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RenderDef {
    width: S<i64>,
    height: S<i64>,
    spp: S<i64>,
    seed: Option<u64>,
    integrator: S<String>,
    max_depth: S<i64>,
    min_attenuation: S<Num>,
    rr_depth: S<i64>,
    accel: S<String>,
    filter: S<String>,
    filter_radius: S<Num>,
    filter_sigma: S<Num>,
    background: Option<Color>,
    ambient: Option<Color>,
    light_selection: S<String>,
    reconstruction: S<String>,
    sampler: S<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDef {
    #[serde(rename = "type")]
    kind: S<String>,
    eye: S<V3>,
    look_at: S<V3>,
    up: S<V3>,
    fov: S<Num>,
    aperture: S<Num>,
    focus_distance: S<Num>,
    scale: S<Num>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialDef {
    #[serde(rename = "type")]
    kind: Spanned<String>,
    albedo: S<Tex>,
    specular: S<Color>,
    roughness: S<Num>,
    ior: S<Ior>,
    metal: S<String>,
    eta: S<Color>,
    k: S<Color>,
    reflectance: S<Color>,
    transmittance: S<Color>,
    base: S<Color>,
    distribution: S<String>,
    two_sided: Option<Spanned<bool>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightDef {
    #[serde(rename = "type")]
    kind: Spanned<String>,
    position: S<V3>,
    intensity: S<Color>,
    direction: S<V3>,
    look_at: S<V3>,
    cone_angle: S<Num>,
    falloff_start: S<Num>,
    irradiance: S<Color>,
    radiance: S<Color>,
    file: S<String>,
    rotate_y: S<Num>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShapeDef {
    #[serde(rename = "type")]
    kind: Spanned<String>,
    material: S<String>,
    emission: S<Color>,
    light_samples: S<i64>,
    transform: S<Vec<Spanned<TransformOp>>>,
    // sphere
    center: S<V3>,
    radius: S<Num>,
    // quad
    corner: S<V3>,
    edge1: S<V3>,
    edge2: S<V3>,
    // box
    min: S<V3>,
    max: S<V3>,
    // mesh
    file: S<String>,
    smooth: S<bool>,
    positions: S<Vec<V3>>,
    indices: S<Vec<[i64; 3]>>,
    // instancing
    array: S<ArrayDef>,
}

/// `array = { count = [nx, ny, nz], step = [dx, dy, dz] }`: the shape repeated on a lattice.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ArrayDef {
    count: [u32; 3],
    step: V3,
}

/// Most copies one `array` may make.
const MAX_ARRAY: u64 = 1 << 20;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TransformOp {
    translate: Option<V3>,
    scale: Option<ScaleValue>,
    rotate: Option<Rotate>,
    matrix: Option<[f32; 16]>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ScaleValue {
    Uniform(f32),
    Axes([f32; 3]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Rotate {
    axis: V3,
    angle: Num,
}

// ---------------------------------------------------------------------------------------------
// Loading

struct Ctx<'a> {
    path: &'a Path,
    src: &'a str,
}

impl Ctx<'_> {
    fn loc(&self, span: Range<usize>) -> Location {
        let start = span.start.min(self.src.len());
        let before = &self.src[..start];
        let line = before.matches('\n').count() + 1;
        let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        Location::LineCol(line, col)
    }

    fn err(&self, span: Range<usize>, msg: impl Into<String>) -> Error {
        Error::at(self.path, self.loc(span), msg)
    }

    /// Errors if a key was given that the chosen type does not use.
    fn reject<T>(&self, field: &S<T>, key: &str, what: &str) -> Result<(), Error> {
        match field {
            Some(f) => Err(self.err(f.span(), format!("'{key}' does not apply to {what}"))),
            None => Ok(()),
        }
    }

    fn int(&self, v: &S<i64>, lo: i64, hi: i64, key: &str, default: i64) -> Result<i64, Error> {
        match v {
            None => Ok(default),
            Some(s) if (lo..=hi).contains(s.get_ref()) => Ok(*s.get_ref()),
            Some(s) => Err(self.err(s.span(), format!("'{key}' must be between {lo} and {hi}, found {}", s.get_ref()))),
        }
    }

    fn num(&self, v: &S<Num>, lo: f32, hi: f32, key: &str, default: f32) -> Result<f32, Error> {
        match v {
            None => Ok(default),
            Some(s) if (lo..=hi).contains(&s.get_ref().0) => Ok(s.get_ref().0),
            Some(s) => {
                Err(self.err(s.span(), format!("'{key}' must be between {lo} and {hi}, found {}", s.get_ref().0)))
            }
        }
    }
}

fn val<T: Copy>(v: &S<T>) -> Option<T> {
    v.as_ref().map(|s| *s.get_ref())
}

/// Loads a scene from a TOML file.
pub fn load(path: &Path) -> Result<LoadedScene, Error> {
    let src = crate::read_text(path)?;
    parse(&src, path)
}

/// Parses scene text; `path` names the file in errors and anchors relative mesh paths.
pub fn parse(src: &str, path: &Path) -> Result<LoadedScene, Error> {
    let cx = Ctx { path, src };
    if src.lines().all(|l| {
        let t = l.trim();
        t.is_empty() || t.starts_with('#')
    }) {
        return Err(Error::new(path, "the scene file is empty"));
    }
    let file: File = toml::from_str(src).map_err(|e| {
        let msg = e.message().trim().to_string();
        match e.span() {
            Some(s) => cx.err(s, msg),
            None => Error::new(path, msg),
        }
    })?;
    let settings = render_settings(&cx, file.render.as_ref())?;
    let (background, ambient) = match &file.render {
        Some(r) => (r.background.map_or(Rgb::ZERO, |c| c.0), r.ambient.map_or(Rgb::ZERO, |c| c.0)),
        None => (Rgb::ZERO, Rgb::ZERO),
    };

    let mut materials = vec![Material::Diffuse { albedo: Rgb::splat(0.8).into() }];
    let mut material_ids: HashMap<&str, usize> = HashMap::new();
    for (name, def) in &file.materials {
        materials.push(material_def(&cx, def)?);
        material_ids.insert(name.as_str(), materials.len() - 1);
    }
    let lights = file.lights.iter().map(|l| light_def(&cx, l)).collect::<Result<Vec<_>, _>>()?;

    let base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut geometries: Vec<Geometry> = Vec::new();
    let mut mesh_cache: HashMap<(PathBuf, bool), usize> = HashMap::new();
    let mut objects = Vec::new();
    for s in &file.shapes {
        let object = shape_def(&cx, s, &base_dir, &material_ids, &mut geometries, &mut mesh_cache)?;
        match &s.get_ref().array {
            None => objects.push(object),
            Some(a) => objects.extend(array_copies(&cx, &object, a)?),
        }
    }

    let mut scene = Scene {
        geometries,
        objects,
        materials,
        lights,
        camera: Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 40.0 })
            .ok_or_else(|| Error::new(path, "internal: default camera"))?,
        background,
        ambient,
        light_selection: Default::default(),
    };
    if let Some(ls) = file.render.as_ref().and_then(|r| r.light_selection.as_ref()) {
        scene.light_selection = match ls.get_ref().as_str() {
            "power" => LightSelection::Power,
            "uniform" => LightSelection::Uniform,
            other => {
                return Err(cx.err(ls.span(), format!("unknown light_selection '{other}' (expected power or uniform)")))
            }
        };
    }
    let frame = file.camera.is_none().then(|| scene.aabb());
    scene.camera = match (&file.camera, frame) {
        (Some(c), _) => camera_def(&cx, c)?,
        (None, Some(b)) => auto_camera(b, settings.width, settings.height)
            .ok_or_else(|| Error::new(path, "the scene has no [camera] and no shapes to frame"))?,
        (None, None) => return Err(Error::new(path, "internal: no camera")),
    };
    scene.check().map_err(|e| Error::new(path, e))?;
    Ok(LoadedScene { scene, settings, frame, warnings: Vec::new() })
}

fn render_settings(cx: &Ctx, r: Option<&RenderDef>) -> Result<SceneSettings, Error> {
    let mut s = SceneSettings::default();
    let Some(r) = r else { return Ok(s) };
    s.width = cx.int(&r.width, 1, 65536, "width", s.width as i64)? as u32;
    s.height = cx.int(&r.height, 1, 65536, "height", s.height as i64)? as u32;
    s.spp = cx.int(&r.spp, 1, 1 << 20, "spp", s.spp as i64)? as u32;
    s.seed = r.seed.unwrap_or(0);
    if let Some(i) = &r.integrator {
        s.integrator = i.get_ref().parse().map_err(|e: String| cx.err(i.span(), e))?;
    }
    if r.max_depth.is_some() {
        s.max_depth = Some(cx.int(&r.max_depth, 0, 100_000, "max_depth", 0)? as u32);
    }
    s.min_attenuation = cx.num(&r.min_attenuation, 0.0, 1.0, "min_attenuation", s.min_attenuation)?;
    s.rr_depth = cx.int(&r.rr_depth, 0, 100_000, "rr_depth", s.rr_depth as i64)? as u32;
    if let Some(a) = &r.accel {
        s.accel = a.get_ref().parse().map_err(|e: String| cx.err(a.span(), e))?;
    }
    if let Some(sm) = &r.sampler {
        s.sampler = sm.get_ref().parse().map_err(|e: String| cx.err(sm.span(), e))?;
    }
    if let Some(rc) = &r.reconstruction {
        s.reconstruction = match rc.get_ref().as_str() {
            "importance" => Reconstruction::ImportanceSampled,
            "splat" => Reconstruction::Splat,
            other => {
                return Err(
                    cx.err(rc.span(), format!("unknown reconstruction '{other}' (expected importance or splat)"))
                )
            }
        };
    }
    let radius = |d: f32| cx.num(&r.filter_radius, 0.0, 16.0, "filter_radius", d);
    s.filter = match r.filter.as_ref().map(|f| (f.get_ref().as_str(), f.span())) {
        None | Some(("gaussian", _)) => {
            let radius = radius(1.5)?;
            let sigma = cx.num(&r.filter_sigma, 1e-3, 16.0, "filter_sigma", 0.5)?;
            Filter::gaussian(radius.max(1e-3), sigma)
        }
        Some((kind, span)) => {
            cx.reject(&r.filter_sigma, "filter_sigma", &format!("the {kind} filter"))?;
            match kind {
                "box" => Filter::Box { radius: radius(0.5)? },
                "tent" => Filter::Tent { radius: radius(1.0)? },
                _ => return Err(cx.err(span, format!("unknown filter '{kind}' (expected box, tent or gaussian)"))),
            }
        }
    };
    Ok(s)
}

fn camera_def(cx: &Ctx, c: &Spanned<CameraDef>) -> Result<Camera, Error> {
    let span = c.span();
    let c = c.get_ref();
    let kind = c.kind.as_ref().map_or("perspective", |k| k.get_ref().as_str());
    let eye = val(&c.eye).map_or(Vec3::new(0.0, 0.0, 5.0), |v| v.0);
    let target = val(&c.look_at).map_or(Vec3::ZERO, |v| v.0);
    let up = val(&c.up).map_or(Vec3::Y, |v| v.0);
    let fov = || cx.num(&c.fov, 0.01, 179.0, "fov", 40.0);
    let projection = match kind {
        "perspective" => {
            let what = "a perspective camera";
            cx.reject(&c.aperture, "aperture", what)?;
            cx.reject(&c.focus_distance, "focus_distance", what)?;
            cx.reject(&c.scale, "scale", what)?;
            Projection::Perspective { fov_y: fov()? }
        }
        "thinlens" => {
            cx.reject(&c.scale, "scale", "a thin-lens camera")?;
            let aperture = cx.num(&c.aperture, 0.0, f32::MAX, "aperture", 0.0)?;
            let focus = cx.num(&c.focus_distance, 1e-6, f32::MAX, "focus_distance", (target - eye).length())?;
            Projection::ThinLens { fov_y: fov()?, aperture, focus_distance: focus }
        }
        "orthographic" => {
            let what = "an orthographic camera";
            cx.reject(&c.fov, "fov", what)?;
            cx.reject(&c.aperture, "aperture", what)?;
            cx.reject(&c.focus_distance, "focus_distance", what)?;
            Projection::Orthographic { half_height: cx.num(&c.scale, 1e-9, f32::MAX, "scale", 1.0)? }
        }
        other => {
            let s = c.kind.as_ref().map_or(span.clone(), |k| k.span());
            return Err(
                cx.err(s, format!("unknown camera type '{other}' (expected perspective, thinlens or orthographic)"))
            );
        }
    };
    Camera::look_at(eye, target, up, projection)
        .ok_or_else(|| cx.err(span, "the camera's eye and look_at coincide, or its view direction is parallel to 'up'"))
}

fn material_def(cx: &Ctx, def: &Spanned<MaterialDef>) -> Result<Material, Error> {
    let m = def.get_ref();
    let kind = m.kind.get_ref().as_str();
    let what = format!("a '{kind}' material");
    let color = |f: &S<Color>, d: Rgb| val(f).map_or(d, |c| c.0);
    let roughness = |d: f32| cx.num(&m.roughness, 0.0, 1.0, "roughness", d);
    let tex = |d: Rgb| -> Result<material::Texture, Error> {
        match &m.albedo {
            None => Ok(material::Texture::Constant(d)),
            Some(t) => match t.get_ref() {
                Tex::Ready(t) => Ok(t.clone()),
                Tex::Image { file, scale } => {
                    let p = cx.path.parent().unwrap_or(Path::new(".")).join(file);
                    let img = crate::image_in::read_rgb(&p)?;
                    let image = material::ImageTexture::new(img.width, img.height, img.pixels)
                        .map_err(|e| cx.err(t.span(), format!("texture '{file}': {e}")))?;
                    Ok(material::Texture::Image { image: std::sync::Arc::new(image), scale: glam::Vec2::splat(*scale) })
                }
            },
        }
    };
    // Keys each type accepts; everything else is rejected with its position.
    let allowed: &[&str] = match kind {
        "diffuse" => &["albedo", "two_sided"],
        "glossy" | "plastic" => &["albedo", "specular", "roughness", "ior", "distribution", "two_sided"],
        "conductor" => &["metal", "eta", "k", "roughness", "distribution", "two_sided"],
        "mirror" => &["reflectance", "two_sided"],
        "dielectric" => &["ior", "transmittance", "roughness", "distribution"],
        "thindielectric" => &["ior", "transmittance"],
        "glazed" => &["ior", "base", "two_sided"],
        _ => {
            return Err(cx.err(
                m.kind.span(),
                format!(
                    "unknown material type '{kind}' (expected diffuse, glossy, plastic, conductor, mirror, \
                     dielectric, thindielectric or glazed)"
                ),
            ))
        }
    };
    let present: [(&str, Option<Range<usize>>); 12] = [
        ("distribution", m.distribution.as_ref().map(|s| s.span())),
        ("two_sided", m.two_sided.as_ref().map(|s| s.span())),
        ("albedo", m.albedo.as_ref().map(|s| s.span())),
        ("specular", m.specular.as_ref().map(|s| s.span())),
        ("roughness", m.roughness.as_ref().map(|s| s.span())),
        ("ior", m.ior.as_ref().map(|s| s.span())),
        ("metal", m.metal.as_ref().map(|s| s.span())),
        ("eta", m.eta.as_ref().map(|s| s.span())),
        ("k", m.k.as_ref().map(|s| s.span())),
        ("reflectance", m.reflectance.as_ref().map(|s| s.span())),
        ("transmittance", m.transmittance.as_ref().map(|s| s.span())),
        ("base", m.base.as_ref().map(|s| s.span())),
    ];
    for (key, span) in present {
        if let Some(span) = span {
            if !allowed.contains(&key) {
                return Err(cx.err(span, format!("'{key}' does not apply to {what}")));
            }
        }
    }
    let ior = |default: f32| -> Result<f32, Error> {
        match &m.ior {
            None => Ok(default),
            Some(s) if s.get_ref().0 >= 1.0 => Ok(s.get_ref().0),
            Some(s) => Err(cx.err(
                s.span(),
                format!(
                    "an index of refraction below 1 ({}) is not supported; put the denser medium inside",
                    s.get_ref().0
                ),
            )),
        }
    };
    let distribution = match m.distribution.as_ref().map(|d| (d.get_ref().as_str(), d.span())) {
        None | Some(("ggx", _)) => Distribution::Ggx,
        Some(("beckmann", _)) => Distribution::Beckmann,
        Some((other, span)) => {
            return Err(cx.err(span, format!("unknown microfacet distribution '{other}' (expected ggx or beckmann)")))
        }
    };
    let material = match kind {
        "diffuse" => Material::Diffuse { albedo: tex(Rgb::splat(0.8))? },
        "glossy" | "plastic" => Material::plastic(
            tex(Rgb::splat(0.5))?,
            color(&m.specular, Rgb::ONE),
            ior(1.5)?,
            roughness(if kind == "glossy" { 0.2 } else { 0.0 })?,
            distribution,
        ),
        "conductor" => {
            let (eta, k) = match (&m.metal, &m.eta, &m.k) {
                (Some(name), None, None) => material::metal(name.get_ref()).ok_or_else(|| {
                    cx.err(
                        name.span(),
                        format!("unknown metal '{}' (expected gold, silver, copper or aluminium)", name.get_ref()),
                    )
                })?,
                (None, Some(eta), Some(k)) => (eta.get_ref().0, k.get_ref().0),
                (None, None, None) => material::metal("silver").map_or((Rgb::ONE, Rgb::ZERO), |v| v),
                _ => return Err(cx.err(def.span(), "a conductor takes either 'metal' or both 'eta' and 'k'")),
            };
            Material::Conductor { eta, k, roughness: roughness(0.0)?, distribution }
        }
        "mirror" => Material::Mirror { reflectance: color(&m.reflectance, Rgb::ONE) },
        "dielectric" => Material::Dielectric {
            ior: ior(1.5)?,
            transmittance: color(&m.transmittance, Rgb::ONE),
            roughness: roughness(0.0)?,
            distribution,
        },
        "thindielectric" => {
            Material::ThinDielectric { ior: ior(1.5)?, transmittance: color(&m.transmittance, Rgb::ONE) }
        }
        _ => Material::plastic(color(&m.base, Rgb::ZERO).into(), Rgb::ONE, ior(1.5)?, 0.0, distribution),
    };
    // Opaque materials are two-sided unless `two_sided = false` (Mitsuba's default).
    Ok(match &m.two_sided {
        Some(t) if !*t.get_ref() => Material::OneSided(Box::new(material)),
        _ => material,
    })
}

fn light_def(cx: &Ctx, def: &Spanned<LightDef>) -> Result<Light, Error> {
    let l = def.get_ref();
    let kind = l.kind.get_ref().as_str();
    let what = format!("a '{kind}' light");
    let need = |v: &S<V3>, key: &str| -> Result<Vec3, Error> {
        val(v).map(|v| v.0).ok_or_else(|| cx.err(def.span(), format!("{what} needs '{key}'")))
    };
    let color = |f: &S<Color>| val(f).map_or(Rgb::ONE, |c| c.0);
    if kind != "environment" {
        cx.reject(&l.radiance, "radiance", &what)?;
        cx.reject(&l.file, "file", &what)?;
        cx.reject(&l.rotate_y, "rotate_y", &what)?;
    }
    match kind {
        "point" => {
            for (f, k) in [(&l.direction, "direction"), (&l.look_at, "look_at")] {
                cx.reject(f, k, &what)?;
            }
            cx.reject(&l.cone_angle, "cone_angle", &what)?;
            cx.reject(&l.falloff_start, "falloff_start", &what)?;
            cx.reject(&l.irradiance, "irradiance", &what)?;
            Ok(Light::Point { position: need(&l.position, "position")?, intensity: color(&l.intensity) })
        }
        "spot" => {
            cx.reject(&l.irradiance, "irradiance", &what)?;
            let position = need(&l.position, "position")?;
            let direction = match (val(&l.direction), val(&l.look_at)) {
                (Some(d), None) => d.0,
                (None, Some(t)) => t.0 - position,
                _ => return Err(cx.err(def.span(), "a spot light needs exactly one of 'direction' and 'look_at'")),
            };
            let direction =
                direction.try_normalize().ok_or_else(|| cx.err(def.span(), "the spot light's direction is zero"))?;
            let cone = cx.num(&l.cone_angle, 0.0, 180.0, "cone_angle", 30.0)?;
            let start = cx.num(&l.falloff_start, 0.0, cone, "falloff_start", (cone - 5.0).max(0.0))?;
            Ok(Light::Spot {
                position,
                direction,
                intensity: color(&l.intensity),
                cos_inner: start.to_radians().cos(),
                cos_outer: cone.to_radians().cos(),
            })
        }
        "directional" => {
            cx.reject(&l.position, "position", &what)?;
            cx.reject(&l.intensity, "intensity", &what)?;
            cx.reject(&l.look_at, "look_at", &what)?;
            cx.reject(&l.cone_angle, "cone_angle", &what)?;
            cx.reject(&l.falloff_start, "falloff_start", &what)?;
            let direction = need(&l.direction, "direction")?
                .try_normalize()
                .ok_or_else(|| cx.err(def.span(), "the light's direction is zero"))?;
            Ok(Light::Directional { direction, irradiance: color(&l.irradiance) })
        }
        "environment" => {
            for (f, k) in [(&l.position, "position"), (&l.direction, "direction"), (&l.look_at, "look_at")] {
                cx.reject(f, k, &what)?;
            }
            cx.reject(&l.intensity, "intensity", &what)?;
            cx.reject(&l.irradiance, "irradiance", &what)?;
            cx.reject(&l.cone_angle, "cone_angle", &what)?;
            cx.reject(&l.falloff_start, "falloff_start", &what)?;
            let map = match &l.file {
                None => None,
                Some(f) => {
                    let p = cx.path.parent().unwrap_or(Path::new(".")).join(f.get_ref());
                    let img = crate::image_in::read_rgb(&p)?;
                    Some(
                        EnvMap::new(img.width, img.height, img.pixels)
                            .map_err(|e| cx.err(f.span(), format!("environment image '{}': {e}", f.get_ref())))?,
                    )
                }
            };
            let angle = cx.num(&l.rotate_y, -360.0, 360.0, "rotate_y", 0.0)?;
            Ok(Light::Environment(Environment {
                scale: val(&l.radiance).map_or(Rgb::ONE, |c| c.0),
                map,
                to_world: glam::Mat3::from_rotation_y(angle.to_radians()),
            }))
        }
        _ => Err(cx.err(
            l.kind.span(),
            format!(
                "unknown light type '{kind}' (expected point, spot, directional or environment; area lights are shapes \
                 with 'emission')"
            ),
        )),
    }
}

fn transform_def(cx: &Ctx, ops: &Spanned<Vec<Spanned<TransformOp>>>) -> Result<Option<Transform>, Error> {
    let mut m = Affine3A::IDENTITY;
    for op in ops.get_ref() {
        let o = op.get_ref();
        let n = [o.translate.is_some(), o.scale.is_some(), o.rotate.is_some(), o.matrix.is_some()]
            .iter()
            .filter(|b| **b)
            .count();
        if n != 1 {
            return Err(
                cx.err(op.span(), "each transform step needs exactly one of translate, scale, rotate or matrix")
            );
        }
        let step = if let Some(t) = o.translate {
            Affine3A::from_translation(t.0)
        } else if let Some(s) = &o.scale {
            let v = match s {
                ScaleValue::Uniform(x) => Vec3::splat(*x),
                ScaleValue::Axes(a) => Vec3::from(*a),
            };
            Affine3A::from_scale(v)
        } else if let Some(r) = &o.rotate {
            let axis = r.axis.0.try_normalize().ok_or_else(|| cx.err(op.span(), "the rotation axis is zero"))?;
            Affine3A::from_quat(Quat::from_axis_angle(axis, r.angle.0.to_radians()))
        } else {
            let a = o.matrix.unwrap_or_default();
            // Row-major 4×4; the last row must be 0 0 0 1.
            if a[12] != 0.0 || a[13] != 0.0 || a[14] != 0.0 || a[15] != 1.0 {
                return Err(cx.err(op.span(), "the matrix's last row must be [0, 0, 0, 1] (affine transforms only)"));
            }
            let m4 = glam::Mat4::from_cols_array(&a).transpose();
            Affine3A::from_mat4(m4)
        };
        m = step * m;
    }
    match Transform::try_new(m) {
        Some(t) if t.is_identity() => Ok(None),
        Some(t) => Ok(Some(t)),
        None => Err(cx.err(ops.span(), "the transform is singular (a zero scale?) or not finite")),
    }
}

fn shape_def(
    cx: &Ctx,
    def: &Spanned<ShapeDef>,
    base_dir: &Path,
    material_ids: &HashMap<&str, usize>,
    geometries: &mut Vec<Geometry>,
    mesh_cache: &mut HashMap<(PathBuf, bool), usize>,
) -> Result<Object, Error> {
    let s = def.get_ref();
    let kind = s.kind.get_ref().as_str();
    let what = format!("a '{kind}' shape");
    let allowed: &[&str] = match kind {
        "sphere" => &["center", "radius"],
        "quad" => &["corner", "edge1", "edge2"],
        "box" => &["min", "max"],
        "mesh" => &["file", "smooth", "positions", "indices"],
        _ => {
            return Err(
                cx.err(s.kind.span(), format!("unknown shape type '{kind}' (expected sphere, quad, box or mesh)"))
            )
        }
    };
    let present: [(&str, Option<Range<usize>>); 10] = [
        ("center", s.center.as_ref().map(|v| v.span())),
        ("radius", s.radius.as_ref().map(|v| v.span())),
        ("corner", s.corner.as_ref().map(|v| v.span())),
        ("edge1", s.edge1.as_ref().map(|v| v.span())),
        ("edge2", s.edge2.as_ref().map(|v| v.span())),
        ("min", s.min.as_ref().map(|v| v.span())),
        ("max", s.max.as_ref().map(|v| v.span())),
        ("file", s.file.as_ref().map(|v| v.span())),
        ("smooth", s.smooth.as_ref().map(|v| v.span())),
        ("positions", s.positions.as_ref().map(|v| v.span())),
    ];
    for (key, span) in present.into_iter().chain([("indices", s.indices.as_ref().map(|v| v.span()))]) {
        if let Some(span) = span {
            if !allowed.contains(&key) {
                return Err(cx.err(span, format!("'{key}' does not apply to {what}")));
            }
        }
    }
    let need = |v: &S<V3>, key: &str| -> Result<Vec3, Error> {
        val(v).map(|v| v.0).ok_or_else(|| cx.err(def.span(), format!("{what} needs '{key}'")))
    };
    let mut push = |g: Geometry| {
        geometries.push(g);
        geometries.len() - 1
    };
    let geometry = match kind {
        "sphere" => {
            let radius = cx.num(&s.radius, 1e-30, f32::MAX, "radius", 1.0)?;
            push(Geometry::Sphere(Sphere { center: val(&s.center).map_or(Vec3::ZERO, |v| v.0), radius }))
        }
        "quad" => {
            let (c, e1, e2) = (need(&s.corner, "corner")?, need(&s.edge1, "edge1")?, need(&s.edge2, "edge2")?);
            if e1.cross(e2).length_squared() == 0.0 {
                return Err(cx.err(def.span(), "the quad's edges are parallel or zero"));
            }
            push(Geometry::Mesh(Mesh::quad(c, e1, e2)))
        }
        "box" => {
            let (a, b) = (need(&s.min, "min")?, need(&s.max, "max")?);
            if !a.cmplt(b).all() {
                return Err(cx.err(def.span(), "a box needs min < max on every axis"));
            }
            push(Geometry::Mesh(Mesh::cuboid(a, b)))
        }
        _ => {
            let smooth = val(&s.smooth).unwrap_or(true);
            match (&s.file, &s.positions, &s.indices) {
                (Some(f), None, None) => {
                    let p = base_dir.join(f.get_ref());
                    let key = (p.clone(), smooth);
                    if let Some(&g) = mesh_cache.get(&key) {
                        g
                    } else {
                        let mut mesh = crate::read_mesh(&p)
                            .map_err(|e| cx.err(f.span(), format!("cannot load mesh '{}': {e}", f.get_ref())))?;
                        if !smooth {
                            mesh.normals = None;
                        }
                        let g = push(Geometry::Mesh(mesh));
                        mesh_cache.insert(key, g);
                        g
                    }
                }
                (None, Some(pos), Some(idx)) => {
                    let mut mesh = Mesh {
                        positions: pos.get_ref().iter().map(|v| v.0).collect(),
                        normals: None,
                        uvs: None,
                        indices: Vec::with_capacity(idx.get_ref().len()),
                    };
                    for t in idx.get_ref() {
                        if t.iter().any(|&i| i < 0 || i >= mesh.positions.len() as i64) {
                            return Err(cx.err(
                                idx.span(),
                                format!("index triple {t:?} is out of range ({} positions)", mesh.positions.len()),
                            ));
                        }
                        mesh.indices.push(t.map(|i| i as u32));
                    }
                    mesh.validate().map_err(|e| cx.err(def.span(), e.to_string()))?;
                    push(Geometry::Mesh(mesh))
                }
                _ => return Err(cx.err(def.span(), "a mesh needs either 'file' or both 'positions' and 'indices'")),
            }
        }
    };
    let material = match &s.material {
        None => 0,
        Some(m) => *material_ids
            .get(m.get_ref().as_str())
            .ok_or_else(|| cx.err(m.span(), format!("no material named '{}' in [materials]", m.get_ref())))?,
    };
    let transform = match &s.transform {
        Some(t) => transform_def(cx, t)?,
        None => None,
    };
    let emission = val(&s.emission).map_or(Rgb::ZERO, |c| c.0);
    let light_samples = cx.int(&s.light_samples, 1, 4096, "light_samples", 8)? as u32;
    if emission == Rgb::ZERO {
        cx.reject(&s.light_samples, "light_samples", "a shape without 'emission'")?;
    }
    if emission != Rgb::ZERO && kind == "sphere" {
        if let Some(t) = &transform {
            if t.uniform_scale().is_none() {
                return Err(cx.err(def.span(), "an emissive sphere may only be scaled uniformly"));
            }
        }
    }
    Ok(Object { geometry, transform, material, emission, light_samples })
}

/// The copies an `array` makes of `object`: each an instance of the same geometry, translated
/// by `step · (i, j, k)` after the object's own transform.
fn array_copies(cx: &Ctx, object: &Object, a: &Spanned<ArrayDef>) -> Result<Vec<Object>, Error> {
    let ArrayDef { count, step } = a.get_ref();
    let total = count.iter().map(|&c| c as u64).product::<u64>();
    if total == 0 || total > MAX_ARRAY {
        return Err(cx.err(a.span(), format!("an array makes between 1 and {MAX_ARRAY} copies, not {total}")));
    }
    let base = object.transform.map_or(Affine3A::IDENTITY, |t| t.m);
    let mut out = Vec::with_capacity(total as usize);
    for k in 0..count[2] {
        for j in 0..count[1] {
            for i in 0..count[0] {
                let offset = step.0 * Vec3::new(i as f32, j as f32, k as f32);
                let t = Transform::try_new(Affine3A::from_translation(offset) * base)
                    .ok_or_else(|| cx.err(a.span(), "an array copy's transform is not finite"))?;
                out.push(Object { transform: (!t.is_identity()).then_some(t), ..object.clone() });
            }
        }
    }
    Ok(out)
}

/// A camera looking at the box `b` from the front, a little from above and the right.
pub fn auto_camera(b: Aabb, width: u32, height: u32) -> Option<Camera> {
    if b.is_empty() {
        return None;
    }
    let c = b.center();
    let r = (b.extent().length() * 0.5).max(1e-6);
    let fov = 40.0f32;
    let aspect = width as f32 / height.max(1) as f32;
    // Distance at which a sphere of radius r fits the narrower field of view.
    let half = (fov.to_radians() * 0.5).tan().atan();
    let half_min = if aspect < 1.0 { (half.tan() * aspect).atan() } else { half };
    let dist = 1.05 * r / half_min.sin();
    let eye = c + Vec3::new(0.3, 0.4, 1.0).normalize() * dist;
    Camera::look_at(eye, c, Vec3::Y, Projection::Perspective { fov_y: fov })
}

/// A scene around a bare mesh: the mesh in a glossy clay material on a floor, lit by a large
/// soft area light above and a dim fill light, framed by [`auto_camera`].
pub fn from_mesh(path: &Path) -> Result<LoadedScene, Error> {
    let clay = Material::plastic(Rgb::new(0.72, 0.66, 0.58).into(), Rgb::splat(0.5), 1.5, 0.25, Distribution::Ggx);
    let (parts, warnings) = mesh_parts(path, &clay)?;
    let b = parts.iter().fold(Aabb::EMPTY, |b, (m, _, _)| b.union(m.aabb()));
    let (c, r) = (b.center(), (b.extent().length() * 0.5).max(1e-6));
    let settings = SceneSettings::default();
    let mut materials =
        vec![Material::Diffuse { albedo: Rgb::splat(0.5).into() }, Material::Diffuse { albedo: Rgb::ZERO.into() }];
    let floor_y = b.min.y;
    let s = 8.0 * r;
    let light_size = 1.5 * r;
    let light_y = c.y + 3.0 * r;
    let light_corner = Vec3::new(c.x - light_size / 2.0 + r, light_y, c.z - light_size / 2.0 + r);
    let mut geometries = vec![
        Geometry::Mesh(Mesh::quad(
            Vec3::new(c.x - s, floor_y, c.z + s),
            Vec3::new(2.0 * s, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -2.0 * s),
        )),
        // Facing down: edge1 × edge2 = -y.
        Geometry::Mesh(Mesh::quad(light_corner, Vec3::new(0.0, 0.0, light_size), Vec3::new(light_size, 0.0, 0.0))),
    ];
    // Radiance chosen so the light delivers an irradiance of about 3 at the mesh's centre.
    let dist2 = (light_y - c.y).powi(2) + 2.0 * r * r;
    let emission = Rgb::splat(3.0 * dist2 / (light_size * light_size));
    let mut objects = vec![
        Object { geometry: 0, transform: None, material: 0, emission: Rgb::ZERO, light_samples: 1 },
        Object { geometry: 1, transform: None, material: 1, emission, light_samples: 16 },
    ];
    for (mesh, material, emission) in parts {
        objects.push(Object {
            geometry: geometries.len(),
            transform: None,
            material: materials.len(),
            emission,
            light_samples: 1,
        });
        geometries.push(Geometry::Mesh(mesh));
        materials.push(material);
    }
    let mut scene = Scene {
        geometries,
        objects,
        materials,
        lights: vec![Light::Directional {
            direction: Vec3::new(0.4, -0.5, -1.0).normalize(),
            irradiance: Rgb::splat(0.4),
        }],
        camera: Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, Projection::Perspective { fov_y: 40.0 })
            .ok_or_else(|| Error::new(path, "internal: default camera"))?,
        background: Rgb::new(0.2, 0.22, 0.25),
        ambient: Rgb::splat(0.08),
        light_selection: Default::default(),
    };
    // Frame the mesh itself, not the floor.
    scene.camera = auto_camera(b, settings.width, settings.height)
        .ok_or_else(|| Error::new(path, "the mesh has no extent to frame"))?;
    Ok(LoadedScene { scene, settings, frame: Some(b), warnings })
}

/// A mesh with its material and emission.
type MeshPart = (Mesh, Material, Rgb);

/// The parts of a bare mesh file with their materials and emission: for an OBJ that assigns
/// materials (`usemtl`, with `mtllib`), one part per material, from the MTL file; otherwise the
/// whole mesh in `default`.
fn mesh_parts(path: &Path, default: &Material) -> Result<(Vec<MeshPart>, Vec<String>), Error> {
    let is_obj = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    if is_obj {
        let obj = crate::obj::read_groups(path)?;
        if obj.has_materials() && !obj.libraries.is_empty() {
            let mut warnings = Vec::new();
            let mut library = Vec::new();
            for (f, line) in &obj.libraries {
                let p = path.parent().unwrap_or(Path::new(".")).join(f);
                match crate::mtl::read(&p) {
                    Ok((m, w)) => {
                        library.extend(m);
                        warnings.extend(w);
                    }
                    Err(e) => warnings
                        .push(format!("{}:{line}: mtllib not read ({e}); using the default material", path.display())),
                }
            }
            let mut parts = Vec::new();
            let mut add = |mut mesh: Mesh, material: Material, emission: Rgb| -> Result<(), Error> {
                mesh.drop_degenerate_indices();
                mesh.validate().map_err(|e| Error::new(path, e.to_string()))?;
                if !mesh.indices.is_empty() {
                    parts.push((mesh, material, emission));
                }
                Ok(())
            };
            for (i, name) in obj.materials.iter().enumerate() {
                match library.iter().find(|m| &m.name == name) {
                    Some(m) => add(obj.mesh(Some(i)), m.material.clone(), m.emission)?,
                    None => {
                        warnings.push(format!(
                            "{}: material '{name}' is not in any mtllib; using the default",
                            path.display()
                        ));
                        add(obj.mesh(Some(i)), default.clone(), Rgb::ZERO)?;
                    }
                }
            }
            add(obj.mesh(Some(usize::MAX)), default.clone(), Rgb::ZERO)?;
            if parts.is_empty() {
                return Err(Error::new(path, "the mesh has no triangles"));
            }
            return Ok((parts, warnings));
        }
    }
    Ok((vec![(crate::read_mesh(path)?, default.clone(), Rgb::ZERO)], Vec::new()))
}
