//! The PDS3 labels of the real rover data read as cameras: the same cameras and grounds as
//! `cahv_to_pinhole.py`'s list of them (`with_cameras/cameras.json`), and what dropping
//! CAHVOR's radial terms costs. These need `../shared/data/real_mars` beside the repository.

use nalgebra::Vector3;
use serde_json::Value;
use std::path::{Path, PathBuf};
use tubeloc_calib::interchange::cahv::Cahvor;
use tubeloc_calib::interchange::linearize::LinearResampling;
use tubeloc_calib::interchange::odl::OdlLabel;
use tubeloc_calib::interchange::pds::read_pds_cameras;
use tubeloc_calib::interchange::pds_label::{label_model, read_resampled_label_camera, LabelModel};

fn with_cameras() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars/with_cameras");
    assert!(d.join("cameras.json").exists(), "{} is missing: these tests need ../shared/data beside the repository", d.display());
    d
}

fn list() -> Vec<Value> {
    serde_json::from_str::<Value>(&std::fs::read_to_string(with_cameras().join("cameras.json")).unwrap()).unwrap().as_array().unwrap().clone()
}

#[test]
fn every_label_gives_the_camera_and_ground_of_the_python_list() {
    let (mut read, mut refused) = (0, 0);
    for e in list() {
        let label = with_cameras().join(e["label_file"].as_str().unwrap());
        let got = read_pds_cameras(&label);
        let (resampled, fisheye) = read_resampled_label_camera(&label).unwrap().expect("a label");
        assert_eq!(fisheye.is_some(), e["model_type"] == "CAHVORE", "{}", label.display());
        let cams = if e["model_type"] == "CAHVORE" {
            // Refused as a plain camera; its linear part, the list's pinhole, once resampled.
            let err = got.unwrap_err().to_string();
            assert!(err.contains("CAHVORE") && err.contains(label.file_name().unwrap().to_str().unwrap()), "{err}");
            refused += 1;
            vec![resampled]
        } else {
            got.unwrap().expect("a label is a PDS camera source")
        };
        assert_eq!(cams.len(), 1);
        let c = &cams[0];
        let num = |v: &Value| v.as_f64().unwrap();
        let m = &c.camera.model;
        assert_eq!((m.width as i64, m.height as i64), (e["image_width"].as_i64().unwrap(), e["image_height"].as_i64().unwrap()), "{}", label.display());
        for (got, key) in [(m.fx, "fx"), (m.fy, "fy"), (m.cx, "cx"), (m.cy, "cy")] {
            assert!((got - num(&e[key])).abs() < 1e-9 * num(&e[key]).abs().max(1.0), "{}: {key} {got} against {}", label.display(), e[key]);
        }
        let t = &c.camera.t_rig_cam;
        for k in 0..3 {
            assert!((t.translation()[k] - num(&e["camera_center_ref_m"][k])).abs() < 1e-12);
            for j in 0..3 {
                // T_rig_cam's rotation is R_cam_from_ref transposed.
                assert!((t.rotation()[(j, k)] - num(&e["R_cam_from_ref"][k][j])).abs() < 1e-9, "{}", label.display());
            }
            let up = -num(&e["R_cam_from_site"][k][2]);
            assert!((c.ground.normal[k] - up).abs() < 1e-9, "{}: ground normal {} against up {up} (axis {k})", label.display(), c.ground.normal);
        }
        assert!((c.ground.offset + num(&e["camera_height_m"])).abs() < 1e-9, "{}", label.display());
        assert_eq!(c.sol, e["sol"].as_i64());
        assert!(c.image.is_none(), "a label describes the image it is given with");
        read += 1;
    }
    assert!(read >= 117 && refused == 2, "{read} read, {refused} CAHVORE refused as plain cameras");
}

/// The largest image displacement (px) between a CAHVOR model and its linearized pinhole over
/// a 33x33 grid of pixels of the pinhole image.
fn largest_radial_displacement(m: &Cahvor, size: (u32, u32)) -> f64 {
    let lin = m.cahv.linearize().unwrap();
    let mut worst: f64 = 0.0;
    for i in 0..=32 {
        for j in 0..=32 {
            let (u, v) = (i as f64 / 32.0 * (size.0 - 1) as f64, j as f64 / 32.0 * (size.1 - 1) as f64);
            let y = (v - lin.cy) / lin.fy;
            let ray = Vector3::new((u - lin.cx - lin.skew * y) / lin.fx, y, 1.0);
            let p = lin.centre + lin.r_cam_from_ref.transpose() * ray;
            let (x1, y1) = m.project(&p).unwrap();
            worst = worst.max(((x1 - u).powi(2) + (y1 - v).powi(2)).sqrt());
        }
    }
    worst
}

#[test]
fn dropping_cahvor_radial_terms_moves_navcam_pixels_by_under_a_pixel() {
    let mut worst: Vec<(f64, String)> = Vec::new();
    for e in list().iter().filter(|e| e["model_type"] == "CAHVOR") {
        let path = with_cameras().join(e["label_file"].as_str().unwrap());
        let label = OdlLabel::parse(&std::fs::read(&path).unwrap()).unwrap();
        let LabelModel::Cahvor(m) = label_model(&label).unwrap() else { panic!("{} is CAHVOR", path.display()) };
        let size = (e["image_width"].as_u64().unwrap() as u32, e["image_height"].as_u64().unwrap() as u32);
        worst.push((largest_radial_displacement(&m, size), format!("{} {}x{}", e["instrument_id"], size.0, size.1)));
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    eprintln!("largest CAHVOR-pinhole displacement: {:?}", &worst[..3.min(worst.len())]);
    assert!(worst.len() >= 100, "{} CAHVOR labels", worst.len());
    assert!(worst[0].0 < 1.0, "{:?}", &worst[..3]);
}

#[test]
fn read_camera_takes_a_camera_json_or_a_label() {
    let e = list().into_iter().find(|e| e["model_type"] == "CAHVOR").unwrap();
    let label = with_cameras().join(e["label_file"].as_str().unwrap());
    let from_label = tubeloc_calib::read_camera(&label).unwrap();
    assert!((from_label.fx - e["fx"].as_f64().unwrap()).abs() < 1e-9);
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("cam.json");
    std::fs::write(&json, serde_json::to_string(&from_label).unwrap()).unwrap();
    assert_eq!(tubeloc_calib::read_camera(&json).unwrap(), from_label);
    let err = tubeloc_calib::read_camera(&dir.path().join("missing.LBL")).unwrap_err().to_string();
    assert!(err.contains("missing.LBL"), "{err}");
}

#[test]
fn a_hazcam_fisheye_resampled_into_its_linear_part_fills_the_frame() {
    for e in list().iter().filter(|e| e["model_type"] == "CAHVORE") {
        let path = with_cameras().join(e["label_file"].as_str().unwrap());
        let (cam, fisheye) = read_resampled_label_camera(&path).unwrap().unwrap();
        let fisheye = fisheye.unwrap();
        let size = (cam.camera.model.width, cam.camera.model.height);
        let map = LinearResampling::new(&fisheye, &cam.camera, size);
        // The fisheye sees more than the pinhole of its central scale: every pixel is covered.
        assert_eq!(map.coverage(), 1.0, "{}", path.display());
        // Taking the raw frame as the pinhole's would be far off: the corner pixel's source.
        let far = map.source_of(0, 0).unwrap();
        let centre = map.source_of(size.0 / 2, size.1 / 2).unwrap();
        let at_centre = (centre.x - (size.0 / 2) as f64).hypot(centre.y - (size.1 / 2) as f64);
        eprintln!("{}: pinhole corner (0, 0) takes raw ({:.1}, {:.1}); centre off by {at_centre:.2} px", path.display(), far.x, far.y);
        assert!(far.x > 0.1 * size.0 as f64 && far.y > 0.1 * size.1 as f64, "{far:?}");
        assert!(at_centre < 2.0, "{at_centre}");
        // Every pinhole pixel's ray images at its source (the far point), to 0.01 px.
        let m = &cam.camera;
        for (u, v) in [(0, 0), (size.0 - 1, 0), (size.0 / 3, size.1 - 1), (size.0 / 2, size.1 / 2)] {
            let s = map.source_of(u, v).unwrap();
            let dir = m.t_rig_cam.rotation() * m.model.unproject(&nalgebra::Point2::new(u as f64, v as f64)).normalize();
            let (x, y) = fisheye.project(&(m.t_rig_cam.translation() + 1000.0 * dir)).unwrap();
            assert!((x - s.x).abs() < 0.01 && (y - s.y).abs() < 0.01);
        }
    }
}

#[test]
fn the_lists_fisheye_entries_are_read_from_their_labels() {
    // `cahv_to_pinhole.py` carries a CAHVORE entry's linear part only; the model comes from the
    // label the entry names, as with that label as the rig.
    let path = with_cameras().join("cameras.json");
    let fisheyes = tubeloc_calib::interchange::pds::fisheye_cameras(&path);
    let expected: Vec<Value> = list().into_iter().filter(|e| e["model_type"] == "CAHVORE").collect();
    assert_eq!(fisheyes.len(), expected.len());
    assert!(!expected.is_empty(), "the real data holds the MER front and MSL rear Hazcam frames");
    for ((name, got), e) in fisheyes.iter().zip(&expected) {
        let image = Path::new(e["image"].as_str().unwrap()).file_name().unwrap().to_str().unwrap();
        let (camera, model) = got.as_ref().unwrap_or_else(|err| panic!("{image}: {err}"));
        assert_eq!((name.as_str(), camera.camera.name.as_str(), camera.image.as_deref(), camera.sol), (image, image, Some(image), e["sol"].as_i64()));
        let (by_label, label_model) = read_resampled_label_camera(&with_cameras().join(e["label_file"].as_str().unwrap())).unwrap().unwrap();
        assert_eq!((&camera.camera.model, camera.ground.offset), (&by_label.camera.model, by_label.ground.offset));
        assert_eq!(format!("{model:?}"), format!("{:?}", label_model.unwrap()));
    }
}

#[test]
fn a_rig_read_once_holds_what_the_separate_readers_give() {
    // `tubeloc locate --rig` reads a list (or a label) once: its pinhole cameras, then its
    // fisheye entries' cameras from their labels, with their models by camera name.
    use tubeloc_calib::interchange::pds::{fisheye_cameras, read_rig_cameras};
    let path = with_cameras().join("cameras.json");
    let read = read_rig_cameras(&path).unwrap().expect("a PDS camera list");
    let pinholes = read_pds_cameras(&path).unwrap().unwrap();
    let fisheyes = fisheye_cameras(&path);
    assert!(read.errors.is_empty(), "{:?}", read.errors);
    assert_eq!(read.cameras.len(), pinholes.len() + fisheyes.len());
    let names: Vec<&str> = read.cameras.iter().map(|c| c.camera.name.as_str()).collect();
    let expected: Vec<&str> = pinholes.iter().map(|c| c.camera.name.as_str()).chain(fisheyes.iter().map(|(n, _)| n.as_str())).collect();
    assert_eq!(names, expected);
    for (name, got) in &fisheyes {
        let (camera, model) = got.as_ref().unwrap();
        let mine = read.cameras.iter().find(|c| &c.camera.name == name).unwrap();
        assert_eq!((&mine.camera.model, mine.ground.offset), (&camera.camera.model, camera.ground.offset));
        assert_eq!(format!("{:?}", read.fisheye_models[name]), format!("{model:?}"));
    }
    assert_eq!(read.fisheye_models.len(), fisheyes.len());
    // A fisheye's label alone: its linear camera and its model.
    let label = with_cameras().join("labels").join("1f581291004ednd2fcp1121r0m1.img.lbl");
    let one = read_rig_cameras(&label).unwrap().expect("a PDS3 label");
    let (by_label, model) = read_resampled_label_camera(&label).unwrap().unwrap();
    assert_eq!(one.cameras.len(), 1);
    assert_eq!(one.cameras[0].camera.model, by_label.camera.model);
    assert_eq!(one.fisheye_models.get(&by_label.camera.name).map(|m| format!("{m:?}")), model.map(|m| format!("{m:?}")));
    // A tubeloc rig (a JSON object): not a PDS rig.
    let rig = std::env::temp_dir().join(format!("tubeloc_rig_once_{}.json", std::process::id()));
    std::fs::write(&rig, "{\"cameras\": []}").unwrap();
    assert!(read_rig_cameras(&rig).unwrap().is_none());
    std::fs::remove_file(&rig).ok();
}
