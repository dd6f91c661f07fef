//! `tubeloc detect`: find tubes in images with one of the detectors and write COCO results
//! (mask RLE, bbox, score) plus the per-detection seeds that `refine` uses.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Which detector to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Line2D template matching.
    Line2d,
    /// The learned segmenter (`--model`, default: the shipped model, embedded in the program).
    Learned,
    /// The learned segmenter's detections (`--model`) and Line2D's pose-verified ones
    /// (`--templates`), each scored by the probability that its refined pose is a tube, the
    /// less probable of two overlapping ones dropped (record 0069).
    Fused,
    /// Detections made elsewhere (`--results coco_results.json`), passed through with an axis
    /// seed from each mask's principal axis.
    External,
}

/// Arguments of `tubeloc detect`.
#[derive(clap::Args)]
pub struct DetectArgs {
    /// Detector.
    #[arg(long, value_enum)]
    pub method: Method,
    /// One input image.
    #[arg(long)]
    pub image: Option<PathBuf>,
    /// COCO image id written for `--image`.
    #[arg(long, default_value_t = 0)]
    pub image_id: u64,
    /// A COCO dataset directory (annotations.json + images): detect in all its images.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Learned model weights (safetensors; default: the shipped model, embedded in the program).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Learned decoder settings: JSON of `DecodeConfig` fields (thresholds, instance score,
    /// mirror averaging); missing fields keep their defaults.
    #[arg(long)]
    pub decode_config: Option<PathBuf>,
    /// External COCO results to pass through (`--method external`).
    #[arg(long)]
    pub results: Option<PathBuf>,
    /// Ground plane "nx,ny,nz,d" in the camera frame (`n·X = d`, n up, metres) for the learned
    /// detector's working scale and Line2D's ground consistency (with `--camera`); dataset
    /// images use their own `ground`.
    #[arg(long, allow_hyphen_values = true)]
    pub ground: Option<tubeloc_core::GroundPlane>,
    /// Instead of --camera, for an --image without a camera model: its camera and ground
    /// (unless --ground) are assumed from its size, as `tubeloc locate --assumed-view` does
    /// (`navcam`: 45 degree field of view, 1.9 m above level ground, 30 degrees down; `mast`: 20
    /// degrees; the other rover cameras' views; `auto`: the view of the camera the image's
    /// product name names, else navcam for a grey image, mast for a colour one; or
    /// `HFOV_DEG,HEIGHT_M,PITCH_DEG`, e.g. `90,2,25`).
    #[arg(long, value_parser = crate::args::assumed_view, requires = "image", conflicts_with_all = ["camera", "dataset"])]
    pub assumed_view: Option<crate::args::AssumedViewArg>,
    /// Distances of the tubes from the camera, "NEAR:FAR" metres, for the learned detector's
    /// working scale (the image is resampled so tubes are about 16 px wide), or "off".
    #[arg(long, default_value = DEFAULT_RANGE_M, value_parser = crate::args::range_band)]
    pub range_m: String,
    /// Output detections (JSON list of COCO results with seeds).
    #[arg(long)]
    pub out: PathBuf,
    /// Line2D options (`--templates`, `--camera`, `--threshold`, ...).
    #[command(flatten)]
    pub line2d: crate::cmd_detect_line2d::Line2dOpts,
}

impl DetectArgs {
    /// `tubeloc detect --method METHOD --dataset DATASET --out OUT` with the command line's
    /// defaults for everything else.
    pub(crate) fn dataset(method: Method, dataset: &Path, out: &Path) -> Self {
        DetectArgs {
            method,
            image: None,
            image_id: 0,
            dataset: Some(dataset.to_path_buf()),
            model: None,
            decode_config: None,
            results: None,
            ground: None,
            assumed_view: None,
            range_m: DEFAULT_RANGE_M.into(),
            out: out.to_path_buf(),
            line2d: line2d_defaults(),
        }
    }
}

/// Default `--range-m`.
const DEFAULT_RANGE_M: &str = "1:4";

/// The Line2D options at their command-line defaults (clap's own defaults, so that they
/// cannot drift from `tubeloc detect --help`).
pub(crate) fn line2d_defaults() -> crate::cmd_detect_line2d::Line2dOpts {
    use clap::{Args, FromArgMatches};
    let cmd = crate::cmd_detect_line2d::Line2dOpts::augment_args(clap::Command::new("detect").no_binary_name(true));
    let matches = cmd.try_get_matches_from(std::iter::empty::<&str>()).expect("every Line2D option has a default");
    crate::cmd_detect_line2d::Line2dOpts::from_arg_matches(&matches).expect("every Line2D option has a default")
}

/// The camera and ground of one `--image` given without a plain camera file. With a PDS camera
/// list as `--camera` (`cahv_to_pinhole.py`'s JSON) or a PDS3 label: the camera of `--image` (the list's camera named after its file, the label's one camera) and its
/// ground (`--ground` when given), and `--camera` cleared so
/// that nothing reads the list as one camera. With `--assumed-view`: that view's camera at the
/// image's size and its ground. `None` for any other `--camera`.
fn image_camera(args: &mut DetectArgs) -> Result<Option<(tubeloc_core::CameraModel, tubeloc_core::GroundPlane)>> {
    if let (Some(view), Some(image)) = (&args.assumed_view, &args.image) {
        let ((w, h), frame) = view.frame_view(image).map_err(anyhow::Error::msg)?;
        if let Some(w) = crate::args::unfit_camera_warning(&frame, image) {
            eprintln!("warning: {w}");
        }
        let view = frame.view;
        let ground = match args.ground {
            Some(g) => g,
            None => view.ground_plane()?,
        };
        return Ok(Some((view.camera(w, h), ground)));
    }
    let Some(path) = args.line2d.camera.clone() else { return Ok(None) };
    let Some(cams) = tubeloc_calib::interchange::pds::read_pds_cameras(&path)? else { return Ok(None) };
    let Some(image) = &args.image else {
        return Err(crate::args::usage(format!("--camera {} is a PDS camera list or label (one camera per image): it takes one --image, the image it describes", path.display())));
    };
    let c = tubeloc_calib::interchange::pds::camera_of_image(&cams, &path, image)?;
    args.line2d.camera = None;
    Ok(Some((c.camera.model.clone(), args.ground.unwrap_or(c.ground))))
}

/// The warning for a frame whose tubes, at their expected range (`range_m`, `--range-m`; none
/// when "off"), are narrower than the learned detector can enlarge to its working width
/// ([`tubeloc_detect::scale::NarrowTubes`]): few of them are found. (Line2D, which
/// enlarges at most `--max-upsample`, warns of its own limit.)
pub fn narrow_tubes_warning(image: &Path, cam: &tubeloc_core::CameraModel, ground: Option<tubeloc_core::GroundPlane>, range_m: &str) -> Option<String> {
    let band = tubeloc_pipeline::shipped::parse_range_band(range_m).ok().flatten()?;
    tubeloc_detect::scale::NarrowTubes::of(cam, ground.map(|g| (g.normal, g.offset)), band).map(|n| format!("{}: {n}", image.display()))
}

/// The note `tubeloc detect --dataset D` prints when images of `D` carry no `camera`: they are
/// detected as they are, not at the pixel scale the detectors work at (the learned detector's
/// working scale, unless `--range-m off`; Line2D's library scale), so tubes much narrower or
/// wider than about 16 px are mostly missed.
fn cameraless_note(dataset: &crate::detect_dataset::DetectionDataset, method: Method, range_m: &str) -> Result<Option<String>> {
    if method == Method::External || (method == Method::Learned && crate::cmd_detect_learned::parse_range_band(range_m)?.is_none()) {
        return Ok(None);
    }
    let without = dataset.cameraless();
    Ok((without > 0).then(|| {
        format!(
            "note: {without} of {} images of {} carry no `camera`: they are detected as they are, not resampled to the pixel scale the detectors work at (tubes about 16 px wide), and tubes much narrower are mostly missed; give each image its `camera` (and `ground`) in the annotations, or locate frames without a model with `tubeloc locate --assumed-view`",
            dataset.coco().images.len(),
            dataset.annotations_path().display()
        )
    }))
}

/// The learned decoder settings of `--decode-config` (defaults without it).
fn decode_config(path: Option<&Path>) -> Result<tubeloc_detect::learned::DecodeConfig> {
    let Some(p) = path else { return Ok(Default::default()) };
    let cfg: tubeloc_detect::learned::DecodeConfig = tubeloc_core::files::read_json(p).with_context(|| format!("decoder config {}", p.display()))?;
    cfg.validate().map_err(|e| anyhow::anyhow!("decoder config {}: {e}", p.display()))?;
    Ok(cfg)
}

/// The warning `tubeloc detect` prints for an underexposed frame (highlights below `locate`'s
/// default `--min-highlight-level`, record 0062), whatever the method, or `None`.
pub fn underexposure_warning(path: &Path, image: &image::DynamicImage) -> Option<String> {
    let (level, min) = (tubeloc_pipeline::frame_highlight_level(image), tubeloc_pipeline::settings::DEFAULT_MIN_HIGHLIGHT_LEVEL);
    (level < min).then(|| format!("warning: {}: underexposed (its highlights lie at grey level {level:.0} < {min:.0}): its detections are unreliable, and tubeloc locate hands over no tube from it", path.display()))
}

/// Refuses an `--image` whose size is not its camera's (`--camera`, or the camera
/// [`image_camera`] found): the working scale and Line2D's ground would be wrong, silently.
fn check_camera_size(args: &DetectArgs, found: Option<&tubeloc_core::CameraModel>) -> Result<()> {
    let Some(image) = &args.image else { return Ok(()) };
    let (camera, from) = match (found, &args.line2d.camera) {
        (Some(c), _) => (c.clone(), "its camera".to_string()),
        (None, Some(path)) => (tubeloc_calib::interchange::read_camera(path).with_context(|| format!("reading camera {}", path.display()))?, format!("the camera {}", path.display())),
        (None, None) => return Ok(()),
    };
    let (w, h) = tubeloc_detect::input::image_size(image).with_context(|| format!("reading {}", image.display()))?;
    if (w, h) != (camera.width, camera.height) {
        anyhow::bail!("{} is {w}x{h} px but {from} describes {}x{} px images: give the camera of this image", image.display(), camera.width, camera.height);
    }
    Ok(())
}

/// Runs `tubeloc detect`.
pub fn run(args: DetectArgs) -> Result<()> {
    args.line2d.check()?;
    let mut args = args;
    let pds = image_camera(&mut args)?;
    check_camera_size(&args, pds.as_ref().map(|(cam, _)| cam))?;
    // The dataset's annotations, read once (images, cameras, grounds, sizes).
    let dataset = args.dataset.as_deref().map(crate::detect_dataset::DetectionDataset::load).transpose()?;
    if let Some(d) = &dataset {
        if let Some(note) = cameraless_note(d, args.method, &args.range_m)? {
            eprintln!("{note}");
        }
    }
    if let (Some((cam, ground)), Some(image)) = (&pds, &args.image) {
        let learned = matches!(args.method, Method::Learned | Method::Fused);
        if let Some(w) = narrow_tubes_warning(image, cam, Some(*ground), &args.range_m).filter(|_| learned) {
            eprintln!("warning: {w}");
        }
    }
    let dets = match args.method {
        Method::Line2d | Method::Fused => {
            let images = crate::cmd_detect_learned::image_list(args.image.as_deref(), args.image_id, dataset.as_ref())?;
            let (cameras, grounds) = match (&dataset, &pds) {
                (Some(d), _) => (d.cameras().clone(), d.grounds()),
                (None, Some((cam, ground))) => ([(args.image_id, cam.clone())].into(), [(args.image_id, *ground)].into()),
                (None, None) => Default::default(),
            };
            if args.ground.is_some() && args.line2d.camera.is_none() && args.dataset.is_none() && pds.is_none() {
                return Err(crate::args::usage("--ground needs --camera (the rays along which the ground's distance is measured)"));
            }
            let fusion = match args.method {
                Method::Fused => {
                    let choice = crate::cmd_detect_learned::ModelChoice::of(args.model.as_deref());
                    if let Some(m) = &args.model {
                        eprintln!("warning: --method fused scores learned detections by the shipped model's pose evidence, not one fitted for {}", m.display());
                    }
                    Some(crate::cmd_detect_line2d::Fusion { model: choice.load()?, decode: decode_config(args.decode_config.as_deref())?, range: crate::cmd_detect_learned::parse_range_band(&args.range_m)?, origin: choice.name() })
                }
                _ => None,
            };
            let dets = crate::cmd_detect_line2d::run_line2d(&args.line2d, &images, &cameras, &grounds, args.ground.as_ref(), fusion)?;
            tubeloc_core::files::write_json(&args.out, &dets).with_context(|| format!("writing {}", args.out.display()))?;
            eprintln!("{} detections -> {}", dets.len(), args.out.display());
            return Ok(());
        }
        Method::Learned => {
            let images = crate::cmd_detect_learned::image_list(args.image.as_deref(), args.image_id, dataset.as_ref())?;
            let model = crate::cmd_detect_learned::ModelChoice::of(args.model.as_deref());
            let cfg = decode_config(args.decode_config.as_deref())?;
            let band = crate::cmd_detect_learned::parse_range_band(&args.range_m)?;
            let scales = match (&pds, band) {
                (Some((cam, ground)), Some(band)) => vec![tubeloc_detect::scale::working_scale(cam, Some((ground.normal, ground.offset)), band)],
                _ => crate::cmd_detect_learned::working_scales(&images, dataset.as_ref(), args.line2d.camera.as_deref(), args.ground.as_ref(), band)?,
            };
            if band.is_some() && args.dataset.is_none() && args.line2d.camera.is_none() && pds.is_none() {
                eprintln!("note: no --camera: images are detected as they are, not at the working scale of --range-m {} (tubes about 16 px wide); pass the camera for that, or --range-m off to silence this", args.range_m);
            }
            crate::cmd_detect_learned::run_learned(&model, &images, &scales, &cfg)?
        }
        Method::External => {
            let results = args.results.as_deref().context("--method external needs --results FILE")?;
            let mut sizes = std::collections::HashMap::new();
            if let Some(d) = &dataset {
                sizes.extend(d.coco().images.iter().map(|im| (im.id, (im.width, im.height))));
            } else if let Some(p) = &args.image {
                let (w, h) = tubeloc_detect::input::image_size(p).with_context(|| format!("reading {}", p.display()))?;
                sizes.insert(args.image_id, (w, h));
            }
            crate::cmd_detect_learned::run_external(results, &|id| sizes.get(&id).copied())?
        }
    };
    tubeloc_core::files::write_json(&args.out, &dets).with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("{} detections -> {}", dets.len(), args.out.display());
    Ok(())
}
