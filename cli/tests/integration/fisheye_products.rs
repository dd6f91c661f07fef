//! `tubeloc locate` on fisheye (CAHVORE) products: a rendered frame (or stereo pair) seen
//! through a CAHVORE lens whose linear part is the render's pinhole, written as PDS3 products,
//! locates as the render does once resampled, and worse taken as its pinhole.

use crate::common;

use common::{ok, p, stderr, tubeloc};
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use std::path::Path;
use tubeloc_calib::interchange::cahv::{Cahv, Cahvor};
use tubeloc_calib::interchange::cahvore::Cahvore;

fn read(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn vec3(v: &Value) -> Vector3<f64> {
    Vector3::from_fn(|i, _| v[i].as_f64().unwrap())
}

/// The image `pinhole` (camera `fx fy cx cy`, axes `r` at `centre` in the rover frame) seen
/// through the CAHVORE lens `lens`: each pixel samples the pinhole image bilinearly where its
/// ray lands; black where the pinhole does not see.
fn through_lens(pinhole: &image::RgbImage, cam: &Value, r: &Matrix3<f64>, centre: &Vector3<f64>, lens: &Cahvore) -> image::RgbImage {
    let f = |k: &str| cam[k].as_f64().unwrap();
    let (w, h) = pinhole.dimensions();
    image::RgbImage::from_fn(w, h, |x, y| {
        let Some((origin, dir)) = lens.ray(x as f64, y as f64) else { return image::Rgb([0; 3]) };
        let q = r.transpose() * (origin + 1000.0 * dir - centre);
        let (u, v) = (f("fx") * q.x / q.z + f("cx"), f("fy") * q.y / q.z + f("cy"));
        // The render's border pixels stand for a pixel beyond it (a lens sees past the frame).
        let inside = |t: f64, n: u32| (-2.0..=(n + 1) as f64).contains(&t);
        if q.z <= 0.0 || !inside(u, w) || !inside(v, h) {
            return image::Rgb([0; 3]);
        }
        let (u, v) = (u.clamp(0.0, (w - 1) as f64), v.clamp(0.0, (h - 1) as f64));
        let (u0, v0) = ((u as u32).min(w - 2), (v as u32).min(h - 2));
        let (fu, fv) = (u - u0 as f64, v - v0 as f64);
        let at = |i: u32, j: u32, k: usize| pinhole.get_pixel(i, j).0[k] as f64;
        image::Rgb([0, 1, 2].map(|k| {
            let top = at(u0, v0, k) * (1.0 - fu) + at(u0 + 1, v0, k) * fu;
            let bottom = at(u0, v0 + 1, k) * (1.0 - fu) + at(u0 + 1, v0 + 1, k) * fu;
            (top * (1.0 - fv) + bottom * fv).round() as u8
        }))
    })
}

/// A general CAHVORE lens (type 3, linearity 0.37, a pupil moving 2 mm) whose linear part is
/// the pinhole `cam` with axes `r` at `c` in the rover frame, with the barrel term `r1`; and its
/// label lines `MODEL_COMPONENT_5` to `_9`.
fn lens_of(cam: &Value, r: &Matrix3<f64>, c: &Vector3<f64>, r1: f64) -> (Cahvore, String) {
    let (a, x, y) = (r.column(2).into_owned(), r.column(0).into_owned(), r.column(1).into_owned());
    let f = |k: &str| cam[k].as_f64().unwrap();
    let cahv = Cahv { c: *c, a, h: f("fx") * x + f("cx") * a, v: f("fy") * y + f("cy") * a };
    let lens = Cahvore { cahvor: Cahvor { cahv, o: a, r: [0.0, r1, 0.0] }, e: [0.002, 0.001, 0.0], linearity: 0.37 };
    let t = |w: &Vector3<f64>| format!("({:.17e},{:.17e},{:.17e})", w.x, w.y, w.z);
    let lines = format!("  MODEL_COMPONENT_5 = {}\n  MODEL_COMPONENT_6 = (0.0,{r1:.17e},0.0)\n  MODEL_COMPONENT_7 = (0.002,0.001,0.0)\n  MODEL_COMPONENT_8 = 3.0\n  MODEL_COMPONENT_9 = 0.37\n", t(&a));
    (lens, lines)
}

/// `v` (a JSON object) with `key` set to the string `value`.
fn dict_with(v: &Value, key: &str, value: &str) -> Value {
    let mut v = v.clone();
    v[key] = Value::String(value.to_string());
    v
}

/// Distance (m) from each true tube centre of `truth` to the nearest located tube of `doc`
/// (centres in the camera frame), sorted.
fn centre_errors(truth: &[Vector3<f64>], doc: &Value) -> Vec<f64> {
    let got: Vec<Vector3<f64>> = doc["tubes"].as_array().unwrap().iter().filter(|t| t["status"] == "located").map(|t| vec3(&t["centre"])).collect();
    let mut g: Vec<f64> = truth.iter().map(|t| got.iter().map(|q| (q - t).norm()).fold(f64::INFINITY, f64::min)).collect();
    g.sort_by(f64::total_cmp);
    g
}

#[test]
fn a_fisheye_product_locates_as_its_pinhole_render_once_resampled() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path();
    let set = tmp.join("st");
    // A 384 px crop of a rendered frame, f 430 px: it reaches 30 degrees off the axis.
    ok(&["synth", "--preset", "tiny", "--out", p(&set), "--scenes", "1", "--resolution", "384"]);
    let im = read(&set.join("annotations.json"))["images"][1].clone();
    let m3 = |v: &Value| Matrix3::from_fn(|i, j| v[i][j].as_f64().unwrap());
    let (r_wl, t_wl) = (m3(&im["T_world_cam"]["rotation"]), vec3(&im["T_world_cam"]["translation"]));
    let cam = &im["camera"];
    let rows = [0, 1, 2].map(|i| [0, 1, 2].map(|j| r_wl[(i, j)]));
    let pose = serde_json::json!({"rotation": rows, "translation": [t_wl.x, t_wl.y, t_wl.z]});
    let rig_path = tmp.join("rig.json");
    std::fs::write(&rig_path, serde_json::json!({"cameras": [{"name": "L", "model": cam, "T_rig_cam": pose}]}).to_string()).unwrap();
    let png = set.join("images").join(im["file_name"].as_str().unwrap());
    let render = image::open(&png).unwrap().to_rgb8();
    // The rover frame is the world with y and z flipped (z down).
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    let (r, c) = (flip * r_wl, flip * t_wl);
    let f = |k: &str| cam[k].as_f64().unwrap();
    // Barrel distortion and the lens type move the far edge of this frame by tens of pixels.
    let (lens, components) = lens_of(cam, &r, &c, -0.04);
    let fish = through_lens(&render, cam, &r, &c, &lens);
    let edge = {
        let (x1, _) = lens.project(&(c + r * Vector3::new(((383.0 - f("cx")) / f("fx")) * 1000.0, 0.0, 1000.0))).unwrap();
        383.0 - x1
    };
    assert!(edge > 10.0, "the lens moves the right edge by {edge} px only");
    let (fish_img, as_pinhole) = (tmp.join("FISH.IMG"), tmp.join("PIN.IMG"));
    common::pds3_product(&fish_img, &fish, cam, &r, &c, &components);
    common::pds3_product(&as_pinhole, &fish, cam, &r, &c, "");
    let n = r_wl.transpose() * Vector3::z();
    let ground = format!("--ground={},{},{},{}", n.x, n.y, n.z, im["ground_height_m"].as_f64().unwrap() - t_wl.z);
    let run = |args: &[&str], out: &str| -> Value {
        let out = tmp.join(out);
        let o = tubeloc(&[args, &["--out", p(&out), &ground]].concat());
        assert!(matches!(o.status.code(), Some(0) | Some(3)), "{}", stderr(&o));
        read(&out)
    };
    let by_render = run(&["locate", "--rig", p(&rig_path), "--image", p(&png)], "render.json");
    let resampled = run(&["locate", "--label-cameras", "--image", p(&fish_img)], "fish.json");
    let unresampled = run(&["locate", "--label-cameras", "--image", p(&as_pinhole)], "pin.json");
    assert_eq!((resampled["resampled_from"].as_str(), unresampled.get("resampled_from")), (Some("CAHVORE"), None));
    // A PDS camera list (`cahv_to_pinhole.py`'s shape) whose CAHVORE entry names the product's
    // label: `locate --rig LIST` reads the model from it and resamples as the label does.
    let fish_png = tmp.join("fish.png");
    fish.save(&fish_png).unwrap();
    let list = tmp.join("cameras.json");
    let entry = serde_json::json!({"image": "images/fish.png", "label_file": "FISH.IMG", "model_type": "CAHVORE", "sol": 7});
    std::fs::write(&list, serde_json::json!([entry]).to_string()).unwrap();
    let by_list = run(&["locate", "--rig", p(&list), "--image", p(&fish_png)], "list.json");
    assert_eq!((by_list["resampled_from"].as_str(), by_list["camera"].as_str()), (Some("CAHVORE"), Some("fish.png")));
    assert_eq!((&by_list["camera_model"], &by_list["up_cam"]), (&resampled["camera_model"], &resampled["up_cam"]));
    let located = |d: &Value| d["tubes"].as_array().unwrap().iter().map(|t| (t["status"].clone(), t["centre"].clone())).collect::<Vec<_>>();
    assert!(!located(&resampled).is_empty() && located(&by_list) == located(&resampled), "{by_list}");
    // An entry whose label is missing fails its frame, naming the list, the image and the label.
    std::fs::write(&list, serde_json::json!([dict_with(&entry, "label_file", "GONE.IMG")]).to_string()).unwrap();
    let o = tubeloc(&["locate", "--rig", p(&list), "--image", p(&fish_png), "--out", p(&tmp.join("gone.json")), &ground]);
    let err = stderr(&o);
    assert!(o.status.code() == Some(1) && err.contains("cameras.json") && err.contains("fish.png") && err.contains("GONE.IMG"), "{err}");
    // Each tube of the scene against the nearest located tube of a run.
    let image_id = im["id"].clone();
    let truth: Vec<Vector3<f64>> = read(&set.join("annotations.json"))["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image_id).map(|a| vec3(&a["T_cam_tube"]["translation"])).collect();
    let (g_render, g_res, g_raw) = (centre_errors(&truth, &by_render), centre_errors(&truth, &resampled), centre_errors(&truth, &unresampled));
    eprintln!("centre errors (m) of the {} tubes: render {g_render:.4?}; resampled {g_res:.4?}; taken as its pinhole {g_raw:.4?}", truth.len());
    // Resampled, every tube is found about as well as in the render (3.9 mm median, 2.4 cm at
    // worst, against 4.6 mm and 2.6 cm); taken as its pinhole, most are lost (0.44 m median).
    let median = |g: &[f64]| g[g.len() / 2];
    assert!(g_res.len() >= 5 && g_res[g_res.len() - 1] < 0.03 && median(&g_res) < 0.01, "resampled: {g_res:?}");
    assert!(median(&g_raw) > 0.1, "taken as its pinhole: {g_raw:?}");
    // Resampled at 0.8 of the linear part's focal length (more of the fisheye's field, at a
    // coarser scale), most tubes are fitted too (4 of 6 within 2 cm, 3 within 1.2 cm, with the
    // model of record 0086), at a lower probability (under the acceptance threshold: a coarser
    // image than the detector was calibrated on).
    let wider = run(&["locate", "--label-cameras", "--image", p(&fish_img), "--fisheye-scale", "0.8"], "wider.json");
    assert!((wider["camera_model"]["fx"].as_f64().unwrap() - 0.8 * f("fx")).abs() < 1e-9 && wider["camera_model"]["cx"] == resampled["camera_model"]["cx"]);
    let fitted: Vec<Vector3<f64>> = wider["tubes"].as_array().unwrap().iter().filter(|t| t["converged"] == true).map(|t| vec3(&t["centre"])).collect();
    let mut g_wide: Vec<f64> = truth.iter().map(|t| fitted.iter().map(|q| (q - t).norm()).fold(f64::INFINITY, f64::min)).collect();
    g_wide.sort_by(f64::total_cmp);
    eprintln!("fitted at 0.8 focal length: {g_wide:.4?}");
    assert!(g_wide[3] < 0.03 && g_wide[2] < 0.015, "at 0.8: {g_wide:?}");
    // Line2D templates built for the label are those of its linear camera, the resampled
    // image's, and locate with them.
    let lin_cam = tmp.join("linear.json");
    std::fs::write(&lin_cam, resampled["camera_model"].to_string()).unwrap();
    let coarse = ["templates", "build", "--step-deg", "30", "--distances", "2:3:0.5", "--inplane-range-deg", "0"];
    let (lib_label, lib_json) = (tmp.join("label.tlt"), tmp.join("json.tlt"));
    ok(&[&coarse[..], &["--camera", p(&fish_img), "--out", p(&lib_label)]].concat());
    ok(&[&coarse[..], &["--camera", p(&lin_cam), "--out", p(&lib_json)]].concat());
    assert!(std::fs::read(&lib_label).unwrap() == std::fs::read(&lib_json).unwrap(), "the label's library differs from its linear camera's");
    let by_line2d = run(&["locate", "--label-cameras", "--image", p(&fish_img), "--detector", "line2d", "--templates", p(&lib_label)], "line2d.json");
    assert_eq!((by_line2d["resampled_from"].as_str(), by_line2d["detector"].as_str()), (Some("CAHVORE"), Some("line2d")));
    // Commands that would take the raw frame as a pinhole refuse the label, naming `locate`.
    let o = tubeloc(&["detect", "--method", "learned", "--image", p(&fish_img), "--camera", p(&fish_img), "--out", p(&tmp.join("d.json"))]);
    let err = stderr(&o);
    assert!(o.status.code() == Some(1) && err.contains("FISH.IMG") && err.contains("CAHVORE") && err.contains("tubeloc locate"), "{err}");
}

#[test]
fn a_stereo_pair_of_fisheye_products_is_resampled_image_by_image() {
    // Rendered stereo pairs (384 px crops, f 1720 px), each image seen through its own CAHVORE
    // lens with a strong barrel term (the crops' far edges move by tens of pixels): `locate
    // --label-cameras --image L --right R` resamples both images before the stereo term, and
    // places the best tube of each pair within a few millimetres of where the rendered pair
    // does; taken as pinholes, the pair places it centimetres off or loses it.
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path();
    let set = tmp.join("st");
    ok(&["synth", "stereo", "--out", p(&set), "--scenes", "1", "--pairs-per-scene", "3", "--resolution", "384", "--seed", "1"]);
    let ann = read(&set.join("annotations.json"));
    let m3 = |v: &Value| Matrix3::from_fn(|i, j| v[i][j].as_f64().unwrap());
    let pose = |r: &Matrix3<f64>, t: &Vector3<f64>| {
        let rows = [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[(i, j)]));
        serde_json::json!({"rotation": rows, "translation": [t.x, t.y, t.z]})
    };
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    for (k, im) in ann["images"].as_array().unwrap().iter().enumerate() {
        let (r_wl, t_wl) = (m3(&im["T_world_cam"]["rotation"]), vec3(&im["T_world_cam"]["translation"]));
        let (r_lr, t_lr) = (m3(&im["T_left_right"]["rotation"]), vec3(&im["T_left_right"]["translation"]));
        let (r_wr, t_wr) = (r_wl * r_lr, t_wl + r_wl * t_lr);
        let rig = serde_json::json!({"cameras": [{"name": "L", "model": im["camera"], "T_rig_cam": pose(&r_wl, &t_wl)}, {"name": "R", "model": im["right_camera"], "T_rig_cam": pose(&r_wr, &t_wr)}], "stereo_pairs": [["L", "R"]]});
        let rig_path = tmp.join(format!("rig{k}.json"));
        std::fs::write(&rig_path, rig.to_string()).unwrap();
        let (left_png, right_png) = (set.join("images").join(im["file_name"].as_str().unwrap()), set.join("right").join(im["right_file_name"].as_str().unwrap()));
        let product = |name: &str| tmp.join(format!("{name}{k}.IMG"));
        for (side, png, cam, r, c) in [("L", &left_png, &im["camera"], flip * r_wl, flip * t_wl), ("R", &right_png, &im["right_camera"], flip * r_wr, flip * t_wr)] {
            let (lens, lines) = lens_of(cam, &r, &c, -1.0);
            let fish = through_lens(&image::open(png).unwrap().to_rgb8(), cam, &r, &c, &lens);
            common::pds3_product(&product(side), &fish, cam, &r, &c, &lines);
            common::pds3_product(&product(&format!("P{side}")), &fish, cam, &r, &c, "");
        }
        let n = r_wl.transpose() * Vector3::z();
        let ground = format!("--ground={},{},{},{}", n.x, n.y, n.z, im["ground_height_m"].as_f64().unwrap() - t_wl.z);
        let run = |args: &[&str], out: &str| -> Value {
            let out = tmp.join(format!("{out}{k}.json"));
            let o = tubeloc(&[args, &["--out", p(&out), &ground]].concat());
            assert!(matches!(o.status.code(), Some(0) | Some(3)), "{}", stderr(&o));
            read(&out)
        };
        let by_rig = run(&["locate", "--rig", p(&rig_path), "--image", p(&left_png), "--right", p(&right_png)], "rig");
        let fish = run(&["locate", "--label-cameras", "--image", p(&product("L")), "--right", p(&product("R"))], "fish");
        let raw = run(&["locate", "--label-cameras", "--image", p(&product("PL")), "--right", p(&product("PR"))], "raw");
        assert_eq!(fish["resampled_from"].as_str(), Some("CAHVORE"));
        let truth: Vec<Vector3<f64>> = ann["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == im["id"]).map(|a| vec3(&a["T_cam_tube"]["translation"])).collect();
        let (g_rig, g_fish, g_raw) = (centre_errors(&truth, &by_rig), centre_errors(&truth, &fish), centre_errors(&truth, &raw));
        let points = |doc: &Value| doc["tubes"].as_array().unwrap().iter().map(|t| t["residuals"]["stereo_points"].as_f64().unwrap_or(0.0)).sum::<f64>();
        eprintln!("pair {k}: best centre error (m) rendered {:.4}, fisheye resampled {:.4}, taken as pinholes {:.4}; stereo points {} / {} / {}", g_rig[0], g_fish[0], g_raw[0], points(&by_rig), points(&fish), points(&raw));
        assert!(g_rig[0] < 0.015 && g_fish[0] <= g_rig[0] + 0.005 && points(&fish) > 0.0, "pair {k}: {g_fish:?} against {g_rig:?}");
        assert!(g_raw[0] >= g_fish[0] + 0.004, "pair {k}: taken as pinholes {g_raw:?} against {g_fish:?}");
    }
}
