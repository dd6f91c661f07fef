//! `tubeloc locate`: the main job. One image (or a stereo pair) and a rig file in, grasp-ready
//! tube poses out.
//!
//! It chains the same subcommands a user runs — `detect` (learned by default, or Line2D, or
//! external results), then `refine` (mono, or with stereo when `--right` is given) — and then
//! adds a grasp frame to every pose, prints one line per tube and writes one JSON document
//! (schema `tubeloc.locate.v1`, documented in the README). Intermediate files (the camera of the
//! chosen rig camera, the detections) are kept next to the output as `<stem>.detections.json`
//! so that a run can be inspected and re-refined.

use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::Vector3;
use serde::Serialize;
use std::path::{Path, PathBuf};
use tubeloc_core::{files, Pose, Rig, TubeAxisPose};

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
    /// External COCO results (`--detector external`).
    #[arg(long)]
    pub results: Option<PathBuf>,
    /// Ground plane "nx,ny,nz,d" in the camera frame (`n·X = d`, n up), metres: places seeds on
    /// the ground and gives the grasp approach direction.
    #[arg(long, allow_hyphen_values = true)]
    pub ground: Option<String>,
    /// Up direction "ux,uy,uz" in the camera frame for the grasp approach when no --ground is
    /// given (default: -y, i.e. the camera is roughly level).
    #[arg(long, allow_hyphen_values = true)]
    pub up: Option<String>,
    /// Output poses (JSON, schema tubeloc.locate.v1).
    #[arg(long)]
    pub out: PathBuf,
    /// Overlay PNG with the fitted contours (default: `<out stem>.overlay.png` next to --out).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
}

/// One located tube: the refined pose plus grasp frames.
#[derive(Serialize, Debug)]
pub struct LocatedTube {
    /// The refined pose (camera frame), flattened into this object.
    #[serde(flatten)]
    pub pose: TubeAxisPose,
    /// Grasp frame in the camera frame (approach +z, fingers close along +y, +x the axis).
    #[serde(rename = "T_cam_grasp")]
    pub t_cam_grasp: Pose,
    /// Grasp frame in the rig frame (`T_rig_cam · T_cam_grasp`).
    #[serde(rename = "T_rig_grasp")]
    pub t_rig_grasp: Pose,
}

/// The document `tubeloc locate` writes.
#[derive(Serialize, Debug)]
pub struct LocateOutput {
    /// Schema name and version: `tubeloc.locate.v1`.
    pub schema: &'static str,
    /// The input image.
    pub image: PathBuf,
    /// The right image, when stereo was used.
    pub right_image: Option<PathBuf>,
    /// Rig camera of `image`.
    pub camera: String,
    /// Detector that seeded the refinement.
    pub detector: String,
    /// Up direction used for the grasp frames, unit vector in the camera frame.
    pub up_cam: Vector3<f64>,
    /// Pose of the camera in the rig frame.
    #[serde(rename = "T_rig_cam")]
    pub t_rig_cam: Pose,
    /// Located tubes, best score first; failed fits are kept with `converged: false`.
    pub tubes: Vec<LocatedTube>,
    /// Run statistics: wall time (s) and peak resident memory (MiB) of the whole run.
    pub run: serde_json::Value,
}

fn parse_vec3(flag: &str, s: &str) -> Result<Vector3<f64>> {
    let v: Vec<f64> = s.split(',').map(|t| t.trim().parse::<f64>()).collect::<std::result::Result<_, _>>().with_context(|| format!("{flag} {s:?}: expected three numbers x,y,z"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("{flag} {s:?}: expected three finite numbers x,y,z");
    }
    let n = Vector3::new(v[0], v[1], v[2]);
    if n.norm() < 1e-9 {
        bail!("{flag} {s:?}: the vector is zero");
    }
    Ok(n.normalize())
}

/// The up direction for grasp frames: the ground normal when given, else `--up`, else -y.
fn up_direction(a: &LocateArgs) -> Result<Vector3<f64>> {
    if let Some(g) = &a.ground {
        let first3 = g.splitn(4, ',').take(3).collect::<Vec<_>>().join(",");
        return parse_vec3("--ground", &first3);
    }
    match &a.up {
        Some(u) => parse_vec3("--up", u),
        None => Ok(-Vector3::y()),
    }
}

fn sidecar(out: &Path, suffix: &str) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "poses".into());
    out.with_file_name(format!("{stem}.{suffix}"))
}

fn s(p: &Path) -> String {
    p.display().to_string()
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
        None => rig.stereo_pairs.first().cloned(),
    };
    let cam_name = match (&a.camera_name, &pair) {
        (Some(n), _) => n.clone(),
        (None, Some((l, _))) => l.clone(),
        (None, None) => rig.cameras.first().map(|c| c.name.clone()).with_context(|| format!("{}: the rig has no cameras", a.rig.display()))?,
    };
    let rig_cam = rig.camera(&cam_name).with_context(|| format!("{}: no camera named {cam_name:?}", a.rig.display()))?;
    if a.right.is_some() {
        match &pair {
            Some((l, _)) if *l == cam_name => {}
            Some((l, r)) => bail!("--right: the image's camera {cam_name:?} is not the left camera of pair {l},{r}"),
            None => bail!("--right: {} has no stereo pair; pass --pair LEFT,RIGHT", a.rig.display()),
        }
    }
    let (w, h) = image::image_dimensions(&a.image).with_context(|| format!("reading {}", a.image.display()))?;
    if (w, h) != (rig_cam.model.width, rig_cam.model.height) {
        bail!("{} is {w}x{h} but rig camera {cam_name:?} in {} is {}x{}", a.image.display(), a.rig.display(), rig_cam.model.width, rig_cam.model.height);
    }
    let up = up_direction(&a)?;
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let camera_path = sidecar(&a.out, "camera.json");
    files::write_json(&camera_path, &rig_cam.model).with_context(|| format!("writing {}", camera_path.display()))?;

    // 1. Detect.
    let dets = sidecar(&a.out, "detections.json");
    let mut w = vec!["detect".to_string(), "--image".into(), s(&a.image), "--out".into(), s(&dets)];
    match a.detector {
        Detector::Learned => {
            w.extend(["--method".into(), "learned".into()]);
            if let Some(m) = &a.model {
                w.extend(["--model".into(), s(m)]);
            }
        }
        Detector::Line2d => {
            let lib = a.templates.as_ref().context("--detector line2d needs --templates LIB.tlt (build one for this camera: tubeloc templates build --camera CAM.json --out LIB.tlt)")?;
            w.extend(["--method".into(), "line2d".into(), "--templates".into(), s(lib), "--camera".into(), s(&camera_path)]);
        }
        Detector::External => {
            let r = a.results.as_ref().context("--detector external needs --results coco_results.json")?;
            w.extend(["--method".into(), "external".into(), "--results".into(), s(r)]);
        }
    }
    crate::run_words(&w).context("detection")?;

    // 2. Refine (mono or stereo).
    let raw_poses = sidecar(&a.out, "refined.json");
    let overlay = a.overlay.clone().unwrap_or_else(|| sidecar(&a.out, "overlay.png"));
    let mut w = vec!["refine".to_string(), "--image".into(), s(&a.image), "--detections".into(), s(&dets), "--out".into(), s(&raw_poses), "--overlay".into(), s(&overlay)];
    match &a.right {
        Some(r) => {
            let (l, rr) = pair.clone().context("stereo needs a pair")?;
            w.extend(["--right".into(), s(r), "--rig".into(), s(&a.rig), "--pair".into(), format!("{l},{rr}")]);
        }
        None => w.extend(["--camera".into(), s(&camera_path)]),
    }
    if let Some(g) = &a.ground {
        w.extend(["--ground".into(), g.clone()]);
    }
    crate::run_words(&w).context("refinement")?;

    // 3. One pose per physical tube, grasp frames, summary, output.
    let mut poses: Vec<TubeAxisPose> = files::read_json(&raw_poses)?;
    poses.sort_by(|x, y| y.converged.cmp(&x.converged).then(y.score.total_cmp(&x.score)));
    let merged = tubeloc_refine::duplicates::merge_duplicates(&mut poses, &tubeloc_core::TubeModel::default());
    let tubes: Vec<LocatedTube> = poses
        .into_iter()
        .map(|pose| {
            let t_cam_grasp = pose.grasp_frame(&up);
            LocatedTube { t_rig_grasp: rig_cam.t_rig_cam * t_cam_grasp, t_cam_grasp, pose }
        })
        .collect();
    let converged = tubes.iter().filter(|t| t.pose.converged).count();
    println!("{}: {} tube(s) located, {} detection(s) rejected, {merged} duplicate(s) merged", a.image.display(), converged, tubes.len() - converged);
    for (i, t) in tubes.iter().enumerate() {
        let p = &t.pose;
        let c = p.centre * 1e3;
        let g = t.t_rig_grasp.translation() * 1e3;
        match &p.failure {
            None => println!(
                "  tube {i}: centre [{:.1}, {:.1}, {:.1}] mm (cam), grasp at [{:.1}, {:.1}, {:.1}] mm (rig), axis [{:.3}, {:.3}, {:.3}], ±{:.1} mm / ±{:.2}°, seal end conf {:.2}, score {:.2}",
                c.x, c.y, c.z, g.x, g.y, g.z, p.axis.x, p.axis.y, p.axis.z, p.centre_std_m() * 1e3, p.axis_std_rad().to_degrees(), p.end_confidence, p.score
            ),
            Some(f) => println!("  tube {i}: rejected ({:?}): {}", f.reason, f.message),
        }
    }
    let doc = LocateOutput {
        schema: "tubeloc.locate.v1",
        image: a.image.clone(),
        right_image: a.right.clone(),
        camera: cam_name,
        detector: format!("{:?}", a.detector).to_lowercase(),
        up_cam: up,
        t_rig_cam: rig_cam.t_rig_cam,
        tubes,
        run: serde_json::json!({"seconds": t0.elapsed().as_secs_f64(), "peak_rss_mb": crate::memory::peak_rss_mb()}),
    };
    files::write_json(&a.out, &doc).with_context(|| format!("writing {}", a.out.display()))?;
    let _ = std::fs::remove_file(&raw_poses);
    eprintln!("poses -> {} (overlay {})", a.out.display(), overlay.display());
    Ok(converged)
}
