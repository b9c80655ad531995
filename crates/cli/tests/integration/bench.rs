//! `snell bench`: output format, agreement between accelerators, ray replay.

use crate::common::{data, run, shared_scene, stderr};

fn field<'a>(line: &'a str, key: &str) -> &'a str {
    let start = line.find(&format!("\"{key}\":")).unwrap_or_else(|| panic!("no {key} in {line}")) + key.len() + 3;
    let rest = &line[start..];
    rest[..rest.find([',', '}']).unwrap()].trim_matches('"')
}

#[test]
fn json_lines_for_every_accelerator_and_workload() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = data("two-tetra.obj");
    let o = run(
        &[
            "bench",
            mesh.to_str().unwrap(),
            "--accel",
            "all",
            "--json",
            "--reps",
            "1",
            "--width",
            "40",
            "--height",
            "40",
            "--threads",
            "2",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 4 * snell_core::accel::AccelKind::ALL.len(), "{out}");
    for l in &lines {
        for key in [
            "mesh",
            "tris",
            "accel",
            "threads",
            "build_ms",
            "accel_bytes",
            "workload",
            "rays",
            "hits",
            "mrays_per_s",
            "sah_cost",
            "nodes",
            "leaves",
            "depth",
        ] {
            field(l, key);
        }
        assert_eq!(field(l, "tris"), "8");
        assert_eq!(field(l, "threads"), "2");
    }
    // Every accelerator finds the same hits (brute traces all rays here: fewer than 2048 hit).
    for workload in ["primary", "primary-packets", "bounce", "bounce-occluded"] {
        let hits: Vec<&str> =
            lines.iter().filter(|l| field(l, "workload") == workload).map(|l| field(l, "hits")).collect();
        assert!(hits.windows(2).all(|w| w[0] == w[1]), "{workload}: {hits:?}");
    }
    // Packets find what single rays find.
    assert_eq!(field(lines[0], "hits"), field(lines[1], "hits"));
    let primary_hits: usize = field(lines[0], "hits").parse().unwrap();
    let bounce_hits: usize = field(lines[2], "hits").parse().unwrap();
    assert!(primary_hits > 100 && bounce_hits > 5, "{primary_hits} {bounce_hits}");
}

#[test]
fn replayed_ray_files_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = data("tetra.obj");
    std::fs::write(dir.path().join("r_primary.f32"), [0u8; 25]).unwrap();
    std::fs::write(dir.path().join("r_bounce.f32"), [0u8; 24]).unwrap();
    let o = run(&["bench", mesh.to_str().unwrap(), "--rays", "r"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("r_primary.f32") && stderr(&o).contains("24 bytes"), "{}", stderr(&o));
    let o = run(&["bench", mesh.to_str().unwrap(), "--rays", "missing"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("missing_primary.f32"), "{}", stderr(&o));
    // An unknown accelerator is a misuse of the command line.
    let o = run(&["bench", mesh.to_str().unwrap(), "--accel", "octree"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("unknown accelerator 'octree'"), "{}", stderr(&o));
}

#[test]
fn a_list_of_accelerators_is_measured_in_its_order_each_once() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = data("two-tetra.obj");
    let args = ["--json", "--reps", "3", "--width", "32", "--height", "32", "--threads", "2"];
    let o =
        run(&[&["bench", mesh.to_str().unwrap(), "--accel", "kdtree,bvh-sah,kdtree"][..], &args].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let accels: Vec<&str> = out.lines().map(|l| field(l, "accel")).collect();
    assert_eq!(accels, ["kdtree"; 4].into_iter().chain(["bvh-sah"; 4]).collect::<Vec<_>>(), "{out}");
    // Traced round by round, each still finds the same hits on every workload.
    let lines: Vec<&str> = out.lines().collect();
    for k in 0..4 {
        assert_eq!(field(lines[k], "workload"), field(lines[k + 4], "workload"));
        assert_eq!(field(lines[k], "hits"), field(lines[k + 4], "hits"), "{out}");
    }
    for bad in ["bvh-sah,", "bvh-sah,,grid", "bvh-sah,octree"] {
        let o = run(&["bench", mesh.to_str().unwrap(), "--accel", bad], dir.path());
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
        assert!(stderr(&o).contains("unknown accelerator"), "{bad}: {}", stderr(&o));
    }
}

#[test]
fn a_list_of_thread_counts_is_measured_per_accelerator_each_once() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = data("two-tetra.obj");
    let args = ["--json", "--reps", "2", "--width", "32", "--height", "32", "--accel", "bvh-sah,grid"];
    let o = run(&[&["bench", mesh.to_str().unwrap(), "--threads", "1,2,1"][..], &args].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().collect();
    // Structure by structure, then thread count (in the order given, each once), then workload.
    let order: Vec<(&str, &str)> = lines.iter().map(|l| (field(l, "accel"), field(l, "threads"))).collect();
    let mut expected = Vec::new();
    for accel in ["bvh-sah", "grid"] {
        for threads in ["1", "2"] {
            expected.extend([(accel, threads); 4]);
        }
    }
    assert_eq!(order, expected, "{out}");
    // Every structure with every thread count finds the same hits on each workload.
    for k in 0..4 {
        let hits: Vec<&str> = (0..4).map(|g| field(lines[g * 4 + k], "hits")).collect();
        assert!(hits.windows(2).all(|w| w[0] == w[1]), "{out}");
        assert!(lines.iter().skip(k).step_by(4).all(|l| field(l, "workload") == field(lines[k], "workload")));
    }
    // Each row carries its own build time.
    assert!(lines.iter().all(|l| field(l, "build_ms").parse::<f64>().unwrap() >= 0.0));
    for bad in ["1,", "0", "1,x", "", "5000"] {
        let o = run(&["bench", mesh.to_str().unwrap(), "--threads", bad], dir.path());
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
        assert!(stderr(&o).contains("is not a thread count"), "{bad}: {}", stderr(&o));
    }
}

#[test]
fn bunny_primary_hits_match_embree() {
    let Some(p) = shared_scene("stanford/bunny.ply") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let o = run(&["bench", p.to_str().unwrap(), "--json", "--reps", "1", "--accel", "bvh-sah"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let primary = out.lines().find(|l| field(l, "workload") == "primary").unwrap();
    // ../shared/bench/README.md: Embree hits 448,052 of the 1,048,576 primary rays.
    let hits: i64 = field(primary, "hits").parse().unwrap();
    assert!((hits - 448_052).abs() <= 45, "{hits} primary hits; Embree has 448052 (0.01 % = 45)");
    let packets = out.lines().find(|l| field(l, "workload") == "primary-packets").unwrap();
    assert_eq!(field(packets, "hits"), field(primary, "hits"), "packets and single rays");
    let bounce = out.lines().find(|l| field(l, "workload") == "bounce").unwrap();
    let hits: i64 = field(bounce, "hits").parse().unwrap();
    // The bounce rays are regenerated from our own hit points (not replayed), so they differ from
    // Embree's in the last bits; the hit count still agrees closely with Embree's 38,984.
    assert!((hits - 38_984).abs() <= 40, "{hits} bounce hits; Embree has 38984");
}

/// Output into a pipe whose reader has gone (`snell bench ... | head`) ends the program
/// quietly (SIGPIPE, or success if everything was written first), never with a panic.
#[test]
fn a_closed_output_pipe_is_not_a_panic() {
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let mesh = data("two-tetra.obj");
    let mut child = crate::common::snell()
        .args(["bench", mesh.to_str().unwrap(), "--accel", "all", "--reps", "2", "--width", "64", "--height", "64"])
        .current_dir(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the reading end before the first line (which comes after every build and trace).
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_ne!(o.status.code(), Some(101), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        // 13: SIGPIPE.
        assert!(o.status.success() || o.status.signal() == Some(13), "{:?}", o.status);
    }
}

/// `--walk-only` adds `bounce-walk` for each BVH: the bounce rays' walks with no triangle test,
/// so nothing blocks them, traced as many as `bounce-occluded` traces; other structures are a
/// misuse of the command line. The summary line counts the bounce rays, not the packets'.
#[test]
fn walk_only_times_the_bounce_rays_walk_without_triangle_tests() {
    let dir = tempfile::tempdir().unwrap();
    // Some bounce rays meet this ball again; its tree has many leaves (the tetrahedra's few
    // triangles are tested as one range, with no walk).
    let ball = crate::common::bumpy_ball(&mut snell_core::sampling::Pcg32::new(17, 3));
    let mut obj = String::new();
    for p in &ball.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for [a, b, c] in &ball.indices {
        obj += &format!("f {} {} {}\n", a + 1, b + 1, c + 1);
    }
    let mesh = dir.path().join("ball.obj");
    std::fs::write(&mesh, obj).unwrap();
    let args = ["--reps", "1", "--width", "40", "--height", "40", "--threads", "2", "--walk-only"];
    let o = run(
        &[&["bench", mesh.to_str().unwrap(), "--json", "--accel", "bvh-sah,bvh-bottomup"][..], &args].concat(),
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 10, "{out}");
    for accel in ["bvh-sah", "bvh-bottomup"] {
        let row = |w: &str| *lines.iter().find(|l| field(l, "accel") == accel && field(l, "workload") == w).unwrap();
        let (walk, occluded) = (row("bounce-walk"), row("bounce-occluded"));
        assert_eq!(field(walk, "hits"), "0", "{out}");
        assert_ne!(field(occluded, "hits"), "0", "{out}");
        assert_eq!(field(walk, "rays"), field(occluded, "rays"), "{out}");
    }
    let o = run(&[&["bench", mesh.to_str().unwrap()][..], &args].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let bounce_rays = out
        .lines()
        .find(|l| l.starts_with("bvh-sah") && l.contains(" bounce "))
        .unwrap()
        .split_whitespace()
        .nth(5)
        .unwrap();
    assert!(out.lines().next().unwrap().contains(&format!("1600 primary and {bounce_rays} bounce rays")), "{out}");
    assert_ne!(bounce_rays, "1600");
    let tetra = data("two-tetra.obj");
    let o = run(&[&["bench", tetra.to_str().unwrap()][..], &args].concat(), dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no tree to walk"), "{}", stderr(&o));
    for accel in ["grid", "bvh-sah,kdtree", "all"] {
        let o = run(&[&["bench", mesh.to_str().unwrap(), "--accel", accel][..], &args].concat(), dir.path());
        assert_eq!(o.status.code(), Some(2), "{accel}: {}", stderr(&o));
        assert!(stderr(&o).contains("--walk-only") && stderr(&o).contains("not a BVH"), "{accel}: {}", stderr(&o));
    }
}
