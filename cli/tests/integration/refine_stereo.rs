//! `tubeloc refine --dataset --stereo` on a small rendered stereo set (3 pairs of 384 px crops
//! of the paper preset, 20 cm baseline): seeds = exact poses perturbed by 10 mm / 5 degrees.

use crate::common;

use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// Runs `tubeloc` with `args`, asserts success and returns its standard error.
fn ok(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(args).output().expect("running tubeloc");
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "tubeloc {args:?} failed: {stderr}");
    stderr
}

fn read(p: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(p).expect("reading JSON")).expect("parsing JSON")
}

fn vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().expect("array");
    [a[0].as_f64().expect("x"), a[1].as_f64().expect("y"), a[2].as_f64().expect("z")]
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

#[test]
fn stereo_term_fixes_the_depth_that_mono_loses() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let set = tmp.path().join("st");
    ok(&["synth", "stereo", "--out", set.to_str().unwrap(), "--scenes", "1", "--pairs-per-scene", "3", "--resolution", "384", "--seed", "1"]);
    let ann = read(&set.join("annotations.json"));
    let img0 = &ann["images"][0];
    let fb = img0["camera"]["fx"].as_f64().unwrap() * img0["baseline_m"].as_f64().unwrap();
    // Exact centres per image (tubes at least half visible, as --gt-seeds seeds them, same order).
    let mut truth: std::collections::BTreeMap<u64, Vec<[f64; 3]>> = Default::default();
    for a in ann["annotations"].as_array().unwrap() {
        if a["visible_fraction"].as_f64().unwrap() >= 0.5 {
            truth.entry(a["image_id"].as_u64().unwrap()).or_default().push(vec3(&a["T_cam_tube"]["translation"]));
        }
    }
    let (mut depth_st, mut depth_mono, mut centre_st, mut zs) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut stderr_st0 = String::new();
    for seed in ["0", "1", "2"] {
        let (mono, st) = (tmp.path().join(format!("mono{seed}.json")), tmp.path().join(format!("st{seed}.json")));
        let base = ["refine", "--dataset", set.to_str().unwrap(), "--gt-seeds", "10,5", "--seed", seed];
        ok(&[&base[..], &["--out", mono.to_str().unwrap()]].concat());
        let stderr = ok(&[&base[..], &["--stereo", "--out", st.to_str().unwrap()]].concat());
        if seed == "0" {
            stderr_st0 = stderr;
        }
        let (pm, ps) = (read(&mono), read(&st));
        let (pm, ps) = (pm.as_array().unwrap(), ps.as_array().unwrap());
        assert_eq!(pm.len(), ps.len());
        for (m, s) in pm.iter().zip(ps) {
            // Tubes outside the right crop have no stereo points: nothing to compare.
            if s["residuals"]["stereo_points"].as_u64().unwrap_or(0) < 50 {
                continue;
            }
            let c = vec3(&s["centre"]);
            let g = truth[&s["image_id"].as_u64().unwrap()].iter().copied().min_by(|a, b| dist(a, &c).total_cmp(&dist(b, &c))).expect("a true tube in the image");
            let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let along = |p: &[f64; 3]| ((p[0] - g[0]) * g[0] + (p[1] - g[1]) * g[1] + (p[2] - g[2]) * g[2]).abs() / n;
            depth_st.push(along(&c));
            depth_mono.push(along(&vec3(&m["centre"])));
            centre_st.push(dist(&c, &g));
            zs.push(g[2]);
        }
    }
    assert!(depth_st.len() >= 8, "only {} tubes with stereo points", depth_st.len());
    // The tubes outside the right crop (mono poses) are left out of the truths by --in-both-views.
    let truths = |extra: &[&str]| {
        let out = tmp.path().join(format!("eval{}", extra.len()));
        ok(&[&["eval", "--gt", set.join("annotations.json").to_str().unwrap(), "--poses", tmp.path().join("st0.json").to_str().unwrap(), "--out", out.to_str().unwrap()], extra].concat());
        let m = read(&out.join("pose_metrics.json"));
        assert_eq!(m["in_both_views"].as_bool(), Some(!extra.is_empty()));
        m["poses"][0]["n_truths"].as_u64().unwrap()
    };
    let (all, both) = (truths(&[]), truths(&["--in-both-views"]));
    assert!(both >= 1 && both < all, "{both} of {all} truths in both views");
    // The run says how many of its poses are mono for want of stereo points.
    let without = read(&tmp.path().join("st0.json")).as_array().unwrap().iter().filter(|p| p["converged"].as_bool() == Some(true) && p["residuals"]["stereo_points"].as_u64() == Some(0)).count();
    assert!(without >= 1, "every tube has stereo points");
    assert!(stderr_st0.contains(&format!("{without} converged poses have no stereo points")), "{stderr_st0}");
    // And how long the fits took, over every seed it refined.
    let n_poses = read(&tmp.path().join("st0.json")).as_array().unwrap().len();
    assert!(stderr_st0.contains("refinement time per seed") && stderr_st0.contains(&format!(" over {n_poses} seeds on ")), "{stderr_st0}");
    let (ds, dm, cs, z) = (median(&mut depth_st), median(&mut depth_mono), median(&mut centre_st), median(&mut zs));
    // SGM's disparity on these ~15 px wide tubes is off by about half a pixel (tube pixels of the
    // stereo crate's evaluation): depth error Z² · 0.5 px / (f B); allow 0.75 px.
    let bound = z * z * 0.75 / fb;
    eprintln!("median depth error: stereo {:.1} mm, mono {:.1} mm (bound {:.1} mm); stereo centre {:.1} mm", ds * 1e3, dm * 1e3, bound * 1e3, cs * 1e3);
    assert!(ds < bound, "stereo median depth error {:.1} mm >= {:.1} mm", ds * 1e3, bound * 1e3);
    assert!(ds < dm / 3.0, "stereo {:.1} mm is not clearly better than mono {:.1} mm in depth", ds * 1e3, dm * 1e3);
    // The seeds are within ±10 mm per coordinate: a stereo fit does not drift beyond twice that.
    assert!(cs < 0.02, "stereo median centre error {:.1} mm", cs * 1e3);
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// `refine` does not depend on `stereo`, so its covariance's count of stereo points per
/// independent measurement mirrors the default SGM census window by hand; this keeps the two
/// in step.
#[test]
fn stereo_points_per_measurement_is_the_default_census_window() {
    let sgm = tubeloc_stereo::sgm::SgmParams::default();
    let refine = tubeloc_refine::RefineConfig::default();
    assert_eq!(refine.solver.stereo_points_per_measurement, (sgm.census_width * sgm.census_height) as f64, "census window {}x{}", sgm.census_width, sgm.census_height);
}

/// Mask detections (the learned segmenter's kind: mask, image axis, no template pose) refined in
/// stereo with the ground plane keep the mask seeds' ground tilt prior through the later stereo
/// stages (two-view contour fit, rims): the tubes, which lie flat, come out parallel to the
/// ground and their axes close to the truth. The detections are the annotation masks with axis
/// seeds turned 2 degrees and moved 2 px off the true image axis.
#[test]
fn mask_detections_in_stereo_with_ground_stay_parallel_to_it() {
    let ms = MaskSet::new("4");
    let ann = read(&ms.set.join("annotations.json"));
    let images: std::collections::BTreeMap<u64, &Value> = ann["images"].as_array().unwrap().iter().map(|i| (i["id"].as_u64().unwrap(), i)).collect();
    let truths = &ms.truths;
    assert!(truths.len() >= 6, "only {} tubes at least half visible", truths.len());
    let poses = ms.refine(&[]);
    let (mut errors, mut matched) = (Vec::new(), 0);
    for p in poses.as_array().unwrap().iter().filter(|p| p["converged"].as_bool() == Some(true)) {
        let id = p["image_id"].as_u64().unwrap();
        let (c, a) = (vec3(&p["centre"]), vec3(&p["axis"]));
        let Some((_, _, ta, _)) = truths.iter().filter(|t| t.0 == id).min_by(|x, y| dist(&x.1, &c).total_cmp(&dist(&y.1, &c))).filter(|t| dist(&t.1, &c) < 0.05) else { continue };
        matched += 1;
        // Upward normal of the world ground (z = 0) in the camera frame: R_world_cam^T z.
        let rot = images[&id]["T_world_cam"]["rotation"].as_array().unwrap();
        let up = [0, 1, 2].map(|i| rot[2][i].as_f64().unwrap());
        let tilt = (a[0] * up[0] + a[1] * up[1] + a[2] * up[2]).abs().asin().to_degrees();
        let true_tilt = (ta[0] * up[0] + ta[1] * up[1] + ta[2] * up[2]).abs().asin().to_degrees();
        assert!((tilt - true_tilt).abs() < 0.5, "image {id}: fitted tilt {tilt:.2} deg against the truth's {true_tilt:.2}");
        errors.push((a[0] * ta[0] + a[1] * ta[1] + a[2] * ta[2]).abs().min(1.0).acos().to_degrees());
    }
    assert!(matched * 4 >= truths.len() * 3, "{matched} of {} tubes refined within 50 mm", truths.len());
    assert!(median(&mut errors) < 0.5, "axis error median {:.2} deg", median(&mut errors));
}

/// Tubes with one end hidden (by a rock, a sand mound or the image border) refined in stereo from
/// their visible masks: the fit alone centres them on what is visible, half the hidden length off
/// along the axis; the visible-end anchoring (`tubeloc_refine::hidden_end`, on by default) puts
/// them back.
#[test]
fn tubes_with_a_hidden_end_are_anchored_at_the_visible_one() {
    let ms = MaskSet::new("6");
    let truths = &ms.truths;
    // |along-axis centre error| (mm) of the partly hidden tubes, and how many poses were anchored.
    let along = |extra: &[&str]| {
        let poses = ms.refine(extra);
        let mut errs = Vec::new();
        let mut anchored = 0;
        for p in poses.as_array().unwrap().iter().filter(|p| p["converged"].as_bool() == Some(true)) {
            anchored += p.get("end_anchored").is_some_and(|v| v.is_string()) as usize;
            let (id, c) = (p["image_id"].as_u64().unwrap(), vec3(&p["centre"]));
            let Some((_, tc, ta, vis)) = truths.iter().filter(|t| t.0 == id).min_by(|x, y| dist(&x.1, &c).total_cmp(&dist(&y.1, &c))).filter(|t| dist(&t.1, &c) < 0.08) else { continue };
            if *vis < 0.85 {
                errs.push(1e3 * ((c[0] - tc[0]) * ta[0] + (c[1] - tc[1]) * ta[1] + (c[2] - tc[2]) * ta[2]).abs());
            }
        }
        (errs, anchored)
    };
    let (fit_alone, none) = along(&["--no-hidden-end"]);
    let (anchored, moved) = along(&[]);
    assert_eq!(none, 0, "--no-hidden-end moved poses");
    assert!(moved >= 1, "no pose anchored");
    assert!(fit_alone.len() >= 3 && anchored.len() == fit_alone.len(), "partly hidden tubes found: {} without, {} with", fit_alone.len(), anchored.len());
    let worst = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    assert!(worst(&anchored) < 10.0, "along-axis errors {anchored:.1?} mm (fit alone {fit_alone:.1?})");
    for (a, f) in anchored.iter().zip(&fit_alone) {
        assert!(*a <= f + 1.0, "a tube moved away: {a:.1} mm against {f:.1} mm by the fit alone");
    }
}

/// Tubes outside the right camera's view get no stereo points of their own and are placed on
/// the ground plane along their rays. With `--ground auto` on a dataset without
/// `ground_height_m` that plane is world z = 0, centimetres off the terrain; the local ground
/// (on by default) moves it to the matched terrain beside each tube, and those tubes land
/// nearer their true centres. With the dataset's `ground_height_m` (the terrain's level) the
/// nominal ground is nearer to start with, and the local ground keeps them within 10 mm.
#[test]
fn tubes_outside_the_right_view_sit_on_the_terrain_beside_them() {
    let ms = MaskSet::new("7");
    let truths = &ms.truths;
    // Centre errors (mm) of the converged poses without stereo points, by (image, truth).
    let errors = |extra: &[&str]| {
        let mut errs = std::collections::BTreeMap::new();
        for p in ms.refine(extra).as_array().unwrap().iter().filter(|p| p["converged"].as_bool() == Some(true) && p["residuals"]["stereo_points"].as_u64() == Some(0)) {
            let (id, c) = (p["image_id"].as_u64().unwrap(), vec3(&p["centre"]));
            let Some(k) = (0..truths.len()).filter(|&k| truths[k].0 == id).min_by(|&x, &y| dist(&truths[x].1, &c).total_cmp(&dist(&truths[y].1, &c))).filter(|&k| dist(&truths[k].1, &c) < 0.08) else { continue };
            errs.insert(k, 1e3 * dist(&truths[k].1, &c));
        }
        errs
    };
    let (level, level_local) = (errors(&["--no-local-ground"]), errors(&[]));
    ms.drop_ground_heights();
    let (nominal, local) = (errors(&["--no-local-ground"]), errors(&[]));
    eprintln!("no stereo points, centre error mm: world z = 0 {nominal:.1?}, local {local:.1?}; terrain level {level:.1?}, local {level_local:.1?}");
    let both: Vec<(f64, f64)> = nominal.iter().filter_map(|(k, n)| local.get(k).map(|l| (*n, *l))).collect();
    assert!(both.len() >= 2, "tubes without stereo points found in both runs: {both:?}");
    assert!(both.iter().all(|(n, _)| *n > 20.0), "world z = 0 is already close: {both:?}");
    assert!(both.iter().all(|(n, l)| *l < 10.0 && l < n), "(z = 0, local) centre errors {both:?} mm");
    for (k, n) in &nominal {
        assert!(level.get(k).is_some_and(|e| e < n), "tube {k}: {:?} mm on the terrain's level, {n:.1} mm on z = 0", level.get(k));
        assert!(level_local.get(k).is_some_and(|e| *e < 10.0), "tube {k}: {:?} mm on the local ground", level_local.get(k));
    }
}

/// A rendered stereo set (2 scenes x 3 pairs, 384 px, `seed`) with the mask detections of
/// [`mask_detections`] written beside it.
struct MaskSet {
    tmp: tempfile::TempDir,
    set: std::path::PathBuf,
    dets: std::path::PathBuf,
    /// Per detection: image id, true centre and axis (camera frame), visible fraction.
    truths: Vec<(u64, [f64; 3], [f64; 3], f64)>,
}

impl MaskSet {
    fn new(seed: &str) -> Self {
        let tmp = tempfile::tempdir().expect("tempdir");
        let set = tmp.path().join("st");
        ok(&["synth", "stereo", "--out", set.to_str().unwrap(), "--scenes", "2", "--pairs-per-scene", "3", "--resolution", "384", "--seed", seed]);
        let (dets, truths) = mask_detections(&read(&set.join("annotations.json")));
        let det_path = tmp.path().join("dets.json");
        std::fs::write(&det_path, serde_json::to_vec(&dets).unwrap()).unwrap();
        MaskSet { tmp, set, dets: det_path, truths }
    }

    /// Removes every image's `ground_height_m`: `--ground auto` is then world z = 0.
    fn drop_ground_heights(&self) {
        let path = self.set.join("annotations.json");
        let mut ann = read(&path);
        for im in ann["images"].as_array_mut().unwrap() {
            im.as_object_mut().unwrap().remove("ground_height_m").expect("synth writes ground_height_m");
        }
        std::fs::write(&path, serde_json::to_vec(&ann).unwrap()).unwrap();
    }

    /// The poses of `tubeloc refine --stereo --ground auto` on the set, with `extra` options.
    fn refine(&self, extra: &[&str]) -> Value {
        let out = self.tmp.path().join("poses.json");
        let args = ["refine", "--dataset", self.set.to_str().unwrap(), "--detections", self.dets.to_str().unwrap(), "--stereo", "--ground", "auto", "--out", out.to_str().unwrap()];
        ok(&[&args[..], extra].concat());
        read(&out)
    }
}

/// A detection's truth: image id, true centre and axis (camera frame), visible fraction.
type Truth = (u64, [f64; 3], [f64; 3], f64);

/// Mask detections of the learned segmenter's kind from a stereo set's annotations: each tube at
/// least half visible gets its visible mask and an axis seed turned 2 degrees and moved 2 px off
/// its true image axis. Returns the detections and, per detection, its image id, true centre and
/// axis (camera frame) and visible fraction.
fn mask_detections(ann: &Value) -> (Vec<Value>, Vec<Truth>) {
    let images: std::collections::BTreeMap<u64, &Value> = ann["images"].as_array().unwrap().iter().map(|i| (i["id"].as_u64().unwrap(), i)).collect();
    let mut dets = Vec::new();
    let mut truths = Vec::new();
    for a in ann["annotations"].as_array().unwrap() {
        if a["visible_fraction"].as_f64().unwrap() < 0.5 {
            continue;
        }
        let cam = &images[&a["image_id"].as_u64().unwrap()]["camera"];
        let (fx, cx, cy) = (cam["fx"].as_f64().unwrap(), cam["cx"].as_f64().unwrap(), cam["cy"].as_f64().unwrap());
        let project = |p: [f64; 3]| [fx * p[0] / p[2] + cx, fx * p[1] / p[2] + cy];
        let c = vec3(&a["T_cam_tube"]["translation"]);
        let r = a["T_cam_tube"]["rotation"].as_array().unwrap();
        let axis = [0, 1, 2].map(|i| r[i][2].as_f64().unwrap());
        let (p0, p1) = (project(c), project([0, 1, 2].map(|i| c[i] + 0.05 * axis[i])));
        let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
        let n = (dx * dx + dy * dy).sqrt();
        let t = 2f64.to_radians();
        let dir = [(dx * t.cos() - dy * t.sin()) / n, (dx * t.sin() + dy * t.cos()) / n];
        let bbox = a["bbox"].clone();
        dets.push(serde_json::json!({
            "image_id": a["image_id"], "category_id": 1, "score": 0.9, "bbox": bbox, "segmentation": a["segmentation"],
            "axis_seed": {"centre_px": [p0[0] - 2.0 * dir[1], p0[1] + 2.0 * dir[0]], "direction_px": dir, "length_px": n * 3.0, "width_px": 2.0 * 0.0075 * fx / c[2]}
        }));
        truths.push((a["image_id"].as_u64().unwrap(), c, axis, a["visible_fraction"].as_f64().unwrap()));
    }
    (dets, truths)
}

#[test]
fn a_stereo_pair_of_pds3_products_locates_as_its_rig_does() {
    // A rendered stereo pair written as two PDS3 products whose labels place both cameras in
    // one rover frame (the world with y and z flipped: z down): `locate --label-cameras
    // --image L.IMG --right R.IMG` makes the pair from the two labels and finds the tubes of
    // `locate --rig rig.json` with the rendered pair, with the stereo term in both.
    use nalgebra::{Matrix3, Vector3};
    let tmp = tempfile::tempdir().expect("tempdir");
    let set = tmp.path().join("st");
    ok(&["synth", "stereo", "--out", set.to_str().unwrap(), "--scenes", "1", "--pairs-per-scene", "1", "--resolution", "384", "--seed", "1"]);
    let im = read(&set.join("annotations.json"))["images"][0].clone();
    let m3 = |v: &Value| Matrix3::from_fn(|i, j| v[i][j].as_f64().unwrap());
    let v3 = |v: &Value| Vector3::from(vec3(v));
    let (r_wl, t_wl) = (m3(&im["T_world_cam"]["rotation"]), v3(&im["T_world_cam"]["translation"]));
    let (r_lr, t_lr) = (m3(&im["T_left_right"]["rotation"]), v3(&im["T_left_right"]["translation"]));
    let (r_wr, t_wr) = (r_wl * r_lr, t_wl + r_wl * t_lr);
    // The rig file of the crop: the rig frame is the world.
    let pose = |r: &Matrix3<f64>, t: &Vector3<f64>| serde_json::json!({"rotation": [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]], "translation": [t.x, t.y, t.z]});
    let rig = serde_json::json!({"cameras": [{"name": "L", "model": im["camera"], "T_rig_cam": pose(&r_wl, &t_wl)}, {"name": "R", "model": im["right_camera"], "T_rig_cam": pose(&r_wr, &t_wr)}], "stereo_pairs": [["L", "R"]]});
    let rig_path = tmp.path().join("rig.json");
    std::fs::write(&rig_path, rig.to_string()).unwrap();
    let (left_png, right_png) = (set.join("images").join(im["file_name"].as_str().unwrap()), set.join("right").join(im["right_file_name"].as_str().unwrap()));
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    let (left_img, right_img) = (tmp.path().join("L.IMG"), tmp.path().join("R.IMG"));
    common::pds3_product(&left_img, &image::open(&left_png).unwrap().to_rgb8(), &im["camera"], &(flip * r_wl), &(flip * t_wl), "");
    common::pds3_product(&right_img, &image::open(&right_png).unwrap().to_rgb8(), &im["right_camera"], &(flip * r_wr), &(flip * t_wr), "");
    // The ground (world z = ground_height_m) in the left camera frame, given to both runs.
    let n = r_wl.transpose() * Vector3::z();
    let ground = format!("--ground={},{},{},{}", n.x, n.y, n.z, im["ground_height_m"].as_f64().unwrap() - t_wl.z);
    let run = |args: &[&str], out: &str| -> Value {
        let out = tmp.path().join(out);
        let o = Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(args).args(["--out", out.to_str().unwrap(), &ground]).output().unwrap();
        assert!(matches!(o.status.code(), Some(0) | Some(3)), "{}", String::from_utf8_lossy(&o.stderr));
        read(&out)
    };
    let by_rig = run(&["locate", "--rig", rig_path.to_str().unwrap(), "--image", left_png.to_str().unwrap(), "--right", right_png.to_str().unwrap()], "rig.json.out");
    let by_labels = run(&["locate", "--label-cameras", "--image", left_img.to_str().unwrap(), "--right", right_img.to_str().unwrap()], "labels.json.out");
    let (a, b) = (by_rig["tubes"].as_array().unwrap(), by_labels["tubes"].as_array().unwrap());
    assert!(!a.is_empty() && a.len() == b.len(), "{} against {} tubes", a.len(), b.len());
    // The labels carry the cameras to rounding, not bit for bit, so a tube at the edge of the
    // right view (a few stereo points, near the stereo term's minimum) or a weak one below the
    // threshold (its place along the axis ill-determined) may fall either way: the tubes handed
    // to the planner, well inside both views, are compared.
    let points = |t: &Value| t["residuals"]["stereo_points"].as_f64().unwrap_or(0.0);
    let mut compared = 0;
    // Each such tube against the nearest of the other run (two tubes of nearly equal
    // probability may be listed in either order).
    for ta in a.iter().filter(|ta| points(ta) >= 50.0 && ta["status"] == "located") {
        let tb = b.iter().min_by(|x, y| dist(&vec3(&x["centre"]), &vec3(&ta["centre"])).total_cmp(&dist(&vec3(&y["centre"]), &vec3(&ta["centre"])))).unwrap();
        assert_eq!(ta["status"], tb["status"]);
        assert!((points(ta) - points(tb)).abs() <= 0.01 * points(ta), "{} against {} stereo points", points(ta), points(tb));
        for k in ["centre", "axis"] {
            let (pa, pb) = (vec3(&ta[k]), vec3(&tb[k]));
            assert!(dist(&pa, &pb) < 1e-4, "{k}: {pa:?} against {pb:?}");
        }
        compared += 1;
    }
    assert!(compared >= 1, "no tube well inside both views: {a:?}");
    // A right image without a label cannot make the pair.
    let o = Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(["locate", "--label-cameras", "--image", left_img.to_str().unwrap(), "--right", right_png.to_str().unwrap(), "--out", tmp.path().join("x.json").to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("not a PDS3 product") && err.contains(right_png.file_name().unwrap().to_str().unwrap()), "{err}");
}
