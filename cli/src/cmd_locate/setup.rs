//! What every frame of a `tubeloc locate` run shares ([`Setup`]): the rig (or each image's
//! camera from its PDS3 label or an assumed view), the detector, the settings and the ignore
//! masks, read or built once.

use super::*;

/// External COCO results, read once and selected per image by its file name.
struct ExternalResults {
    list: Vec<CocoResult>,
    names: Option<BTreeMap<u64, String>>,
    origin: String,
}

impl ExternalResults {
    fn read(a: &LocateArgs) -> Result<Self> {
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
        Ok(ExternalResults { list, names, origin: path.display().to_string() })
    }

    /// The detections of `image` (of `size` pixels): its results, selected by its file name and
    /// converted.
    fn detections_for(&self, image: &Path, size: (u32, u32)) -> Result<ExternalDetections> {
        let image_name = image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let origin = &self.origin;
        let list = detector::select_results_for_image(self.list.clone(), &image_name, self.names.as_ref(), origin)?;
        let dets = list.iter().enumerate().map(|(k, r)| detector::detection_from_coco_result(r, Some(size), &format!("{origin}: entry {k} (image {})", r.image_id))).collect::<std::result::Result<Vec<_>, _>>()?;
        Ok(ExternalDetections::new(dets, origin.clone()))
    }
}

/// How each frame's locator is had: one locator (its detector loaded once) for every frame, or
/// (external results) one per frame with that frame's detections.
enum FrameLocators {
    /// One locator; with a camera per image (a PDS camera list), switched to each frame's.
    Shared(Box<std::sync::Mutex<Locator>>),
    External(ExternalResults),
}

/// What every frame of a run shares: the rig, the camera selection, the settings and the
/// detector (a model or template library is loaded once).
pub struct Setup {
    pub(super) rig: Rig,
    pub(super) rig_path: PathBuf,
    pub(super) selection: CameraSelection,
    pub(super) settings: LocatorSettings,
    locators: FrameLocators,
    camera: tubeloc_core::RigCamera,
    /// A rig of one camera per image (a PDS camera list, without `--camera-name`): each frame
    /// is taken by the camera named after its file (a PDS3 label's one camera takes every
    /// frame).
    per_image: bool,
    /// The cameras of a PDS camera list with their grounds (used when `--ground` is not
    /// given); empty for other rig files.
    pub(super) pds: Vec<tubeloc_calib::interchange::pds::PdsCamera>,
    /// With `--label-cameras`, `--assumed-view` or a PDS camera list's fisheye entries: why an
    /// image gets no camera, by image file name (that frame fails; the others run).
    label_errors: BTreeMap<String, String>,
    /// The fisheye (CAHVORE) models of the cameras whose labels give one, by camera name: their
    /// images are resampled into the camera, the model's linear part, before locating.
    fisheyes: BTreeMap<String, tubeloc_calib::interchange::cahvore::Cahvore>,
    /// With `--assumed-view`: the view each image was given, by image file name (`navcam`,
    /// `m100`, ..., or the numbers as given), and the warning for an image whose product name
    /// names a camera no mast view fits ([`crate::args::unfit_camera_warning`]).
    pub(super) assumed_views: BTreeMap<String, (String, Option<String>)>,
    /// `--ignore-mask`: one mask for every frame, or a folder of masks by image stem.
    ignore_mask: Option<IgnoreMasks>,
    /// Name of the detector (`learned`, `line2d`, `external`).
    pub detector_name: String,
}

impl Setup {
    /// Reads the rig (with `--label-cameras`, the labels of `images`), builds the detector and
    /// the settings (score calibration) of `a`.
    pub fn new(a: &LocateArgs, images: &[&Path]) -> Result<Self> {
        // With --label-cameras and --right (one stereo pair), both labels, the right one last.
        let label_images: Vec<&Path> = images.iter().copied().chain(a.right.as_deref().filter(|_| a.label_cameras)).collect();
        let mut fisheyes = BTreeMap::new();
        let mut assumed_views = BTreeMap::new();
        let (rig_path, pds, label_errors) = if let Some(view) = &a.assumed_view {
            let (cams, views, errors) = assumed_cameras(view, &label_images);
            assumed_views = views;
            if cams.is_empty() {
                bail!("{}", errors.into_values().next().unwrap_or_else(|| "--assumed-view: no image".into()));
            }
            let described = match view {
                crate::args::AssumedViewArg::View(spec, _) => format!("the assumed {spec} view (--assumed-view)"),
                crate::args::AssumedViewArg::Auto => "the assumed view of each frame's camera or kind (--assumed-view auto: the camera its product name names, else navcam for grey, mast for colour)".to_string(),
            };
            (PathBuf::from(described), Some(cams), errors)
        } else if a.label_cameras {
            let (cams, errors) = label_cameras(&label_images, a.label_dir.as_deref());
            if cams.is_empty() || (a.right.is_some() && !errors.is_empty()) {
                bail!("{}", errors.into_values().next().unwrap_or_else(|| "--label-cameras: no image".into()));
            }
            let mut list = Vec::with_capacity(cams.len());
            for (c, fisheye) in cams {
                fisheyes.extend(fisheye.map(|m| (c.camera.name.clone(), m)));
                list.push(c);
            }
            (PathBuf::from("the images' PDS3 labels (--label-cameras)"), Some(list), errors)
        } else {
            let rig_path = a.rig_path()?.to_path_buf();
            // A PDS3 label is read here with its fisheye model, if any; a PDS camera list with
            // the fisheye models of its CAHVORE entries, from their labels (a frame whose label
            // cannot be read fails, the others run); other rigs as rigs.
            let (pds, errors) = match tubeloc_calib::interchange::pds::read_rig_cameras(&rig_path).context("rig")? {
                Some(read) => {
                    fisheyes.extend(read.fisheye_models);
                    (Some(read.cameras), read.errors)
                }
                None => (None, BTreeMap::new()),
            };
            (rig_path, pds, errors)
        };
        // A fisheye's pinhole at the asked scale (same principal point, same pose and ground).
        let mut pds = pds;
        for c in pds.iter_mut().flatten().filter(|c| fisheyes.contains_key(&c.camera.name)) {
            (c.camera.model.fx, c.camera.model.fy) = (c.camera.model.fx * a.fisheye_scale, c.camera.model.fy * a.fisheye_scale);
        }
        let mut rig: Rig = match &pds {
            Some(cams) => tubeloc_calib::interchange::pds::rig_of(cams),
            None => tubeloc_calib::read_rig(&rig_path).context("rig")?,
        };
        // Two labels of one moment (a stereo pair): both cameras stand in the same rover frame,
        // so the pair's geometry is theirs.
        let label_pair = match (a.label_cameras, &rig.cameras[..]) {
            (true, [left, right]) if a.right.is_some() => Some((left.name.clone(), right.name.clone())),
            _ => None,
        };
        if let Some(p) = &label_pair {
            rig.stereo_pairs.push(p.clone());
        }
        let pair = match &a.pair {
            Some(p) => {
                let (l, r) = p.split_once(',').with_context(|| format!("--pair {p:?}: expected LEFT,RIGHT"))?;
                Some((l.trim().to_string(), r.trim().to_string()))
            }
            None => label_pair,
        };
        // A PDS camera list holds one camera per image, named after the image's file.
        let per_image = pds.is_some() && a.camera_name.is_none() && pair.is_none();
        let pds = pds.unwrap_or_default();
        let camera_name = match (per_image, &a.image) {
            (true, Some(image)) => {
                if let Some(e) = image.file_name().and_then(|n| label_errors.get(n.to_string_lossy().as_ref())) {
                    bail!("{e}");
                }
                Some(pds_camera_of(&pds, &rig_path, image)?.camera.name.clone())
            }
            _ => a.camera_name.clone(),
        };
        let selection = CameraSelection { camera: camera_name, pair };
        let model = crate::cmd_detect_learned::ModelChoice::of(a.model.as_deref());
        let mut settings = tubeloc_pipeline::shipped::locate_settings(a.detector.name(), a.calibration.as_deref(), model.path(), a.min_pose_evidence)?;
        settings.min_highlight_level = a.min_highlight_level;
        settings.max_limb_continuation = a.max_limb_continuation.0;
        if let Some(p) = a.min_probability {
            settings.calibration.threshold = p;
        }
        let shared: Option<Box<dyn TubeDetector>> = match a.detector {
            // The same detector the Python package builds from the same options.
            Detector::Learned => Some(Box::new(tubeloc_pipeline::shipped::learned_detector(a.model.as_deref(), &a.range_m)?)),
            Detector::Line2d => Some(Box::new(tubeloc_pipeline::shipped::line2d_detector(a.templates.as_deref(), Some("shipped"))?)),
            Detector::Fused => Some(Box::new(tubeloc_pipeline::shipped::fused_detector(a.templates.as_deref(), a.model.as_deref(), &a.range_m)?)),
            Detector::External => None,
        };
        // External results: a locator without detections resolves the camera here; each frame
        // gets its own.
        let external = match shared {
            None => Some(ExternalResults::read(a)?),
            Some(_) => None,
        };
        let detector = shared.unwrap_or_else(|| Box::new(ExternalDetections::new(Vec::new(), "")));
        let locator = Locator::new(&rig, &selection, detector, settings.clone()).with_context(|| rig_path.display().to_string())?;
        let (camera, detector_name) = (locator.camera().clone(), locator.detector().name().to_string());
        let locators = match external {
            Some(ext) => FrameLocators::External(ext),
            None => FrameLocators::Shared(Box::new(std::sync::Mutex::new(locator))),
        };
        let ignore_mask = match &a.ignore_mask {
            Some(p) if p.is_dir() => Some(IgnoreMasks::PerFrame(p.clone())),
            Some(p) => {
                let mask = open_image(p).context("--ignore-mask")?;
                let plane = tubeloc_pipeline::ignore_mask_of(&mask);
                Some(IgnoreMasks::Every(p.clone(), mask, plane))
            }
            None => None,
        };
        Ok(Setup { rig, rig_path, selection, settings, locators, camera, per_image, pds, label_errors, fisheyes, assumed_views, ignore_mask, detector_name })
    }

    /// The rig camera that took `image`: the run's, or with a camera per image the one named
    /// after its file.
    fn camera_of(&self, image: &Path) -> Result<&tubeloc_core::RigCamera> {
        if !self.per_image {
            return Ok(&self.camera);
        }
        if let Some(e) = image.file_name().and_then(|n| self.label_errors.get(n.to_string_lossy().as_ref())) {
            bail!("{e}");
        }
        Ok(&pds_camera_of(&self.pds, &self.rig_path, image)?.camera)
    }

    /// Checks that `image` (`size` pixels) is the size of the rig camera that took it.
    pub(super) fn check_size(&self, image: &Path, (w, h): (u32, u32)) -> Result<()> {
        let cam = self.camera_of(image)?;
        if (w, h) != (cam.model.width, cam.model.height) {
            bail!("{} is {w}x{h} but rig camera {:?} in {} is {}x{}", image.display(), cam.name, self.rig_path.display(), cam.model.width, cam.model.height);
        }
        Ok(())
    }

    /// The `--ignore-mask` of the frame `image` (of `size` pixels, as stored) as the camera
    /// `camera` sees it (resampled with a fisheye frame); the mask must be the frame's size.
    pub(super) fn ignore_mask_for(&self, camera: &tubeloc_core::RigCamera, image: &Path, size: (u32, u32)) -> Result<Option<std::borrow::Cow<'_, tubeloc_core::Plane<u8>>>> {
        let (path, read);
        let mask = match &self.ignore_mask {
            None => return Ok(None),
            Some(IgnoreMasks::Every(p, m, plane)) => {
                // The same mask for every frame: made once for pinhole frames.
                if (m.width(), m.height()) == size && !self.fisheyes.contains_key(&camera.name) {
                    return Ok(Some(std::borrow::Cow::Borrowed(plane)));
                }
                path = p.clone();
                m
            }
            Some(IgnoreMasks::PerFrame(dir)) => {
                path = dir.join(format!("{}.png", image.file_stem().map(|s| s.to_string_lossy()).unwrap_or_default()));
                if !path.exists() {
                    return Ok(None);
                }
                if std::fs::canonicalize(&path).ok() == std::fs::canonicalize(image).ok() {
                    bail!("--ignore-mask {}: the mask of {} is the image itself; keep the masks in a folder of their own", dir.display(), image.display());
                }
                read = open_image(&path).context("--ignore-mask")?;
                &read
            }
        };
        if (mask.width(), mask.height()) != size {
            bail!("--ignore-mask {} is {}x{} but the image {} is {}x{}: the mask is drawn on the frame as stored", path.display(), mask.width(), mask.height(), image.display(), size.0, size.1);
        }
        Ok(Some(std::borrow::Cow::Owned(tubeloc_pipeline::ignore_mask_of(&self.as_seen_by(camera, mask.clone()).0))))
    }

    /// `image` as the camera `camera` sees it: resampled into it when the camera is a fisheye
    /// model's linear part, with the model's name.
    pub(super) fn as_seen_by(&self, camera: &tubeloc_core::RigCamera, image: image::DynamicImage) -> (image::DynamicImage, Option<&'static str>) {
        match self.fisheyes.get(&camera.name) {
            Some(m) => (tubeloc_calib::interchange::linearize::LinearResampling::new(m, camera, (image.width(), image.height())).apply(&image), Some("CAHVORE")),
            None => (image, None),
        }
    }

    /// Runs `f` with the locator of the frame `image` (of `size` pixels).
    pub(super) fn with_locator<R>(&self, image: &Path, size: (u32, u32), f: impl FnOnce(&Locator) -> Result<R>) -> Result<R> {
        match &self.locators {
            FrameLocators::Shared(l) => {
                let mut l = l.lock().unwrap_or_else(|e| e.into_inner());
                if self.per_image {
                    l.select_camera(&self.camera_of(image)?.name)?;
                }
                f(&l)
            }
            FrameLocators::External(ext) => {
                let dets = ext.detections_for(image, size)?;
                let mut selection = self.selection.clone();
                if self.per_image {
                    selection.camera = Some(self.camera_of(image)?.name.clone());
                }
                let l = Locator::new(&self.rig, &selection, Box::new(dets), self.settings.clone()).with_context(|| self.rig_path.display().to_string())?;
                f(&l)
            }
        }
    }
}

/// `--ignore-mask`: one mask for every frame (its path, image, and the mask as a pinhole frame
/// takes it, made once), or a folder holding a mask per frame, `<image stem>.png`.
enum IgnoreMasks {
    Every(PathBuf, image::DynamicImage, tubeloc_core::Plane<u8>),
    PerFrame(PathBuf),
}

/// A camera of a PDS3 label, with the fisheye model its image is resampled from, if any.
type LabelCamera = (tubeloc_calib::interchange::pds::PdsCamera, Option<tubeloc_calib::interchange::cahvore::Cahvore>);

/// The cameras of `--label-cameras`: each image's own PDS3 label, the camera named after the
/// image's file; and, by image file name, why an image gives none.
fn label_cameras(images: &[&Path], label_dir: Option<&Path>) -> (Vec<LabelCamera>, BTreeMap<String, String>) {
    use tubeloc_calib::interchange::{detached_label::DetachedLabels, pds_label::read_resampled_label_camera};
    let mut detached = DetachedLabels::new(label_dir);
    let mut read = |image: &Path, name: &str| -> Result<LabelCamera> {
        let own = match read_resampled_label_camera(image).context("--label-cameras")? {
            Some(c) => Some(c),
            None => match detached.of(image).context("--label-cameras")? {
                Some(label) => Some(read_resampled_label_camera(&label).context("--label-cameras")?.with_context(|| format!("--label-cameras: {}, the label of {}, is not a PDS3 label", label.display(), image.display()))?),
                None => None,
            },
        };
        let Some((mut c, fisheye)) = own else {
            bail!(
                "--label-cameras: {} is not a PDS3 product (an .IMG with its label at the head, or a .LBL), and no label in {} names it (its product name with .LBL, the version character may stand for `_`): give --label-dir, --rig with its label or camera, or --assumed-view",
                image.display(),
                detached.folder_for(image).display()
            );
        };
        (c.camera.name, c.image) = (name.to_string(), Some(name.to_string()));
        Ok((c, fisheye))
    };
    let (mut cams, mut errors) = (Vec::new(), BTreeMap::new());
    for image in images {
        let name = image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        match read(image, &name) {
            Ok(c) => cams.push(c),
            Err(e) => {
                errors.insert(name, format!("{e:#}"));
            }
        }
    }
    (cams, errors)
}

/// The cameras of `--assumed-view`: each image's camera (named after its file) and ground
/// under `view`, from the image's size (with `auto`, and its product name or its pixels: grey
/// or colour); by image file name, the view's name and the warning for a frame of a camera no
/// mast view fits; and, by image file name, why an image gives none.
type AssumedCameras = (Vec<tubeloc_calib::interchange::pds::PdsCamera>, BTreeMap<String, (String, Option<String>)>, BTreeMap<String, String>);
fn assumed_cameras(view: &crate::args::AssumedViewArg, images: &[&Path]) -> AssumedCameras {
    use rayon::prelude::*;
    let one = |image: &&Path| {
        let name = image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let camera = view.frame_view(image).map_err(|e| format!("--assumed-view: {e}")).and_then(|((w, h), frame)| {
            let (rig, ground) = frame.view.rig(&name, w, h).map_err(|e| format!("--assumed-view: {e}"))?;
            let note = crate::args::unfit_camera_warning(&frame, image);
            Ok((tubeloc_calib::interchange::pds::PdsCamera { camera: rig.cameras[0].clone(), ground, sol: None, image: Some(name.clone()) }, (frame.name, note)))
        });
        (name, camera)
    };
    let read: Vec<_> = if view.by_frame() { images.par_iter().map(one).collect() } else { images.iter().map(one).collect() };
    let (mut cams, mut names, mut errors) = (Vec::new(), BTreeMap::new(), BTreeMap::new());
    for (name, camera) in read {
        match camera {
            Ok((c, view_name)) => {
                cams.push(c);
                names.insert(name, view_name);
            }
            Err(e) => {
                errors.insert(name, e);
            }
        }
    }
    (cams, names, errors)
}

/// The camera of the PDS camera list `cameras` (read from `rig_path`) that took `image`: the
/// one named after its file.
fn pds_camera_of<'a>(cameras: &'a [tubeloc_calib::interchange::pds::PdsCamera], rig_path: &Path, image: &Path) -> Result<&'a tubeloc_calib::interchange::pds::PdsCamera> {
    tubeloc_calib::interchange::pds::camera_of_image(cameras, rig_path, image).map_err(|e| anyhow::anyhow!("{e}; give --camera-name"))
}
