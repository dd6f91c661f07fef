//! Tags rendered by tubeloc-synth are detected with the right ids at the exact corners: this
//! checks the tag tables, the corner order and the pixel convention end to end.

use nalgebra::{Rotation3, Vector3};
use tubeloc_calib::{DetectorConfig, TagDetector};
use tubeloc_core::{CameraModel, Distortion, Pose};
use tubeloc_synth::calib_set::{render_board, BoardLayout};
use tubeloc_synth::tags::TagFamily;

#[test]
fn rendered_board_corners_match_projection() {
    let board = BoardLayout::grid(TagFamily::Tag36h11, 4, 3, 0.05, 0.07, 10);
    let model = CameraModel { distortion: Distortion { k1: -0.05, k2: 0.02, p1: 3e-4, p2: -2e-4, k3: 0.0 }, ..CameraModel::from_hfov(640, 480, 70.0) };
    let pose = Pose::from_parts(Rotation3::from_euler_angles(0.25, -0.3, 0.15), Vector3::new(0.02, -0.01, 0.55));
    let img = render_board(&model, &pose, &board, 1.5, 7).unwrap();
    let mut det = TagDetector::new(DetectorConfig::default()).unwrap();
    let found = det.detect(&img).unwrap();
    assert_eq!(found.len(), 12, "ids {:?}", found.iter().map(|d| d.id).collect::<Vec<_>>());
    let mut errs = Vec::new();
    for d in &found {
        let k = board.tags.iter().position(|t| t.id == d.id).expect("id on board");
        for (c, p) in d.corners.iter().zip(board.corners(k)) {
            let q = model.project(&pose.transform_point(&p)).unwrap();
            errs.push((c[0] - q.x).hypot(c[1] - q.y));
        }
        assert!(d.decision_margin > 50.0 && d.hamming == 0);
    }
    errs.sort_by(f64::total_cmp);
    let (median, max) = (errs[errs.len() / 2], errs[errs.len() - 1]);
    eprintln!("rendered board: corner error median {median:.3} px, max {max:.3} px");
    assert!(median < 0.1 && max < 0.3, "median {median} max {max}");
}
