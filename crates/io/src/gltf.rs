//! glTF 2.0 scenes (`.gltf` with external or embedded buffers, and binary `.glb`), mapped to
//! Snell's scene. Parsing, validation and image decoding are the `gltf` crate's.
//!
//! What is mapped: the default scene's node hierarchy with its transforms (meshes used by one
//! node are placed in world space; meshes used by several are instanced); triangle primitives
//! with normals and the first UV set; the first camera met (perspective or orthographic; with
//! no camera the scene is framed automatically); metallic-roughness materials with their base
//! colour textures; emission (with `KHR_materials_emissive_strength`);
//! `KHR_materials_transmission`, `KHR_materials_ior`, `KHR_materials_volume` and
//! `KHR_materials_specular`; `KHR_lights_punctual`.
//!
//! Materials: glTF's model is a blend that Snell renders as one of its BSDFs, chosen by the
//! factors. Metals (`metallic ≥ 0.5`) become conductors reflecting the base colour at normal
//! incidence (`eta = 1`, `k = 2 √(r / (1 - r))`, as pbrt's `reflectance` conductor); transmissive
//! surfaces (`transmission ≥ 0.5`) become glass, a thin pane unless `KHR_materials_volume`
//! gives them a thickness; the rest become Snell's plastic (a Fresnel coat of index `ior` over
//! the base colour), or plain Lambert when `KHR_materials_specular` turns the coat off.
//! `alpha = roughness²`, GGX, as the glTF specification defines it. Light units are taken as
//! they are: a point light of intensity `I` candela emits `I · color` radiant intensity.
//! UVs have `v` down in glTF and are flipped to Snell's `v` up.
//!
//! Everything approximated or ignored is reported in [`LoadedScene::warnings`], naming the
//! file, the line where the element starts and the element (`materials[2] "name"`); malformed
//! files are errors, with the line and column where the JSON is wrong.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use glam::{Affine3A, Mat4, Vec2, Vec3};

use snell_core::camera::{Camera, Projection};
use snell_core::geometry::Aabb;
use snell_core::image::srgb_decode;
use snell_core::integrator::IntegratorKind;
use snell_core::light::Light;
use snell_core::material::microfacet::Distribution;
use snell_core::material::{ImageTexture, Material, Texture};
use snell_core::scene::{Geometry, LightSelection, Object, Scene};
use snell_core::shape::Mesh;
use snell_core::Rgb;

use crate::scene::{auto_camera, LoadedScene, SceneSettings};
use crate::{shapes, Error, Location};

fn gltf_error(path: &Path, e: gltf::Error) -> Error {
    match e {
        gltf::Error::Deserialize(j) => {
            Error::at(path, Location::LineCol(j.line(), j.column()), format!("malformed glTF JSON: {j}"))
        }
        gltf::Error::Io(io) => Error::io(path, io),
        gltf::Error::Validation(list) => {
            let items: Vec<String> = list.iter().take(5).map(|(p, e)| format!("{p}: {e}")).collect();
            Error::new(path, format!("invalid glTF: {}", items.join("; ")))
        }
        other => Error::new(path, format!("cannot read the glTF file: {other}")),
    }
}

struct Ctx<'a> {
    path: &'a Path,
    /// Line of each top-level array element in the JSON (`"materials[2]"`).
    lines: HashMap<String, usize>,
    buffers: &'a [gltf::buffer::Data],
    images: &'a [gltf::image::Data],
    warnings: Vec<String>,
    materials: Vec<Material>,
    emission: Vec<Rgb>,
    material_of: HashMap<Option<usize>, usize>,
    image_of: HashMap<usize, Arc<ImageTexture>>,
    geometries: Vec<Geometry>,
    /// Geometry of each (mesh, primitive) instanced more than once.
    shared: HashMap<(usize, usize), Option<usize>>,
    uses: HashMap<usize, usize>,
    objects: Vec<Object>,
    lights: Vec<Light>,
    camera: Option<(gltf::Camera<'a>, Mat4)>,
    bounds: Aabb,
}

/// The line on which each element of a top-level array starts (`"materials[2]"` → 41), read
/// from the JSON text, so that warnings can name file, line and element. (The JSON parser gives
/// positions for syntax errors only.)
fn element_lines(text: &[u8]) -> HashMap<String, usize> {
    enum C {
        Obj { key: String, expect_key: bool },
        Arr(usize),
    }
    let mut out = HashMap::new();
    let mut stack: Vec<C> = Vec::new();
    let (mut line, mut i) = (1usize, 0usize);
    let mut in_scalar = false;
    let record = |stack: &[C], out: &mut HashMap<String, usize>, line: usize| {
        if let [C::Obj { key, .. }, C::Arr(k)] = stack {
            out.entry(format!("{key}[{k}]")).or_insert(line);
        }
    };
    while i < text.len() {
        let c = text[i];
        let scalar = !matches!(c, b'"' | b'{' | b'}' | b'[' | b']' | b',' | b':') && !c.is_ascii_whitespace();
        if !scalar {
            in_scalar = false;
        }
        match c {
            b'\n' => line += 1,
            b'"' => {
                let start = i + 1;
                i += 1;
                while i < text.len() && text[i] != b'"' {
                    if text[i] == b'\\' {
                        i += 1;
                    }
                    i += 1;
                }
                let s = String::from_utf8_lossy(&text[start..i.min(text.len())]).into_owned();
                match stack.last_mut() {
                    Some(C::Obj { key, expect_key }) if *expect_key => {
                        *key = s;
                        *expect_key = false;
                    }
                    _ => record(&stack, &mut out, line),
                }
            }
            b'{' | b'[' => {
                record(&stack, &mut out, line);
                stack.push(if c == b'{' { C::Obj { key: String::new(), expect_key: true } } else { C::Arr(0) });
            }
            b'}' | b']' => {
                stack.pop();
            }
            b',' => match stack.last_mut() {
                Some(C::Arr(k)) => *k += 1,
                Some(C::Obj { expect_key, .. }) => *expect_key = true,
                None => {}
            },
            _ if scalar && !in_scalar => {
                in_scalar = true;
                record(&stack, &mut out, line);
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// The JSON text of a `.gltf`, or the JSON chunk of a `.glb`.
fn json_text(bytes: &[u8]) -> &[u8] {
    if bytes.len() >= 20 && &bytes[0..4] == b"glTF" && &bytes[16..20] == b"JSON" {
        let len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        return bytes.get(20..20 + len).unwrap_or(&[]);
    }
    bytes
}

fn element(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("{kind}[{index}] \"{n}\""),
        None => format!("{kind}[{index}]"),
    }
}

impl<'a> Ctx<'a> {
    fn warn(&mut self, what: &str, msg: impl AsRef<str>) {
        let key = what.split([' ', '.']).next().unwrap_or(what);
        let s = match self.lines.get(key) {
            Some(line) => format!("{}:{line}: {what}: {}", self.path.display(), msg.as_ref()),
            None => format!("{}: {what}: {}", self.path.display(), msg.as_ref()),
        };
        if !self.warnings.contains(&s) {
            self.warnings.push(s);
        }
    }

    /// An image as linear RGB (8- and 16-bit data decoded from sRGB when `srgb`).
    fn image(&mut self, index: usize, srgb: bool) -> Result<Arc<ImageTexture>, Error> {
        if let Some(i) = self.image_of.get(&index) {
            return Ok(i.clone());
        }
        let data =
            self.images.get(index).ok_or_else(|| Error::new(self.path, format!("images[{index}] is missing")))?;
        use gltf::image::Format as F;
        let (channels, bytes) = match data.format {
            F::R8 => (1, 1),
            F::R8G8 => (2, 1),
            F::R8G8B8 => (3, 1),
            F::R8G8B8A8 => (4, 1),
            F::R16 => (1, 2),
            F::R16G16 => (2, 2),
            F::R16G16B16 => (3, 2),
            F::R16G16B16A16 => (4, 2),
            F::R32G32B32FLOAT => (3, 4),
            F::R32G32B32A32FLOAT => (4, 4),
        };
        let value = |p: &[u8], c: usize| -> f32 {
            let o = c * bytes;
            match bytes {
                1 => p[o] as f32 / 255.0,
                2 => u16::from_le_bytes([p[o], p[o + 1]]) as f32 / 65535.0,
                _ => f32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]]),
            }
        };
        let stride = channels * bytes;
        let (w, h) = (data.width as usize, data.height as usize);
        if data.pixels.len() < w * h * stride {
            return Err(Error::new(self.path, format!("images[{index}] has fewer pixels than its size")));
        }
        let pixels = data
            .pixels
            .chunks_exact(stride)
            .take(w * h)
            .map(|p| {
                let c = match channels {
                    1 | 2 => Rgb::splat(value(p, 0)),
                    _ => Rgb::new(value(p, 0), value(p, 1), value(p, 2)),
                };
                if srgb && bytes < 4 {
                    c.map(srgb_decode)
                } else {
                    c
                }
            })
            .collect();
        let img = Arc::new(
            ImageTexture::new(w, h, pixels).map_err(|e| Error::new(self.path, format!("images[{index}]: {e}")))?,
        );
        self.image_of.insert(index, img.clone());
        Ok(img)
    }

    /// A texture reference as an image, noting what is not supported about it.
    fn texture(&mut self, info: &gltf::texture::Info, srgb: bool, what: &str) -> Result<Arc<ImageTexture>, Error> {
        if info.tex_coord() != 0 {
            self.warn(what, "only the first UV set is read; the texture uses it");
        }
        if info.texture_transform().is_some() {
            self.warn(what, "KHR_texture_transform is ignored");
        }
        let source = info.texture().source().index();
        self.image(source, srgb)
    }

    fn material(&mut self, m: &gltf::Material) -> Result<usize, Error> {
        if let Some(&i) = self.material_of.get(&m.index()) {
            return Ok(i);
        }
        let what = match m.index() {
            Some(i) => element("materials", i, m.name()),
            None => "the default material".to_string(),
        };
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let factor = Rgb::new(r, g, b);
        let base = match pbr.base_color_texture() {
            Some(info) => {
                let img = self.texture(&info, true, &what)?;
                let pixels = img.pixels.iter().map(|&c| c * factor).collect();
                let img = ImageTexture::new(img.width, img.height, pixels)
                    .map_err(|e| Error::new(self.path, format!("{what}: base colour texture: {e}")))?;
                Texture::Image { image: Arc::new(img), scale: Vec2::ONE }
            }
            None => Texture::Constant(factor),
        };
        let (mut metallic, mut roughness) = (pbr.metallic_factor(), pbr.roughness_factor());
        if let Some(info) = pbr.metallic_roughness_texture() {
            // Roughness in green, metalness in blue: their means scale the factors.
            let img = self.texture(&info, false, &what)?;
            let mean = img.mean();
            roughness *= mean.y;
            metallic *= mean.z;
            self.warn(&what, "the metallic-roughness texture is averaged (one roughness and metalness per material)");
        }
        let alpha = roughness.clamp(0.0, 1.0).powi(2);
        let ior = m.ior().unwrap_or(1.5);
        if !(ior >= 1.0 && ior.is_finite()) {
            return Err(Error::new(self.path, format!("{what}: ior {ior} must be at least 1")));
        }
        let transmission = m.transmission().map(|t| t.transmission_factor()).unwrap_or(0.0);
        if m.transmission().is_some_and(|t| t.transmission_texture().is_some()) {
            self.warn(&what, "the transmission texture is ignored");
        }
        let specular = m.specular().map(|s| (s.specular_factor(), Rgb::from(s.specular_color_factor())));
        if metallic > 0.0 && metallic < 1.0 {
            self.warn(&what, format!("metallic {metallic} is rendered as {}", if metallic >= 0.5 { 1 } else { 0 }));
        }
        if matches!(m.alpha_mode(), gltf::material::AlphaMode::Blend | gltf::material::AlphaMode::Mask) {
            self.warn(&what, "alpha blending and masking are ignored: the surface is opaque");
        }
        if m.normal_texture().is_some() || m.occlusion_texture().is_some() {
            self.warn(&what, "normal and occlusion textures are ignored");
        }
        let material = if metallic >= 0.5 {
            let r = base.mean().clamp(Rgb::ZERO, Rgb::splat(0.9999));
            if !matches!(base, Texture::Constant(_)) {
                self.warn(&what, "a metal's base colour texture is averaged");
            }
            let k = (r / (Rgb::ONE - r)).map(|x| 2.0 * x.sqrt());
            Material::Conductor { eta: Rgb::ONE, k, roughness: alpha, distribution: Distribution::Ggx }
        } else if transmission >= 0.5 {
            let tint = base.mean();
            match m.volume() {
                Some(v) if v.thickness_factor() > 0.0 => {
                    if v.attenuation_distance().is_finite() {
                        self.warn(&what, "volume attenuation is not rendered (no participating media)");
                    }
                    Material::Dielectric { ior, transmittance: tint, roughness: alpha, distribution: Distribution::Ggx }
                }
                _ => {
                    if alpha > 0.0 {
                        self.warn(&what, "a thin transmissive surface is rendered smooth");
                    }
                    Material::ThinDielectric { ior, transmittance: tint }
                }
            }
        } else {
            match specular {
                Some((0.0, _)) => Material::Diffuse { albedo: base },
                other => {
                    let (s, c) = other.unwrap_or((1.0, Rgb::ONE));
                    Material::plastic(base, c * s, ior, alpha, Distribution::Ggx)
                }
            }
        };
        let strength = m.emissive_strength().unwrap_or(1.0);
        let mut emission = Rgb::from(m.emissive_factor()) * strength;
        if let Some(info) = m.emissive_texture() {
            let img = self.texture(&info, true, &what)?;
            emission *= img.mean();
            self.warn(&what, "the emissive texture is averaged (Snell's emitters are uniform)");
        }
        let idx = self.materials.len();
        self.materials.push(material);
        self.emission.push(emission);
        self.material_of.insert(m.index(), idx);
        Ok(idx)
    }

    fn primitive_mesh(&mut self, p: &gltf::Primitive, what: &str) -> Result<Option<Mesh>, Error> {
        if p.mode() != gltf::mesh::Mode::Triangles {
            self.warn(what, format!("{:?} primitives are not rendered (triangles only)", p.mode()));
            return Ok(None);
        }
        let buffers = self.buffers;
        let reader = p.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = match reader.read_positions() {
            Some(it) => it.map(Vec3::from).collect(),
            None => return Err(Error::new(self.path, format!("{what} has no POSITION"))),
        };
        let normals = reader.read_normals().map(|it| it.map(Vec3::from).collect::<Vec<_>>());
        let uvs =
            reader.read_tex_coords(0).map(|t| t.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect::<Vec<_>>());
        let flat: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        if !flat.len().is_multiple_of(3) {
            return Err(Error::new(self.path, format!("{what}: {} indices are not whole triangles", flat.len())));
        }
        let mut m = Mesh { positions, normals, uvs, indices: flat.chunks(3).map(|c| [c[0], c[1], c[2]]).collect() };
        m.drop_degenerate_indices();
        m.validate().map_err(|e| Error::new(self.path, format!("{what}: {e}")))?;
        Ok((!m.indices.is_empty()).then_some(m))
    }

    fn node(&mut self, node: gltf::Node<'a>, parent: Mat4) -> Result<(), Error> {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        let what = element("nodes", node.index(), node.name());
        if !world.is_finite() {
            return Err(Error::new(self.path, format!("{what}: the transform is not finite")));
        }
        let affine = Affine3A::from_mat4(world);
        if let Some(mesh) = node.mesh() {
            let instanced = self.uses.get(&mesh.index()).copied().unwrap_or(0) > 1;
            for p in mesh.primitives() {
                let pwhat = format!("{} primitive {}", element("meshes", mesh.index(), mesh.name()), p.index());
                let material = self.material(&p.material())?;
                let emission = self.emission[material];
                let key = (mesh.index(), p.index());
                let (geometry, transform) = if instanced {
                    let g = match self.shared.get(&key) {
                        Some(g) => *g,
                        None => {
                            let g = match self.primitive_mesh(&p, &pwhat)? {
                                Some(m) => {
                                    self.geometries.push(Geometry::Mesh(m));
                                    Some(self.geometries.len() - 1)
                                }
                                None => None,
                            };
                            self.shared.insert(key, g);
                            g
                        }
                    };
                    let Some(g) = g else { continue };
                    (g, Some(affine))
                } else {
                    let Some(mut m) = self.primitive_mesh(&p, &pwhat)? else { continue };
                    shapes::bake(&mut m, affine)
                        .ok_or_else(|| Error::new(self.path, format!("{what}: the transform is not invertible")))?;
                    self.geometries.push(Geometry::Mesh(m));
                    (self.geometries.len() - 1, None)
                };
                let o = shapes::object(&self.geometries, geometry, None, transform, material, emission)
                    .map_err(|e| Error::new(self.path, format!("{what}: {e}")))?;
                let b = self.geometries[geometry].aabb();
                self.bounds = self.bounds.union(o.transform.as_ref().map_or(b, |t| t.aabb(&b)));
                self.objects.push(o);
            }
        }
        if let Some(c) = node.camera() {
            if self.camera.is_none() {
                self.camera = Some((c, world));
            } else {
                self.warn(&what, "a second camera is ignored (the first one met is used)");
            }
        }
        if let Some(l) = node.light() {
            let color = Rgb::from(l.color()) * l.intensity();
            let position = affine.transform_point3(Vec3::ZERO);
            let direction = affine.transform_vector3(-Vec3::Z).normalize_or_zero();
            if l.range().is_some() {
                self.warn(&what, "the light's range is ignored (physical falloff)");
            }
            match l.kind() {
                gltf::khr_lights_punctual::Kind::Point => {
                    self.lights.push(Light::Point { position, intensity: color });
                }
                gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                    if direction == Vec3::ZERO {
                        return Err(Error::new(self.path, format!("{what}: the spot light has no direction")));
                    }
                    self.lights.push(Light::Spot {
                        position,
                        direction,
                        intensity: color,
                        cos_inner: inner_cone_angle.cos(),
                        cos_outer: outer_cone_angle.cos(),
                    });
                }
                gltf::khr_lights_punctual::Kind::Directional => {
                    if direction == Vec3::ZERO {
                        return Err(Error::new(self.path, format!("{what}: the light has no direction")));
                    }
                    self.lights.push(Light::Directional { direction, irradiance: color });
                }
            }
        }
        for child in node.children() {
            self.node(child, world)?;
        }
        Ok(())
    }
}

/// Loads a glTF 2.0 scene (`.gltf` or `.glb`).
pub fn load(path: &Path) -> Result<LoadedScene, Error> {
    let bytes = crate::read_file(path)?;
    // The gltf crate's validation indexes the accessors of a primitive's POSITION without a
    // bounds check (gltf-json 1.4.1, mesh.rs): check those references first.
    let unvalidated = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| gltf_error(path, e))?;
    let root = unvalidated.document.as_json();
    for (i, m) in root.meshes.iter().enumerate() {
        for (j, p) in m.primitives.iter().enumerate() {
            let refs = p.attributes.values().chain(p.indices.iter());
            if let Some(bad) = refs.map(|a| a.value()).find(|&a| a >= root.accessors.len()) {
                return Err(Error::new(
                    path,
                    format!("invalid glTF: meshes[{i}].primitives[{j}] refers to accessor {bad}, which does not exist"),
                ));
            }
        }
    }
    // Validate the same parse, then load its buffers and images (external files relative to
    // this one). Anything else the crate cannot take is an error, not a crash.
    let gltf::Gltf { document, blob } = unvalidated;
    let base = path.parent().unwrap_or(Path::new("."));
    let imported = std::panic::catch_unwind(move || {
        let doc = gltf::Document::from_json(document.into_json())?;
        let buffers = gltf::import_buffers(&doc, Some(base), blob)?;
        let images = gltf::import_images(&doc, Some(base), &buffers)?;
        Ok::<_, gltf::Error>((doc, buffers, images))
    })
    .map_err(|_| Error::new(path, "invalid glTF: the gltf crate could not read this file"))?;
    let (doc, buffers, images) = imported.map_err(|e| gltf_error(path, e))?;
    let scene =
        doc.default_scene().or_else(|| doc.scenes().next()).ok_or_else(|| Error::new(path, "the file has no scene"))?;
    let lines = element_lines(json_text(&bytes));
    let mut cx = Ctx {
        path,
        lines,
        buffers: &buffers,
        images: &images,
        warnings: Vec::new(),
        materials: Vec::new(),
        emission: Vec::new(),
        material_of: HashMap::new(),
        image_of: HashMap::new(),
        geometries: Vec::new(),
        shared: HashMap::new(),
        uses: HashMap::new(),
        objects: Vec::new(),
        lights: Vec::new(),
        camera: None,
        bounds: Aabb::EMPTY,
    };
    // How many nodes use each mesh (shared meshes are instanced, the rest placed in world space).
    for n in doc.nodes() {
        if let Some(m) = n.mesh() {
            *cx.uses.entry(m.index()).or_default() += 1;
        }
    }
    for ext in doc.extensions_used() {
        if !matches!(
            ext,
            "KHR_lights_punctual"
                | "KHR_materials_emissive_strength"
                | "KHR_materials_transmission"
                | "KHR_materials_ior"
                | "KHR_materials_volume"
                | "KHR_materials_specular"
                | "KHR_texture_transform"
        ) {
            let at = doc.extensions_used().position(|e| e == ext).unwrap_or(0);
            cx.warn(&format!("extensionsUsed[{at}]"), format!("extension {ext} is not supported"));
        }
    }
    for node in scene.nodes() {
        cx.node(node, Mat4::IDENTITY)?;
    }
    if cx.objects.is_empty() {
        return Err(Error::new(path, "the scene has no triangles to render"));
    }
    let mut settings = SceneSettings { integrator: IntegratorKind::Path, ..SceneSettings::default() };
    settings.max_depth = Some(8);
    let mut frame = None;
    let camera = match cx.camera.take() {
        Some((c, world)) => {
            let what = element("cameras", c.index(), c.name());
            let m = Affine3A::from_mat4(world);
            let (projection, aspect) = match c.projection() {
                gltf::camera::Projection::Perspective(p) => {
                    let fov_y = p.yfov().to_degrees();
                    if !(fov_y > 0.0 && fov_y < 180.0) {
                        return Err(Error::new(path, format!("{what}: yfov {} is out of range", p.yfov())));
                    }
                    (Projection::Perspective { fov_y }, p.aspect_ratio())
                }
                gltf::camera::Projection::Orthographic(o) => {
                    (Projection::Orthographic { half_height: o.ymag().abs() }, Some(o.xmag() / o.ymag()))
                }
            };
            if let Some(a) = aspect.filter(|a| a.is_finite() && *a > 0.0) {
                settings.height = 512;
                settings.width = ((512.0 * a).round() as u32).clamp(1, 65536);
            }
            Camera::with_frame(
                m.transform_point3(Vec3::ZERO),
                m.transform_vector3(Vec3::X),
                m.transform_vector3(Vec3::Y),
                m.transform_vector3(-Vec3::Z),
                projection,
            )
            .ok_or_else(|| Error::new(path, format!("{what}: the camera's node gives no view direction")))?
        }
        None => {
            frame = Some(cx.bounds);
            auto_camera(cx.bounds, settings.width, settings.height)
                .ok_or_else(|| Error::new(path, "the scene has no extent to frame"))?
        }
    };
    let mut lights = cx.lights;
    if lights.is_empty() && !cx.emission.iter().any(|e| *e != Rgb::ZERO) {
        cx.warnings.push(format!("{}: the scene has no lights: it is lit by a white environment", path.display()));
        lights.push(Light::Environment(snell_core::light::Environment {
            scale: Rgb::ONE,
            map: None,
            to_world: glam::Mat3::IDENTITY,
        }));
    }
    let scene = Scene {
        geometries: cx.geometries,
        objects: cx.objects,
        materials: cx.materials,
        lights,
        camera,
        background: Rgb::ZERO,
        ambient: Rgb::ZERO,
        light_selection: LightSelection::Power,
    };
    scene.check().map_err(|e| Error::new(path, e))?;
    Ok(LoadedScene { scene, settings, frame, warnings: cx.warnings })
}
