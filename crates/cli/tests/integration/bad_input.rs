//! Every kind of bad input gives exit status 1, a message naming the file (and the line and
//! column, or byte offset) and what is wrong, no panic, and no output file.

use std::path::Path;

use crate::common::{run, stderr};

/// Writes `files` into a fresh directory, renders `target` there, and checks the failure.
/// Returns stderr.
fn fails(files: &[(&str, &[u8])], target: &str, extra: &[&str], expect: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    for (name, content) in files {
        std::fs::write(dir.path().join(name), content).unwrap();
    }
    let mut args = vec!["render", target, "-o", "out.png", "--width", "8", "--height", "8", "--spp", "1"];
    args.extend_from_slice(extra);
    let o = run(&args, dir.path());
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "expected exit 1, got {:?}; stderr:\n{err}", o.status);
    assert!(!err.contains("panicked"), "panic:\n{err}");
    for e in expect {
        assert!(err.contains(e), "stderr should mention {e:?}:\n{err}");
    }
    assert!(!dir.path().join("out.png").exists(), "an output file was written");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left behind: {leftovers:?}");
    err
}

const GOOD_HEAD: &str = "[camera]\neye = [0, 0, 5]\n\n[[shapes]]\ntype = \"sphere\"\n";

#[test]
fn missing_scene_file() {
    fails(&[], "nowhere.toml", &[], &["nowhere.toml", "no such file"]);
}

#[test]
fn missing_mesh_file() {
    fails(&[], "nowhere.ply", &[], &["nowhere.ply", "no such file"]);
    let scene = b"[[shapes]]\ntype = \"mesh\"\nfile = \"gone.obj\"\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:8", "gone.obj", "no such file"]);
}

#[test]
fn toml_syntax_error_names_line_and_column() {
    // An unclosed array is reported where the parser gives up: the end of the file.
    let scene = b"[camera]\neye = [0, 0, 5\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:1", "expected `]`"]);
    let scene = b"[render]\nwidth = = 3\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:2:9"]);
}

#[test]
fn unknown_key_names_line_and_column() {
    let scene = format!("{GOOD_HEAD}radius = 1\ncolour = [1, 0, 0]\n");
    fails(&[("s.toml", scene.as_bytes())], "s.toml", &[], &["s.toml:7:1", "unknown field `colour`"]);
    // A key that exists, but not for this type.
    let scene = b"[materials.m]\ntype = \"diffuse\"\nior = 1.5\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:7", "'ior' does not apply to a 'diffuse' material"]);
    let scene = b"[render]\nspp = 4\n\n[rendr]\nspp = 4\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:4:", "unknown field `rendr`"]);
}

#[test]
fn obj_face_index_out_of_range() {
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n";
    fails(&[("m.obj", obj)], "m.obj", &[], &["m.obj:5", "out of range"]);
    // Through a scene file too: the scene's line and the mesh's line.
    let scene = b"[[shapes]]\ntype = \"mesh\"\nfile = \"m.obj\"\n";
    fails(&[("m.obj", obj), ("s.toml", scene)], "s.toml", &[], &["s.toml:3:8", "m.obj:5", "out of range"]);
}

#[test]
fn nan_or_infinite_vertex() {
    let obj = b"v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n";
    fails(&[("m.obj", obj)], "m.obj", &[], &["m.obj:2", "not a finite number"]);
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 -inf\nf 1 2 3\n";
    fails(&[("m.obj", obj)], "m.obj", &[], &["m.obj:3", "not a finite number"]);
    let mut ply = ply_header("binary_little_endian", 3, 1);
    for v in [[0.0f32, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        v.iter().for_each(|c| ply.extend_from_slice(&c.to_le_bytes()));
    }
    ply.push(3);
    [0i32, 1, 2].iter().for_each(|i| ply.extend_from_slice(&i.to_le_bytes()));
    fails(&[("m.ply", &ply)], "m.ply", &[], &["m.ply", "byte", "vertex 1 has a NaN or infinite coordinate"]);
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n";
    fails(&[("m.ply", ascii)], "m.ply", &[], &["m.ply:11", "NaN or infinite"]);
    let scene = format!("{GOOD_HEAD}center = [0, nan, 0]\n");
    fails(&[("s.toml", scene.as_bytes())], "s.toml", &[], &["s.toml:6:10", "finite"]);
}

fn ply_header(format: &str, vertices: u64, faces: u64) -> Vec<u8> {
    format!(
        "ply\nformat {format} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\nelement face {faces}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    .into_bytes()
}

fn good_binary_ply() -> Vec<u8> {
    let mut ply = ply_header("binary_little_endian", 3, 1);
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        v.iter().for_each(|c| ply.extend_from_slice(&c.to_le_bytes()));
    }
    ply.push(3);
    [0i32, 1, 2].iter().for_each(|i| ply.extend_from_slice(&i.to_le_bytes()));
    ply
}

#[test]
fn truncated_binary_ply() {
    let ply = good_binary_ply();
    // Cut inside the face list: the header's sizes still fit, the data does not.
    let cut = &ply[..ply.len() - 2];
    let err = fails(&[("m.ply", cut)], "m.ply", &[], &["m.ply", "at byte", "truncated"]);
    assert!(err.contains(&format!("byte {}", ply.len() - 9)) || err.contains("byte"), "{err}");
    // Cut inside the vertices: caught by the size check before reading.
    let cut = &ply[..ply.len() - 20];
    fails(&[("m.ply", cut)], "m.ply", &[], &["m.ply", "bytes"]);
}

#[test]
fn ply_declaring_a_trillion_vertices_fails_fast() {
    let mut ply = ply_header("binary_little_endian", 1_000_000_000_000, 1);
    ply.extend_from_slice(&good_binary_ply()[ply_header("binary_little_endian", 3, 1).len()..]);
    fails(&[("m.ply", &ply)], "m.ply", &[], &["m.ply", "1000000000000", "bytes"]);
    let mut ply = ply_header("ascii", 1_000_000_000_000, 1);
    ply.extend_from_slice(b"0 0 0\n");
    fails(&[("m.ply", &ply)], "m.ply", &[], &["m.ply", "1000000000000"]);
}

#[test]
fn empty_files() {
    fails(&[("s.toml", b"")], "s.toml", &[], &["s.toml", "empty"]);
    fails(&[("s.toml", b"# only a comment\n\n")], "s.toml", &[], &["s.toml", "empty"]);
    fails(&[("m.obj", b"")], "m.obj", &[], &["m.obj", "empty"]);
    fails(&[("m.ply", b"")], "m.ply", &[], &["m.ply", "empty"]);
    fails(&[("m.obj", b"v 0 0 0\n")], "m.obj", &[], &["m.obj", "no faces"]);
}

#[test]
fn negative_or_nan_ior() {
    for (ior, col) in [("-1.5", 7), ("nan", 7), ("0", 7), ("-inf", 7)] {
        let scene = format!("[materials.g]\ntype = \"dielectric\"\nior = {ior}\n");
        fails(&[("s.toml", scene.as_bytes())], "s.toml", &[], &["s.toml:3:", "index of refraction"]);
        let _ = col;
    }
    let scene = b"[materials.g]\ntype = \"dielectric\"\nior = \"unobtainium\"\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:7", "unknown IOR preset 'unobtainium'"]);
    let scene = b"[materials.g]\ntype = \"glazed\"\nior = 0.5\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:7", "below 1"]);
}

#[test]
fn zero_sized_image() {
    let scene = format!("[render]\nwidth = 0\n\n{GOOD_HEAD}");
    fails(&[("s.toml", scene.as_bytes())], "s.toml", &[], &["s.toml:2:9", "'width' must be between 1"]);
    let scene = format!("[render]\nheight = 0\n\n{GOOD_HEAD}");
    fails(&[("s.toml", scene.as_bytes())], "s.toml", &[], &["s.toml:2:10", "'height'"]);
}

#[test]
fn image_too_large_to_allocate() {
    let dir = tempfile::tempdir().unwrap();
    let o = run(&["render", "--width", "65536", "--height", "65536", "-o", "out.png"], dir.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("65536x65536") && stderr(&o).contains("at most"), "{}", stderr(&o));
    assert!(!dir.path().join("out.png").exists());
}

#[test]
fn zero_size_on_the_command_line_is_misuse() {
    let dir = tempfile::tempdir().unwrap();
    let o = crate::common::run(&["render", "--width", "0", "-o", "out.png"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!dir.path().join("out.png").exists());
    let o = crate::common::run(&["render", "--bogus"], dir.path());
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn other_bad_values() {
    let scene = b"[[shapes]]\ntype = \"sphere\"\nmaterial = \"nope\"\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:12", "no material named 'nope'"]);
    let scene = b"[[shapes]]\ntype = \"sphere\"\nradius = -1\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:10", "'radius'"]);
    let scene = b"[[shapes]]\ntype = \"sphere\"\ntransform = [{ scale = 0 }]\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:", "singular"]);
    let scene = b"[[shapes]]\ntype = \"torus\"\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:2:8", "unknown shape type 'torus'"]);
    let scene = b"[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, 0]\n[[shapes]]\ntype = \"sphere\"\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:1:", "coincide"]);
    let scene = b"[render]\naccel = \"octree\"\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:2:9", "unknown accelerator 'octree'"]);
    fails(&[("s.txt", b"hello")], "s.txt", &[], &["s.txt", "unsupported scene format"]);
    let invalid_utf8: &[u8] = b"[render]\nspp = 1 # \xff\xfe\n";
    fails(&[("s.toml", invalid_utf8)], "s.toml", &[], &["s.toml:2:11", "not valid UTF-8"]);
}

#[test]
fn text_that_is_not_utf8_is_reported_where_it_is_in_every_text_format() {
    // The first bad byte's line and column (in bytes), whichever reader opens the file.
    let xml: &[u8] = b"<scene version=\"3.0.0\">\n  <!-- \xc3\x28 -->\n</scene>\n";
    fails(&[("s.xml", xml)], "s.xml", &[], &["s.xml:2:8", "not valid UTF-8"]);
    let pbrt: &[u8] = b"Camera \"perspective\"\n# caf\xe9\n";
    fails(&[("s.pbrt", pbrt)], "s.pbrt", &[], &["s.pbrt:2:6", "not valid UTF-8"]);
    // A file that another one includes names itself.
    let top: &[u8] = b"<scene version=\"3.0.0\">\n<include filename=\"part.xml\"/>\n</scene>\n";
    let part: &[u8] = b"\xff<scene version=\"3.0.0\"/>\n";
    fails(&[("s.xml", top), ("part.xml", part)], "s.xml", &[], &["part.xml:1:1", "not valid UTF-8"]);
}

#[test]
fn unwritable_output_fails_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let o = crate::common::run(&["render", "-o", "no/such/dir/out.png"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
    let o = crate::common::run(&["render", "-o", "out.jpg"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("out.jpg") && stderr(&o).contains(".png or .exr"));
    assert!(!Path::new(&dir.path().join("out.jpg")).exists());
}

#[test]
fn bad_arrays() {
    let scene = b"[[shapes]]\ntype = \"sphere\"\narray = { count = [0, 1, 1], step = [1, 0, 0] }\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:9", "copies"]);
    let scene = b"[[shapes]]\ntype = \"sphere\"\narray = { count = [2000, 2000, 1], step = [1, 0, 0] }\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:9", "copies"]);
    let scene = b"[[shapes]]\ntype = \"sphere\"\narray = { count = [2, 2], step = [1, 0, 0] }\n";
    fails(&[("s.toml", scene)], "s.toml", &[], &["s.toml:3:"]);
}

/// Writes `bytes` to `path` and loads it with `load`: whether it loaded. A refusal must name
/// the file, and a panic fails the test.
fn loads_or_names_the_file(
    path: &Path,
    bytes: &[u8],
    load: impl FnOnce(&Path) -> Result<(), String> + std::panic::UnwindSafe,
) -> bool {
    std::fs::write(path, bytes).unwrap();
    let name = path.file_name().unwrap().to_string_lossy();
    match std::panic::catch_unwind(|| load(path)) {
        Ok(Ok(())) => true,
        Ok(Err(e)) => {
            assert!(e.contains(&*name), "{e}");
            false
        }
        Err(_) => panic!("{name}: a damaged file made the reader panic"),
    }
}

/// A Mitsuba scene of inline shapes (no files of its own), for the damaged copies below.
const INLINE_XML: &str = r#"<scene version="3.0.0">
    <default name="spp" value="4"/>
    <integrator type="path"><integer name="max_depth" value="5"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 6" target="0, 0.5, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film>
    </sensor>
    <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf>
    <bsdf type="roughconductor" id="metal"><string name="material" value="Au"/><float name="alpha" value="0.2"/></bsdf>
    <bsdf type="dielectric" id="glass"><float name="int_ior" value="1.5"/></bsdf>
    <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/></transform><ref id="white"/></shape>
    <shape type="cube"><transform name="to_world"><translate x="-1" y="0.5"/><scale value="0.5"/></transform><ref id="metal"/></shape>
    <shape type="sphere"><point name="center" x="1" y="0.6" z="0"/><float name="radius" value="0.6"/><ref id="glass"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 9, 8"/></emitter>
    </shape>
    <emitter type="constant"><rgb name="radiance" value="0.1"/></emitter>
</scene>
"#;

/// A cube as OBJ (positions, texture coordinates, normals, faces of three and four corners).
const CUBE_OBJ: &str = "# cube\no cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 -1\nvn 0 0 1\nf 1/1/1 3/3/1 2/2/1\nf 1/1/1 4/3/1 3/2/1\nf 5/1/2 6/2/2 7/3/2 8/3/2
f -1 -2 -3\n";

/// The same cube as ASCII PLY.
const CUBE_PLY: &str = "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z
element face 3\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1
3 0 2 1\n3 0 3 2\n4 4 5 6 7\n";

/// Every prefix of a scene file in each text format Snell reads (the repository's default
/// scene, pbrt and glTF Cornell boxes, a Mitsuba scene, an OBJ and a PLY mesh; cut every few
/// bytes), and copies with bytes overwritten by characters that matter to the syntax, or
/// with runs of bytes deleted or repeated elsewhere: each loads or fails with an error naming
/// the file, never a panic.
#[test]
fn truncated_and_damaged_scene_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let repo = |name: &str| std::fs::read(crate::common::repo_scene(name)).unwrap();
    let files: [(&str, Vec<u8>); 6] = [
        ("default.toml", repo("default.toml")),
        ("cornell-box.pbrt", repo("cornell-box.pbrt")),
        ("cornell-box.gltf", repo("cornell-box.gltf")),
        ("inline.xml", INLINE_XML.as_bytes().to_vec()),
        ("cube.obj", CUBE_OBJ.as_bytes().to_vec()),
        ("cube.ply", CUBE_PLY.as_bytes().to_vec()),
    ];
    let mut rng = snell_core::sampling::Pcg32::new(11, 12);
    for (name, bytes) in files {
        let p = dir.path().join(name);
        let load = |b: &[u8]| {
            // As `snell render` loads it (the meshes in `scene::from_mesh`'s scene, whose
            // clay coat is integrated once per process).
            loads_or_names_the_file(&p, b, |p| snell_io::load_scene(p, &[]).map(|_| ()).map_err(|e| e.to_string()))
        };
        assert!(load(&bytes), "the undamaged {name} does not load");
        let mut refused = 0;
        let step = (bytes.len() / 150).max(1);
        for cut in (0..bytes.len()).step_by(step) {
            refused += !load(&bytes[..cut]) as u32;
        }
        let mut at = |len: usize| rng.next_u32() as usize % len.max(1);
        for k in 0..240 {
            let mut b = bytes.clone();
            let i = at(b.len());
            match k % 3 {
                // A character that matters to the syntax.
                0 => {
                    let chars = b"[]{}<>\"'/=:,.-0e9#x\n ";
                    b[i] = chars[at(chars.len())];
                }
                // A run of up to 40 bytes deleted.
                1 => {
                    let n = 1 + at(40);
                    b.drain(i..(i + n).min(b.len()));
                }
                // A run of up to 60 bytes from elsewhere put in.
                _ => {
                    let j = at(b.len());
                    let run = b[j..(j + 1 + at(60)).min(b.len())].to_vec();
                    b.splice(i..i, run);
                }
            }
            refused += !load(&b) as u32;
        }
        // Most damaged copies are refused: the damage was seen, not just survived.
        assert!(refused >= 150, "{name}: only {refused} of the damaged copies were refused");
    }
}

/// Damaged images in each format Snell reads (textures, environment maps and `snell diff`'s
/// inputs all go through `read_rgb`): every prefix (cut every few bytes) and copies with bytes
/// overwritten, half of them within the header, decode or fail with an error naming the file,
/// never a panic.
#[test]
fn damaged_images_never_panic() {
    use image::{DynamicImage, ImageFormat, Rgb32FImage};
    let dir = tempfile::tempdir().unwrap();
    // 16 wide, so that the Radiance file's rows are run-length encoded.
    let img = Rgb32FImage::from_fn(16, 8, |x, y| image::Rgb([x as f32 / 4.0, y as f32 / 2.0, 0.25]));
    let encode = |f: ImageFormat| {
        let d = DynamicImage::ImageRgb32F(img.clone());
        let d = if f == ImageFormat::Png { DynamicImage::ImageRgb8(d.to_rgb8()) } else { d };
        let mut out = std::io::Cursor::new(Vec::new());
        d.write_to(&mut out, f).unwrap();
        out.into_inner()
    };
    let rows: Vec<[f32; 3]> = img.pixels().map(|p| p.0).collect();
    let files = [
        ("t.png", encode(ImageFormat::Png)),
        ("t.exr", encode(ImageFormat::OpenExr)),
        ("t.hdr", encode(ImageFormat::Hdr)),
        ("t.pfm", crate::common::pfm(16, 8, &rows)),
    ];
    let mut rng = snell_core::sampling::Pcg32::new(64, 65);
    for (name, bytes) in files {
        let p = dir.path().join(name);
        let read = |b: &[u8]| {
            loads_or_names_the_file(&p, b, |p| snell_io::image_in::read_rgb(p).map(|_| ()).map_err(|e| e.to_string()))
        };
        assert!(read(&bytes), "the undamaged {name} does not decode");
        let mut refused = 0;
        for cut in (0..bytes.len()).step_by((bytes.len() / 100).max(1)) {
            refused += !read(&bytes[..cut]) as u32;
        }
        for k in 0..200 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.next_u32() % 4 {
                let span = if k % 2 == 0 { b.len().min(64) } else { b.len() };
                b[rng.next_u32() as usize % span] = rng.next_u32() as u8;
            }
            refused += !read(&b) as u32;
        }
        // Most prefixes lack pixels: the damage was seen, not just survived.
        assert!(refused >= 90, "{name}: only {refused} of the damaged copies were refused");
    }
}

/// A texture or environment image with a negative or non-finite value is refused, naming the
/// scene's line, the image and the first such pixel (from the top left), whichever reader
/// loads it. (Such texels rendered black, or made every sample that met them count as black,
/// without a word.)
#[test]
fn images_with_negative_or_non_finite_values_name_the_pixel() {
    let mut rows = vec![[0.5f32; 3]; 8];
    rows[4 + 2] = [0.5, f32::NAN, 0.5];
    rows[4 + 3] = [-0.25, 0.5, 0.5];
    let bad = crate::common::pfm(4, 2, &rows);
    let texture =
        format!("{GOOD_HEAD}material = \"m\"\n\n[materials.m]\ntype = \"diffuse\"\nalbedo = {{ image = \"t.pfm\" }}\n");
    fails(&[("s.toml", texture.as_bytes()), ("t.pfm", &bad)], "s.toml", &[], &["s.toml:10:", "t.pfm", "pixel (2, 1)"]);
    let env = format!("{GOOD_HEAD}\n[[lights]]\ntype = \"environment\"\nfile = \"e.pfm\"\n");
    fails(&[("s.toml", env.as_bytes()), ("e.pfm", &bad)], "s.toml", &[], &["s.toml:9:", "e.pfm", "pixel (2, 1)"]);
    let xml = b"<scene version=\"3.0.0\">\n<shape type=\"sphere\">\n<bsdf type=\"diffuse\">\n\
        <texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"t.pfm\"/></texture>\n\
        </bsdf>\n</shape>\n</scene>\n";
    fails(&[("s.xml", xml), ("t.pfm", &bad)], "s.xml", &[], &["s.xml:4:", "t.pfm", "pixel (2, 1)"]);
    let xml = b"<scene version=\"3.0.0\">\n<shape type=\"sphere\"/>\n\
        <emitter type=\"envmap\"><string name=\"filename\" value=\"e.pfm\"/></emitter>\n</scene>\n";
    fails(&[("s.xml", xml), ("e.pfm", &bad)], "s.xml", &[], &["s.xml:3:", "e.pfm", "pixel (2, 1)"]);
    // pbrt's `invert` would clamp the NaN away: the file's values are checked first.
    let pbrt = |params: &str| {
        format!(
            "WorldBegin\nTexture \"t\" \"spectrum\" \"imagemap\" \"string filename\" \"t.pfm\" {params}\n\
             Material \"diffuse\" \"texture reflectance\" \"t\"\nShape \"sphere\"\n"
        )
    };
    let inverted = pbrt("\"bool invert\" true");
    fails(&[("s.pbrt", inverted.as_bytes()), ("t.pfm", &bad)], "s.pbrt", &[], &["s.pbrt:2:", "t.pfm", "pixel (2, 1)"]);
    let good = crate::common::pfm(4, 2, &[[0.5f32; 3]; 8]);
    let negative = pbrt("\"float scale\" -2");
    fails(
        &[("s.pbrt", negative.as_bytes()), ("t.pfm", &good)],
        "s.pbrt",
        &[],
        &["s.pbrt:2:", "'scale' must not be negative"],
    );
    // Only the values are at fault: the same image without them renders.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), &texture).unwrap();
    std::fs::write(dir.path().join("t.pfm"), good).unwrap();
    let o = run(&["render", "s.toml", "-o", "out.png", "--width", "8", "--height", "8", "--spp", "1"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
}
