//! Markdown report builder and the evaluation report folder.

use nalgebra::{Rotation3, Vector3};
use tubeloc_core::{Pose, TubeModel};
use tubeloc_eval::pose_bop::ModelPoints;
use tubeloc_eval::pose_match::{match_by_centre_distance, TubeEstimate, TubeTruth};
use tubeloc_eval::pose_summary::{evaluate_poses, PoseEvalConfig};
use tubeloc_eval::report::{fmt_metric, slug, write_eval_report, Breakdown, EvalReport, Report, Table};

#[test]
fn table_markdown_is_escaped_and_aligned() {
    let mut t = Table::new(["terrain", "AP50"]);
    t.row(["flat|sand", "0.812"]).row(["bed\nrock"]);
    assert_eq!(t.to_markdown(), "| terrain | AP50 |\n| --- | ---: |\n| flat\\|sand | 0.812 |\n| bed rock |  |\n");
    let mut r = Report::new("Run");
    r.heading(2, "Summary").table(t).image("PR", "pr.png", Some("pr.svg".into())).paragraph("done");
    let md = r.to_markdown();
    assert!(md.starts_with("# Run\n\n## Summary\n\n| terrain"), "{md}");
    assert!(md.contains("![PR](pr.png)\n\n[PR (SVG)](pr.svg)\n") && md.ends_with("\ndone\n"));
    assert_eq!(fmt_metric(-1.0), "n/a");
    assert_eq!(fmt_metric(0.25), "0.250");
    assert_eq!(slug("Time of day"), "time_of_day");
}

#[test]
fn eval_report_folder_has_linked_plots_and_tables() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("out");
    // A pose evaluation with one exact and one 4 mm-off estimate.
    let p = |x: f64| Pose::from_parts(Rotation3::from_euler_angles(1.2, 0.1, 0.3), Vector3::new(x, 0.0, 1.0));
    let truths = vec![TubeTruth { image_id: 1, pose: p(0.0) }, TubeTruth { image_id: 2, pose: p(0.1) }];
    let ests = vec![TubeEstimate { image_id: 1, pose: p(0.0), score: 0.9, std: None }, TubeEstimate { image_id: 2, pose: p(0.104), score: 0.8, std: None }];
    let m = match_by_centre_distance(&truths, &ests, 0.05);
    let model = ModelPoints::from_tube(&TubeModel::default(), 0.004).unwrap();
    let ev = evaluate_poses(&truths, &ests, &m, &model, &PoseEvalConfig::default()).unwrap();
    let mut prec = [0.9; 101];
    prec[80..].fill(0.0);
    let report = EvalReport {
        title: "Line2D on benchmark".into(),
        inputs: vec![("ground truth".into(), "gt.json".into()), ("iou type".into(), "segm".into())],
        stats: vec![("AP".into(), 0.5), ("AP50".into(), 0.72), ("AP small".into(), -1.0)],
        pr_curves: vec![(0.5, prec), (0.55, [-1.0; 101])],
        breakdowns: vec![Breakdown { attribute: "time of day".into(), metrics: vec!["AP50".into(), "AR".into()], rows: vec![("morning".into(), 12, vec![0.7, 0.4]), ("noon".into(), 9, vec![-1.0, 0.5])] }],
        poses: vec![("mono".into(), ev.clone()), ("stereo".into(), ev)],
    };
    let path = write_eval_report(&dir, &report).unwrap();
    assert_eq!(path, dir.join("report.md"));
    let md = std::fs::read_to_string(&path).unwrap();
    assert!(md.starts_with("# Line2D on benchmark\n"));
    assert!(md.contains("| AP50 | 0.720 |") && md.contains("| AP small | n/a |"));
    assert!(md.contains("| 0.50 | 0.713 |"), "AP of the 0.5 curve (mean of 80 × 0.9 and 21 × 0 = 0.7129): {md}");
    assert!(md.contains("| morning | 12 | 0.700 | 0.400 |") && md.contains("| noon | 9 | n/a | 0.500 |"));
    assert!(md.contains("2 of 2 truths matched by greedy by score, nearest 3D centre within 50.0 mm"));
    // Both estimates point to the right end.
    assert!(md.contains("| mono |") && md.contains("100%"));
    // Every relative link resolves to a written file; PNGs decode.
    let mut links = 0;
    for part in md.split("](").skip(1) {
        let target = &part[..part.find(')').unwrap()];
        assert!(dir.join(target).is_file(), "dangling link {target}");
        if target.ends_with(".png") {
            image::open(dir.join(target)).unwrap();
        }
        links += 1;
    }
    assert!(links >= 13, "{links} links"); // PR, 1 breakdown, 4 histograms (PNG + SVG each), JSON
    assert!(dir.join("breakdown_time_of_day.svg").is_file());
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("pose_eval.json")).unwrap()).unwrap();
    assert_eq!(json[1]["label"], "stereo");
    assert_eq!(json[0]["evaluation"]["n_matched"], 2);
}
