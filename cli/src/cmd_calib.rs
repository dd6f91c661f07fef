//! `tubeloc calib`: AprilTag detection, tag-pair ground truth for datasets, rig calibration.

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use std::path::{Path, PathBuf};
use tubeloc_calib::interchange::{kalibr, ros};
use tubeloc_calib::{calibrate, estimate_tube_pose, load_calib_set_reporting, save_rig_yaml, CalibError, CalibrationOptions, CornerSource, DetectorConfig, TagFamily, TagMount};
use tubeloc_core::{files, CameraModel, Rig};

/// Calibration subcommands.
#[derive(Subcommand)]
pub enum CalibCommand {
    /// Detect AprilTags in images and print/write them as JSON (OpenCV pixel convention).
    Detect(DetectArgs),
    /// Calibrate a camera rig from a calibration set (`tubeloc synth calib` output).
    Rig(RigArgs),
    /// Add tag-pair ground-truth tube poses to a dataset's annotations.json.
    Groundtruth(GroundtruthArgs),
}

/// Options shared by the commands that detect tags.
#[derive(Args, Clone)]
pub struct DetectorArgs {
    /// Tag families to look for (tag36h11, tag25h9, tag16h5, tagStandard41h12), comma separated.
    #[arg(long, value_delimiter = ',', default_value = "tag36h11")]
    pub family: Vec<String>,
    /// Quad decimation factor (1 = full resolution).
    #[arg(long, default_value_t = 1.0, value_parser = crate::args::decimation)]
    pub decimate: f32,
    /// Images detected at once by `calib detect`, `calib groundtruth` and `calib rig`, each on one thread
    /// (the AprilTag C detector's own worker pool is not used: it races and can crash).
    #[arg(long, default_value_t = 2, value_parser = crate::args::positive_u8)]
    pub threads: u8,
    /// Snap quad edges to strong gradients (off by default, as in the reference detector's
    /// corners; can help when decimating).
    #[arg(long)]
    pub refine_edges: bool,
    /// Accepted for old scripts: edge refinement is off unless --refine-edges.
    #[arg(long, hide = true, conflicts_with = "refine_edges")]
    pub no_refine_edges: bool,
    /// Encoding of the images: `linear` (camera photos and raw data, 8-bit values used as
    /// they are, as the reference C detector does; chosen on real photos, docs/design/0026) or
    /// `srgb` (images rendered in linear light and sRGB-encoded, like `tubeloc synth` scenes:
    /// linearized first, which removes a ~0.3 px inward corner bias there).
    #[arg(long, default_value = "linear", value_parser = ["srgb", "linear"])]
    pub encoding: String,
}

impl DetectorArgs {
    /// The settings for images rendered by `tubeloc synth` (`--encoding srgb --refine-edges`,
    /// tag36h11, full resolution, 2 threads).
    pub(crate) fn rendered() -> Self {
        DetectorArgs { family: vec!["tag36h11".into()], decimate: 1.0, threads: 2, refine_edges: true, no_refine_edges: false, encoding: "srgb".into() }
    }

    /// The detector's settings, checked ([`DetectorConfig::validate`]).
    fn config(&self) -> Result<DetectorConfig> {
        let families = self.family.iter().map(|f| TagFamily::from_name(f.trim())).collect::<Result<Vec<_>, _>>()?;
        let config = DetectorConfig { families, decimation: self.decimate, threads: self.threads, refine_edges: self.refine_edges, linearize_srgb: self.encoding == "srgb", ..Default::default() };
        config.validate()?;
        Ok(config)
    }
}

/// `tubeloc calib detect`.
#[derive(Args)]
pub struct DetectArgs {
    /// Images to read.
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Write all detections here as JSON (default: print to stdout).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub detector: DetectorArgs,
}

/// `tubeloc calib rig`.
#[derive(Args)]
pub struct RigArgs {
    /// Calibration set folder (with calib_set.json).
    #[arg(long)]
    pub views: PathBuf,
    /// Output rig (tubeloc JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the rig as OpenCV FileStorage YAML.
    #[arg(long)]
    pub yaml: Option<PathBuf>,
    /// Also write ROS camera_info YAML files into this folder: `NAME.yaml` per camera, with its
    /// first stereo pair's rectification (R) and projection (P) matrices.
    #[arg(long)]
    pub ros: Option<PathBuf>,
    /// Also write a kalibr camchain (pinhole, radtan). kalibr's radtan has no k3, hence --fix-k3.
    #[arg(long, requires = "fix_k3")]
    pub camchain: Option<PathBuf>,
    /// Corner source: detect (run the detector on the images), noisy or exact (from the file).
    #[arg(long, default_value = "detect", value_parser = ["detect", "noisy", "exact"])]
    pub corners: String,
    /// Keep k3 = 0.
    #[arg(long)]
    pub fix_k3: bool,
    /// Write the full report (per-camera, per-view RMS, uncertainties) here as JSON.
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub detector: DetectorArgs,
}

/// `tubeloc calib groundtruth`.
#[derive(Args)]
pub struct GroundtruthArgs {
    /// Dataset folder with annotations.json and the images.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Tag mount description. Default: each image's own `tags.tags[*].T_tube_tag` (written by
    /// `tubeloc synth`) when present, else the shipped data/tag_mount.toml.
    #[arg(long)]
    pub mount: Option<PathBuf>,
    /// Camera model JSON (or a PDS3 label) for images whose entry has no `camera` field.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    #[command(flatten)]
    pub detector: DetectorArgs,
}

/// Runs `tubeloc calib`.
pub fn run(cmd: CalibCommand) -> Result<()> {
    match cmd {
        CalibCommand::Detect(a) => run_detect(a),
        CalibCommand::Rig(a) => run_rig(a),
        CalibCommand::Groundtruth(a) => run_groundtruth(a),
    }
}

/// The tags of each image of `paths`, in order (`tubeloc_calib::detect_files`: `--threads`
/// images at once, record 0079); `bar` advances by one per image.
fn detect_images(d: &DetectorArgs, paths: &[PathBuf], bar: &indicatif::ProgressBar) -> Result<Vec<Result<Vec<tubeloc_calib::TagDetection>, tubeloc_calib::CalibError>>> {
    Ok(tubeloc_calib::detect_files(&d.config()?, paths, &|| bar.inc(1))?)
}

fn run_detect(a: DetectArgs) -> Result<()> {
    let found = detect_images(&a.detector, &a.images, &indicatif::ProgressBar::hidden())?;
    let mut all = serde_json::Map::new();
    for (p, d) in a.images.iter().zip(found) {
        all.insert(p.display().to_string(), serde_json::to_value(d?)?);
    }
    let v = serde_json::Value::Object(all);
    match a.out {
        Some(out) => files::write_json(&out, &v).with_context(|| format!("writing {}", out.display()))?,
        None => crate::out::outln!("{}", serde_json::to_string_pretty(&v)?),
    }
    Ok(())
}

fn run_rig(a: RigArgs) -> Result<()> {
    let source = match a.corners.as_str() {
        "exact" => CornerSource::Exact,
        "noisy" => CornerSource::Noisy,
        _ => CornerSource::Detect,
    };
    let config = a.detector.config()?;
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(indicatif::ProgressStyle::with_template("detect tags {bar:30} {pos}/{len} images {elapsed}").unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()));
    let set = load_calib_set_reporting(&a.views, source, Some(&config), &|n| {
        bar.set_length(n as u64);
        bar.inc(1);
    })
    .with_context(|| format!("reading calibration set {}", a.views.display()))?;
    bar.finish_and_clear();
    let opts = CalibrationOptions { fix_k3: a.fix_k3, ..Default::default() };
    let cal = calibrate(&set.input, &opts).with_context(|| format!("calibrating from {}", a.views.display()))?;
    // Every export is built before anything is written, so that a refused one writes nothing.
    if let Some(p) = &a.camchain {
        kalibr::rig_to_camchain(&cal.rig).with_context(|| format!("--camchain {}", p.display()))?;
    }
    if let Some(d) = &a.ros {
        ros::rig_camera_infos(&cal.rig).with_context(|| format!("--ros {}", d.display()))?;
    }
    cal.rig.save_json(&a.out).with_context(|| format!("writing {}", a.out.display()))?;
    // Each file is read back as a check.
    if let Some(y) = &a.yaml {
        save_rig_yaml(&cal.rig, y).with_context(|| format!("writing {}", y.display()))?;
        tubeloc_calib::load_rig_yaml(y).with_context(|| format!("re-reading {}", y.display()))?;
    }
    if let Some(d) = &a.ros {
        for p in ros::save_rig_camera_infos(&cal.rig, d).with_context(|| format!("writing {}", d.display()))? {
            ros::CameraInfo::load(&p).with_context(|| format!("re-reading {}", p.display()))?;
        }
    }
    if let Some(p) = &a.camchain {
        kalibr::save_camchain(&cal.rig, p).with_context(|| format!("writing {}", p.display()))?;
        kalibr::load_camchain(p).with_context(|| format!("re-reading {}", p.display()))?;
    }
    Rig::load_json(&a.out).with_context(|| format!("re-reading {}", a.out.display()))?;
    if let Some(r) = &a.report {
        files::write_json(r, &cal).with_context(|| format!("writing {}", r.display()))?;
    }
    for c in &cal.cameras {
        let (m, sd) = (&c.model, &c.std);
        crate::out::outln!(
            "{:>6}: fx {:.3}±{:.3} fy {:.3}±{:.3} cx {:.3}±{:.3} cy {:.3}±{:.3} k1 {:.5}±{:.5} k2 {:.5}±{:.5} p1 {:.6}±{:.6} p2 {:.6}±{:.6} k3 {:.5}±{:.5}  rms {:.3} px  views {}  outliers {}",
            c.name,
            m.fx,
            sd[0],
            m.fy,
            sd[1],
            m.cx,
            sd[2],
            m.cy,
            sd[3],
            m.distortion.k1,
            sd[4],
            m.distortion.k2,
            sd[5],
            m.distortion.p1,
            sd[6],
            m.distortion.p2,
            sd[7],
            m.distortion.k3,
            sd[8],
            c.rms_px,
            c.views.len(),
            c.outliers
        );
        let ps = &c.t_rig_cam_std;
        if ps.translation_m.iter().chain(&ps.rotation_rad).any(|v| *v > 0.0) {
            let t = c.t_rig_cam.translation();
            crate::out::outln!(
                "        position in rig {:.2}±{:.2} {:.2}±{:.2} {:.2}±{:.2} mm, rotation std {:.4} {:.4} {:.4} deg",
                t.x * 1e3,
                ps.translation_m[0] * 1e3,
                t.y * 1e3,
                ps.translation_m[1] * 1e3,
                t.z * 1e3,
                ps.translation_m[2] * 1e3,
                ps.rotation_rad[0].to_degrees(),
                ps.rotation_rad[1].to_degrees(),
                ps.rotation_rad[2].to_degrees()
            );
        }
    }
    for (l, r, b) in &cal.baselines {
        crate::out::outln!("baseline {l}-{r}: {:.2} mm", b * 1e3);
    }
    crate::out::outln!("overall rms {:.4} px per corner ({:.4} px per coordinate)", cal.rms_px, cal.rms_coord_px);
    for s in &cal.skipped {
        eprintln!("skipped: {s}");
    }
    Ok(())
}

fn bbox_score(ann: &serde_json::Value, u: f64, v: f64) -> f64 {
    let Some(b) = ann.get("bbox").and_then(|b| b.as_array()) else { return f64::INFINITY };
    let b: Vec<f64> = b.iter().filter_map(|x| x.as_f64()).collect();
    if b.len() != 4 {
        return f64::INFINITY;
    }
    let inside = u >= b[0] && u <= b[0] + b[2] && v >= b[1] && v <= b[1] + b[3];
    let d = (u - (b[0] + b[2] / 2.0)).hypot(v - (b[1] + b[3] / 2.0));
    if inside {
        d
    } else {
        1e6 + d
    }
}

/// The mount recorded with an image by `tubeloc synth` (`tags.tags[*]` with `id`, `size_m`,
/// `T_tube_tag`), if any.
fn mount_from_image(im: &serde_json::Value) -> Option<TagMount> {
    let tags = im.get("tags")?.get("tags")?.as_array()?;
    let mut out = Vec::new();
    for t in tags {
        let id = t.get("id")?.as_u64()? as u32;
        let size_m = t.get("size_m")?.as_f64()?;
        let pose: tubeloc_core::Pose = serde_json::from_value(t.get("T_tube_tag")?.clone()).ok()?;
        out.push(tubeloc_calib::MountedTag { id, size_m, t_tube_tag: pose });
    }
    (!out.is_empty()).then_some(TagMount { family: tubeloc_calib::TagFamily::Tag36h11, tags: out })
}

fn run_groundtruth(a: GroundtruthArgs) -> Result<()> {
    let given_mount = a.mount.as_deref().map(TagMount::load).transpose()?;
    let fallback_cam = a.camera.as_deref().map(tubeloc_calib::read_camera).transpose()?;
    let ann_path = a.dataset.join("annotations.json");
    let mut coco: serde_json::Value = files::read_json(&ann_path)?;
    let images = coco.get("images").and_then(|v| v.as_array()).cloned().with_context(|| format!("{}: no `images` array", ann_path.display()))?;
    // Each image's entry is checked first (in order), then the tags of all are detected at
    // once (`--threads`), then each pose is estimated and matched in order.
    let mut entries = Vec::with_capacity(images.len());
    for (i, im) in images.iter().enumerate() {
        let id = im.get("id").cloned().with_context(|| format!("{}: images[{i}] has no id", ann_path.display()))?;
        let file = im.get("file_name").and_then(|f| f.as_str()).with_context(|| format!("{}: images[{i}] has no file_name", ann_path.display()))?;
        let camera: CameraModel = match im.get("camera") {
            Some(c) => serde_json::from_value(c.clone()).with_context(|| format!("{}: images[{i}].camera", ann_path.display()))?,
            None => fallback_cam.clone().with_context(|| format!("{}: images[{i}] has no `camera`; pass --camera", ann_path.display()))?,
        };
        let mount = match &given_mount {
            Some(m) => m.clone(),
            None => mount_from_image(im).unwrap_or_else(TagMount::default_mount),
        };
        let direct = a.dataset.join(file);
        let path = if direct.is_file() { direct } else { a.dataset.join("images").join(file) };
        entries.push((id, camera, mount, path));
    }
    let bar = indicatif::ProgressBar::new(images.len() as u64);
    let paths: Vec<PathBuf> = entries.iter().map(|e| e.3.clone()).collect();
    let found = detect_images(&a.detector, &paths, &bar)?;
    let (mut posed, mut single, mut none) = (0, 0, 0);
    for ((id, camera, mount, path), dets) in entries.into_iter().zip(found) {
        let dets = dets?;
        let est = match estimate_tube_pose(&camera, &mount, &dets) {
            Ok(e) => e,
            Err(CalibError::NoTags(_)) => {
                none += 1;
                continue;
            }
            Err(e) => return Err(anyhow::Error::new(e).context(format!("tag pose in {}", path.display()))),
        };
        let c = est.t_cam_tube.translation();
        let centre = camera.project(&nalgebra::Point3::from(c));
        let anns = coco.get_mut("annotations").and_then(|v| v.as_array_mut()).with_context(|| format!("{}: no `annotations` array", ann_path.display()))?;
        let mut best: Option<(f64, usize)> = None;
        for (k, ann) in anns.iter().enumerate() {
            if ann.get("image_id") != Some(&id) {
                continue;
            }
            let flagged = ["carries_tags", "has_tags"].iter().any(|k| ann.get(*k).and_then(|v| v.as_bool()).unwrap_or(false));
            let score = if flagged { -1.0 } else { centre.map(|p| bbox_score(ann, p.x, p.y)).unwrap_or(f64::INFINITY) };
            if best.map(|b| score < b.0).unwrap_or(true) {
                best = Some((score, k));
            }
        }
        // A tag pose whose tube centre falls in no annotated tube's box belongs to a tube that
        // is not annotated (cut by the crop, fully occluded): it is no ground truth for any.
        let Some((_, k)) = best.filter(|b| b.0 < 1e6) else {
            none += 1;
            continue;
        };
        let obj = anns[k].as_object_mut().with_context(|| format!("{}: annotation is not an object", ann_path.display()))?;
        obj.insert("T_cam_tube_tags".into(), serde_json::to_value(est.t_cam_tube)?);
        obj.insert("tags_pose".into(), serde_json::json!({"single_tag": est.single_tag, "ambiguous": est.ambiguous, "tags_used": est.tags_used, "rms_px": est.rms_px, "covariance": est.covariance}));
        posed += 1;
        if est.single_tag {
            single += 1;
        }
    }
    bar.finish_and_clear();
    files::write_json(&ann_path, &coco).with_context(|| format!("writing {}", ann_path.display()))?;
    crate::out::outln!("{}: {posed} tag poses ({single} from one tag only), {none} images without mount tags", ann_path.display());
    if posed == 0 && !images.is_empty() {
        bail!("no mount tag found in any image of {}", Path::new(&a.dataset).display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cmd {
        #[command(flatten)]
        detector: DetectorArgs,
    }

    /// The command line's detector defaults are the library's (docs/design/0026); only the
    /// thread count differs, which does not change the detections.
    #[test]
    fn detector_defaults_are_the_library_defaults() {
        let config = Cmd::parse_from(["calib"]).detector.config().unwrap();
        assert_eq!(config, DetectorConfig { threads: 2, ..Default::default() });
        let config = Cmd::parse_from(["calib", "--encoding", "srgb", "--refine-edges"]).detector.config().unwrap();
        assert!(config.linearize_srgb && config.refine_edges);
    }
}
