//! The glTF 2.0 reader: hierarchy, materials, cameras and lights on small files built here,
//! bad files, and the repository's glTF Cornell box against Mitsuba's reference.

use serde_json::{json, Value};

use snell_core::camera::Projection;
use snell_core::filter::Filter;
use snell_core::light::Light;
use snell_core::material::{Material, Texture};
use snell_core::scene::Geometry;
use snell_core::Vec3;
use snell_io::scene::LoadedScene;

use crate::common::{repo_scene, run, stderr};
use crate::mitsuba::compare_with_mitsuba;

/// A glTF document with one triangle mesh (a unit right triangle in z = 0 with UVs) in a
/// base64 buffer; `extra` is merged into the top level.
fn doc(extra: Value) -> Value {
    let mut blob = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        p.iter().for_each(|x| blob.extend(x.to_le_bytes()));
    }
    for uv in [[0f32, 1.], [1., 1.], [0., 0.]] {
        uv.iter().for_each(|x| blob.extend(x.to_le_bytes()));
    }
    let uri = format!("data:application/octet-stream;base64,{}", base64::encode(&blob));
    let mut d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "material": 0}]}],
        "materials": [{}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 24}
        ],
        "buffers": [{"byteLength": blob.len(), "uri": uri}]
    });
    if let (Value::Object(d), Value::Object(e)) = (&mut d, extra) {
        for (k, v) in e {
            d.insert(k, v);
        }
    }
    d
}

fn load(d: &Value) -> Result<LoadedScene, String> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.gltf");
    std::fs::write(&p, serde_json::to_string_pretty(d).unwrap()).unwrap();
    snell_io::gltf::load(&p).map_err(|e| e.to_string())
}

#[test]
fn node_hierarchy_transforms_and_instancing() {
    let d = doc(json!({
        "scenes": [{"nodes": [0, 2]}],
        "nodes": [
            {"translation": [10, 0, 0], "scale": [2, 2, 2], "children": [1]},
            {"mesh": 0, "rotation": [0, 0, 0.70710677, 0.70710677]},
            {"mesh": 1, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,-5,1]},
            {"mesh": 1, "translation": [0, 0, 5]}
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}}]},
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}}]}
        ]
    }));
    // Node 3 is not in the scene; node 2's mesh is used twice (by nodes 2 and 3), so it is instanced.
    let l = load(&d).unwrap();
    assert_eq!(l.scene.objects.len(), 2);
    let m = match &l.scene.geometries[l.scene.objects[0].geometry] {
        Geometry::Mesh(m) => m,
        other => panic!("{other:?}"),
    };
    // Parent T·S, child R (90° about z): x → y, scaled by 2, moved by 10 in x.
    assert!((m.positions[1] - Vec3::new(10.0, 2.0, 0.0)).length() < 1e-5, "{:?}", m.positions);
    let o = &l.scene.objects[1];
    let t = o.transform.as_ref().expect("an instanced mesh keeps its transform");
    assert_eq!(t.point(Vec3::ZERO), Vec3::new(0.0, 0.0, -5.0));
    match &l.scene.geometries[o.geometry] {
        // glTF's v runs down the image; Snell's up.
        Geometry::Mesh(m) => assert_eq!(m.uvs.as_ref().unwrap()[2], snell_core::Vec2::new(0.0, 1.0)),
        other => panic!("{other:?}"),
    }
    // No camera: framed automatically; no light: a white environment, with a warning.
    assert!(l.frame.is_some());
    assert!(matches!(l.scene.lights[0], Light::Environment(_)));
    assert!(l.warnings.iter().any(|w| w.contains("no lights")), "{:?}", l.warnings);
}

#[test]
fn materials_map_by_their_factors_and_extensions() {
    let d = doc(json!({
        "nodes": [{"mesh": 0}, {"mesh": 1}, {"mesh": 2}, {"mesh": 3}, {"mesh": 4}, {"mesh": 5}],
        "scenes": [{"nodes": [0, 1, 2, 3, 4, 5]}],
        "meshes": (0..6).map(|i| json!({"primitives": [{"attributes": {"POSITION": 0}, "material": i}]})).collect::<Vec<_>>(),
        "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume",
                           "KHR_materials_specular", "KHR_materials_emissive_strength", "EXT_unknown"],
        "materials": [
            {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.6, 0.2, 1], "metallicFactor": 1, "roughnessFactor": 0.5}},
            {"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 0.2}},
            {"pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.33}}},
            {"pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0.1},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1},
                            "KHR_materials_volume": {"thicknessFactor": 0.5}}},
            {"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1], "metallicFactor": 0},
             "extensions": {"KHR_materials_specular": {"specularFactor": 0}}},
            {"emissiveFactor": [1, 0.5, 0.25],
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8}}}
        ]
    }));
    let l = load(&d).unwrap();
    let m = |i: usize| &l.scene.materials[l.scene.objects[i].material];
    match m(0) {
        Material::Conductor { eta, k, roughness, .. } => {
            let r0 = ((*eta - Vec3::ONE) * (*eta - Vec3::ONE) + *k * *k)
                / ((*eta + Vec3::ONE) * (*eta + Vec3::ONE) + *k * *k);
            assert!((r0 - Vec3::new(0.9, 0.6, 0.2)).abs().max_element() < 1e-4, "{r0:?}");
            assert!((roughness - 0.25).abs() < 1e-6, "alpha = roughness²");
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(m(1), Material::Plastic { ior, roughness, .. } if *ior == 1.5 && (roughness - 0.04).abs() < 1e-6));
    assert!(matches!(m(2), Material::ThinDielectric { ior, .. } if *ior == 1.33), "no volume: thin-walled");
    assert!(
        matches!(m(3), Material::Dielectric { ior, roughness, .. } if *ior == 1.5 && (roughness - 0.01).abs() < 1e-6)
    );
    assert!(matches!(m(4), Material::Diffuse { albedo: Texture::Constant(c) } if *c == Vec3::new(0.2, 0.4, 0.6)));
    assert_eq!(l.scene.objects[5].emission, Vec3::new(8.0, 4.0, 2.0));
    // Warnings name file, line and element.
    let text = serde_json::to_string_pretty(&d).unwrap();
    let line = text.lines().position(|t| t.contains("\"EXT_unknown\"")).unwrap() + 1;
    let want = format!("s.gltf:{line}: extensionsUsed[5]: extension EXT_unknown");
    assert!(l.warnings.iter().any(|w| w.contains(&want)), "{want}: {:?}", l.warnings);
}

#[test]
fn cameras_and_punctual_lights() {
    let d = doc(json!({
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1, 0.5, 0.5], "intensity": 4},
            {"type": "spot", "intensity": 2, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.4}},
            {"type": "directional", "intensity": 3}
        ]}},
        "scenes": [{"nodes": [0, 1, 2, 3, 4, 5]}],
        "nodes": [
            {"mesh": 0},
            {"camera": 0, "translation": [0, 0, 5]},
            {"camera": 1},
            {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [1, 2, 3]},
            {"extensions": {"KHR_lights_punctual": {"light": 1}}, "rotation": [-0.70710677, 0, 0, 0.70710677]},
            {"extensions": {"KHR_lights_punctual": {"light": 2}}}
        ],
        "cameras": [
            {"type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 2.0, "znear": 0.1}},
            {"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 10}}
        ]
    }));
    let l = load(&d).unwrap();
    let c = &l.scene.camera;
    assert_eq!(c.eye, Vec3::new(0.0, 0.0, 5.0));
    let (right, up, forward) = c.frame();
    assert!(
        (forward - -Vec3::Z).length() < 1e-6 && (up - Vec3::Y).length() < 1e-6 && (right - Vec3::X).length() < 1e-6
    );
    assert!(matches!(c.projection(), Projection::Perspective { fov_y } if (fov_y - 0.5f32.to_degrees()).abs() < 1e-4));
    assert_eq!((l.settings.width, l.settings.height), (1024, 512));
    assert!(l.warnings.iter().any(|w| w.contains("second camera")), "{:?}", l.warnings);
    let lights = &l.scene.lights;
    assert!(
        matches!(lights[0], Light::Point { position, intensity } if position == Vec3::new(1.0, 2.0, 3.0) && intensity == Vec3::new(4.0, 2.0, 2.0))
    );
    match lights[1] {
        // Turned -90° about x, the spot's -z points down.
        Light::Spot { direction, cos_inner, cos_outer, .. } => {
            assert!((direction - -Vec3::Y).length() < 1e-5, "{direction:?}");
            assert!((cos_inner - 0.2f32.cos()).abs() < 1e-6 && (cos_outer - 0.4f32.cos()).abs() < 1e-6);
        }
        ref other => panic!("{other:?}"),
    }
    assert!(
        matches!(lights[2], Light::Directional { direction, irradiance } if direction == -Vec3::Z && irradiance == Vec3::splat(3.0))
    );
}

#[test]
fn binary_gltf_loads_like_text() {
    // A .glb: the JSON chunk and the buffer in a BIN chunk.
    let mut d = doc(json!({}));
    let uri = d["buffers"][0]["uri"].as_str().unwrap().to_string();
    let mut bin = base64::decode(uri.split(',').nth(1).unwrap()).unwrap();
    d["buffers"][0] = json!({"byteLength": bin.len()});
    let mut js = serde_json::to_vec(&d).unwrap();
    while !js.len().is_multiple_of(4) {
        js.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + js.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((js.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&js);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.glb"), &glb).unwrap();
    let l = snell_io::gltf::load(&dir.path().join("s.glb")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(l.scene.objects.len(), 1);
    // Truncated: an error, not a panic.
    std::fs::write(dir.path().join("t.glb"), &glb[..glb.len() - 10]).unwrap();
    let e = snell_io::gltf::load(&dir.path().join("t.glb")).unwrap_err().to_string();
    assert!(e.contains("t.glb"), "{e}");
}

#[test]
fn bad_files_are_errors_with_a_place() {
    let dir = tempfile::tempdir().unwrap();
    // Malformed JSON: line and column.
    std::fs::write(
        dir.path().join("a.gltf"),
        "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [ {\"mesh\": } ]\n}",
    )
    .unwrap();
    let e = snell_io::gltf::load(&dir.path().join("a.gltf")).unwrap_err().to_string();
    assert!(e.contains("a.gltf:3:"), "{e}");
    // Wrong types and unknown references are validation errors naming the element.
    let mut d = doc(json!({}));
    d["nodes"][0]["mesh"] = json!(7);
    let e = load(&d).unwrap_err();
    assert!(e.contains("nodes[0].mesh"), "{e}");
    let mut d = doc(json!({}));
    d["accessors"][0]["count"] = json!("three");
    assert!(load(&d).unwrap_err().contains("malformed glTF JSON"));
    // Indices past the vertices.
    let mut d = doc(json!({}));
    d["accessors"][0]["count"] = json!(2);
    d["meshes"][0]["primitives"][0]["attributes"] = json!({"POSITION": 0});
    d["bufferViews"][0]["byteLength"] = json!(24);
    assert!(load(&d).unwrap_err().contains("whole triangles"));
    // A primitive whose POSITION names no accessor (the gltf crate's own check would panic).
    let mut d = doc(json!({}));
    d["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(9);
    assert!(load(&d).unwrap_err().contains("accessor 9"));
    // A missing buffer file.
    let mut d = doc(json!({}));
    d["buffers"][0]["uri"] = json!("missing.bin");
    assert!(load(&d).is_err());
    let o = run(&["render", "a.gltf", "-o", "x.exr"], dir.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!dir.path().join("x.exr").exists());
}

/// The repository's glTF Cornell box (scenes/cornell-box.gltf, written from the Mitsuba
/// scene's meshes) converges to Mitsuba's reference of cbox-rgb.xml. glTF has no reconstruction
/// filter or path depth, so those of the Mitsuba scene are set (box, max_depth 6).
#[test]
fn gltf_cornell_box_matches_mitsuba() {
    let mut l = snell_io::gltf::load(&repo_scene("cornell-box.gltf")).unwrap_or_else(|e| panic!("{e}"));
    assert!(l.warnings.is_empty(), "{:?}", l.warnings);
    assert!(l.scene.materials.iter().all(|m| matches!(m, Material::Diffuse { .. })));
    l.settings.filter = Filter::Box { radius: 0.5 };
    compare_with_mitsuba("cornell-box.gltf", &l, "cbox-rgb", 256, 256, 6, 1.2);
}
