//! `tubeloc locate`: the main job. One image (or a stereo pair) and a rig file in, grasp-ready
//! tube poses out.
//!
//! Reading files, building the detector and writing the outputs happen here; the pipeline itself
//! (detect -> (stereo) -> refine -> stages after the fit -> duplicate merging -> grasp frames)
//! is [`tubeloc_pipeline::Locator`]. The run writes one JSON document (schema
//! `tubeloc.locate.v1`, documented in the README; it also holds the camera model and the
//! detections that seeded the refinement) and the overlay PNG, each atomically, both before
//! anything is printed; a failing run writes neither.

use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::Vector3;
use serde::Serialize;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use tubeloc_core::{files, CameraModel, CocoResult, Pose, Rig, TubeDetection};
use tubeloc_pipeline::{detector, CameraSelection, ExternalDetections, GroundPlane, LearnedDetector, Line2dTubeDetector, LocateInput, LocatedTube, Locator, LocatorSettings, TubeDetector};

/// Detector that seeds the refinement.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Detector {
    /// The learned segmenter (`--model`, default: the shipped model in data/models/).
    Learned,
    /// Line2D template matching (`--templates LIB.tlt`, built for the rig camera).
    Line2d,
    /// Detections made elsewhere (`--results coco_results.json`, e.g. Detectron2).
    External,
}

/// Arguments of `tubeloc locate`.
#[derive(Args, Debug)]
pub struct LocateArgs {
    /// Rig file (tubeloc JSON from `tubeloc calib rig`, or the `rig.json` of a synthetic dataset).
    #[arg(long)]
    pub rig: PathBuf,
    /// The (left) image.
    #[arg(long)]
    pub image: PathBuf,
    /// Right image of a stereo pair: adds the stereo term to the refinement.
    #[arg(long)]
    pub right: Option<PathBuf>,
    /// Rig camera that took `--image` (default: the left camera of `--pair`, or of the rig's first
    /// stereo pair).
    #[arg(long)]
    pub camera_name: Option<String>,
    /// Stereo pair "LEFT,RIGHT" of the rig (default: the rig's first stereo pair).
    #[arg(long)]
    pub pair: Option<String>,
    /// Detector that seeds the refinement.
    #[arg(long, value_enum, default_value = "learned")]
    pub detector: Detector,
    /// Learned model weights (default: data/models/tubenet.safetensors).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Line2D template library (`--detector line2d`).
    #[arg(long)]
    pub templates: Option<PathBuf>,
    /// External COCO results (`--detector external`). Entries are selected by the image's file
    /// name: by an entry's own "file_name" field, or through --results-images; results for a
    /// single image id are taken whole.
    #[arg(long)]
    pub results: Option<PathBuf>,
    /// With --results: a COCO file whose images[] (id, file_name) tell which results belong to
    /// --image (e.g. the dataset's annotations.json).
    #[arg(long, requires = "results")]
    pub results_images: Option<PathBuf>,
    /// Ground plane "nx,ny,nz,d" in the camera frame (`n·X = d`, n up), metres: places seeds on
    /// the ground and gives the grasp approach direction.
    #[arg(long, allow_hyphen_values = true)]
    pub ground: Option<GroundPlane>,
    /// Up direction "ux,uy,uz" in the camera frame for the grasp approach when no --ground is
    /// given (default: -y, i.e. the camera is roughly level).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_up)]
    pub up: Option<Vector3<f64>>,
    /// Score calibration JSON (probability of a tube and acceptance threshold; `tubeloc eval
    /// --calibrate` writes one). Default for the learned detector: the one beside the model
    /// (`data/models/tubenet.calibration.json`); other detectors: none (probability = score).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Accept tubes whose probability is at least this (default: the calibration's threshold,
    /// chosen for precision >= 0.95 on real validation composites).
    #[arg(long, value_parser = probability)]
    pub min_probability: Option<f64>,
    /// Distances of the tubes from the camera, "NEAR:FAR" metres: the learned detector runs at
    /// the working scale of this band (or of --ground), or "off" (the image as it is).
    #[arg(long, default_value = "1:4")]
    pub range_m: String,
    /// Output poses (JSON, schema tubeloc.locate.v1).
    #[arg(long)]
    pub out: PathBuf,
    /// Overlay PNG with the fitted contours (default: `<out stem>.overlay.png` next to --out).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
}

/// A probability in [0, 1].
fn probability(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("{s:?}: expected a probability in [0, 1]")),
    }
}

/// `--up ux,uy,uz`: three finite numbers, not all zero (normalized).
fn parse_up(s: &str) -> std::result::Result<Vector3<f64>, String> {
    let v: Vec<f64> = s.split(',').map(|t| t.trim().parse::<f64>()).collect::<std::result::Result<_, _>>().map_err(|_| format!("{s:?}: expected three numbers ux,uy,uz"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("{s:?}: expected three finite numbers ux,uy,uz"));
    }
    let n = Vector3::new(v[0], v[1], v[2]);
    if n.norm() < 1e-9 {
        return Err(format!("{s:?}: the vector is zero"));
    }
    Ok(n.normalize())
}

/// The document `tubeloc locate` writes.
#[derive(Serialize, Debug)]
pub struct LocateDoc<'a> {
    /// Schema name and version: `tubeloc.locate.v1`.
    pub schema: &'static str,
    /// The input image.
    pub image: &'a Path,
    /// The right image, when stereo was used.
    pub right_image: Option<&'a Path>,
    /// Rig camera of `image`.
    pub camera: &'a str,
    /// Detector that seeded the refinement.
    pub detector: &'a str,
    /// Up direction used for the grasp frames, unit vector in the camera frame.
    pub up_cam: Vector3<f64>,
    /// Pose of the camera in the rig frame.
    #[serde(rename = "T_rig_cam")]
    pub t_rig_cam: Pose,
    /// Located tubes, best score first, then the rejected detections (`status` says why).
    pub tubes: Vec<TubeOut<'a>>,
    /// The probability threshold tubes were accepted at.
    pub min_probability: f64,
    /// Run statistics: wall time (s) and peak resident memory (MiB) of the whole run.
    pub run: serde_json::Value,
    /// The model of the camera that took `image`.
    pub camera_model: &'a CameraModel,
    /// The detections that seeded the refinement (COCO results with tubeloc's seed fields).
    pub detections: &'a [TubeDetection],
}

/// One tube of the document: the pose, grasp frames and probability, and what became of it.
#[derive(Serialize, Debug)]
pub struct TubeOut<'a> {
    /// The tube.
    #[serde(flatten)]
    pub tube: &'a LocatedTube,
    /// `located` (handed to the planner), `fit_failed`, `low_probability` or `intersects_tube`.
    pub status: &'static str,
}

fn sidecar(out: &Path, suffix: &str) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "poses".into());
    out.with_file_name(format!("{stem}.{suffix}"))
}

/// External results for `--image`: read, selected by the image's file name, converted.
fn external_detections(a: &LocateArgs, size: (u32, u32)) -> Result<ExternalDetections> {
    let path = a.results.as_ref().context("--detector external needs --results coco_results.json")?;
    let text = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let list: Vec<CocoResult> = serde_json::from_slice(&text).with_context(|| format!("{}: not a COCO results list", path.display()))?;
    let names = match &a.results_images {
        Some(p) => {
            let ds = tubeloc_core::CocoDataset::load(p).with_context(|| format!("reading {}", p.display()))?;
            Some(ds.images.iter().map(|im| (im.id, im.file_name.clone())).collect())
        }
        None => None,
    };
    let image_name = a.image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let origin = path.display().to_string();
    let list = detector::select_results_for_image(list, &image_name, names.as_ref(), &origin)?;
    let dets = list.iter().enumerate().map(|(k, r)| detector::detection_from_coco_result(r, Some(size), &format!("{origin}: entry {k} (image {})", r.image_id))).collect::<std::result::Result<Vec<_>, _>>()?;
    Ok(ExternalDetections::new(dets, origin))
}

/// The detector of the arguments.
fn detector_of(a: &LocateArgs, size: (u32, u32)) -> Result<Box<dyn TubeDetector>> {
    Ok(match a.detector {
        Detector::Learned => {
            let model = a.model.clone().unwrap_or_else(crate::cmd_detect_learned::default_model);
            if !model.exists() {
                bail!("learned model {} not found: pass --model FILE, or restore the shipped data/models/tubenet.safetensors (data/models/README.md has the command that trains it)", model.display());
            }
            let mut d = LearnedDetector::load(&model, Default::default())?;
            d.range = crate::cmd_detect_learned::parse_range_band(&a.range_m)?;
            Box::new(d)
        }
        Detector::Line2d => {
            let lib = a.templates.as_ref().context("--detector line2d needs --templates LIB.tlt (build one for this camera: tubeloc templates build --camera CAM.json --out LIB.tlt)")?;
            let lib = tubeloc_detect::line2d::TemplateLibrary::load(lib).with_context(|| format!("reading {}", lib.display()))?;
            Box::new(Line2dTubeDetector::new(tubeloc_detect::line2d::Line2dDetector::new(lib, Default::default())?))
        }
        Detector::External => Box::new(external_detections(a, size)?),
    })
}

fn open_image(p: &Path) -> Result<image::DynamicImage> {
    image::open(p).with_context(|| format!("cannot read image {}", p.display()))
}

/// Runs `tubeloc locate`; returns the number of converged tubes.
pub fn run(a: LocateArgs) -> Result<usize> {
    let t0 = std::time::Instant::now();
    let rig = Rig::load_json(&a.rig).with_context(|| format!("rig {}", a.rig.display()))?;
    let pair = match &a.pair {
        Some(p) => {
            let (l, r) = p.split_once(',').with_context(|| format!("--pair {p:?}: expected LEFT,RIGHT"))?;
            Some((l.trim().to_string(), r.trim().to_string()))
        }
        None => None,
    };
    let selection = CameraSelection { camera: a.camera_name.clone(), pair };
    let (w, h) = image::image_dimensions(&a.image).with_context(|| format!("reading {}", a.image.display()))?;
    let detector = detector_of(&a, (w, h))?;
    let detector_name = detector.name().to_string();
    let mut settings = LocatorSettings::default();
    settings.calibration = match (&a.calibration, a.detector) {
        (Some(p), _) => crate::cmd_detect_learned::load_calibration(Some(p), Path::new(""))?,
        (None, Detector::Learned) => crate::cmd_detect_learned::load_calibration(None, &a.model.clone().unwrap_or_else(crate::cmd_detect_learned::default_model))?,
        (None, _) => settings.calibration,
    };
    if let Some(p) = a.min_probability {
        settings.calibration.threshold = p;
    }
    let min_probability = settings.calibration.threshold;
    let locator = Locator::new(&rig, &selection, detector, settings).with_context(|| a.rig.display().to_string())?;
    let cam = locator.camera().clone();
    if (w, h) != (cam.model.width, cam.model.height) {
        bail!("{} is {w}x{h} but rig camera {:?} in {} is {}x{}", a.image.display(), cam.name, a.rig.display(), cam.model.width, cam.model.height);
    }
    let image = open_image(&a.image)?;
    let right = a.right.as_deref().map(open_image).transpose()?;
    let input = LocateInput { image: &image, right: right.as_ref(), ground: a.ground, up: a.up };
    let found = locator.locate(&input).with_context(|| format!("locating tubes in {}", a.image.display()))?;

    // Outputs: the overlay, then the poses, each written atomically; nothing printed before.
    let overlay_path = a.overlay.clone().unwrap_or_else(|| sidecar(&a.out, "overlay.png"));
    let tubes: Vec<TubeOut> = found.tubes.iter().map(|t| TubeOut { tube: t, status: "located" }).chain(found.rejected.iter().map(|r| TubeOut { tube: &r.tube, status: r.reason.name() })).collect();
    let overlay = locator.overlay_located(&image, tubes.iter().map(|t| t.tube));
    let png = tubeloc_pipeline::overlay::png_bytes(&overlay).context("encoding the overlay PNG")?;
    let doc = LocateDoc {
        schema: "tubeloc.locate.v1",
        image: &a.image,
        right_image: a.right.as_deref(),
        camera: &cam.name,
        detector: &detector_name,
        up_cam: found.up_cam,
        t_rig_cam: cam.t_rig_cam,
        tubes,
        min_probability,
        run: serde_json::json!({"seconds": t0.elapsed().as_secs_f64(), "peak_rss_mb": crate::memory::peak_rss_mb()}),
        camera_model: &cam.model,
        detections: &found.detections,
    };
    let json = serde_json::to_vec_pretty(&doc).context("serializing the poses")?;
    for p in [&a.out, &overlay_path] {
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    files::write_atomic(&overlay_path, &png).with_context(|| format!("writing {}", overlay_path.display()))?;
    if let Err(e) = files::write_atomic(&a.out, &json) {
        let _ = std::fs::remove_file(&overlay_path);
        return Err(e).with_context(|| format!("writing {}", a.out.display()));
    }

    let converged = found.tubes.len();
    print_summary(&a.image, &found, converged);
    eprintln!("poses -> {} (overlay {})", a.out.display(), overlay_path.display());
    Ok(converged)
}

/// One line per tube on stdout; a closed pipe ends the printing quietly (the files are written).
fn print_summary(image: &Path, found: &tubeloc_pipeline::LocateOutput, converged: usize) {
    let mut out = std::io::stdout().lock();
    let mut lines = vec![format!("{}: {} tube(s) located, {} detection(s) rejected, {} duplicate(s) merged", image.display(), converged, found.rejected.len(), found.merged)];
    let low: Vec<Option<(f64, f64)>> = found
        .tubes
        .iter()
        .map(|_| None)
        .chain(found.rejected.iter().map(|r| match r.reason {
            tubeloc_pipeline::Rejection::LowProbability { probability, threshold } => Some((probability, threshold)),
            _ => None,
        }))
        .collect();
    for (i, t) in found.all_tubes().enumerate() {
        let p = &t.pose;
        if let Some((pr, th)) = low[i] {
            lines.push(format!("  tube {i}: rejected (probability of a tube {pr:.3} < {th:.3}), score {:.2}", p.score));
            continue;
        }
        if let Some(tubeloc_pipeline::Rejection::IntersectsTube { other }) = i.checked_sub(found.tubes.len()).map(|k| &found.rejected[k].reason) {
            lines.push(format!("  tube {i}: rejected (its solid intersects tube {other}'s), score {:.2}", p.score));
            continue;
        }
        let c = p.centre * 1e3;
        let g = t.t_rig_grasp.translation() * 1e3;
        lines.push(match &p.failure {
            None => format!(
                "  tube {i}: centre [{:.1}, {:.1}, {:.1}] mm (cam), grasp at [{:.1}, {:.1}, {:.1}] mm (rig), axis [{:.3}, {:.3}, {:.3}], ±{:.1} mm / ±{:.2}°, seal end conf {:.2}, score {:.2}, P(tube) {:.3}",
                c.x,
                c.y,
                c.z,
                g.x,
                g.y,
                g.z,
                p.axis.x,
                p.axis.y,
                p.axis.z,
                p.centre_std_m() * 1e3,
                p.axis_std_rad().to_degrees(),
                p.end_confidence,
                p.score,
                t.probability
            ),
            Some(f) => format!("  tube {i}: rejected ({:?}): {}", f.reason, f.message),
        });
    }
    for l in lines {
        if let Err(e) = writeln!(out, "{l}") {
            if e.kind() != std::io::ErrorKind::BrokenPipe {
                eprintln!("warning: printing the summary: {e}");
            }
            return;
        }
    }
    let _ = out.flush();
}
