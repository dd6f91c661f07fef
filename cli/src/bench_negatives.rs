//! The tube-free frames of the real stage of `tubeloc bench`: `negatives_val` under the
//! assumed camera of each frame (`--assumed-view auto`: the mast camera its product name names,
//! otherwise by kind: grey Navcam, 45 degree field of view, 1.9 m high, 30 degrees down;
//! colour: the mast view), and the frames of the part's sols with PDS camera models under their
//! own. Every detection kept and every tube `locate` hands over there is false. Each figure per
//! frame carries its interval by sol ([`crate::bench_intervals`]) and a breakdown by the data's
//! folder (camera and frame size).

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use tubeloc_core::AssumedView;
use tubeloc_pipeline::FusedTubeDetector;

/// Assumed view of the negative frame at `path`, what `tubeloc locate --assumed-view auto`
/// takes ([`AssumedView::of_frame`]): the view of the mast camera its product name names,
/// otherwise grey Navcam-like or the colour mast view; with its name.
fn negative_view(path: &Path, grey: bool) -> (String, AssumedView) {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let frame = AssumedView::of_frame(&name, || grey);
    (frame.name, frame.view)
}

/// Learned detections kept at the threshold on each real negative frame.
pub fn negatives(data: &Path, detector: &Arc<dyn tubeloc_pipeline::TubeDetector>, settings: &tubeloc_pipeline::LocatorSettings, frames: Option<usize>) -> Result<Value> {
    let paths = negative_paths(data, frames)?;
    let sols = negative_sols(data, &paths)?;
    let cal = &settings.calibration;
    let mut per_frame = Vec::new();
    for p in &paths {
        let image = tubeloc_detect::input::open_eight_bit(p).with_context(|| format!("reading {}", p.display()))?;
        let grey = tubeloc_detect::input::rgb8_of(&image).info.grey;
        // `locate` at its defaults on the frame, with the assumed camera and ground (what
        // `tubeloc locate --assumed-view` builds); its detector runs at the working scale `s`.
        let (view_name, view) = negative_view(p, grey);
        let (rig, ground) = view.rig("assumed", image.width(), image.height())?;
        let s = tubeloc_detect::scale::working_scale(&rig.cameras[0].model, Some(view.ground()), Default::default());
        let locator = tubeloc_pipeline::Locator::new(&rig, &tubeloc_pipeline::CameraSelection { camera: None, pair: None }, Box::new(detector.clone()), settings.clone())?;
        let out = locator.locate(&tubeloc_pipeline::LocateInput { image: &image, right: None, ground: Some(ground), up: None, ignore: None })?;
        let (found, located) = (&out.detections, out.tubes.len());
        let kept = found.iter().filter(|d| cal.probability(d.score) >= cal.threshold).count();
        per_frame.push(json!({"image": p.strip_prefix(data).unwrap_or(p).display().to_string(), "grey": grey, "view": view_name, "scale": s, "detections": found.len(), "kept": kept, "located": located}));
    }
    let n = per_frame.len().max(1) as f64;
    let sum = |k: &str| per_frame.iter().filter_map(|f| f[k].as_u64()).sum::<u64>() as f64 / n;
    let ci = |k: &str| crate::bench_intervals::per_frame_by_sol(&per_frame, &sols, k);
    Ok(json!({"frames": per_frame.len(), "kept_per_frame": sum("kept"), "kept_per_frame_ci": ci("kept"), "detections_per_frame": sum("detections"), "located_per_frame": sum("located"), "located_per_frame_ci": ci("located"), "per_frame": per_frame}))
}

/// `locate` at its defaults on the real frames of the `split`'s sols that come with PDS camera
/// models (`with_cameras`, pinhole, at least 512 px; all, or the first `frames`): each frame
/// under its own camera and ground (the rig of `with_cameras/cameras.json`, record 0057).
/// None shows a tube, so every located tube is false. A data folder without the camera list
/// gives no frames.
pub fn pds_negatives(data: &Path, split: tubeloc_synth::real_frames::RealSplit, model: &crate::cmd_detect_learned::ModelChoice, settings: &tubeloc_pipeline::LocatorSettings, frames: Option<usize>) -> Result<Value> {
    let list = data.join("with_cameras").join("cameras.json");
    if !list.exists() {
        return Ok(json!({"frames": 0, "located_per_frame": Value::Null, "per_frame": []}));
    }
    let cams = tubeloc_calib::interchange::pds::read_pds_cameras(&list)?.with_context(|| format!("{} is not a PDS camera list", list.display()))?;
    let mut chosen: Vec<_> = cams.into_iter().filter(|c| c.camera.model.width.min(c.camera.model.height) >= 512 && split.holds(c.sol)).collect();
    chosen.sort_by(|a, b| a.camera.name.cmp(&b.camera.name));
    chosen.truncate(frames.unwrap_or(usize::MAX));
    let mut per_frame = Vec::new();
    if !chosen.is_empty() {
        let rig = tubeloc_calib::interchange::pds::rig_of(&chosen);
        let mut locator = tubeloc_pipeline::Locator::new(&rig, &Default::default(), Box::new(model.detector()?), settings.clone())?;
        for c in &chosen {
            let path = data.join("with_cameras/images").join(&c.camera.name);
            let image = tubeloc_detect::input::open_eight_bit(&path).with_context(|| format!("reading {}", path.display()))?;
            locator.select_camera(&c.camera.name)?;
            let out = locator.locate(&tubeloc_pipeline::LocateInput { image: &image, right: None, ground: Some(c.ground), up: None, ignore: None }).with_context(|| path.display().to_string())?;
            per_frame.push(json!({"image": c.camera.name, "sol": c.sol, "detections": out.detections.len(), "located": out.tubes.len()}));
        }
    }
    let located = per_frame.iter().filter_map(|f| f["located"].as_u64()).sum::<u64>();
    let sols: Vec<Option<i64>> = per_frame.iter().map(|f| f["sol"].as_i64()).collect();
    let ci = crate::bench_intervals::per_frame_by_sol(&per_frame, &sols, "located");
    Ok(json!({"frames": per_frame.len(), "located_per_frame": located as f64 / per_frame.len().max(1) as f64, "located_per_frame_ci": ci, "per_frame": per_frame}))
}

/// The sol of each of `paths` (frames in `data`) from the data's `MANIFEST.tsv`; `None` where
/// it gives none.
fn negative_sols(data: &Path, paths: &[PathBuf]) -> Result<Vec<Option<i64>>> {
    let sols = crate::bench_intervals::manifest_sols(data)?;
    Ok(paths.iter().map(|p| p.strip_prefix(data).ok().and_then(|r| sols.get(r).copied())).collect())
}

/// The `negatives_val` frames (all, or `frames` spread over the folders), sorted: the image
/// files ([`tubeloc_detect::input::image_files`]) of the folder itself and of every folder below
/// it. A folder without one is an error naming it, not a figure over no frames.
fn negative_paths(data: &Path, frames: Option<usize>) -> Result<Vec<PathBuf>> {
    let dir = data.join("negatives_val");
    let mut paths: Vec<PathBuf> = Vec::new();
    let mut folders = vec![dir.clone()];
    while let Some(folder) = folders.pop() {
        let read = || format!("reading {}", folder.display());
        paths.extend(tubeloc_detect::input::image_files(&folder).with_context(read)?);
        for entry in std::fs::read_dir(&folder).with_context(read)? {
            let p = entry.with_context(read)?.path();
            if p.is_dir() {
                folders.push(p);
            }
        }
    }
    if paths.is_empty() {
        bail!("{}: no image files in it or in the folders below it ({}): the tube-free frames are measured on them", dir.display(), tubeloc_detect::input::IMAGE_EXTENSIONS.map(|e| format!(".{e}")).join(" "));
    }
    paths.sort();
    if let Some(n) = frames {
        // Spread the subset over the folders.
        let step = (paths.len() as f64 / n.max(1) as f64).max(1.0);
        paths = (0..n.min(paths.len())).map(|i| paths[(i as f64 * step) as usize].clone()).collect();
    }
    Ok(paths)
}

/// Line2D's detections verified by pose, and the fused detections made from the same Line2D
/// matches, on each real negative frame, under the same assumed cameras as the learned
/// detector's negatives: `[line2d, fused]`.
pub fn line2d_negatives(data: &Path, det: &FusedTubeDetector, frames: Option<usize>) -> Result<[Value; 2]> {
    let paths = negative_paths(data, frames)?;
    let sols = negative_sols(data, &paths)?;
    let (mut l2_frames, mut fused_frames) = (Vec::new(), Vec::new());
    for p in &paths {
        let image = tubeloc_detect::input::open_eight_bit(p).with_context(|| format!("reading {}", p.display()))?;
        let input = tubeloc_detect::input::rgb8_of(&image);
        let grey = input.info.grey;
        // The assumed camera and ground, as `tubeloc detect --assumed-view` takes them.
        let (view_name, view) = negative_view(p, grey);
        let (camera, ground) = (view.camera(image.width(), image.height()), view.ground_plane()?);
        let t = Instant::now();
        let (found, _) = det.line2d_verified(&image, Some(&camera), Some(&ground), 0)?;
        let l2_ms = t.elapsed().as_secs_f64() * 1e3;
        let l2_json: Vec<Value> = found.iter().map(|d| d.to_coco_json(0)).collect();
        let t = Instant::now();
        let fused = det.fuse(&image, &camera, Some(&ground), 0, found)?;
        let fused_ms = l2_ms + t.elapsed().as_secs_f64() * 1e3;
        let (sx, sy) = det.line2d().scale_for(Some(&camera));
        // As `tubeloc detect` writes them (COCO results entries).
        let frame = |found: Vec<Value>, ms: f64| json!({"image": p.strip_prefix(data).unwrap_or(p).display().to_string(), "grey": grey, "view": view_name, "scale": (sx * sy).sqrt(), "kept": found.len(), "ms": ms, "scores": found.iter().map(|d| d["score"].as_f64().unwrap_or(f64::NAN)).collect::<Vec<_>>()});
        l2_frames.push(frame(l2_json, l2_ms));
        fused_frames.push(frame(crate::cmd_detect_line2d::fused_json(fused, 0), fused_ms));
    }
    let summary = |per_frame: Vec<Value>| {
        let n = per_frame.len().max(1) as f64;
        let kept = per_frame.iter().filter_map(|f| f["kept"].as_u64()).sum::<u64>() as f64;
        let max = per_frame.iter().filter_map(|f| f["kept"].as_u64()).max().unwrap_or(0);
        let ms = per_frame.iter().filter_map(|f| f["ms"].as_f64()).sum::<f64>();
        let ci = crate::bench_intervals::per_frame_by_sol(&per_frame, &sols, "kept");
        json!({"frames": per_frame.len(), "kept_per_frame": kept / n, "kept_per_frame_ci": ci, "max_per_frame": max, "ms_per_image": ms / n, "per_frame": per_frame})
    };
    Ok([summary(l2_frames), summary(fused_frames)])
}

/// The folder of `negatives_val` a frame lies in (`negatives_val/<folder>/<file>`: the data's
/// group, one camera and frame size; `a/b` for a folder below another; `.` for a frame in
/// `negatives_val` itself), from its path relative to the data folder.
fn folder_of(image: &str) -> String {
    let parts: Vec<String> = Path::new(image).components().skip(1).map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    match parts.len() {
        0 => "(none)".into(),
        1 => ".".into(),
        n => parts[..n - 1].join("/"),
    }
}

/// Per folder of `negatives_val`: how many frames, and the mean of `field` over them, from a
/// tube-free run's `per_frame` list (in folder order).
pub fn by_folder(run: &Value, field: &str) -> Vec<(String, usize, f64)> {
    let mut by: std::collections::BTreeMap<String, (usize, f64)> = std::collections::BTreeMap::new();
    for f in run["per_frame"].as_array().into_iter().flatten() {
        let e = by.entry(folder_of(f["image"].as_str().unwrap_or(""))).or_default();
        e.0 += 1;
        e.1 += f[field].as_f64().unwrap_or(0.0);
    }
    by.into_iter().map(|(k, (n, sum))| (k, n, sum / n.max(1) as f64)).collect()
}

/// The markdown table of the figures per tube-free frame by folder of `negatives_val`: for each
/// `(column title, run, field)`, the mean of `field` over the folder's frames.
pub fn folder_table(columns: &[(&str, &Value, &str)]) -> String {
    let Some((_, first, field)) = columns.first() else { return String::new() };
    let folders = by_folder(first, field);
    let per_column: Vec<Vec<(String, usize, f64)>> = columns.iter().map(|(_, run, field)| by_folder(run, field)).collect();
    let mut md = format!("| folder of `negatives_val` | frames | {} |\n|---|---:|{}\n", columns.iter().map(|c| c.0).collect::<Vec<_>>().join(" | "), "---:|".repeat(columns.len()));
    for (i, (folder, n, _)) in folders.iter().enumerate() {
        let cells: Vec<String> = per_column.iter().map(|c| c.get(i).filter(|r| &r.0 == folder).map_or("-".into(), |r| format!("{:.2}", r.2))).collect();
        md.push_str(&format!("| `{folder}` | {n} | {} |\n", cells.join(" | ")));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_per_frame_are_broken_down_by_folder() {
        let run = json!({"per_frame": [
            {"image": "negatives_val/msl_navcam_1024/a.png", "kept": 3, "located": 1},
            {"image": "negatives_val/msl_navcam_1024/b.png", "kept": 0, "located": 0},
            {"image": "negatives_val/msl_mastcam_marsdata/c.jpg", "kept": 1, "located": 0},
        ]});
        assert_eq!(by_folder(&run, "kept"), vec![("msl_mastcam_marsdata".to_string(), 1, 1.0), ("msl_navcam_1024".to_string(), 2, 1.5)]);
        let md = folder_table(&[("kept", &run, "kept"), ("located", &run, "located")]);
        assert!(md.contains("| `msl_navcam_1024` | 2 | 1.50 | 0.50 |"), "{md}");
        assert!(md.starts_with("| folder of `negatives_val` | frames | kept | located |\n|---|---:|---:|---:|\n"), "{md}");
    }

    #[test]
    fn frames_are_read_from_the_folder_itself_and_every_folder_below_it() {
        let dir = tempfile::tempdir().unwrap();
        let neg = dir.path().join("negatives_val");
        std::fs::create_dir_all(neg.join("navcam/deep")).unwrap();
        std::fs::create_dir_all(neg.join("empty")).unwrap();
        for f in ["top.png", "navcam/a.JPG", "navcam/deep/b.tif", "navcam/notes.txt", "navcam/p.img", "navcam/p.lbl"] {
            std::fs::write(neg.join(f), b"x").unwrap();
        }
        let rel: Vec<String> = negative_paths(dir.path(), None).unwrap().iter().map(|p| p.strip_prefix(dir.path()).unwrap().display().to_string()).collect();
        assert_eq!(rel, ["negatives_val/navcam/a.JPG", "negatives_val/navcam/deep/b.tif", "negatives_val/navcam/p.lbl", "negatives_val/top.png"]);
        let folders: Vec<String> = rel.iter().map(|r| folder_of(r)).collect();
        assert_eq!(folders, ["navcam", "navcam/deep", "navcam", "."]);
        assert_eq!(negative_paths(dir.path(), Some(2)).unwrap().len(), 2);

        let empty = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(empty.path().join("negatives_val/navcam")).unwrap();
        std::fs::write(empty.path().join("negatives_val/navcam/readme.txt"), b"x").unwrap();
        let e = negative_paths(empty.path(), None).unwrap_err().to_string();
        assert!(e.contains("negatives_val: no image files in it or in the folders below it (.png .jpg"), "{e}");
    }
}
