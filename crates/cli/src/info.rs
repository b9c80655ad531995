//! `snell info SCENE`: what a scene file turned into, and what was ignored or approximated.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Result;
use snell_core::camera::Projection;
use snell_core::light::Light;
use snell_core::material::Material;
use snell_core::scene::Geometry;

#[derive(clap::Args)]
pub struct InfoArgs {
    /// Scene file (.toml, or Mitsuba 3 .xml) or mesh (.obj, .ply).
    pub scene: PathBuf,
    /// Mitsuba scenes: set a parameter (`$name`), overriding the file's `<default>`.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = crate::parse_define)]
    pub define: Vec<(String, String)>,
}

fn material_kind(m: &Material) -> &'static str {
    match m.surface() {
        Material::Diffuse { .. } => "diffuse",
        Material::Plastic { roughness, .. } if *roughness > 0.0 => "rough plastic",
        Material::Plastic { .. } => "plastic",
        Material::Conductor { roughness, .. } if *roughness > 0.0 => "rough conductor",
        Material::Conductor { .. } => "conductor",
        Material::Mirror { .. } => "mirror",
        Material::Dielectric { roughness, .. } if *roughness > 0.0 => "rough dielectric",
        Material::Dielectric { .. } => "dielectric",
        Material::ThinDielectric { .. } => "thin dielectric",
        Material::OneSided(_) => "one-sided",
    }
}

fn light_kind(l: &Light) -> &'static str {
    match l {
        Light::Point { .. } => "point",
        Light::Spot { .. } => "spot",
        Light::Directional { .. } => "directional",
        Light::Area(_) => "area",
        Light::Environment(e) if e.map.is_some() => "environment map",
        Light::Environment(_) => "constant environment",
    }
}

pub fn run(args: InfoArgs) -> Result<()> {
    let loaded = crate::load(Some(&args.scene), &args.define)?;
    let scene = &loaded.scene;
    let s = &loaded.settings;
    let (mut meshes, mut spheres, mut instanced, mut emitters) = (0, 0, 0, 0);
    let mut uses = vec![0usize; scene.geometries.len()];
    for o in &scene.objects {
        uses[o.geometry] += 1;
    }
    for o in &scene.objects {
        match scene.geometries[o.geometry] {
            Geometry::Mesh(_) => meshes += 1,
            Geometry::Sphere(_) => spheres += 1,
        }
        if uses[o.geometry] > 1 {
            instanced += 1;
        }
        if o.emission != snell_core::Rgb::ZERO {
            emitters += 1;
        }
    }
    println!("{}", args.scene.display());
    println!(
        "shapes       {} ({meshes} meshes, {spheres} spheres; {instanced} share their geometry with others; {emitters} emit)",
        scene.objects.len()
    );
    println!("triangles    {} (rendered), {} stored", scene.triangle_count(), {
        scene.geometries.iter().map(|g| if let Geometry::Mesh(m) = g { m.indices.len() } else { 0 }).sum::<usize>()
    });
    let mut kinds: BTreeMap<String, usize> = BTreeMap::new();
    for m in &scene.materials {
        let k = material_kind(m);
        *kinds.entry(if m.two_sided() { k.to_string() } else { format!("{k} (one-sided)") }).or_default() += 1;
    }
    let list = |k: &BTreeMap<String, usize>| k.iter().map(|(n, c)| format!("{c} {n}")).collect::<Vec<_>>().join(", ");
    println!("materials    {} ({})", scene.materials.len(), list(&kinds));
    let mut lk: BTreeMap<String, usize> = BTreeMap::new();
    for l in &scene.lights {
        *lk.entry(light_kind(l).to_string()).or_default() += 1;
    }
    if emitters > 0 {
        *lk.entry("area".to_string()).or_default() += emitters;
    }
    println!("lights       {} ({})", lk.values().sum::<usize>(), if lk.is_empty() { "none".into() } else { list(&lk) });
    let c = &scene.camera;
    let (_, up, fwd) = c.frame();
    let proj = match c.projection() {
        Projection::Perspective { fov_y } => format!("perspective, vertical fov {fov_y:.3}°"),
        Projection::ThinLens { fov_y, aperture, focus_distance } => {
            format!("thin lens, vertical fov {fov_y:.3}°, aperture radius {aperture}, focus at {focus_distance}")
        }
        Projection::Orthographic { half_height } => format!("orthographic, half height {half_height}"),
    };
    println!(
        "camera       {proj}; eye ({:.3}, {:.3}, {:.3}), forward ({:.3}, {:.3}, {:.3}), up ({:.3}, {:.3}, {:.3}){}",
        c.eye.x,
        c.eye.y,
        c.eye.z,
        fwd.x,
        fwd.y,
        fwd.z,
        up.x,
        up.y,
        up.z,
        if loaded.frame.is_some() { " (placed automatically)" } else { "" }
    );
    println!(
        "film         {}x{}, {} spp, seed {}, filter {:?}, {:?}",
        s.width,
        s.height,
        s.spp,
        s.seed,
        s.filter_name(),
        s.reconstruction
    );
    let depth = s.max_depth.map_or("unbounded".to_string(), |d| d.to_string());
    println!("integrator   {}, max_depth {depth}, rr_depth {}, sampler {:?}", s.integrator, s.rr_depth, s.sampler);
    if loaded.warnings.is_empty() {
        println!("ignored or approximated: nothing");
    } else {
        println!("ignored or approximated ({}):", loaded.warnings.len());
        for w in &loaded.warnings {
            println!("  {w}");
        }
    }
    Ok(())
}
