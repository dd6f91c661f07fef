//! SGM on rendered benchmark pairs (`tubeloc-synth` stereo sets, read back through their file
//! contract): disparity errors against the exact disparity over valid and tube pixels, and the
//! 3D accuracy of triangulated tube points.

use std::path::Path;
use tubeloc_core::{CameraModel, CocoDataset, Plane, Pose, Rle, Segmentation, TubeModel};
use tubeloc_stereo::pair_eval::PairEval;
use tubeloc_stereo::{io, RectifiedGeometry, SgmMatcher, SgmParams};
use tubeloc_synth::dataset::DatasetSpec;
use tubeloc_synth::stereo_set::{write_stereo_set, StereoSetSpec};

fn gray(path: &Path) -> Plane<u8> {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
    Plane::from_vec(img.width() as usize, img.height() as usize, img.into_raw())
}

#[test]
fn sgm_on_rendered_pairs_is_accurate_on_valid_and_tube_pixels() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("set");
    let mut base = DatasetSpec::preset("tiny", 4).unwrap().with_scenes(2).unwrap();
    base.scale = 0.25;
    base.crop = 320;
    let spec = StereoSetSpec { base, pair: ("L20".into(), "R20".into()), pairs_per_scene: 1 };
    write_stereo_set(&spec, &dir, false, &|_, _| {}).unwrap();

    let ds = CocoDataset::load(&dir.join("annotations.json")).unwrap();
    let model = TubeModel::default();
    let (mut ev, mut exact) = (PairEval::default(), PairEval::default());
    for img in &ds.images {
        let e = &img.extra;
        let cam: CameraModel = serde_json::from_value(e["camera"].clone()).unwrap();
        let geom = RectifiedGeometry { f: cam.fx, cx: cam.cx, cy: cam.cy, baseline: e["baseline_m"].as_f64().unwrap() };
        let left = gray(&dir.join("images").join(&img.file_name));
        let right = gray(&dir.join("right").join(e["right_file_name"].as_str().unwrap()));
        let gt = io::decode_pfm(&std::fs::read(dir.join("disparity").join(e["disparity_file_name"].as_str().unwrap())).unwrap()).unwrap();
        // Search range from the exact disparities (as a user would from the working distance).
        let finite: Vec<f32> = gt.data.iter().copied().filter(|d| d.is_finite()).collect();
        let dmin = finite.iter().copied().fold(f32::INFINITY, f32::min).floor() as i32 - 4;
        let dmax = finite.iter().copied().fold(0.0, f32::max).ceil() as i32 + 4;
        let nd = ((dmax - dmin) as usize).div_ceil(16) * 16;
        let params = SgmParams { min_disparity: dmin.max(0), num_disparities: nd, ..SgmParams::default() };
        let est = SgmMatcher::new(params).unwrap().compute(&left, &right).unwrap();
        let masks: Vec<(tubeloc_core::BinaryMask, Pose)> = ds
            .annotations
            .iter()
            .filter(|a| a.image_id == img.id)
            .map(|a| {
                let Some(Segmentation::CompressedRle { counts, size }) = &a.segmentation else { panic!("RLE expected") };
                let mask = Rle::from_compressed_string(counts, *size).unwrap().to_mask().unwrap();
                (mask, serde_json::from_value(a.extra["T_cam_tube"].clone()).unwrap())
            })
            .collect();
        let tubes: Vec<(&tubeloc_core::BinaryMask, Pose)> = masks.iter().map(|(m, p)| (m, *p)).collect();
        ev.add(&est, &gt, &geom, &tubes, &model);
        exact.add(&gt, &gt, &geom, &tubes, &model);
    }
    let s = ev.summary();
    let x = exact.summary();
    eprintln!("SGM: {s:?}");
    eprintln!("exact disparity: {x:?}");
    // The metric itself: exact disparities score perfectly and triangulate onto the surface.
    assert_eq!(x.valid.bad1, 0.0);
    assert!(x.tube_p90_mm < 0.5, "exact tube points p90 {} mm", x.tube_p90_mm);
    assert!(s.valid.pixels > 50_000 && s.tube.pixels > 100, "{s:?}");
    assert!(s.valid.bad2 < 0.05, "valid bad-2.0 {}", s.valid.bad2);
    assert!(s.valid.mae < 0.4, "valid MAE {}", s.valid.mae);
    assert!(s.tube.bad2 < 0.10, "tube bad-2.0 {}", s.tube.bad2);
    assert!(s.tube_median_mm < 6.0, "tube median distance {} mm", s.tube_median_mm);
}
