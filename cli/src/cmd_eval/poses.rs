//! `tubeloc eval --poses`: refined tube poses against the true poses of a COCO dataset.
//!
//! Truths are the annotations with a pose in the truth field (`T_cam_tube`, the exact pose, or
//! `T_cam_tube_tags`, the tag-pair ground truth) whose `visible_fraction` is at least the
//! given minimum; estimates are the converged poses. Matching is greedy by score on the centre
//! distance (gated); errors per matched pair are the axis angle, the centre's perpendicular
//! distance to the true axis and its along-axis offset, the end direction, and the BOP MSSD /
//! MSPD with the tube's symmetries (MSPD with each image's `images[].camera`). Writes
//! `pose_metrics.json` (summaries and recalls per label), `pose_eval.json` (with every pair),
//! histograms (PNG + SVG) and `report.md` into the output folder.

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tubeloc_core::files::{read_json, write_json};
use tubeloc_core::{CameraModel, CocoDataset, Pose, TubeAxisPose, TubeModel};
use tubeloc_eval::pose_bop::ModelPoints;
use tubeloc_eval::pose_match::{match_by_centre_distance, TubeEstimate, TubeTruth};
use tubeloc_eval::pose_summary::{evaluate_poses, PoseEvalConfig, PoseEvaluation, Summary};

/// `--poses LABEL=PATH` or `PATH` (label: the file stem), parsed when the command line is.
pub(crate) fn label_and_path(s: &str) -> std::result::Result<(String, PathBuf), String> {
    Ok(match s.split_once('=') {
        Some((l, p)) if !l.is_empty() && !p.is_empty() => (l.to_string(), PathBuf::from(p)),
        _ => {
            let p = PathBuf::from(s);
            (p.file_stem().map(|x| x.to_string_lossy().into_owned()).unwrap_or_else(|| s.to_string()), p)
        }
    })
}

fn med_p90(s: &Summary) -> String {
    match (s.median, s.p90) {
        (Some(m), Some(p)) => format!("{m:.2} / {p:.2}"),
        _ => "n/a".into(),
    }
}

/// Which annotations are truths: those with a pose in `field`, a `visible_fraction` of at least
/// `min_visible` and, with `in_both_views`, an axis at least half inside the right image.
pub struct TruthFilter<'a> {
    /// Annotation field of the true pose (`T_cam_tube` or `T_cam_tube_tags`).
    pub field: &'a str,
    /// Least `visible_fraction`.
    pub min_visible: f64,
    /// Keep only tubes whose axis is at least half inside the right image.
    pub in_both_views: bool,
}

/// Fraction of 21 points along the tube axis at `pose` (left camera frame) that project inside
/// the right image of `camera`, with `t_left_right` mapping right-camera points into the left
/// camera's frame.
fn right_view_fraction(pose: &Pose, length: f64, t_left_right: &Pose, camera: &CameraModel) -> f64 {
    let (c, a) = (pose.translation(), pose.rotation().column(2).into_owned());
    let to_right = t_left_right.inverse();
    let inside = (0..21)
        .filter(|k| {
            let p = to_right.transform_point(&nalgebra::Point3::from(c + a * (length * (*k as f64 / 20.0 - 0.5))));
            camera.project(&p).is_some_and(|u| u.x >= 0.0 && u.y >= 0.0 && u.x <= camera.width as f64 - 1.0 && u.y <= camera.height as f64 - 1.0)
        })
        .count();
    inside as f64 / 21.0
}

/// Runs the pose evaluation of each poses file against `gt_path`.
pub fn run(gt_path: &Path, poses: &[(String, PathBuf)], filter: &TruthFilter, match_mm: f64, out: Option<&Path>) -> Result<()> {
    let (truth_field, min_visible) = (filter.field, filter.min_visible);
    let gt = CocoDataset::load(gt_path).with_context(|| format!("loading ground truth {}", gt_path.display()))?;
    let mut right_views = BTreeMap::new();
    if filter.in_both_views {
        for im in &gt.images {
            let (Some(c), Some(t)) = (im.extra.get("right_camera"), im.extra.get("T_left_right")) else {
                bail!("{}: image {} has no right_camera and T_left_right (--in-both-views needs a stereo dataset)", gt_path.display(), im.id);
            };
            let c: CameraModel = serde_json::from_value(c.clone()).with_context(|| format!("{}: image {}: right_camera", gt_path.display(), im.id))?;
            let t: Pose = serde_json::from_value(t.clone()).with_context(|| format!("{}: image {}: T_left_right", gt_path.display(), im.id))?;
            right_views.insert(im.id, (c, t));
        }
    }
    let length = TubeModel::default().length;
    let mut truths = Vec::new();
    for a in &gt.annotations {
        let vis = a.extra.get("visible_fraction").and_then(|v| v.as_f64()).unwrap_or(1.0);
        let Some(v) = a.extra.get(truth_field) else { continue };
        if vis >= min_visible {
            let pose: Pose = serde_json::from_value(v.clone()).with_context(|| format!("{}: annotation {}: {truth_field}", gt_path.display(), a.id))?;
            if filter.in_both_views {
                let (c, t) = right_views.get(&a.image_id).with_context(|| format!("{}: annotation {}: no image {}", gt_path.display(), a.id, a.image_id))?;
                if right_view_fraction(&pose, length, t, c) < 0.5 {
                    continue;
                }
            }
            truths.push(TubeTruth { image_id: a.image_id, pose });
        }
    }
    let in_both = if filter.in_both_views { ", at least half in the right view" } else { "" };
    if truths.is_empty() {
        bail!("{}: no annotation with {truth_field} and visible_fraction >= {min_visible}{in_both}", gt_path.display());
    }
    let mut cameras = BTreeMap::new();
    for im in &gt.images {
        if let Some(v) = im.extra.get("camera") {
            let c: CameraModel = serde_json::from_value(v.clone()).with_context(|| format!("{}: image {}: camera", gt_path.display(), im.id))?;
            cameras.insert(im.id, c);
        }
    }
    let model = ModelPoints::from_tube(&TubeModel::default(), 0.002).context("sampling the tube model")?;
    let config = PoseEvalConfig { cameras, ..Default::default() };
    let mut evals: Vec<(String, PoseEvaluation)> = Vec::new();
    crate::out::outln!("{} truths ({truth_field}, visible_fraction >= {min_visible}{in_both}); matching: nearest centre within {match_mm} mm", truths.len());
    crate::out::outln!("| poses | converged / all | matched | axis deg med / p90 | perp mm med / p90 | |along| mm med / p90 | centre mm med / p90 | ends right | AR MSSD | AR MSPD |");
    crate::out::outln!("|---|---|---|---|---|---|---|---|---|---|");
    for (label, path) in poses {
        let (label, path) = (label.clone(), path.clone());
        let all: Vec<TubeAxisPose> = read_json(&path).with_context(|| format!("reading poses {}", path.display()))?;
        let est: Vec<TubeEstimate> = all.iter().filter(|p| p.converged).map(TubeEstimate::from_axis_pose).collect();
        let matching = match_by_centre_distance(&truths, &est, match_mm * 1e-3);
        let e = evaluate_poses(&truths, &est, &matching, &model, &config).with_context(|| format!("evaluating {}", path.display()))?;
        let s = &e.summaries;
        crate::out::outln!(
            "| {label} | {} / {} | {} / {} | {} | {} | {} | {} | {:.0}% | {:.3} | {} |",
            est.len(),
            all.len(),
            e.n_matched,
            e.n_truths,
            med_p90(&s.axis_angle_deg),
            med_p90(&s.perpendicular_mm),
            med_p90(&s.along_axis_abs_mm),
            med_p90(&s.centre_distance_mm),
            e.end_correct_fraction * 100.0,
            e.bop.ar_mssd,
            e.bop.ar_mspd.map(|v| format!("{v:.3}")).unwrap_or_else(|| "n/a".into())
        );
        evals.push((label, e));
    }
    if let Some(out) = out {
        let metrics: Vec<serde_json::Value> = evals
            .iter()
            .map(|(l, e)| {
                serde_json::json!({
                    "label": l, "n_truths": e.n_truths, "n_estimates": e.n_estimates, "n_matched": e.n_matched,
                    "method": e.method, "end_correct_fraction": e.end_correct_fraction, "summaries": e.summaries, "bop": e.bop,
                })
            })
            .collect();
        let p = out.join("pose_metrics.json");
        write_json(&p, &serde_json::json!({ "gt": gt_path, "truth_field": truth_field, "min_visible": min_visible, "in_both_views": filter.in_both_views, "match_mm": match_mm, "poses": metrics }))
            .with_context(|| format!("writing {}", p.display()))?;
        let report = tubeloc_eval::report::EvalReport {
            title: "Tube pose evaluation".into(),
            inputs: std::iter::once(("ground truth".to_string(), gt_path.display().to_string()))
                .chain(poses.iter().map(|(l, p)| ("poses".to_string(), format!("{l}={}", p.display()))))
                .chain(std::iter::once(("truths".to_string(), format!("`{truth_field}`, visible_fraction >= {min_visible}{in_both}"))))
                .collect(),
            poses: evals,
            ..Default::default()
        };
        let md = tubeloc_eval::report::write_eval_report(out, &report).with_context(|| format!("writing the report in {}", out.display()))?;
        eprintln!("report: {}", md.display());
    }
    Ok(())
}
