//! `tubeloc bench`: the paper's experiments on the paper preset, in one resumable command.
//!
//! Stages (each one's outputs are written atomically and recorded in `<out>/bench_state.json`;
//! a rerun skips the stages already done, so an interrupted run resumes where it stopped):
//!
//! 1. `dataset`: the paper preset (`tubeloc synth --preset paper`), unless `--dataset` is given
//!    or every part on it (`line2d`, `learned`, `poses`, `tags`, `fullres`) is skipped.
//! 2. `splits`: one COCO folder per split (`no-tags`, `with-tags`), optionally subsampled.
//! 3. `templates`: the default Line2D library for the benchmark camera.
//! 4. `line2d/<split>`, `learned/<split>`: detection and COCO evaluation (PR curves, breakdowns
//!    by terrain, time, height and occlusion) — the paper's Tables I and II.
//! 5. `poses/<detector>/<split>`: refinement of the detections and pose errors against the
//!    renderer's exact poses (coarse seeds vs mono refinement), with histograms.
//! 6. `stereo`: a small synthetic stereo set, refined with and without the stereo term, evaluated
//!    on all tubes and on the tubes in both views.
//! 7. `fullres`: `tubeloc locate` on one full-resolution 5472x3648 image in a child process,
//!    with its peak memory.
//! 8. `report.md`: everything above with the paper's figures beside ours.

use crate::cmd_calib::{CalibCommand, DetectorArgs, GroundtruthArgs};
use crate::cmd_detect::{DetectArgs, Method};
use crate::cmd_eval::EvalArgs;
use crate::cmd_refine::dataset::{refine_dataset, DatasetJob, DatasetSeeds};
use crate::cmd_refine::GroundArg;
use crate::cmd_synth::DatasetArgs;
use crate::cmd_synth_stereo::SynthStereoArgs;
use anyhow::{bail, Context, Result};
use clap::Args;
use serde_json::{json, Value};

/// Tubes each real composite set of a full run holds at least (issue: at least 100 tubes on the
/// real test frames, grey and colour).
const MIN_REAL_TUBES: usize = 100;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tubeloc_core::{files, CameraModel};
use tubeloc_detect::line2d::ViewParams;

/// The parts of the benchmark, as `--skip` and `--only` name them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
pub enum Part {
    /// Line2D detection and evaluation.
    Line2d,
    /// Learned detection and evaluation.
    Learned,
    /// Refinement and pose errors on the benchmark splits.
    Poses,
    /// Stereo refinement on a synthetic stereo set.
    Stereo,
    /// Full-resolution memory measurement.
    Fullres,
    /// Tag-pair ground truth on the with-tags split against the exact poses.
    Tags,
    /// Real imagery: composites on real test frames and false positives on real negatives.
    Real,
}

/// Arguments of `tubeloc bench`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Output folder: report.md, plots and every intermediate file (resumable).
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// An existing paper-preset dataset (default: render one into <out>/dataset).
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Scenes to render when generating the dataset (default: the paper preset's).
    #[arg(long, value_parser = crate::args::positive_usize)]
    pub scenes: Option<usize>,
    /// Use at most this many images per split (evenly spaced by image id; default: all).
    #[arg(long, value_parser = crate::args::positive_usize)]
    pub images_per_split: Option<usize>,
    /// Line2D library (default: built into <out>/templates.tlt for the benchmark camera).
    #[arg(long)]
    pub templates: Option<PathBuf>,
    /// Learned model used on both splits (default: the shipped model, embedded in the program).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Cross-split protocol: model trained on the with-tags split (tested on no-tags).
    #[arg(long)]
    pub model_trained_with_tags: Option<PathBuf>,
    /// Cross-split protocol: model trained on the no-tags split (tested on with-tags).
    #[arg(long)]
    pub model_trained_no_tags: Option<PathBuf>,
    /// Parts to skip (comma separated).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub skip: Vec<Part>,
    /// Parts to run, the others skipped (comma separated; e.g. `--only real`: the real stage
    /// alone, on no synthetic dataset).
    #[arg(long, value_enum, value_delimiter = ',', conflicts_with = "skip")]
    pub only: Vec<Part>,
    /// Scenes of the synthetic stereo set.
    #[arg(long, default_value_t = 4, value_parser = crate::args::positive_usize)]
    pub stereo_scenes: usize,
    /// The real rover data (`MANIFEST.tsv`, `backgrounds/`, `negatives_val/`, `with_cameras/`)
    /// for the real stage. Grey composites need `with_cameras/`, colour ones Mastcam
    /// backgrounds, the tube-free rows `negatives_val/`: what the folder lacks is left out.
    #[arg(long, default_value = "../shared/data/real_mars")]
    pub real_data: PathBuf,
    /// Real stage: the part of the real data, split by sol: `test` (the figures to report),
    /// `val` (the same measures on the validation part, to choose settings on; the tube-free
    /// `negatives_val` frames are then not run), or `all` (every frame whatever its sol, as
    /// `test` measures them: for a real data folder of new frames in the same layout, none of
    /// which trained the model).
    #[arg(long, default_value = "test")]
    pub real_split: tubeloc_synth::real_frames::RealSplit,
    /// Real stage: use at most this many frames per set (default: all).
    #[arg(long)]
    pub real_frames: Option<usize>,
    /// Real stage: tubes each composite set (grey, colour) holds at least; a set made with fewer
    /// is made again with more composites per frame (up to 32). Default: 100, or none with
    /// --real-frames.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub real_min_tubes: Option<u64>,
    /// Real stage: score calibration JSON (default: the one beside the model).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Line2D stages: far-search factors, as `tubeloc detect --far-scale` ("K" or COLOUR:GREY)
    #[arg(long, default_value = crate::cmd_detect_line2d::DEFAULT_FAR_SCALE, value_parser = crate::args::far_scale)]
    pub line2d_far_scale: (f64, f64),
    /// Line2D stages: largest enlargement to the library's scale, as `tubeloc detect
    /// --max-upsample`
    #[arg(long, default_value_t = tubeloc_detect::line2d::params::MAX_UPSAMPLE, value_parser = crate::args::upsample_limit)]
    pub line2d_max_upsample: f64,
    /// Redo every stage even if recorded as done.
    #[arg(long)]
    pub fresh: bool,
}

/// The benchmark's splits, with the paper's Line2D (AP50, AR) and Mask R-CNN (AP50, AR) figures
/// (Tables I and II; Mask R-CNN tested on this split after training on the other).
type SplitFigures = (&'static str, (f64, f64), (f64, f64));

/// The splits with the paper's figures (see above).
const SPLITS: [SplitFigures; 2] = [("no-tags", (0.345, 0.184), (0.911, 0.555)), ("with-tags", (0.255, 0.153), (0.918, 0.575))];

/// Stage bookkeeping: wall time per finished stage, persisted after each one.
struct Stages {
    path: PathBuf,
    done: BTreeMap<String, Value>,
}

impl Stages {
    fn load(out: &Path, fresh: bool) -> Result<Stages> {
        let path = out.join("bench_state.json");
        let done = if path.exists() && !fresh { files::read_json(&path).with_context(|| format!("{}: delete it or pass --fresh", path.display()))? } else { BTreeMap::new() };
        Ok(Stages { path, done })
    }

    /// Runs `f` unless stage `name` is recorded as done and all `outputs` exist; records its
    /// wall time (and what `f` returns) and the process peak memory so far.
    fn run(&mut self, name: &str, outputs: &[PathBuf], f: impl FnOnce() -> Result<Value>) -> Result<()> {
        if self.done.contains_key(name) && outputs.iter().all(|p| p.exists()) {
            eprintln!("== bench: {name}: done in an earlier run, skipped");
            return Ok(());
        }
        eprintln!("\n== bench: {name}");
        let t = Instant::now();
        let extra = f().with_context(|| format!("bench stage {name:?}"))?;
        let rec = json!({"seconds": t.elapsed().as_secs_f64(), "peak_rss_mb": crate::memory::peak_rss_mb(), "result": extra});
        self.done.insert(name.to_string(), rec);
        files::write_json(&self.path, &self.done)?;
        Ok(())
    }

    fn seconds(&self, name: &str) -> Option<f64> {
        self.done.get(name)?.get("seconds")?.as_f64()
    }

    fn result(&self, name: &str) -> Option<&Value> {
        self.done.get(name)?.get("result")
    }
}

/// The attributes the detection evaluations are broken down by.
const BREAKDOWN: [&str; 4] = ["terrain", "time", "height_m", "occlusion"];

/// Writes `<dir>/annotations.json` with the images of one split (evenly subsampled to at most
/// `limit`), their annotations, and an `images` link to the dataset's images.
fn write_split(dataset: &Path, split: &str, limit: Option<usize>, dir: &Path) -> Result<usize> {
    let src = dataset.join("annotations.json");
    let mut v: Value = files::read_json(&src)?;
    let images = v.get("images").and_then(Value::as_array).with_context(|| format!("{}: no images array", src.display()))?;
    let mut keep: Vec<Value> = images.iter().filter(|im| im.get("split").and_then(Value::as_str) == Some(split)).cloned().collect();
    if keep.is_empty() {
        bail!("{}: no images with split {split:?} (is it a paper-preset dataset?)", src.display());
    }
    keep.sort_by_key(|im| im.get("id").and_then(Value::as_u64).unwrap_or(0));
    if let Some(n) = limit.filter(|&n| n > 0 && n < keep.len()) {
        let step = keep.len() as f64 / n as f64;
        keep = (0..n).map(|i| keep[(i as f64 * step) as usize].clone()).collect();
    }
    let ids: std::collections::HashSet<u64> = keep.iter().filter_map(|im| im.get("id").and_then(Value::as_u64)).collect();
    let anns: Vec<Value> = v.get("annotations").and_then(Value::as_array).map(|a| a.iter().filter(|x| x.get("image_id").and_then(Value::as_u64).is_some_and(|id| ids.contains(&id))).cloned().collect()).unwrap_or_default();
    let n = keep.len();
    v["images"] = Value::Array(keep);
    v["annotations"] = Value::Array(anns);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let link = dir.join("images");
    if !link.exists() {
        let target = std::fs::canonicalize(dataset.join("images")).with_context(|| format!("{}/images", dataset.display()))?;
        std::os::unix::fs::symlink(&target, &link).with_context(|| format!("linking {} -> {}", link.display(), target.display()))?;
    }
    files::write_json(&dir.join("annotations.json"), &v)?;
    Ok(n)
}

/// Detection + evaluation of one detector on one split (`detect` holds the detector's
/// options; its dataset and output are set here); returns ms per image.
fn detect_and_eval(mut detect: DetectArgs, split_dir: &Path, out: &Path, n_images: usize) -> Result<Value> {
    std::fs::create_dir_all(out)?;
    let dets = out.join("detections.json");
    (detect.dataset, detect.out) = (Some(split_dir.to_path_buf()), dets.clone());
    let t = Instant::now();
    crate::cmd_detect::run(detect)?;
    let ms = t.elapsed().as_secs_f64() * 1e3 / n_images.max(1) as f64;
    crate::cmd_eval::run(EvalArgs::detections(&split_dir.join("annotations.json"), &dets, &out.join("eval"), &BREAKDOWN))?;
    Ok(json!({"ms_per_image": ms}))
}

/// Runs `tubeloc bench`.
pub fn run(mut a: BenchArgs) -> Result<()> {
    if !a.only.is_empty() {
        use clap::ValueEnum;
        a.skip = Part::value_variants().iter().filter(|p| !a.only.contains(p)).copied().collect();
    }
    if a.real_split == tubeloc_synth::real_frames::RealSplit::Train {
        bail!("--real-split train: the real stage measures on the val, test or all part (the training part's frames are the model's backgrounds)");
    }
    let out = a.out.clone();
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let mut st = Stages::load(&out, a.fresh)?;
    let t0 = Instant::now();

    // 1. Dataset: only for the parts on the synthetic paper preset (with those skipped, e.g.
    // the real stage alone, none is rendered or read).
    let synthetic = [Part::Line2d, Part::Learned, Part::Poses, Part::Tags, Part::Fullres].iter().any(|p| !a.skip.contains(p));
    let dataset = match &a.dataset {
        _ if !synthetic => PathBuf::new(),
        Some(d) => d.clone(),
        None => {
            let d = out.join("dataset");
            st.run("dataset", &[d.join("annotations.json")], || {
                crate::cmd_synth::run_dataset(DatasetArgs { preset: "paper".into(), out: Some(d.clone()), scenes: a.scenes, resolution: None, scale: None, seed: 0, tube_mesh: None, shard: (0, 1), force: true })?;
                Ok(Value::Null)
            })?;
            d
        }
    };
    if synthetic && !dataset.join("annotations.json").exists() {
        bail!("{}: no annotations.json (render one with `tubeloc synth --preset paper --out DIR`)", dataset.display());
    }

    // 2. Splits.
    let split_dir = |split: &str| out.join("splits").join(split);
    let outputs: Vec<PathBuf> = SPLITS.iter().map(|(sp, ..)| split_dir(sp).join("annotations.json")).collect();
    let camera = out.join("camera.json");
    if synthetic {
        st.run("splits", &outputs, || {
            let mut r = serde_json::Map::new();
            for (sp, ..) in SPLITS {
                r.insert(sp.into(), json!(write_split(&dataset, sp, a.images_per_split, &split_dir(sp))?));
            }
            Ok(Value::Object(r))
        })?;
        // The benchmark camera: the first image's (crops share the focal length).
        let gt0: Value = files::read_json(&split_dir(SPLITS[0].0).join("annotations.json"))?;
        files::write_json(&camera, &gt0["images"][0]["camera"])?;
    }
    let n_images = |sp: &str| st.result("splits").and_then(|r| r[sp].as_u64()).unwrap_or(0) as usize;
    let n_img: BTreeMap<&str, usize> = if synthetic { SPLITS.iter().map(|(sp, ..)| (*sp, n_images(sp))).collect() } else { BTreeMap::new() };

    // 3 + 4. Line2D.
    if !a.skip.contains(&Part::Line2d) {
        let lib = match &a.templates {
            Some(l) => l.clone(),
            None => {
                let l = out.join("templates.tlt");
                st.run("templates", std::slice::from_ref(&l), || {
                    crate::cmd_templates::build_for_camera(&CameraModel::load_json(&camera)?, ViewParams::default(), &l)?;
                    Ok(Value::Null)
                })?;
                l
            }
        };
        for (sp, ..) in SPLITS {
            let dir = out.join("line2d").join(sp);
            st.run(&format!("line2d/{sp}"), &[dir.join("eval/metrics.json")], || {
                let mut detect = DetectArgs::dataset(Method::Line2d, &split_dir(sp), &dir);
                (detect.line2d.templates, detect.line2d.camera) = (Some(lib.clone()), Some(camera.clone()));
                (detect.line2d.far_scale, detect.line2d.max_upsample) = (a.line2d_far_scale, a.line2d_max_upsample);
                detect_and_eval(detect, &split_dir(sp), &dir, n_img[sp])
            })?;
        }
    }

    // 4. Learned.
    if !a.skip.contains(&Part::Learned) {
        for (sp, ..) in SPLITS {
            let cross = if sp == "no-tags" { &a.model_trained_with_tags } else { &a.model_trained_no_tags };
            let model = crate::cmd_detect_learned::ModelChoice::of(cross.as_deref().or(a.model.as_deref()));
            if let crate::cmd_detect_learned::ModelChoice::File(p) = &model {
                if !p.exists() {
                    bail!("learned model {} not found (pass --model, or --skip learned)", p.display());
                }
            }
            let dir = out.join("learned").join(sp);
            st.run(&format!("learned/{sp}"), &[dir.join("eval/metrics.json")], || {
                let mut detect = DetectArgs::dataset(Method::Learned, &split_dir(sp), &dir);
                detect.model = model.path().map(Path::to_path_buf);
                let mut r = detect_and_eval(detect, &split_dir(sp), &dir, n_img[sp])?;
                r["model"] = json!(model.name());
                r["protocol"] = json!(if cross.is_some() { "cross-split" } else { "trained on generated scenes" });
                Ok(r)
            })?;
        }
    }

    // 5. Poses from each detector's detections.
    if !a.skip.contains(&Part::Poses) {
        for det in ["line2d", "learned"] {
            for (sp, ..) in SPLITS {
                let dets = out.join(det).join(sp).join("detections.json");
                if !dets.exists() {
                    continue;
                }
                let dir = out.join("poses").join(det).join(sp);
                // Learned masks are also snapped to the refined poses' silhouettes and scored.
                let snap = det == "learned";
                let mut outputs = vec![dir.join("eval/pose_metrics.json")];
                if snap {
                    outputs.push(dir.join("snapped_eval/metrics.json"));
                }
                st.run(&format!("poses/{det}/{sp}"), &outputs, || {
                    std::fs::create_dir_all(&dir)?;
                    let (poses, seeds, snapped) = (dir.join("poses.json"), dir.join("seeds.json"), dir.join("snapped.json"));
                    let t = Instant::now();
                    let mut job = DatasetJob::new(split_dir(sp), DatasetSeeds::Detections(dets.clone()), poses.clone());
                    job.ground = Some(GroundArg::Auto);
                    job.seeds_out = Some(seeds.clone());
                    job.snapped_out = snap.then(|| snapped.clone());
                    refine_dataset(&job)?;
                    let secs = t.elapsed().as_secs_f64();
                    let gt = split_dir(sp).join("annotations.json");
                    crate::cmd_eval::run(EvalArgs::poses(&gt, &[("coarse", &seeds), ("mono", &poses)], &dir.join("eval")))?;
                    if snap {
                        crate::cmd_eval::run(EvalArgs::detections(&gt, &snapped, &dir.join("snapped_eval"), &BREAKDOWN))?;
                    }
                    let n: Vec<Value> = files::read_json(&poses)?;
                    Ok(json!({"refine_seconds": secs, "poses": n.len(), "ms_per_image": secs * 1e3 / n_img[sp].max(1) as f64}))
                })?;
            }
        }
    }

    // 6. Stereo on a synthetic stereo set: seeds alone, mono and stereo refinement, from (a)
    //    ground-truth seeds perturbed by 10 mm / 5 deg (the refiner alone) and (b) the learned
    //    detector's detections (the whole chain).
    if !a.skip.contains(&Part::Stereo) {
        let sdir = out.join("stereo");
        let set = sdir.join("set");
        let model = crate::cmd_detect_learned::ModelChoice::of(a.model.as_deref());
        st.run("stereo", &[sdir.join("gt_seeds/eval/pose_metrics.json"), sdir.join("learned/eval/pose_metrics.json"), sdir.join("learned/eval_both_views/pose_metrics.json")], || {
            crate::cmd_synth_stereo::run(SynthStereoArgs { out: set.clone(), preset: "paper".into(), scenes: Some(a.stereo_scenes), pairs_per_scene: 4, resolution: None, scale: None, seed: 3, pair: "L20,R20".into(), force: true })?;
            let gt = set.join("annotations.json");
            let dets = sdir.join("learned_detections.json");
            let mut detect = DetectArgs::dataset(Method::Learned, &set, &dets);
            detect.model = model.path().map(Path::to_path_buf);
            crate::cmd_detect::run(detect)?;
            let mut r = serde_json::Map::new();
            let gt_seeds = DatasetSeeds::Gt { pos_mm: 10.0, deg: 5.0, seed: 0, min_visible: 0.5 };
            for (name, seeds) in [("gt_seeds", gt_seeds), ("learned", DatasetSeeds::Detections(dets.clone()))] {
                let dir = sdir.join(name);
                std::fs::create_dir_all(&dir)?;
                let seeds_of = |ground: bool| dir.join(if ground { "seeds_ground.json" } else { "seeds.json" });
                let mut labels: Vec<(String, PathBuf)> = vec![("coarse".into(), seeds_of(false)), ("coarse_ground".into(), seeds_of(true))];
                // With and without the ground plane of the rig's pose (`--ground auto`): a rover
                // knows its cameras' height and tilt, and mono seeds need it for their tilt.
                for (mode, stereo, ground) in [("mono", false, false), ("stereo", true, false), ("mono_ground", false, true), ("stereo_ground", true, true)] {
                    let poses = dir.join(format!("poses_{mode}.json"));
                    let mut job = DatasetJob::new(set.clone(), seeds.clone(), poses.clone());
                    if stereo {
                        // The stereo runs' seeds (depth from the stereo points) are the coarse rows.
                        job.stereo = true;
                        job.seeds_out = Some(seeds_of(ground));
                    }
                    if ground {
                        job.ground = Some(GroundArg::Auto);
                    }
                    let t = Instant::now();
                    refine_dataset(&job)?;
                    r.insert(format!("{name}/{mode}_seconds"), json!(t.elapsed().as_secs_f64()));
                    labels.push((mode.into(), poses));
                }
                let labels: Vec<(&str, &Path)> = labels.iter().map(|(l, p)| (l.as_str(), p.as_path())).collect();
                crate::cmd_eval::run(EvalArgs::poses(&gt, &labels, &dir.join("eval")))?;
                // Only the tubes both cameras see: the others get mono poses from a stereo run.
                crate::cmd_eval::run(EvalArgs { in_both_views: true, ..EvalArgs::poses(&gt, &labels, &dir.join("eval_both_views")) })?;
            }
            Ok(Value::Object(r))
        })?;
    }

    // 6a. Grasp collision checks on the synthetic stereo set (learned detections, the images'
    //     own ground), stereo (terrain checked) and mono.
    if !a.skip.contains(&Part::Stereo) {
        let sdir = out.join("stereo");
        st.run("stereo/grasp", &[sdir.join("grasp.json")], || {
            let (set, dets) = (sdir.join("set"), sdir.join("learned_detections.json"));
            let r = json!({"stereo": crate::bench_grasp::run(&set, &dets, true, None, None)?, "mono": crate::bench_grasp::run(&set, &dets, false, None, None)?});
            files::write_json(&sdir.join("grasp.json"), &r)?;
            Ok(r)
        })?;
    }

    // 6b. Tag-pair ground truth on the with-tags split (a copy, so the dataset is not modified).
    if !a.skip.contains(&Part::Tags) {
        let tdir = out.join("tags");
        st.run("tags", &[tdir.join("annotations.json")], || {
            write_split(&dataset, "with-tags", a.images_per_split, &tdir)?;
            crate::cmd_calib::run(CalibCommand::Groundtruth(GroundtruthArgs { dataset: tdir.clone(), mount: None, camera: None, detector: DetectorArgs::rendered() }))?;
            crate::figures::tag_pose_errors(&tdir.join("annotations.json"))
        })?;
    }

    // 6c. The with-tags split's refined poses against the tag-pair ground truth (the paper's
    // pose protocol), beside the same poses against the exact ones in step 5.
    if !a.skip.contains(&Part::Tags) && !a.skip.contains(&Part::Poses) {
        let tag_gt = out.join("tags").join("annotations.json");
        for det in ["line2d", "learned"] {
            let dir = out.join("poses").join(det).join("with-tags");
            let (poses, seeds) = (dir.join("poses.json"), dir.join("seeds.json"));
            if !(tag_gt.exists() && poses.exists() && seeds.exists()) {
                continue;
            }
            st.run(&format!("poses/{det}/with-tags/tag-truth"), &[dir.join("eval_tag_truth/pose_metrics.json")], || {
                let eval = EvalArgs::poses(&tag_gt, &[("coarse", &seeds), ("mono", &poses)], &dir.join("eval_tag_truth"));
                crate::cmd_eval::run(EvalArgs { truth_field: "T_cam_tube_tags".into(), ..eval })?;
                Ok(json!({}))
            })?;
        }
    }

    // 7. Full resolution, in a child process so that its peak memory is its own.
    if !a.skip.contains(&Part::Fullres) {
        let fdir = out.join("fullres");
        st.run("fullres", &[fdir.join("poses.json")], || fullres(&dataset, &fdir))?;
    }

    // 8. Real imagery.
    if !a.skip.contains(&Part::Real) {
        let model = crate::cmd_detect_learned::ModelChoice::of(a.model.as_deref());
        let calibration = model.calibration(a.calibration.as_deref())?;
        let stage = crate::cmd_bench_real::RealStage {
            data: a.real_data.clone(),
            split: a.real_split,
            model,
            calibration,
            frames: a.real_frames,
            per_grey_frame: 4,
            // A full run's sets hold at least 100 tubes each (grey and colour); a run cut to a
            // few frames (CI) keeps its sets as made.
            min_tubes: a.real_min_tubes.map(|n| n as usize).or(a.real_frames.is_none().then_some(MIN_REAL_TUBES)),
            grasp_images: None,
            line2d_far_scale: a.line2d_far_scale,
            line2d_max_upsample: a.line2d_max_upsample,
        };
        let real_dir = crate::cmd_bench_real::stage_dir(&out, a.real_split);
        let name = real_dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        st.run(&name, &[real_dir.join("report.md")], || {
            crate::cmd_bench_real::run(&stage, &out)?;
            Ok(json!({}))
        })?;
    }

    // 9. Report.
    let report = write_report(&out, &st, &n_img, a.real_split)?;
    eprintln!("\nbench finished in {:.0} s (this run); report: {}", t0.elapsed().as_secs_f64(), report.display());
    Ok(())
}

/// Upscales one benchmark image to the rig camera's full 5472x3648 frame and runs `tubeloc
/// locate` on it in a child process; returns its wall time and peak memory.
fn fullres(dataset: &Path, dir: &Path) -> Result<Value> {
    std::fs::create_dir_all(dir)?;
    let rig_path = dataset.join("rig.json");
    let rig = tubeloc_calib::read_rig(&rig_path)?;
    let (l, _) = rig.stereo_pairs.first().cloned().with_context(|| format!("{}: no stereo pair", rig_path.display()))?;
    let cam = rig.camera(&l).with_context(|| format!("{}: no camera {l}", rig_path.display()))?;
    let gt: Value = files::read_json(&dataset.join("annotations.json"))?;
    let first = gt["images"][0]["file_name"].as_str().context("dataset has no images")?;
    let src = image::open(dataset.join("images").join(first)).with_context(|| format!("reading {first}"))?;
    let big = src.resize_exact(cam.model.width, cam.model.height, image::imageops::FilterType::Triangle).to_rgb8();
    let img_path = dir.join("fullres.png");
    let mut buf = std::io::Cursor::new(Vec::new());
    big.write_to(&mut buf, image::ImageFormat::Png)?;
    files::write_atomic(&img_path, &buf.into_inner())?;
    let exe = std::env::current_exe().context("locating the tubeloc executable")?;
    let t = Instant::now();
    let status = std::process::Command::new(&exe).arg("locate").arg("--rig").arg(&rig_path).arg("--image").arg(&img_path).arg("--out").arg(dir.join("poses.json")).status().with_context(|| format!("running {}", exe.display()))?;
    if !matches!(status.code(), Some(0) | Some(3)) {
        bail!("locate on the full-resolution image failed ({status})");
    }
    let doc: Value = files::read_json(&dir.join("poses.json"))?;
    Ok(json!({"seconds": t.elapsed().as_secs_f64(), "peak_rss_mb": doc["run"]["peak_rss_mb"], "width": cam.model.width, "height": cam.model.height}))
}

fn f3(x: f64) -> String {
    format!("{x:.3}")
}

/// Writes `<out>/report.md` from the stage results; returns its path.
fn write_report(out: &Path, st: &Stages, n_img: &BTreeMap<&str, usize>, real_split: tubeloc_synth::real_frames::RealSplit) -> Result<PathBuf> {
    let mut r = String::new();
    let _ = writeln!(r, "# tubeloc bench: the paper's experiments on the synthetic paper preset\n");
    let _ = writeln!(
        r,
        "Written by `tubeloc bench` (tubeloc {}). Images per split: {}. Every number below was measured by this run; the paper's figures are its Tables I and II (real Mars-yard images, so they compare the method, not the data).\n",
        env!("CARGO_PKG_VERSION"),
        if n_img.is_empty() { "none (the parts on the synthetic preset skipped)".to_string() } else { n_img.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ") }
    );
    // One table row per split: `stages(sp)` names the stages whose `ms_per_image` add up to
    // the row's time, `eval_dir(sp)` the evaluation folder (relative to `out`).
    let table = |r: &mut String, stages: &dyn Fn(&str) -> Vec<String>, eval_dir: &dyn Fn(&str) -> String, paper_of: &dyn Fn(usize) -> (f64, f64), title: &str| {
        let _ = writeln!(r, "## {title}\n\n| test split | AP [.5] ours | AR [.5:.95] ours | AP [.5] paper | AR paper | ms / image | details |\n|---|---|---|---|---|---|---|");
        for (i, (sp, ..)) in SPLITS.iter().enumerate() {
            let rel = eval_dir(sp);
            let m = out.join(&rel).join("metrics.json");
            let (p_ap, p_ar) = paper_of(i);
            match crate::figures::ap50_ar(&m) {
                Some((ap, ar)) => {
                    let ms: Option<f64> = stages(sp).iter().map(|k| st.result(k).and_then(|v| v["ms_per_image"].as_f64())).sum();
                    let ms = ms.map(|x| format!("{x:.0}")).unwrap_or_default();
                    let _ = writeln!(r, "| {sp} | {} | {} | {} | {} | {ms} | [report]({rel}/report.md) |", f3(ap), f3(ar), f3(p_ap), f3(p_ar));
                }
                None => {
                    let _ = writeln!(r, "| {sp} | not run | | {} | {} | | |", f3(p_ap), f3(p_ar));
                }
            }
        }
        r.push('\n');
    };
    table(&mut r, &|sp| vec![format!("line2d/{sp}")], &|sp| format!("line2d/{sp}/eval"), &|i| SPLITS[i].1, "Table I: Line2D");
    let protocol = st.result("learned/no-tags").and_then(|v| v["protocol"].as_str().map(String::from)).unwrap_or_else(|| "not run".into());
    table(&mut r, &|sp| vec![format!("learned/{sp}")], &|sp| format!("learned/{sp}/eval"), &|i| SPLITS[i].2, &format!("Table II: learned segmenter ({protocol}; the paper's Mask R-CNN was trained on the other split)"));
    table(
        &mut r,
        &|sp| vec![format!("learned/{sp}"), format!("poses/learned/{sp}")],
        &|sp| format!("poses/learned/{sp}/snapped_eval"),
        &|i| SPLITS[i].2,
        "Table II (b): the learned masks snapped to their mono-refined poses' silhouettes (`tubeloc refine --snapped-out`; time: detection + refinement)",
    );
    for (det, rel) in [("line2d", "line2d/{sp}/eval"), ("learned", "learned/{sp}/eval"), ("learned, snapped", "poses/learned/{sp}/snapped_eval")] {
        for (sp, ..) in SPLITS {
            let dir = out.join(rel.replace("{sp}", sp));
            if let Ok(md) = std::fs::read_to_string(dir.join("breakdown.md")) {
                let _ = writeln!(r, "### {det} on {sp}: breakdown (AP50 / AP / AR100 per value)\n\n{md}\n");
            }
        }
    }
    let _ = writeln!(r, "PR curves: each detector's `eval/report.md` above holds the ten PR curves (IoU 0.50 to 0.95) as PNG.\n");
    let _ = writeln!(r, "## Pose errors (tubes at least half visible, against the renderer's exact poses)\n");
    for det in ["line2d", "learned"] {
        for (sp, ..) in SPLITS {
            let p = out.join("poses").join(det).join(sp).join("eval/report.md");
            if let Some(t) = crate::figures::pose_table(&p) {
                let _ = writeln!(r, "### {det} detections on {sp}: coarse seeds and mono refinement ([report with histograms](poses/{det}/{sp}/eval/report.md))\n\n{t}");
            }
        }
    }
    for det in ["line2d", "learned"] {
        let p = out.join("poses").join(det).join("with-tags/eval_tag_truth/report.md");
        if let Some(t) = crate::figures::pose_table(&p) {
            let _ = writeln!(r, "### {det} detections on with-tags, against the tag-pair ground truth (`T_cam_tube_tags`, the paper's protocol) ([report with histograms](poses/{det}/with-tags/eval_tag_truth/report.md))\n\n{t}");
        }
    }
    for (name, what) in [("gt_seeds", "exact poses perturbed by 10 mm / 5 deg as seeds"), ("learned", "learned detections as seeds")] {
        let p = out.join("stereo").join(name).join("eval/report.md");
        if let Some(t) = crate::figures::pose_table(&p) {
            let _ = writeln!(r, "### Synthetic stereo set (L20/R20, 1024 crops at half resolution), {what} ([report with histograms](stereo/{name}/eval/report.md))\n\n{t}");
        }
        let p = out.join("stereo").join(name).join("eval_both_views/report.md");
        if let Some(t) = crate::figures::pose_table(&p) {
            let _ = writeln!(r, "### The same, tubes in both views only (axis at least half inside the right image, `tubeloc eval --in-both-views`) ([report with histograms](stereo/{name}/eval_both_views/report.md))\n\n{t}");
        }
    }
    if st.result("stereo").is_some() {
        let _ = writeln!(r, "Rows: `coarse` / `coarse_ground` are the seeds of the stereo runs without / with the ground plane of the rig's pose (`--ground auto`; detections' seeds take their depth from the stereo points, their tilt from the ground); `mono` / `stereo` refine without it, `mono_ground` / `stereo_ground` with it. A pose counts where its centre lies within 50 mm of a truth (matched counts in the linked reports).\n");
    }
    if let Some(g) = st.result("stereo/grasp") {
        let _ = writeln!(r, "### Grasp collision checks on the synthetic stereo set (`locate` on the learned detections, each image's own ground; [0031](../docs/design/0031-grasp-collision-check.md))\n\n{}\nChanged: the chosen grasp is tilted or shifted from the plain grasp from above, or none is feasible. Mono checks the ground plane and the other tubes only.\n", crate::bench_grasp::table(&[("stereo", &g["stereo"]), ("mono", &g["mono"])]));
    }
    if let Some(Value::Object(t)) = st.result("tags") {
        let _ = writeln!(r, "\n## Tag-pair ground truth vs the renderer's exact poses (with-tags split)\n\n`tubeloc calib groundtruth` (PnP on all eight corners + LM) on the rendered images; sRGB images are linearized before tag detection.\n");
        r += &crate::figures::tag_table(t);
    }
    if let Ok(real) = std::fs::read_to_string(crate::cmd_bench_real::stage_dir(out, real_split).join("report.md")) {
        let _ = writeln!(r, "\n{real}");
    }
    let _ = writeln!(r, "\n## Timings and memory\n\n| stage | wall s | peak RSS of the bench process so far, MiB |\n|---|---|---|");
    for (name, v) in &st.done {
        let _ = writeln!(r, "| {name} | {:.1} | {} |", st.seconds(name).unwrap_or(0.0), v["peak_rss_mb"].as_f64().map(|m| format!("{m:.0}")).unwrap_or_default());
    }
    if let Some(f) = st.result("fullres") {
        let _ = writeln!(
            r,
            "\nFull resolution ({}x{}): `tubeloc locate` in a child process took {:.1} s with a peak RSS of {} MiB.",
            f["width"],
            f["height"],
            f["seconds"].as_f64().unwrap_or(0.0),
            f["peak_rss_mb"].as_f64().map(|m| format!("{m:.0}")).unwrap_or("?".into())
        );
    }
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let _ = writeln!(r, "\nMachine: {} logical CPUs. Command: `tubeloc {}`.", std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1), argv.join(" "));
    let p = out.join("report.md");
    files::write_atomic(&p, r.as_bytes())?;
    Ok(p)
}
