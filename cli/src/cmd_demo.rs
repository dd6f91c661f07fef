//! `tubeloc demo`: the whole pipeline on a small generated with-tags scene, no arguments needed.
//!
//! It runs the same steps a user runs as subcommands, called in-process with typed arguments: render a with-tags scene, derive the paper's
//! tag-pair ground truth from the rendered AprilTags, detect tubes with both detectors (Line2D
//! with a small library built for the scene's camera; the learned segmenter with the shipped
//! model), score the detections with COCO metrics, refine every detection into a tube axis
//! pose, score the poses against the renderer's exact poses (with histograms), run the main job
//! `tubeloc locate` on the first image, and write `report.md`.

use crate::cmd_calib::{CalibCommand, DetectorArgs, GroundtruthArgs};
use crate::cmd_detect::{DetectArgs, Method};
use crate::cmd_eval::EvalArgs;
use crate::cmd_refine::dataset::{refine_dataset, DatasetJob, DatasetSeeds};
use crate::cmd_refine::GroundArg;
use crate::cmd_synth::DatasetArgs;
use anyhow::{Context, Result};
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tubeloc_core::{files, CameraModel, CocoDataset, Pose};
use tubeloc_detect::line2d::ViewParams;

/// Arguments of `tubeloc demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder (replaced if it exists).
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Seed of the generated scene.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Crop side of the rendered images, pixels.
    #[arg(long, default_value_t = 512, value_parser = crate::args::positive_u32)]
    pub resolution: u32,
    /// Learned model (default: the shipped model, embedded in the program; a file that does not
    /// exist is skipped).
    #[arg(long)]
    pub model: Option<PathBuf>,
}

/// Runs `tubeloc demo`.
pub fn run(a: DemoArgs) -> Result<()> {
    let t0 = Instant::now();
    let out = &a.out;
    if out.exists() {
        std::fs::remove_dir_all(out).with_context(|| format!("replacing {}", out.display()))?;
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let dataset = out.join("dataset");
    let mut log = Vec::<(String, f64)>::new();
    // One timed step: `what` is the equivalent command line, shown to the user.
    let step = |name: &str, what: String, log: &mut Vec<(String, f64)>, f: &mut dyn FnMut() -> Result<()>| -> Result<()> {
        eprintln!("\n== demo: {name}: {what}");
        let t = Instant::now();
        f().with_context(|| format!("demo step {name:?}"))?;
        log.push((name.to_string(), t.elapsed().as_secs_f64()));
        Ok(())
    };

    // 1. A with-tags CFA6 scene from the tiny preset, at quarter resolution.
    let render = format!("tubeloc synth --preset tiny --scenes 1 --scale 0.5 --resolution {} --seed {} --force --out {}", a.resolution, a.seed, dataset.display());
    step("render a with-tags scene", render, &mut log, &mut || {
        crate::cmd_synth::run_dataset(DatasetArgs { preset: "tiny".into(), out: Some(dataset.clone()), scenes: Some(1), resolution: Some(a.resolution), scale: Some(0.5), seed: a.seed, tube_mesh: None, shard: (0, 1), force: true })
    })?;
    let gt_path = dataset.join("annotations.json");

    // 2. The paper's ground truth: tube poses from the AprilTag pair on the tagged tube.
    // A scene may show no tag pair (tags hidden or out of the crops): reported, not fatal.
    let groundtruth = GroundtruthArgs { dataset: dataset.clone(), mount: None, camera: None, detector: DetectorArgs::rendered() };
    let what = format!("tubeloc calib groundtruth --dataset {} --encoding srgb --refine-edges", dataset.display());
    let mut groundtruth = Some(groundtruth);
    if let Err(e) = step("tag-pair ground truth", what, &mut log, &mut || crate::cmd_calib::run(CalibCommand::Groundtruth(groundtruth.take().context("run once")?))) {
        eprintln!("demo: no tag-pair ground truth: {e:#}");
    }
    let tags = crate::figures::tag_pose_errors(&gt_path)?;

    let gt = CocoDataset::load(&gt_path)?;
    let first = gt.images.first().with_context(|| format!("{}: no images", gt_path.display()))?;
    let camera: CameraModel =
        serde_json::from_value(first.extra.get("camera").cloned().with_context(|| format!("{}: image {} has no camera", gt_path.display(), first.id))?).with_context(|| format!("{}: image {}: camera", gt_path.display(), first.id))?;
    let cam_path = out.join("camera.json");
    files::write_json(&cam_path, &camera)?;

    // 3. Detectors: Line2D (a library coarser than the default, to stay quick) and the
    //    learned segmenter when a model is available.
    let lib = out.join("templates.tlt");
    let views = ViewParams { dist_min: 1.0, dist_max: 3.5, dist_step: 0.25, step_deg: 12.0, ..ViewParams::default() };
    let what = format!("tubeloc templates build --out {} --camera {} --distances 1.0:3.5:0.25 --step-deg 12", lib.display(), cam_path.display());
    step("build Line2D templates", what, &mut log, &mut || crate::cmd_templates::build_for_camera(&camera, views.clone(), &lib))?;
    let model = crate::cmd_detect_learned::ModelChoice::of(a.model.as_deref());
    let mut detectors: Vec<(&str, Method)> = vec![("line2d", Method::Line2d)];
    match &model {
        crate::cmd_detect_learned::ModelChoice::File(m) if !m.exists() => eprintln!("demo: no learned model at {} (skipping the learned detector)", m.display()),
        _ => detectors.push(("learned", Method::Learned)),
    }
    let mut pose_inputs: Vec<(String, PathBuf)> = Vec::new();
    for &(det, method) in &detectors {
        let dets = out.join(format!("{det}_detections.json"));
        let mut detect = DetectArgs::dataset(method, &dataset, &dets);
        match method {
            Method::Line2d => (detect.line2d.templates, detect.line2d.camera) = (Some(lib.clone()), Some(cam_path.clone())),
            _ => detect.model = model.path().map(Path::to_path_buf),
        }
        let mut detect = Some(detect);
        step(&format!("detect ({det})"), format!("tubeloc detect --method {det} --dataset {} --out {}", dataset.display(), dets.display()), &mut log, &mut || crate::cmd_detect::run(detect.take().context("run once")?))?;
        let eval_dir = out.join(format!("eval_{det}"));
        let what = format!("tubeloc eval --gt {} --dt {} --out {}", gt_path.display(), dets.display(), eval_dir.display());
        step(&format!("evaluate detections ({det})"), what, &mut log, &mut || crate::cmd_eval::run(EvalArgs::detections(&gt_path, &dets, &eval_dir, &[])))?;
        let (poses, seeds) = (out.join(format!("{det}_poses.json")), out.join(format!("{det}_seeds.json")));
        // Refinement through the pipeline, as `tubeloc refine --dataset D --detections F --ground auto`.
        let mut job = DatasetJob::new(dataset.clone(), DatasetSeeds::Detections(dets.clone()), poses.clone());
        job.ground = Some(GroundArg::Auto);
        job.seeds_out = Some(seeds.clone());
        eprintln!("\n== demo: refine ({det} seeds) in {}", dataset.display());
        let t = Instant::now();
        refine_dataset(&job).with_context(|| format!("demo step \"refine ({det} seeds)\""))?;
        log.push((format!("refine ({det} seeds)"), t.elapsed().as_secs_f64()));
        pose_inputs.push((format!("{det}-coarse"), seeds));
        pose_inputs.push((format!("{det}-refined"), poses));
    }

    // 4. Pose errors against the renderer's exact poses, all detectors in one set of histograms.
    let pose_dir = out.join("eval_poses");
    let labels: Vec<(&str, &Path)> = pose_inputs.iter().map(|(l, p)| (l.as_str(), p.as_path())).collect();
    let what = format!("tubeloc eval --gt {} --out {} --poses {}", gt_path.display(), pose_dir.display(), labels.iter().map(|(l, p)| format!("{l}={}", p.display())).collect::<Vec<_>>().join(" "));
    step("evaluate poses", what, &mut log, &mut || crate::cmd_eval::run(EvalArgs::poses(&gt_path, &labels, &pose_dir)))?;

    // 5. The main job on the first image: a one-camera rig, the known ground plane.
    let rig = serde_json::json!({"cameras": [{"name": "demo", "model": camera, "T_rig_cam": Pose::identity()}], "stereo_pairs": []});
    let rig_path = out.join("rig.json");
    files::write_json(&rig_path, &rig)?;
    let image = dataset.join("images").join(&first.file_name);
    let (detector, model_arg, templates) = match detectors.last() {
        Some(("learned", _)) => (crate::cmd_locate::Detector::Learned, a.model.clone(), None),
        _ => (crate::cmd_locate::Detector::Line2d, None, Some(lib.clone())),
    };
    // The image's nominal ground, as `tubeloc refine --ground auto` takes it (normalized as
    // `--ground nx,ny,nz,d` is).
    let ground = match crate::cmd_refine::ground_of(first).with_context(|| gt_path.display().to_string())? {
        Some(g) => Some(tubeloc_core::GroundPlane::new(g.normal, g.offset).with_context(|| format!("{}: image {}: ground", gt_path.display(), first.id))?),
        None => None,
    };
    let mut locate = crate::cmd_locate::LocateArgs::single(rig_path.clone(), image.clone(), out.join("locate/poses.json"));
    (locate.detector, locate.model, locate.templates, locate.ground) = (detector, model_arg, templates, ground);
    eprintln!("\n== demo: locate on {}", image.display());
    let t = Instant::now();
    crate::cmd_locate::run(locate).context("demo step \"locate\"")?;
    log.push(("locate (first image)".into(), t.elapsed().as_secs_f64()));

    let report = build_report(&a, &log, &detectors.iter().map(|d| d.0).collect::<Vec<_>>(), &tags, out);
    let report_path = out.join("report.md");
    files::write_atomic(&report_path, report.as_bytes())?;
    crate::out::outln!("\ndemo finished in {:.1} s; report: {}", t0.elapsed().as_secs_f64(), report_path.display());
    Ok(())
}

fn build_report(a: &DemoArgs, log: &[(String, f64)], detectors: &[&str], tags: &serde_json::Value, out: &Path) -> String {
    let mut r = String::new();
    let _ = writeln!(r, "# tubeloc demo\n\nScene: tiny preset, with-tags CFA6, seed {}, {} px crops at half resolution (the paper preset's scale). Every number below was measured by this run.\n", a.seed, a.resolution);
    let _ = writeln!(r, "## Detection (COCO, segm; PR curves in each `eval_*/report.md`)\n\n| detector | AP [.5] | AR [.5:.95] | report |\n|---|---|---|---|");
    for det in detectors {
        let m = crate::figures::ap50_ar(&out.join(format!("eval_{det}/metrics.json")));
        let (ap, ar) = m.map(|(x, y)| (format!("{x:.3}"), format!("{y:.3}"))).unwrap_or_default();
        let _ = writeln!(r, "| {det} | {ap} | {ar} | [eval_{det}/report.md](eval_{det}/report.md) |");
    }
    if !detectors.contains(&"learned") {
        let _ = writeln!(r, "\nThe learned detector was skipped: no model file.");
    }
    let _ = writeln!(r, "\n## Tube poses vs the renderer's exact poses (tubes at least half visible)\n");
    match crate::figures::pose_table(&out.join("eval_poses/report.md")) {
        Some(t) => {
            let _ = writeln!(r, "{t}\nHistograms: [eval_poses/report.md](eval_poses/report.md).\n\n![axis angle](eval_poses/pose_axis_angle.png)\n");
        }
        None => {
            let _ = writeln!(r, "(no pose table: see eval_poses/)\n");
        }
    }
    let _ = writeln!(r, "## Tag-pair ground truth vs exact poses\n\nThe paper's ground truth comes from two AprilTags on one tube (`tubeloc calib groundtruth`); here it is checked against the renderer's exact pose.\n");
    match tags {
        serde_json::Value::Object(t) if !t.is_empty() => r += &crate::figures::tag_table(t),
        _ => r += "No tag pair was detected in this scene.\n",
    }
    let _ = writeln!(r, "\n## The main job: `tubeloc locate` on the first image\n\nGrasp poses: [locate/poses.json](locate/poses.json).\n\n![fitted contours (green: located, red: rejected)](locate/poses.overlay.png)\n");
    let _ = writeln!(r, "## Steps\n\n| step | seconds |\n|---|---:|");
    for (name, s) in log {
        let _ = writeln!(r, "| {name} | {s:.2} |");
    }
    r
}
