//! The grasp table of `tubeloc bench`: `locate`'s grasp collision check on a dataset's images.
//!
//! Each image (up to a limit) runs through the pipeline's [`Locator`] with the dataset's
//! detections of that image as seeds, its own ground (`--ground auto`: the image's
//! `T_world_cam`) and, for a stereo set, its right image. Counted over the located tubes: how
//! many have a feasible grasp, how many grasps the check changed from the plain grasp from
//! above, whether terrain was checked, and the tubes rejected for interpenetrating a stronger
//! one. On a set with true poses (`T_cam_tube`), also how many located tubes are tubes of the
//! set: their centre within [`MATCH_M`] of a true tube's, matched one to one (the pose
//! evaluation's gate), strongest first.

use anyhow::{Context, Result};
use rayon::prelude::*;
use serde_json::{json, Value};
use std::path::Path;
use tubeloc_core::{CocoDataset, Pose, Rig, RigCamera};
use tubeloc_eval::pose_match::{match_by_centre_distance, TubeEstimate, TubeTruth};
use tubeloc_pipeline::{CameraSelection, ExternalDetections, LocateInput, Locator, LocatorSettings, Rejection};

/// Greatest distance (metres) between a located tube's centre and a true tube's centre for the
/// located tube to count as that tube: the 50 mm gate of `tubeloc eval --poses`.
pub const MATCH_M: f64 = 0.05;

/// Runs the grasp check over up to `max_images` images of the dataset in `set` seeded by the
/// detections file `dets` (stereo with the right images when `stereo`), accepting tubes as
/// `acceptance`'s calibration and pose evidence do when given (else every converged tube is
/// located). Returns the counts.
pub fn run(set: &Path, dets: &Path, stereo: bool, max_images: Option<usize>, acceptance: Option<&LocatorSettings>) -> Result<Value> {
    let ann = set.join("annotations.json");
    let ds = CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
    let all = tubeloc_core::detection::read_coco_results(dets)?;
    let mut images: Vec<_> = ds.images.iter().collect();
    images.truncate(max_images.unwrap_or(usize::MAX));
    let mut settings = acceptance.cloned().unwrap_or_default();
    // As `refine --ground auto`: the nominal ground's height is the terrain's level, not a constraint.
    settings.refine.priors.ground_height_known = false;
    let per_image: Vec<Value> = images
        .par_iter()
        .map(|im| -> Result<Value> {
            let camera = crate::cmd_refine::dataset::camera_of(im)?;
            let ground = crate::cmd_refine::dataset::ground_of(im)?;
            let path = [set.join(&im.file_name), set.join("images").join(&im.file_name)].into_iter().find(|p| p.exists()).with_context(|| format!("{}: image {} not found", set.display(), im.file_name))?;
            let image = tubeloc_detect::input::open_eight_bit(&path).with_context(|| format!("reading {}", path.display()))?;
            let right = if stereo { Some(crate::cmd_refine::dataset::right_view_of(set, im)?) } else { None };
            let mut cameras = vec![RigCamera { name: "left".into(), model: camera, t_rig_cam: Pose::identity() }];
            let mut pairs = Vec::new();
            if let Some((_, rcam, t_left_right)) = &right {
                cameras.push(RigCamera { name: "right".into(), model: rcam.clone(), t_rig_cam: *t_left_right });
                pairs.push(("left".to_string(), "right".to_string()));
            }
            let rig = Rig { cameras, stereo_pairs: pairs };
            let mine: Vec<_> = all
                .iter()
                .filter(|d| d.image_id == im.id)
                .cloned()
                .map(|mut d| {
                    d.image_id = 0;
                    d
                })
                .collect();
            let locator = Locator::new(&rig, &CameraSelection::default(), Box::new(ExternalDetections::new(mine, "bench")), settings.clone())?;
            let out = locator.locate(&LocateInput { image: &image, right: right.as_ref().map(|r| &r.0), ground, up: None, ignore: None })?;
            let t = &out.tubes;
            let truths: Vec<TubeTruth> = ds.annotations.iter().filter(|a| a.image_id == im.id).filter_map(|a| Some(TubeTruth { image_id: 0, pose: serde_json::from_value(a.extra.get("T_cam_tube")?.clone()).ok()? })).collect();
            let located: Vec<TubeEstimate> = t.iter().map(|t| TubeEstimate { image_id: 0, ..TubeEstimate::from_axis_pose(&t.pose) }).collect();
            let matching = match_by_centre_distance(&truths, &located, MATCH_M);
            // Each located tube that is no tube of the set: its probability and how far its
            // centre lies from the nearest true tube's (metres; none when the image has none).
            let false_tubes: Vec<Value> = matching
                .unmatched_estimates
                .iter()
                .map(|&e| {
                    let c = located[e].pose.translation();
                    let nearest = truths.iter().map(|tr| (tr.pose.translation() - c).norm()).min_by(f64::total_cmp);
                    json!({"probability": t[e].probability, "nearest_truth_m": nearest})
                })
                .collect();
            Ok(json!({
                "image": im.file_name,
                "located": t.len(),
                "truths": truths.len(),
                "true_located": matching.pairs.len(),
                "false_tubes": false_tubes,
                "feasible": t.iter().filter(|t| t.grasp.feasible).count(),
                "changed": t.iter().filter(|t| t.grasp.changed).count(),
                "changed_feasible": t.iter().filter(|t| t.grasp.changed && t.grasp.feasible).count(),
                "terrain_checked": t.iter().filter(|t| t.grasp.terrain_checked).count(),
                "intersecting": out.rejected.iter().filter(|r| matches!(r.reason, Rejection::IntersectsTube { .. })).count(),
                "rejected_ground": t.iter().map(|t| t.grasp.rejected.ground).sum::<usize>(),
                "rejected_tube": t.iter().map(|t| t.grasp.rejected.tube).sum::<usize>(),
                "rejected_terrain": t.iter().map(|t| t.grasp.rejected.terrain).sum::<usize>(),
                "candidates": t.iter().map(|t| t.grasp.candidates_tried).sum::<usize>(),
                "grasp_ms": out.timings.grasp_ms,
            }))
        })
        .collect::<Result<_>>()?;
    let sum = |k: &str| per_image.iter().filter_map(|v| v[k].as_u64()).sum::<u64>();
    let grasp_ms: f64 = per_image.iter().filter_map(|v| v["grasp_ms"].as_f64()).sum();
    let located = sum("located");
    Ok(json!({
        "images": per_image.len(),
        "located": located,
        "truths": sum("truths"),
        "true_located": sum("true_located"),
        "feasible": sum("feasible"),
        "changed": sum("changed"),
        "changed_feasible": sum("changed_feasible"),
        "terrain_checked": sum("terrain_checked"),
        "intersecting": sum("intersecting"),
        "rejected_ground": sum("rejected_ground"),
        "rejected_tube": sum("rejected_tube"),
        "rejected_terrain": sum("rejected_terrain"),
        "candidates": sum("candidates"),
        "grasp_ms_per_tube": if located > 0 { grasp_ms / located as f64 } else { 0.0 },
        // The images where `locate` handed over a tube that is none of the set's.
        "false_located": per_image.iter().filter(|v| v["false_tubes"].as_array().is_some_and(|f| !f.is_empty())).map(|v| json!({"image": v["image"], "false_tubes": v["false_tubes"]})).collect::<Vec<_>>(),
    }))
}

/// The markdown table of [`run`]'s results, one row per `(name, result)`.
pub fn table(rows: &[(&str, &Value)]) -> String {
    let mut t = String::from("| set | images | located tubes | of them true tubes (centre within 50 mm) | true tubes located | feasible grasp | changed by the check (of which feasible) | terrain checked | rejected: overlapping a stronger tube | candidates rejected: ground / tube / terrain | grasp stage ms per tube |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|\n");
    for (name, v) in rows {
        let n = v["located"].as_u64().unwrap_or(0);
        let share = |k: &str| if n > 0 { format!("{} ({:.0}%)", v[k], 100.0 * v[k].as_u64().unwrap_or(0) as f64 / n as f64) } else { "-".into() };
        let (truths, right) = (v["truths"].as_u64().unwrap_or(0), v["true_located"].as_u64().unwrap_or(0));
        let true_located = if truths > 0 { share("true_located") } else { "-".into() };
        let recall = if truths > 0 { format!("{right} of {truths} ({:.0}%)", 100.0 * right as f64 / truths as f64) } else { "-".into() };
        t += &format!(
            "| {name} | {} | {n} | {true_located} | {recall} | {} | {} ({}) | {} | {} | {} / {} / {} of {} | {:.2} |\n",
            v["images"],
            share("feasible"),
            share("changed"),
            v["changed_feasible"],
            v["terrain_checked"],
            v["intersecting"],
            v["rejected_ground"],
            v["rejected_tube"],
            v["rejected_terrain"],
            v["candidates"],
            v["grasp_ms_per_tube"].as_f64().unwrap_or(f64::NAN)
        );
    }
    t
}
