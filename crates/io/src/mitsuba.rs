//! Mitsuba 3 XML scenes (`<scene version="3.x">`), mapped to Snell's scene.
//!
//! What is read: `<default>` and `$name` substitution (with `-D name=value` from the command
//! line taking precedence), `<include>` (relative to the including file, cycles rejected),
//! `id`s and `<ref>`; transforms (`translate`, `rotate`, `scale`, `matrix`, `lookat`), each
//! applied after the ones before it, as Mitsuba composes them; shapes `obj`, `ply`,
//! `serialized` (with `shape_index`), `sphere`,
//! `rectangle`, `cube`, `disk`, `cylinder`, `shapegroup` + `instance`, with `face_normals` and
//! `flip_normals`; BSDFs `diffuse`, `dielectric`, `thindielectric`, `roughdielectric`,
//! `conductor`, `roughconductor`, `plastic`, `roughplastic`, `twosided`; the `checkerboard`
//! and `bitmap` textures; named indices of refraction and metals; `rgb` and `spectrum` values; emitters
//! `area`, `point`, `spot`, `directional`, `constant`, `envmap`; the `perspective` and `thinlens` sensors,
//! `hdrfilm` and its `rfilter`, the sampler's `sample_count` and `seed`; integrators `path` and
//! `direct`. Units and defaults are Mitsuba's.
//!
//! Everything else is reported, with file, line and column, in [`LoadedScene::warnings`], and
//! loading continues where the result still means something. Malformed XML, missing files,
//! unknown references and include cycles are errors.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Mat3, Mat4, Vec2, Vec3};
use quick_xml::events::{BytesStart, Event};
use quick_xml::reader::Reader;

use snell_core::camera::{Camera, Projection};
use snell_core::filter::Filter;
use snell_core::integrator::IntegratorKind;
use snell_core::light::{EnvMap, Environment, Light};
use snell_core::material::microfacet::Distribution;
use snell_core::material::{self, Material, Texture};
use snell_core::render::Reconstruction;
use snell_core::sampling::SamplerKind;
use snell_core::scene::{Geometry, LightSelection, Object, Scene};
use snell_core::shape::{Mesh, Sphere};
use snell_core::Rgb;

use crate::scene::{LoadedScene, SceneSettings};
use crate::{shapes, spectrum};
use crate::{Error, Location};

/// One XML element, with where it came from.
#[derive(Clone, Debug)]
struct Node {
    tag: String,
    attrs: Vec<(String, String)>,
    children: Vec<Node>,
    file: usize,
    pos: usize,
}

impl Node {
    fn attr(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// The child property element named `name` (`<float name="...">` and the like).
    fn prop(&self, name: &str) -> Option<&Node> {
        self.children.iter().find(|c| c.attr("name") == Some(name))
    }
}

/// The source files, for positions in messages.
struct Files {
    paths: Vec<PathBuf>,
    texts: Vec<String>,
}

impl Files {
    fn location(&self, file: usize, pos: usize) -> Location {
        let text = &self.texts[file];
        let pos = pos.min(text.len());
        let before = &text.as_bytes()[..pos];
        let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
        let col = pos - before.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1) + 1;
        Location::LineCol(line, col)
    }

    fn err(&self, n: &Node, msg: impl Into<String>) -> Error {
        Error::at(&self.paths[n.file], self.location(n.file, n.pos), msg)
    }

    fn note(&self, n: &Node, msg: impl AsRef<str>) -> String {
        let e = self.err(n, msg.as_ref());
        e.to_string()
    }
}

/// Reads a file into an element tree (the root element).
fn parse_xml(files: &mut Files, path: &Path) -> Result<Node, Error> {
    let text = crate::read_text(path)?;
    let file = files.paths.len();
    files.paths.push(path.to_path_buf());
    files.texts.push(text);
    let text = &files.texts[file];
    let mut reader = Reader::from_str(text);
    let mut stack: Vec<Node> = Vec::new();
    let mut root: Option<Node> = None;
    let start = |e: &BytesStart, pos: usize| -> Result<Node, String> {
        let tag = String::from_utf8_lossy(e.name().as_ref()).into_owned();
        let mut attrs = Vec::new();
        for a in e.attributes() {
            let a = a.map_err(|e| format!("malformed attribute: {e}"))?;
            let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
            let value = a.unescape_value().map_err(|e| format!("malformed attribute value: {e}"))?.into_owned();
            attrs.push((key, value));
        }
        Ok(Node { tag, attrs, children: Vec::new(), file, pos })
    };
    loop {
        let pos = reader.buffer_position() as usize;
        let ev = reader.read_event().map_err(|e| {
            Error::at(path, files.location(file, reader.error_position() as usize), format!("malformed XML: {e}"))
        })?;
        let here = |m: String| Error::at(path, files.location(file, pos), m);
        match ev {
            Event::Start(e) => stack.push(start(&e, pos).map_err(here)?),
            Event::Empty(e) => {
                let n = start(&e, pos).map_err(here)?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(n),
                    None if root.is_none() => root = Some(n),
                    None => return Err(here("more than one root element".into())),
                }
            }
            Event::End(_) => {
                let Some(n) = stack.pop() else { return Err(here("unexpected closing tag".into())) };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(n),
                    None if root.is_none() => root = Some(n),
                    None => return Err(here("more than one root element".into())),
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if let Some(open) = stack.last() {
        return Err(files.err(open, format!("<{}> is not closed before the end of the file", open.tag)));
    }
    root.ok_or_else(|| Error::new(path, "no XML element in the file"))
}

/// Substitutes `$name` in every attribute value of `n` and its children.
fn substitute(files: &Files, n: &mut Node, defs: &HashMap<String, String>) -> Result<(), Error> {
    let (file, pos) = (n.file, n.pos);
    for (_, v) in n.attrs.iter_mut() {
        if !v.contains('$') {
            continue;
        }
        let mut out = String::new();
        let mut rest = v.as_str();
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let name: String = rest[i + 1..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            if name.is_empty() {
                out.push('$');
                rest = &rest[i + 1..];
                continue;
            }
            let value = defs.get(&name).ok_or_else(|| {
                Error::at(
                    &files.paths[file],
                    files.location(file, pos),
                    format!("'${name}' has no value: no <default name=\"{name}\"> and no -D {name}=..."),
                )
            })?;
            out.push_str(value);
            rest = &rest[i + 1 + name.len()..];
        }
        out.push_str(rest);
        *v = out;
    }
    for c in n.children.iter_mut() {
        substitute(files, c, defs)?;
    }
    Ok(())
}

/// The scene's top-level elements in order, with includes expanded and defaults applied.
fn flatten(
    files: &mut Files,
    root: Node,
    defs: &mut HashMap<String, String>,
    chain: &mut Vec<PathBuf>,
    out: &mut Vec<Node>,
) -> Result<(), Error> {
    if root.tag != "scene" {
        return Err(
            files.err(&root, format!("the root element is <{}>; a Mitsuba scene starts with <scene>", root.tag))
        );
    }
    if let Some(v) = root.attr("version") {
        if !v.starts_with('3') && !v.starts_with('2') {
            return Err(
                files.err(&root, format!("scene version {v}: only Mitsuba 3 scenes (version=\"3.x\") are read"))
            );
        }
    }
    for mut c in root.children {
        if c.tag == "default" {
            let (Some(name), Some(value)) = (c.attr("name"), c.attr("value")) else {
                return Err(files.err(&c, "<default> needs 'name' and 'value'"));
            };
            defs.entry(name.to_string()).or_insert_with(|| value.to_string());
            continue;
        }
        substitute(files, &mut c, defs)?;
        if c.tag == "include" {
            let Some(f) = c.attr("filename") else { return Err(files.err(&c, "<include> needs 'filename'")) };
            let base = files.paths[c.file].parent().unwrap_or(Path::new(".")).to_path_buf();
            let path = base.join(f);
            let canon = path.canonicalize().map_err(|e| {
                let mut err = files.err(&c, format!("cannot include '{}': ", path.display()));
                err.message.push_str(&Error::io(&path, e).message);
                err
            })?;
            if chain.contains(&canon) {
                return Err(files.err(&c, format!("include cycle: '{}' includes itself", path.display())));
            }
            let sub = parse_xml(files, &path)?;
            chain.push(canon);
            flatten(files, sub, defs, chain, out)?;
            chain.pop();
            continue;
        }
        out.push(c);
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Values

/// Mitsuba's table of named indices of refraction (its documentation's values).
const IORS: [(&str, f32); 23] = [
    ("vacuum", 1.0),
    ("helium", 1.00004),
    ("hydrogen", 1.00013),
    ("air", 1.00028),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

fn numbers(s: &str) -> Option<Vec<f32>> {
    s.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).map(|t| t.parse().ok()).collect()
}

/// What a converted scene is made of, and what it could not map.
struct Ctx {
    files: Files,
    main_dir: PathBuf,
    warnings: Vec<String>,
    ids: HashMap<String, Node>,
    materials: Vec<Material>,
    material_of: HashMap<String, usize>,
    geometries: Vec<Geometry>,
    objects: Vec<Object>,
    lights: Vec<Light>,
    groups: HashMap<String, Vec<GroupShape>>,
    background: Rgb,
}

/// A shape inside a `shapegroup`, ready to be instanced.
#[derive(Clone)]
struct GroupShape {
    geometry: usize,
    transform: Option<Affine3A>,
    material: usize,
    emission: Rgb,
}

impl Ctx {
    fn warn(&mut self, n: &Node, msg: impl AsRef<str>) {
        let s = self.files.note(n, msg);
        self.warnings.push(s);
    }

    fn float(&self, n: &Node, name: &str, default: f32) -> Result<f32, Error> {
        let Some(p) = n.prop(name) else { return Ok(default) };
        let v = p.attr("value").ok_or_else(|| self.files.err(p, format!("'{name}' has no value")))?;
        match p.tag.as_str() {
            "float" | "integer" => v
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| self.files.err(p, format!("'{name}': '{v}' is not a number"))),
            other => Err(self.files.err(p, format!("'{name}' should be a <float>, not <{other}>"))),
        }
    }

    fn int(&self, n: &Node, name: &str, default: i64) -> Result<i64, Error> {
        let Some(p) = n.prop(name) else { return Ok(default) };
        let v = p.attr("value").unwrap_or("");
        v.trim().parse::<i64>().map_err(|_| self.files.err(p, format!("'{name}': '{v}' is not an integer")))
    }

    fn boolean(&self, n: &Node, name: &str, default: bool) -> Result<bool, Error> {
        let Some(p) = n.prop(name) else { return Ok(default) };
        match p.attr("value").unwrap_or("") {
            "true" => Ok(true),
            "false" => Ok(false),
            v => Err(self.files.err(p, format!("'{name}': '{v}' is not true or false"))),
        }
    }

    fn string<'a>(&self, n: &'a Node, name: &str) -> Option<&'a str> {
        n.prop(name).and_then(|p| p.attr("value"))
    }

    /// A point or vector property: `x`, `y`, `z` attributes or `value="x, y, z"`.
    fn vec3(&self, n: &Node, name: &str, default: Vec3) -> Result<Vec3, Error> {
        let Some(p) = n.prop(name) else { return Ok(default) };
        self.xyz(p, default)
    }

    fn xyz(&self, p: &Node, default: Vec3) -> Result<Vec3, Error> {
        if let Some(v) = p.attr("value") {
            return match numbers(v).as_deref() {
                Some([x, y, z]) => Ok(Vec3::new(*x, *y, *z)),
                Some([a]) => Ok(Vec3::splat(*a)),
                _ => Err(self.files.err(p, format!("'{v}' is not three numbers"))),
            };
        }
        let mut out = default;
        for (i, k) in ["x", "y", "z"].iter().enumerate() {
            if let Some(v) = p.attr(k) {
                out[i] = v.trim().parse().map_err(|_| self.files.err(p, format!("{k}='{v}' is not a number")))?;
            }
        }
        Ok(out)
    }

    /// A colour: `<rgb>`, `<spectrum>` (uniform value, `λ:value` pairs or a file), a number, or
    /// a texture (see [`Ctx::texture`]; here its mean).
    fn color(&mut self, n: &Node, name: &str, default: Rgb) -> Result<Rgb, Error> {
        Ok(self.texture(n, name, default)?.mean())
    }

    fn texture(&mut self, n: &Node, name: &str, default: Rgb) -> Result<Texture, Error> {
        let Some(p) = n.prop(name) else { return Ok(Texture::Constant(default)) };
        let p = p.clone();
        let p = if p.tag == "ref" { self.lookup(&p)? } else { p };
        let value = p.attr("value").unwrap_or("");
        let c = match p.tag.as_str() {
            "rgb" => match numbers(value).as_deref() {
                Some([r, g, b]) => Rgb::new(*r, *g, *b),
                Some([v]) => Rgb::splat(*v),
                _ => return Err(self.files.err(&p, format!("<rgb> '{value}' is not one or three numbers"))),
            },
            "float" => Rgb::splat(value.trim().parse().map_err(|_| self.files.err(&p, "not a number"))?),
            "spectrum" => self.spectrum(&p)?,
            "texture" => return self.texture_node(&p),
            other => return Err(self.files.err(&p, format!("'{name}' should be a colour, not <{other}>"))),
        };
        if !c.is_finite() || c.min_element() < 0.0 {
            return Err(self.files.err(&p, format!("'{name}' must be finite and not negative")));
        }
        Ok(Texture::Constant(c))
    }

    fn texture_node(&mut self, p: &Node) -> Result<Texture, Error> {
        match p.attr("type").unwrap_or("") {
            "checkerboard" => {
                let a = self.color(p, "color0", Rgb::splat(0.4))?;
                let b = self.color(p, "color1", Rgb::splat(0.2))?;
                // Two squares per unit of u and of v, scaled by a `to_uv` scale.
                let mut scale = 2.0;
                if let Some(t) = p.prop("to_uv") {
                    let m = self.transform(t)?;
                    let s = m.matrix3.x_axis.x;
                    if (m.matrix3.y_axis.y - s).abs() > 1e-6 * s.abs() || m.translation != glam::Vec3A::ZERO {
                        self.warn(t, "checkerboard 'to_uv': only a uniform scale is used");
                    }
                    scale *= s;
                }
                Ok(Texture::Checker { a, b, scale })
            }
            "bitmap" => {
                let f = self.string(p, "filename").ok_or_else(|| self.files.err(p, "bitmap needs 'filename'"))?;
                let path = self.resolve(p, f)?;
                let img = crate::image_in::read_rgb(&path)?;
                let image = material::ImageTexture::new(img.width, img.height, img.pixels)
                    .map_err(|e| self.files.err(p, format!("bitmap '{f}': {e}")))?;
                let mut scale = Vec2::ONE;
                if let Some(t) = p.prop("to_uv") {
                    let m = self.transform(t)?;
                    scale = Vec2::new(m.matrix3.x_axis.x, m.matrix3.y_axis.y);
                    if m.translation != glam::Vec3A::ZERO || m.matrix3.x_axis.y != 0.0 || m.matrix3.y_axis.x != 0.0 {
                        self.warn(t, "bitmap 'to_uv': only the scale is used");
                    }
                }
                if self.boolean(p, "raw", false)? {
                    self.warn(p, "'raw' is ignored: 8-bit images are always decoded from sRGB");
                }
                Ok(Texture::Image { image: std::sync::Arc::new(image), scale })
            }
            other => {
                self.warn(p, format!("texture type '{other}' is not supported yet; using grey 0.5"));
                Ok(Texture::Constant(Rgb::splat(0.5)))
            }
        }
    }

    /// A spectrum to RGB through the CIE 1931 observer, normalised as Mitsuba's RGB variants
    /// do (see [`crate::spectrum`]): emitted quantities (`radiance`, `irradiance`,
    /// `intensity`) as absolute colours, everything else white-balanced. A `blackbody` spectrum
    /// (which Mitsuba's RGB variants refuse) gives Planck's radiance in W/(m² sr nm).
    fn spectrum(&mut self, p: &Node) -> Result<Rgb, Error> {
        let kind = match p.attr("name") {
            Some("radiance" | "irradiance" | "intensity") => spectrum::Kind::Emission,
            _ => spectrum::Kind::Reflectance,
        };
        if p.attr("type") == Some("blackbody") {
            let t = self.float(p, "temperature", f32::NAN)?;
            let scale = self.float(p, "scale", 1.0)?;
            let c = spectrum::blackbody(t)
                .ok_or_else(|| self.files.err(p, "a blackbody needs a positive 'temperature' in kelvin"))?;
            self.warn(p, format!("blackbody at {t} K converted to RGB {c} (Mitsuba's spectral units)"));
            return Ok(c * scale);
        }
        let pairs: Vec<(f32, f32)> = if let Some(f) = p.attr("filename") {
            let path = self.resolve(p, f)?;
            let text = crate::read_text(&path)?;
            let mut v = Vec::new();
            for (i, line) in text.lines().enumerate() {
                let t = line.trim();
                if t.is_empty() || t.starts_with('#') {
                    continue;
                }
                match numbers(t).as_deref() {
                    Some([l, x]) => v.push((*l, *x)),
                    _ => return Err(Error::at(&path, Location::Line(i + 1), "expected 'wavelength value'")),
                }
            }
            v
        } else {
            let value = p.attr("value").unwrap_or("");
            if let Ok(x) = value.trim().parse::<f32>() {
                return Ok(Rgb::splat(x));
            }
            let mut v = Vec::new();
            for item in value.split(',') {
                let mut it = item.split(':');
                match (it.next().and_then(|a| a.trim().parse().ok()), it.next().and_then(|b| b.trim().parse().ok())) {
                    (Some(l), Some(x)) => v.push((l, x)),
                    _ => return Err(self.files.err(p, format!("spectrum '{value}': expected 'λ:value' pairs"))),
                }
            }
            v
        };
        let c = spectrum::to_rgb(&pairs, kind)
            .ok_or_else(|| self.files.err(p, "the spectrum needs wavelengths in increasing order"))?;
        self.warn(p, "spectrum converted to RGB through the CIE 1931 observer (rendered in RGB)");
        Ok(c)
    }

    fn resolve(&self, n: &Node, f: &str) -> Result<PathBuf, Error> {
        let including = self.files.paths[n.file].parent().unwrap_or(Path::new(".")).to_path_buf();
        for base in [&self.main_dir, &including] {
            let p = base.join(f);
            if p.exists() {
                return Ok(p);
            }
        }
        // The including file's folder is named only where it is not the main file's.
        let looked = if including == self.main_dir {
            self.main_dir.display().to_string()
        } else {
            format!("{} and {}", self.main_dir.display(), including.display())
        };
        Err(self.files.err(n, format!("file '{f}' not found (looked in {looked})")))
    }

    fn lookup(&self, r: &Node) -> Result<Node, Error> {
        let id = r.attr("id").ok_or_else(|| self.files.err(r, "<ref> needs 'id'"))?;
        self.ids.get(id).cloned().ok_or_else(|| self.files.err(r, format!("unknown reference '{id}'")))
    }

    /// A `<transform>`: its operations applied in order (each after the previous ones).
    fn transform(&self, t: &Node) -> Result<Affine3A, Error> {
        let mut m = Affine3A::IDENTITY;
        for op in &t.children {
            let step = match op.tag.as_str() {
                "translate" => Affine3A::from_translation(self.xyz(op, Vec3::ZERO)?),
                "scale" => Affine3A::from_scale(self.xyz(op, Vec3::ONE)?),
                "rotate" => {
                    let axis = self.xyz(op, Vec3::ZERO)?;
                    let angle: f32 = op
                        .attr("angle")
                        .unwrap_or("0")
                        .trim()
                        .parse()
                        .map_err(|_| self.files.err(op, "rotate: 'angle' is not a number"))?;
                    if axis.length_squared() == 0.0 {
                        return Err(self.files.err(op, "rotate needs a non-zero axis"));
                    }
                    Affine3A::from_axis_angle(axis.normalize(), angle.to_radians())
                }
                "matrix" => {
                    let v = op.attr("value").unwrap_or("");
                    let n = numbers(v).ok_or_else(|| self.files.err(op, "matrix: not numbers"))?;
                    let m4 = match n.len() {
                        16 => Mat4::from_cols_array(&n.try_into().unwrap_or([0.0; 16])).transpose(),
                        9 => Mat4::from_mat3(Mat3::from_cols_array(&n.try_into().unwrap_or([0.0; 9])).transpose()),
                        k => return Err(self.files.err(op, format!("matrix: {k} numbers, expected 16 or 9"))),
                    };
                    if m4.row(3) != glam::Vec4::new(0.0, 0.0, 0.0, 1.0) {
                        return Err(self.files.err(op, "matrix: projective matrices are not supported"));
                    }
                    Affine3A::from_mat4(m4)
                }
                "lookat" => {
                    let get = |k: &str| -> Result<Vec3, Error> {
                        let v = op.attr(k).ok_or_else(|| self.files.err(op, format!("lookat needs '{k}'")))?;
                        match numbers(v).as_deref() {
                            Some([x, y, z]) => Ok(Vec3::new(*x, *y, *z)),
                            _ => Err(self.files.err(op, format!("lookat '{k}': '{v}' is not three numbers"))),
                        }
                    };
                    let (o, target) = (get("origin")?, get("target")?);
                    let up = if op.attr("up").is_some() { get("up")? } else { Vec3::Y };
                    let dir = (target - o).normalize_or_zero();
                    let left = up.cross(dir).normalize_or_zero();
                    if dir == Vec3::ZERO || left == Vec3::ZERO {
                        return Err(self.files.err(op, "lookat: origin equals target, or up is parallel to the view"));
                    }
                    let new_up = dir.cross(left);
                    Affine3A::from_cols(left.into(), new_up.into(), dir.into(), o.into())
                }
                other => return Err(self.files.err(op, format!("unknown transform operation <{other}>"))),
            };
            m = step * m;
        }
        if !m.is_finite() {
            return Err(self.files.err(t, "the transform is not finite"));
        }
        Ok(m)
    }

    fn to_world(&self, n: &Node) -> Result<Option<Affine3A>, Error> {
        match n.children.iter().find(|c| c.tag == "transform" && c.attr("name").unwrap_or("to_world") == "to_world") {
            Some(t) => self.transform(t).map(Some),
            None => Ok(None),
        }
    }

    fn ior(&self, n: &Node, name: &str, default: f32) -> Result<f32, Error> {
        let Some(p) = n.prop(name) else { return Ok(default) };
        let v = p.attr("value").unwrap_or("");
        if p.tag == "string" {
            let key = v.trim().to_ascii_lowercase();
            return IORS
                .iter()
                .find(|(k, _)| *k == key)
                .map(|(_, x)| *x)
                .ok_or_else(|| self.files.err(p, format!("unknown index of refraction '{v}'")));
        }
        let x = self.float(n, name, default)?;
        if x <= 0.0 {
            return Err(self.files.err(p, format!("'{name}' must be positive")));
        }
        Ok(x)
    }

    fn distribution(&mut self, n: &Node) -> Result<(Distribution, f32), Error> {
        let d = match self.string(n, "distribution").unwrap_or("beckmann") {
            "beckmann" => Distribution::Beckmann,
            "ggx" => Distribution::Ggx,
            other => {
                let p = n.prop("distribution").unwrap_or(n);
                return Err(self.files.err(p, format!("unknown microfacet distribution '{other}'")));
            }
        };
        if n.prop("alpha_u").is_some() || n.prop("alpha_v").is_some() {
            self.warn(n, "anisotropic roughness (alpha_u, alpha_v) is approximated by their mean");
            let (u, v) = (self.float(n, "alpha_u", 0.1)?, self.float(n, "alpha_v", 0.1)?);
            return Ok((d, 0.5 * (u + v)));
        }
        Ok((d, self.float(n, "alpha", 0.1)?.max(0.0)))
    }

    /// Converts a `<bsdf>` to a material (cached per id).
    fn bsdf(&mut self, b: &Node) -> Result<usize, Error> {
        let b = if b.tag == "ref" { self.lookup(b)? } else { b.clone() };
        if let Some(id) = b.attr("id") {
            if let Some(&m) = self.material_of.get(id) {
                return Ok(m);
            }
        }
        let mut m = self.material(&b)?;
        // Mitsuba's opaque BSDFs reflect on the front only, unless wrapped in `twosided`.
        let opaque = matches!(
            m,
            Material::Diffuse { .. } | Material::Plastic { .. } | Material::Conductor { .. } | Material::Mirror { .. }
        );
        if opaque && b.attr("type") != Some("twosided") {
            m = Material::OneSided(Box::new(m));
        }
        let idx = self.materials.len();
        self.materials.push(m);
        if let Some(id) = b.attr("id") {
            self.material_of.insert(id.to_string(), idx);
        }
        Ok(idx)
    }

    fn material(&mut self, b: &Node) -> Result<Material, Error> {
        let kind = b.attr("type").unwrap_or("");
        let eta_of =
            |cx: &Ctx| -> Result<f32, Error> { Ok(cx.ior(b, "int_ior", 1.5046)? / cx.ior(b, "ext_ior", 1.000277)?) };
        Ok(match kind {
            "diffuse" => Material::Diffuse { albedo: self.texture(b, "reflectance", Rgb::splat(0.5))? },
            "dielectric" | "roughdielectric" | "thindielectric" => {
                let ior = eta_of(self)?;
                let transmittance = self.color(b, "specular_transmittance", Rgb::ONE)?;
                if b.prop("specular_reflectance").is_some() {
                    self.warn(b, "'specular_reflectance' of a dielectric is ignored (taken as 1)");
                }
                if kind == "thindielectric" {
                    Material::ThinDielectric { ior, transmittance }
                } else {
                    let (distribution, roughness) =
                        if kind == "roughdielectric" { self.distribution(b)? } else { (Distribution::Beckmann, 0.0) };
                    Material::Dielectric { ior, transmittance, roughness, distribution }
                }
            }
            "conductor" | "roughconductor" => {
                let (distribution, roughness) =
                    if kind == "roughconductor" { self.distribution(b)? } else { (Distribution::Beckmann, 0.0) };
                let tint = self.color(b, "specular_reflectance", Rgb::ONE)?;
                let named = self.string(b, "material").unwrap_or(if b.prop("eta").is_some() { "" } else { "none" });
                if named == "none" {
                    if roughness > 0.0 {
                        // A perfect rough mirror: the complex index of a nearly perfect conductor.
                        Material::Conductor { eta: Rgb::ZERO, k: Rgb::splat(1e4), roughness, distribution }
                    } else {
                        Material::Mirror { reflectance: tint }
                    }
                } else {
                    let (eta, k) = if named.is_empty() {
                        (self.color(b, "eta", Rgb::ZERO)?, self.color(b, "k", Rgb::ONE)?)
                    } else {
                        material::metal(named).ok_or_else(|| {
                            let p = b.prop("material").unwrap_or(b);
                            self.files.err(p, format!("unknown conductor '{named}' (known: Au, Ag, Cu, Al, none)"))
                        })?
                    };
                    if tint != Rgb::ONE {
                        self.warn(b, "'specular_reflectance' of a Fresnel conductor is ignored");
                    }
                    let ext = self.ior(b, "ext_eta", 1.0)?;
                    Material::Conductor { eta: eta / ext, k: k / ext, roughness, distribution }
                }
            }
            "plastic" | "roughplastic" => {
                let (distribution, roughness) =
                    if kind == "roughplastic" { self.distribution(b)? } else { (Distribution::Beckmann, 0.0) };
                let nonlinear = self.boolean(b, "nonlinear", false)?;
                let ior = self.ior(b, "int_ior", 1.49)? / self.ior(b, "ext_ior", 1.000277)?;
                let mut m = Material::plastic(
                    self.texture(b, "diffuse_reflectance", Rgb::splat(0.5))?,
                    self.color(b, "specular_reflectance", Rgb::ONE)?,
                    ior,
                    roughness,
                    distribution,
                );
                if let Material::Plastic { coat, .. } = &mut m {
                    coat.nonlinear = nonlinear;
                }
                m
            }
            "twosided" => match self.nested_material(b)? {
                Some(m) => m.surface().clone(),
                None => return Err(self.files.err(b, "twosided needs a nested <bsdf>")),
            },
            "mask" => {
                self.warn(b, "'mask' (opacity) is not supported: the surface is rendered opaque");
                self.nested_material(b)?.unwrap_or(Material::Diffuse { albedo: Texture::Constant(Rgb::splat(0.5)) })
            }
            other => {
                self.warn(b, format!("BSDF type '{other}' is not supported; using diffuse grey 0.5"));
                Material::Diffuse { albedo: Texture::Constant(Rgb::splat(0.5)) }
            }
        })
    }

    /// The material of the `<bsdf>` (or `<ref>` to one) nested in an adapter BSDF.
    fn nested_material(&mut self, b: &Node) -> Result<Option<Material>, Error> {
        match b.children.iter().find(|c| c.tag == "bsdf" || c.tag == "ref").cloned() {
            Some(i) => {
                let i = if i.tag == "ref" { self.lookup(&i)? } else { i };
                self.material(&i).map(Some)
            }
            None => Ok(None),
        }
    }

    /// The shape's geometry in its own space and the transform placing it.
    fn shape_geometry(&mut self, s: &Node) -> Result<Option<(Geometry, Option<Affine3A>)>, Error> {
        let kind = s.attr("type").unwrap_or("");
        let to_world = self.to_world(s)?;
        let mut mesh = match kind {
            "obj" | "ply" => {
                let f = self.string(s, "filename").ok_or_else(|| self.files.err(s, "the shape needs 'filename'"))?;
                let path = self.resolve(s, f)?;
                crate::read_mesh(&path)?
            }
            "serialized" => {
                let f = self.string(s, "filename").ok_or_else(|| self.files.err(s, "the shape needs 'filename'"))?;
                let path = self.resolve(s, f)?;
                let index = self.int(s, "shape_index", 0)?;
                let index =
                    usize::try_from(index).map_err(|_| self.files.err(s, "shape_index must not be negative"))?;
                let mut mesh = crate::serialized::read(&path, index)?;
                mesh.drop_degenerate_indices();
                mesh.validate().map_err(|e| Error::new(&path, e.to_string()))?;
                mesh
            }
            "rectangle" => Mesh::quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0)),
            "cube" => Mesh::cuboid(Vec3::splat(-1.0), Vec3::ONE),
            "disk" => {
                self.warn(s, "disk tessellated into 128 triangles");
                shapes::disk(128)
            }
            "cylinder" => {
                let (p0, p1) = (self.vec3(s, "p0", Vec3::ZERO)?, self.vec3(s, "p1", Vec3::Z)?);
                let radius = self.float(s, "radius", 1.0)?;
                if radius <= 0.0 || (p1 - p0).length_squared() == 0.0 {
                    return Err(self.files.err(s, "the cylinder needs a positive radius and p0 != p1"));
                }
                self.warn(s, "cylinder tessellated into 128 quads with smooth normals (open ends, as Mitsuba's)");
                shapes::cylinder(p0, p1, radius, 128)
            }
            "sphere" => {
                let center = self.vec3(s, "center", Vec3::ZERO)?;
                let radius = self.float(s, "radius", 1.0)?;
                if radius <= 0.0 {
                    return Err(self.files.err(s, "the sphere's radius must be positive"));
                }
                if self.boolean(s, "flip_normals", false)? {
                    self.warn(s, "flip_normals on a sphere is ignored");
                }
                return Ok(Some((Geometry::Sphere(Sphere { center, radius }), to_world)));
            }
            other => {
                self.warn(s, format!("shape type '{other}' is not supported; skipped"));
                return Ok(None);
            }
        };
        if self.boolean(s, "face_normals", false)? {
            mesh.normals = None;
        }
        if self.boolean(s, "flip_normals", false)? {
            shapes::flip(&mut mesh, true);
        }
        // Meshes are placed in world space, as Mitsuba does (instances keep their transform).
        if let Some(m) = to_world {
            shapes::bake(&mut mesh, m).ok_or_else(|| self.files.err(s, "the transform is not invertible"))?;
        }
        Ok(Some((Geometry::Mesh(mesh), None)))
    }

    /// Converts one shape: its geometry, material and area emission.
    fn shape(&mut self, s: &Node) -> Result<Option<GroupShape>, Error> {
        let Some((geometry, transform)) = self.shape_geometry(s)? else { return Ok(None) };
        let mut material = None;
        let mut emission = Rgb::ZERO;
        for c in &s.children {
            let c = if c.tag == "ref" { self.lookup(c)? } else { c.clone() };
            match c.tag.as_str() {
                "bsdf" => material = Some(self.bsdf(&c)?),
                "emitter" => {
                    if c.attr("type") != Some("area") {
                        self.warn(&c, "only 'area' emitters can be attached to shapes; ignored");
                        continue;
                    }
                    emission = self.color(&c, "radiance", Rgb::ONE)?;
                }
                _ => {}
            }
        }
        let material = match material {
            Some(m) => m,
            None => {
                // Mitsuba's default BSDF: diffuse with reflectance 0.5 (one-sided).
                let d = Material::Diffuse { albedo: Texture::Constant(Rgb::splat(0.5)) };
                self.materials.push(Material::OneSided(Box::new(d)));
                self.materials.len() - 1
            }
        };
        let g = self.geometries.len();
        self.geometries.push(geometry);
        Ok(Some(GroupShape { geometry: g, transform, material, emission }))
    }

    fn place(&mut self, s: &GroupShape, outer: Option<Affine3A>, at: &Node) -> Result<(), Error> {
        let o = shapes::object(&self.geometries, s.geometry, outer, s.transform, s.material, s.emission)
            .map_err(|e| self.files.err(at, e))?;
        self.objects.push(o);
        Ok(())
    }

    fn emitter(&mut self, e: &Node) -> Result<(), Error> {
        let to_world = self.to_world(e)?;
        let kind = e.attr("type").unwrap_or("");
        match kind {
            "point" => {
                let p = match to_world {
                    Some(m) => m.translation.into(),
                    None => self.vec3(e, "position", Vec3::ZERO)?,
                };
                let intensity = self.color(e, "intensity", Rgb::ONE)?;
                self.lights.push(Light::Point { position: p, intensity });
            }
            "spot" => {
                let m = to_world.unwrap_or(Affine3A::IDENTITY);
                let cutoff = self.float(e, "cutoff_angle", 20.0)?;
                let beam = self.float(e, "beam_width", cutoff * 0.75)?;
                self.warn(e, "spot falloff between beam_width and cutoff_angle is smooth, not Mitsuba's linear ramp");
                let intensity = self.color(e, "intensity", Rgb::ONE)?;
                self.lights.push(Light::Spot {
                    position: m.translation.into(),
                    direction: m.transform_vector3(Vec3::Z).normalize(),
                    intensity,
                    cos_inner: beam.to_radians().cos(),
                    cos_outer: cutoff.to_radians().cos(),
                });
            }
            "directional" => {
                let d = match to_world {
                    Some(m) => m.transform_vector3(Vec3::Z),
                    None => self.vec3(e, "direction", Vec3::Z)?,
                };
                if d.length_squared() == 0.0 {
                    return Err(self.files.err(e, "the direction is zero"));
                }
                let irradiance = self.color(e, "irradiance", Rgb::ONE)?;
                self.lights.push(Light::Directional { direction: d.normalize(), irradiance });
            }
            "constant" | "envmap" => {
                if self.lights.iter().any(|l| matches!(l, Light::Environment(_))) {
                    self.warn(e, "a second environment emitter is ignored");
                    return Ok(());
                }
                let to_world = shapes::rotation(to_world.unwrap_or(Affine3A::IDENTITY));
                let (scale, map) = if kind == "constant" {
                    (self.color(e, "radiance", Rgb::ONE)?, None)
                } else {
                    let f = self.string(e, "filename").ok_or_else(|| self.files.err(e, "envmap needs 'filename'"))?;
                    let path = self.resolve(e, f)?;
                    let img = crate::image_in::read_rgb(&path)?;
                    let map = EnvMap::new(img.width, img.height, img.pixels)
                        .map_err(|bad| self.files.err(e, format!("envmap '{f}': {bad}")))?;
                    (Rgb::splat(self.float(e, "scale", 1.0)?), Some(map))
                };
                self.lights.push(Light::Environment(Environment { scale, map, to_world }));
            }
            "area" => {
                if e.attr("id").is_none() {
                    self.warn(e, "an area emitter outside a shape emits nothing; ignored");
                }
            }
            other => self.warn(e, format!("emitter type '{other}' is not supported yet; ignored")),
        }
        Ok(())
    }
}

/// Loads a Mitsuba 3 scene. `defines` are `-D name=value` settings, which take precedence over
/// the file's `<default>`s.
pub fn load(path: &Path, defines: &[(String, String)]) -> Result<LoadedScene, Error> {
    let mut files = Files { paths: Vec::new(), texts: Vec::new() };
    let root = parse_xml(&mut files, path)?;
    let mut defs: HashMap<String, String> = defines.iter().cloned().collect();
    let mut top = Vec::new();
    let canon = path.canonicalize().map_err(|e| Error::io(path, e))?;
    flatten(&mut files, root, &mut defs, &mut vec![canon], &mut top)?;
    let main_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut cx = Ctx {
        files,
        main_dir,
        warnings: Vec::new(),
        ids: HashMap::new(),
        materials: Vec::new(),
        material_of: HashMap::new(),
        geometries: Vec::new(),
        objects: Vec::new(),
        lights: Vec::new(),
        groups: HashMap::new(),
        background: Rgb::ZERO,
    };
    // Named elements first, so that references may point forward.
    for n in &top {
        if let Some(id) = n.attr("id") {
            cx.ids.insert(id.to_string(), n.clone());
        }
        for c in &n.children {
            if let Some(id) = c.attr("id") {
                if matches!(c.tag.as_str(), "bsdf" | "texture" | "emitter") {
                    cx.ids.insert(id.to_string(), c.clone());
                }
            }
        }
    }
    let mut settings = SceneSettings { integrator: IntegratorKind::Path, ..SceneSettings::default() };
    settings.filter = Filter::gaussian(2.0, 0.5);
    // Mitsuba's film splats samples into every pixel their filter covers.
    settings.reconstruction = Reconstruction::Splat;
    let mut camera = None;
    let (mut width, mut height) = (768u32, 576u32);
    for n in &top {
        match n.tag.as_str() {
            "bsdf" | "texture" => {} // converted where used
            "shape" => match n.attr("type") {
                Some("shapegroup") => {
                    let Some(id) = n.attr("id") else { return Err(cx.files.err(n, "a shapegroup needs an 'id'")) };
                    let mut parts = Vec::new();
                    for c in n.children.iter().filter(|c| c.tag == "shape") {
                        if let Some(s) = cx.shape(c)? {
                            parts.push(s);
                        }
                    }
                    cx.groups.insert(id.to_string(), parts);
                }
                Some("instance") => {
                    let r = n
                        .children
                        .iter()
                        .find(|c| c.tag == "ref")
                        .ok_or_else(|| cx.files.err(n, "an instance needs a <ref> to a shapegroup"))?;
                    let id = r.attr("id").unwrap_or("");
                    let parts = cx
                        .groups
                        .get(id)
                        .cloned()
                        .ok_or_else(|| cx.files.err(r, format!("unknown shapegroup '{id}'")))?;
                    let m = cx.to_world(n)?;
                    for p in &parts {
                        cx.place(p, m, n)?;
                    }
                }
                _ => {
                    if let Some(s) = cx.shape(n)? {
                        cx.place(&s, None, n)?;
                    }
                }
            },
            "emitter" => cx.emitter(n)?,
            "sensor" => {
                let kind = n.attr("type").unwrap_or("");
                if kind != "perspective" && kind != "thinlens" {
                    cx.warn(n, format!("sensor type '{kind}' is not supported; using a perspective camera"));
                }
                if let Some(film) = n.children.iter().find(|c| c.tag == "film") {
                    width = cx.int(film, "width", 768)?.clamp(1, 65536) as u32;
                    height = cx.int(film, "height", 576)?.clamp(1, 65536) as u32;
                    if let Some(f) = film.children.iter().find(|c| c.tag == "rfilter") {
                        settings.filter = match f.attr("type").unwrap_or("") {
                            "box" => Filter::Box { radius: 0.5 },
                            "tent" => Filter::Tent { radius: cx.float(f, "radius", 1.0)? },
                            "gaussian" => {
                                let sd = cx.float(f, "stddev", 0.5)?.max(1e-3);
                                Filter::gaussian(4.0 * sd, sd)
                            }
                            other => {
                                cx.warn(f, format!("filter '{other}' is not supported; using Gaussian"));
                                Filter::gaussian(2.0, 0.5)
                            }
                        };
                    }
                }
                if let Some(s) = n.children.iter().find(|c| c.tag == "sampler") {
                    match s.attr("type").unwrap_or("independent") {
                        "independent" => settings.sampler = SamplerKind::Independent,
                        t => {
                            settings.sampler = SamplerKind::Sobol;
                            cx.warn(s, format!("sampler '{t}' is rendered with Owen-scrambled Sobol points"));
                        }
                    }
                    settings.spp = cx.int(s, "sample_count", 4)?.clamp(1, 1 << 20) as u32;
                    settings.seed = cx.int(s, "seed", 0)?.max(0) as u64;
                }
                camera = Some((n.clone(), kind == "thinlens"));
            }
            "integrator" => match n.attr("type").unwrap_or("") {
                t @ ("path" | "direct") => {
                    let d = if t == "direct" { 2 } else { cx.int(n, "max_depth", -1)? };
                    settings.max_depth = (d >= 0).then_some(d as u32);
                    settings.rr_depth = cx.int(n, "rr_depth", 5)?.max(0) as u32;
                    if t == "direct" {
                        cx.warn(n, "'direct' is rendered as path tracing with max_depth 2 (the same expectation)");
                    }
                }
                other => cx.warn(n, format!("integrator '{other}' is not supported; using path tracing")),
            },
            other => cx.warn(n, format!("<{other}> is not supported; ignored")),
        }
    }
    settings.width = width;
    settings.height = height;
    let camera = match camera {
        Some((s, thin)) => sensor_camera(&mut cx, &s, thin, width, height)?,
        None => {
            return Err(Error::new(path, "the scene has no <sensor>"));
        }
    };
    let scene = Scene {
        geometries: cx.geometries,
        objects: cx.objects,
        materials: if cx.materials.is_empty() {
            vec![Material::Diffuse { albedo: Rgb::splat(0.5).into() }]
        } else {
            cx.materials
        },
        lights: cx.lights,
        camera,
        background: cx.background,
        ambient: Rgb::ZERO,
        // Mitsuba picks emitters uniformly.
        light_selection: LightSelection::Uniform,
    };
    scene.check().map_err(|e| Error::new(path, e))?;
    Ok(LoadedScene { scene, settings, frame: None, warnings: cx.warnings })
}

fn sensor_camera(cx: &mut Ctx, s: &Node, thin: bool, width: u32, height: u32) -> Result<Camera, Error> {
    let m = cx.to_world(s)?.unwrap_or(Affine3A::IDENTITY);
    let eye: Vec3 = m.translation.into();
    let forward = m.transform_vector3(Vec3::Z);
    let up = m.transform_vector3(Vec3::Y);
    let aspect = width as f32 / height as f32;
    let fov = if let Some(fl) = cx.string(s, "focal_length") {
        let mm: f32 = fl.trim_end_matches("mm").trim().parse().map_err(|_| {
            let p = s.prop("focal_length").unwrap_or(s);
            cx.files.err(p, format!("focal_length '{fl}' is not a length like '50mm'"))
        })?;
        // Full-frame 36 mm film width.
        2.0 * (18.0 / mm).atan().to_degrees()
    } else {
        cx.float(s, "fov", 90.0)?
    };
    let axis = if s.prop("focal_length").is_some() { "x" } else { cx.string(s, "fov_axis").unwrap_or("x") };
    let axis = match axis {
        "smaller" => {
            if width < height {
                "x"
            } else {
                "y"
            }
        }
        "larger" => {
            if width > height {
                "x"
            } else {
                "y"
            }
        }
        other => other,
    };
    let t = (fov.to_radians() * 0.5).tan();
    let fov_y = match axis {
        "x" => 2.0 * (t / aspect).atan().to_degrees(),
        "y" => fov,
        "diagonal" => 2.0 * (t / (1.0 + aspect * aspect).sqrt()).atan().to_degrees(),
        other => {
            let p = s.prop("fov_axis").unwrap_or(s);
            return Err(cx.files.err(p, format!("unknown fov_axis '{other}'")));
        }
    };
    if !(fov_y > 0.0 && fov_y < 180.0) {
        return Err(cx.files.err(s, format!("field of view {fov} degrees is out of range")));
    }
    for ignored in ["near_clip", "far_clip"] {
        if let Some(p) = s.prop(ignored) {
            cx.warn(p, format!("'{ignored}' is ignored"));
        }
    }
    let projection = if thin {
        Projection::ThinLens {
            fov_y,
            aperture: cx.float(s, "aperture_radius", 0.0)?,
            focus_distance: cx.float(s, "focus_distance", 0.0)?,
        }
    } else {
        Projection::Perspective { fov_y }
    };
    // Mitsuba's camera space: +z forward, +y up, +x to the left of the image; a transform
    // that mirrors it mirrors the picture.
    Camera::with_frame(eye, -m.transform_vector3(Vec3::X), up, forward, projection)
        .ok_or_else(|| cx.files.err(s, "the sensor's transform has no valid view direction"))
}
