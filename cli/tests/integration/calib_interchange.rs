//! `tubeloc calib rig` writes ROS camera_info and kalibr camchain files, and every `--rig`
//! reads them back through one reader.

use crate::common;
use common::{ok, p, stderr, tubeloc};

#[test]
fn calib_rig_exports_ros_and_kalibr_and_rig_arguments_read_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let set = d.join("set");
    ok(&["synth", "calib", "--default-rig", "--views", "12", "--no-images", "--out", p(&set)]);
    let (json, cv, ros, chain) = (d.join("rig.json"), d.join("rig.yaml"), d.join("ros"), d.join("camchain.yaml"));
    ok(&["calib", "rig", "--views", p(&set), "--corners", "exact", "--fix-k3", "--out", p(&json), "--yaml", p(&cv), "--ros", p(&ros), "--camchain", p(&chain)]);
    let mut names: Vec<String> = std::fs::read_dir(&ros).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["L20.yaml", "L40.yaml", "R20.yaml", "R40.yaml"]);
    let ours = tubeloc_calib::read_rig(&json).unwrap();
    for f in [&cv, &chain] {
        let back = tubeloc_calib::read_rig(f).unwrap();
        assert_eq!(back.stereo_pairs, ours.stereo_pairs);
        for (a, b) in ours.cameras.iter().zip(&back.cameras) {
            assert_eq!((&a.name, a.model.width), (&b.name, b.model.width));
            assert!((a.model.fx - b.model.fx).abs() <= 1e-12 * a.model.fx, "{}: fx {} vs {}", f.display(), a.model.fx, b.model.fx);
        }
    }
    // A command's --rig reads the camchain (by content: the extension says nothing).
    let renamed = d.join("chain.json.txt");
    std::fs::copy(&chain, &renamed).unwrap();
    ok(&["synth", "calib", "--rig", p(&renamed), "--views", "2", "--no-images", "--out", p(&d.join("again"))]);
}

#[test]
fn camchain_needs_fix_k3_and_unknown_rig_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = tubeloc(&["calib", "rig", "--views", p(d), "--out", p(&d.join("r.json")), "--camchain", p(&d.join("c.yaml"))]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--fix-k3"), "{}", stderr(&o));
    let junk = d.join("notes.txt");
    std::fs::write(&junk, "hello: world\n").unwrap();
    let o = tubeloc(&["locate", "--rig", p(&junk), "--image", p(&d.join("x.png")), "--out", p(&d.join("o.json"))]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains(&format!("{}: not a rig file in a known format; tried tubeloc JSON", junk.display())) && e.contains("kalibr camchain"), "{e}");
}

/// Calibrating from rendered tag images (the default rig, tags detected by the AprilTag
/// library) leaves nothing on stderr from the C library: no `WRN: Matrix is singular.` from
/// its homography step, and the bundle adjustment has no gauge freedom to warn about. The
/// views detected one at a time (`--threads 1`) give the same rig, byte for byte, as two at once.
#[test]
fn calibrating_from_tag_images_prints_no_library_warning() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let set = d.join("set");
    let synth = ok(&["synth", "calib", "--default-rig", "--views", "8", "--out", p(&set)]);
    let rig = ok(&["calib", "rig", "--views", p(&set), "--out", p(&d.join("rig.json"))]);
    for (what, o) in [("synth calib", &synth), ("calib rig", &rig)] {
        let e = stderr(o);
        assert!(!e.contains("WRN") && !e.contains("singular"), "{what} printed a library warning:\n{e}");
    }
    assert!(String::from_utf8_lossy(&rig.stdout).contains("overall rms"), "{}", String::from_utf8_lossy(&rig.stdout));
    ok(&["calib", "rig", "--views", p(&set), "--threads", "1", "--out", p(&d.join("rig1.json"))]);
    assert_eq!(std::fs::read(d.join("rig1.json")).unwrap(), std::fs::read(d.join("rig.json")).unwrap(), "--threads 1 and 2 give different rigs");
}
