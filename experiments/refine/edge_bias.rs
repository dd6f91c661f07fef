//! Diagnostic: edge localization bias of the contour model at exact poses on a rendered COCO
//! dataset (annotations with `T_cam_tube`). For every visible limb / rim sample at full
//! resolution it reports the offset (pixels along the outward normal) of the strongest image
//! edge, the outermost edge of the limb's polarity, and of the annotation mask's boundary.
//! Environment `PROFILE=<annotation id>` also prints that tube's body-limb intensity profiles
//! (-6..+6 px along the outward normal, 0.5 px steps, grey levels).
//! Level 0 is differentiated unsmoothed (the refiner's default) unless `BLUR0=1` is set.
//! Usage: cargo run --release --manifest-path experiments/Cargo.toml --bin edge_bias -- DIR [MAX_IMAGES] [MIN_VIS]

use nalgebra::{Point2, Vector3};
use tubeloc_core::{CocoDataset, Plane, Pose, TubeModel};
use tubeloc_refine::contour::{build_samples, project_with_normal, SampleKind};
use tubeloc_refine::edges::{build_pyramid_with, roi};
use tubeloc_refine::{AxisState, CylinderModel};

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = std::path::PathBuf::from(&args[1]);
    let max_images: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let min_vis: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(0.9);
    let ds = CocoDataset::load(&dir.join("annotations.json")).expect("annotations");
    let model = CylinderModel::new(&TubeModel::default()).unwrap();
    // kind: 0 limb body, 1 limb foot/seal, 2 rim
    let mut all: Vec<Vec<f64>> = vec![Vec::new(); 9];
    for im in ds.images.iter().take(max_images) {
        let cam: tubeloc_core::CameraModel = serde_json::from_value(im.extra["camera"].clone()).unwrap();
        let path = dir.join("images").join(&im.file_name);
        let img = image::open(&path).expect("image").to_luma8();
        let plane = Plane::from_vec(img.width() as usize, img.height() as usize, img.into_raw().iter().map(|&v| v as f32 / 255.0).collect());
        for a in ds.annotations.iter().filter(|a| a.image_id == im.id) {
            let vis = a.extra.get("visible_fraction").and_then(|v| v.as_f64()).unwrap_or(1.0);
            if vis < min_vis {
                continue;
            }
            let t: Pose = serde_json::from_value(a.extra["T_cam_tube"].clone()).unwrap();
            let st = AxisState { c: t.translation(), a: t.transform_vector(&Vector3::z()) };
            let f = st.frame().unwrap();
            let mask = a.segmentation.as_ref().and_then(|s| s.to_rle(cam.height, cam.width).ok()).and_then(|r| r.to_mask().ok());
            let Some(rect) = roi(a.bbox, 20.0, cam.width as usize, cam.height as usize) else { continue };
            let pyr = build_pyramid_with(&plane, &cam, rect, 1, std::env::var("BLUR0").is_ok());
            let lv = &pyr[0];
            let mut per: Vec<Vec<f64>> = vec![Vec::new(); 9];
            for s in build_samples(&model, &st, &lv.camera, 2.0) {
                let Some(p) = s.eval(&model, &f) else { continue };
                if !s.on_silhouette(&model, &f, &p) || model.occludes(&st.c, &st.a, &(p.x + p.out * 3e-4)) {
                    continue;
                }
                let Some((u, n)) = project_with_normal(&lv.camera, &p) else { continue };
                if !lv.inside(&u, 8.0) {
                    continue;
                }
                let k = match s.kind {
                    SampleKind::Limb { .. } if s.section == 1 => 0,
                    SampleKind::Limb { .. } => 1,
                    SampleKind::Rim { .. } => 2,
                };
                let hits = lv.search_all(&u, &n, 5, 0.004, 0, 0.25);
                if hits.len > 0 {
                    per[3 * k].push(hits.hits[0].offset);
                    // outermost hit of the strongest's polarity
                    let pol = hits.hits[0].strength.signum();
                    let o = hits.hits[..hits.len].iter().filter(|h| h.strength.signum() == pol).map(|h| h.offset).fold(f64::MIN, f64::max);
                    per[3 * k + 1].push(o);
                }
                if let (Ok(want), SampleKind::Limb { side, .. }) = (std::env::var("PROFILE"), s.kind) {
                    if want == a.id.to_string() && s.section == 1 {
                        let prof: Vec<String> = (-12..=12).map(|i| {
                            let q = u + n * (i as f64 * 0.5);
                            let (x, y) = (q.x + rect.0 as f64, q.y + rect.1 as f64);
                            let (x0, y0) = (x.floor() as usize, y.floor() as usize);
                            let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
                            let v = plane.get(x0, y0) * (1.0 - fx) * (1.0 - fy) + plane.get(x0 + 1, y0) * fx * (1.0 - fy) + plane.get(x0, y0 + 1) * (1.0 - fx) * fy + plane.get(x0 + 1, y0 + 1) * fx * fy;
                            format!("{:.0}", v * 255.0)
                        }).collect();
                        println!("side {side:+} {}", prof.join(" "));
                    }
                }
                if let Some(m) = &mask {
                    // mask boundary: outermost in->out transition along n (0.1 px steps)
                    let uf = Point2::new(u.x + rect.0 as f64, u.y + rect.1 as f64);
                    let at = |t: f64| {
                        let q = uf + n * t;
                        q.x >= -0.5 && q.y >= -0.5 && m.get((q.x + 0.5) as usize, (q.y + 0.5) as usize)
                    };
                    let mut best = None;
                    let mut prev = at(-5.0);
                    for i in -49..=50 {
                        let tt = i as f64 * 0.1;
                        let c = at(tt);
                        if prev && !c {
                            best = Some(tt - 0.05);
                        }
                        prev = c;
                    }
                    if let Some(b) = best {
                        per[3 * k + 2].push(b);
                    }
                }
            }
            let meds: Vec<String> = per.iter_mut().map(|v| format!("{:+.2}({})", median(v), v.len())).collect();
            println!("ann {} z {:.2} vis {:.2} body[strong,outer,mask] {} {} {} | ends {} {} {} | rims {} {} {}", a.id, st.c.z, vis, meds[0], meds[1], meds[2], meds[3], meds[4], meds[5], meds[6], meds[7], meds[8]);
            for (k, v) in per.into_iter().enumerate() {
                all[k].extend(v);
            }
        }
    }
    let meds: Vec<String> = all.iter_mut().map(|v| format!("{:+.2}({})", median(v), v.len())).collect();
    println!("ALL body[strong,outer,mask] {} {} {} | ends {} {} {} | rims {} {} {}", meds[0], meds[1], meds[2], meds[3], meds[4], meds[5], meds[6], meds[7], meds[8]);
}
