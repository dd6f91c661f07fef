//! Hard negatives for fine-tuning: crops of tube-free real frames around the learned
//! detector's own confident detections there, at the frame's working scale.
//!
//! usage: hard_negative_crops DATA FILES.json DET_DIR CALIBRATION.json MIN_P CROP OUT
//!
//! FILES.json: frame paths relative to DATA (tube-free frames of the training sols); DET_DIR:
//! `tubeloc detect --method learned --assumed-view auto --image DATA/F --out DET_DIR/F'.json`
//! for each, F' being F with `/` replaced by `__`. Each frame is seen under the assumed view of
//! its kind (navcam for grey, mast for colour, as `--assumed-view auto`), resampled to its
//! working scale as the detector resamples it, and a CROP x CROP crop is cut around each
//! detection whose calibrated probability reaches MIN_P (one per 128 px neighbourhood). OUT
//! gets the crops and an `annotations.json` without annotations (images without `camera`, so
//! the trainer takes them as they are).
use std::path::PathBuf;
use tubeloc_core::ScoreCalibration;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    assert!(a.len() == 8, "usage: hard_negative_crops DATA FILES.json DET_DIR CALIBRATION.json MIN_P CROP OUT");
    let (data, det_dir, out) = (PathBuf::from(&a[1]), PathBuf::from(&a[3]), PathBuf::from(&a[7]));
    let files: Vec<String> = serde_json::from_str(&std::fs::read_to_string(&a[2]).unwrap()).unwrap();
    let cal: ScoreCalibration = serde_json::from_str(&std::fs::read_to_string(&a[4]).unwrap()).unwrap();
    let (min_p, crop): (f64, usize) = (a[5].parse().unwrap(), a[6].parse().unwrap());
    std::fs::create_dir_all(out.join("images")).unwrap();
    let mut images = Vec::new();
    for f in &files {
        let det_path = det_dir.join(format!("{}.json", f.replace('/', "__")));
        let dets: Vec<serde_json::Value> = serde_json::from_str(&std::fs::read_to_string(&det_path).unwrap()).unwrap();
        let mut centres: Vec<(f64, f64)> = Vec::new();
        for d in &dets {
            let p = cal.probability(d["score"].as_f64().unwrap());
            let c = &d["axis_seed"]["centre_px"];
            let (x, y) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
            if p >= min_p && centres.iter().all(|(u, v)| (u - x).hypot(v - y) > 128.0) {
                centres.push((x, y));
            }
        }
        if centres.is_empty() {
            continue;
        }
        let input = tubeloc_detect::input::load(&data.join(f)).unwrap();
        let (w, h) = (input.width, input.height);
        let (_, view) = tubeloc_core::AssumedView::of_kind(input.info.grey);
        let (rig, ground) = view.rig("frame", w as u32, h as u32).unwrap();
        let s = tubeloc_detect::scale::working_scale(&rig.cameras[0].model, Some((ground.normal, ground.offset)), Default::default());
        let (nw, nh) = tubeloc_detect::scale::scaled_size(w, h, s);
        let planes: Vec<f32> = (0..3).flat_map(|c| input.rgb.iter().skip(c).step_by(3).map(|&v| v as f32).collect::<Vec<_>>()).collect();
        let big = tubeloc_detect::scale::resample_planes(&planes, 3, w, h, nw, nh);
        let (cw, ch) = (crop.min(nw), crop.min(nh));
        for (k, (x, y)) in centres.iter().enumerate() {
            let x0 = ((x * s) as i64 - cw as i64 / 2).clamp(0, (nw - cw) as i64) as usize;
            let y0 = ((y * s) as i64 - ch as i64 / 2).clamp(0, (nh - ch) as i64) as usize;
            let img = image::RgbImage::from_fn(cw as u32, ch as u32, |i, j| {
                let at = |c: usize| big[c * nw * nh + (y0 + j as usize) * nw + x0 + i as usize].round().clamp(0.0, 255.0) as u8;
                image::Rgb([at(0), at(1), at(2)])
            });
            let name = format!("{:05}_{}_{k}.png", images.len() + 1, f.rsplit('/').next().unwrap().rsplit_once('.').unwrap().0);
            img.save(out.join("images").join(&name)).unwrap();
            images.push(serde_json::json!({"id": images.len() + 1, "file_name": name, "width": cw, "height": ch, "source": f, "working_scale": s}));
        }
    }
    let n = images.len();
    let doc = serde_json::json!({"info": {"description": "hard negatives: crops of tube-free training frames around the learned detector's detections", "min_p": min_p}, "images": images, "annotations": [], "categories": [{"id": 1, "name": "tube", "supercategory": "object"}]});
    std::fs::write(out.join("annotations.json"), serde_json::to_string(&doc).unwrap()).unwrap();
    eprintln!("{n} crops -> {}", out.display());
}
