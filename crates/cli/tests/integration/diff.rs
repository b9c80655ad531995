//! `snell diff`: the numbers against hand computation, the formats, and bad input.

use crate::common::{pfm, run, stderr};

fn json_field(s: &str, key: &str) -> f64 {
    let i = s.find(&format!("\"{key}\":")).unwrap_or_else(|| panic!("{key} missing in {s}")) + key.len() + 3;
    s[i..].split([',', '}']).next().unwrap().parse().unwrap()
}

#[test]
fn diff_reports_relmse_rmse_and_means() {
    let dir = tempfile::tempdir().unwrap();
    let r = [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]];
    let t = [[1.1, 1.0, 1.0], [0.1, 0.1, 0.1]];
    std::fs::write(dir.path().join("r.pfm"), pfm(2, 1, &r)).unwrap();
    std::fs::write(dir.path().join("t.pfm"), pfm(2, 1, &t)).unwrap();
    let o = run(&["diff", "t.pfm", "r.pfm", "--json", "--error", "e.png"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let s = String::from_utf8_lossy(&o.stdout);
    // relMSE: pixel 1: (0.01 / 1.01) / 3; pixel 2: 3 · (0.01 / 0.01) / 3 = 1; mean over 2 pixels.
    let expect = (0.01 / 1.01 / 3.0 + 1.0) / 2.0;
    assert!((json_field(&s, "relmse") - expect).abs() < 1e-6, "{s}");
    // RMSE over 6 channel values: 4 of them differ by 0.1.
    let rmse = (4.0 * 0.01f64 / 6.0).sqrt();
    assert!((json_field(&s, "rmse") - rmse).abs() < 1e-6, "{s}");
    assert!(dir.path().join("e.png").is_file());
    // An image against itself.
    let o = run(&["diff", "r.pfm", "r.pfm", "--json"], dir.path());
    assert_eq!(json_field(&String::from_utf8_lossy(&o.stdout), "relmse"), 0.0);
}

#[test]
fn diff_reads_exr_and_png_and_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let common = ["render", "--width", "8", "--height", "6", "--spp", "1"];
    for out in ["a.exr", "a.png"] {
        let o = run(&[&common[..], &["-o", out]].concat(), dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
    }
    // PNG is 8-bit sRGB: close to the EXR, not equal.
    let o = run(&["diff", "a.png", "a.exr", "--json"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let rel = json_field(&String::from_utf8_lossy(&o.stdout), "relmse");
    assert!(rel > 0.0 && rel < 0.05, "{rel}");
    let o = run(&["render", "--width", "4", "--height", "6", "--spp", "1", "-o", "b.exr"], dir.path());
    assert!(o.status.success());
    let o = run(&["diff", "a.exr", "b.exr"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("differ in size"), "{}", stderr(&o));
    std::fs::write(dir.path().join("bad.pfm"), b"PF\n4 4\n-1.0\n\x00\x00").unwrap();
    let o = run(&["diff", "bad.pfm", "a.exr"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("bad.pfm") && stderr(&o).contains("truncated"), "{}", stderr(&o));
    let o = run(&["diff", "missing.exr", "a.exr"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    let o = run(&["diff", "a.exr"], dir.path());
    assert_eq!(o.status.code(), Some(2));
}
