//! The frames of the real data and the view each is composited under: its `MANIFEST.tsv`,
//! the split by sol, and the frames a composite set of a part is made on.
//!
//! Two kinds of view:
//! - **PDS geometry** ([`views_from_cameras_json`]): frames whose CAHV/CAHVOR camera model was
//!   linearized by `cahv_to_pinhole.py`. The ground is the site frame's level plane at the
//!   camera's height (`up_cam = R_cam_from_site · (0, 0, -1)`, site z points down), the sun is
//!   the label's solar direction in the camera frame. The composite's shadows and light match
//!   the frame.
//! - **Assumed geometry** ([`AssumedView`]): backgrounds without a camera model get a pinhole
//!   with a given horizontal field of view, a mast height, a pitch below the horizon and a roll;
//!   the sun is drawn at random above the horizon.

use crate::composite::PhotoEncoding;
use crate::SynthError;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;
use std::path::{Path, PathBuf};
use tubeloc_core::CameraModel;

/// A real frame with the geometry a composite needs.
#[derive(Clone, Debug)]
pub struct RealView {
    /// The photograph.
    pub image: PathBuf,
    /// Sol of the frame (for splits), when known.
    pub sol: Option<i64>,
    /// Camera (linear pinhole) of the photograph, its size included.
    pub camera: CameraModel,
    /// Unit up direction of the ground in the camera frame.
    pub up_cam: Vector3<f64>,
    /// Height of the camera centre above the ground, metres.
    pub height_m: f64,
    /// Unit direction toward the sun in the camera frame, when known (a composite of a frame
    /// without one draws one: [`random_sun`]).
    pub sun_cam: Option<Vector3<f64>>,
    /// Where the geometry came from (`pds` or `assumed`).
    pub geometry: &'static str,
    /// How the photograph's pixel values encode light: sRGB, or the linear stretch its
    /// `MANIFEST.tsv` row's `conversion` names ([`encoding_of_conversion`]).
    pub encoding: PhotoEncoding,
}

impl RealView {
    /// The ground plane in the camera frame as `(n, d)` with `n` the unit up normal and
    /// `n · X = d` (metres): `d = -height`.
    pub fn ground(&self) -> (Vector3<f64>, f64) {
        (self.up_cam, -self.height_m)
    }
}

/// Reads the views of `cameras.json` (as written by `cahv_to_pinhole.py`); image paths are
/// relative to the file's folder. Frames of a CAHVORE (fisheye) model are left out: a pinhole
/// does not describe them. Each entry needs `image`, `image_width`, `image_height`, `fx`, `fy`,
/// `cx`, `cy`, `R_cam_from_site` and `camera_height_m`; the sun is optional:
/// `sun_direction_camera`, else `sun_direction_site` turned by `R_cam_from_site`.
pub fn views_from_cameras_json(path: &Path) -> Result<Vec<RealView>, SynthError> {
    let err = |message: String| SynthError::Data { path: path.to_path_buf(), message };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let list: Vec<Value> = serde_json::from_str(&text).map_err(|e| err(format!("not a JSON list of cameras: {e}")))?;
    let root = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (k, e) in list.iter().enumerate() {
        let ctx = |m: &str| err(format!("entry {k}: {m}"));
        if e.get("model_type").and_then(Value::as_str) == Some("CAHVORE") {
            continue;
        }
        let num = |key: &str| e.get(key).and_then(Value::as_f64).filter(|v| v.is_finite()).ok_or_else(|| ctx(&format!("missing or non-finite `{key}`")));
        let vec3 = |v: &Value| -> Option<Vector3<f64>> {
            let a = v.as_array()?;
            (a.len() == 3).then_some(())?;
            Some(Vector3::new(a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?))
        };
        let image = e.get("image").and_then(Value::as_str).ok_or_else(|| ctx("missing `image`"))?;
        let rows = e.get("R_cam_from_site").and_then(Value::as_array).filter(|r| r.len() == 3).ok_or_else(|| ctx("missing `R_cam_from_site` (3x3)"))?;
        let rows: Vec<Vector3<f64>> = rows.iter().map(vec3).collect::<Option<_>>().ok_or_else(|| ctx("`R_cam_from_site` is not 3x3 numbers"))?;
        let r = Matrix3::from_rows(&[rows[0].transpose(), rows[1].transpose(), rows[2].transpose()]);
        if !((r * r.transpose() - Matrix3::identity()).abs().max() < 1e-3 && (r.determinant() - 1.0).abs() < 1e-3) {
            return Err(ctx("`R_cam_from_site` is not a rotation (orthonormal, determinant 1)"));
        }
        let up_cam = (r * Vector3::new(0.0, 0.0, -1.0)).normalize();
        let camera = CameraModel { width: num("image_width")? as u32, height: num("image_height")? as u32, fx: num("fx")?, fy: num("fy")?, cx: num("cx")?, cy: num("cy")?, distortion: Default::default() };
        camera.validate().map_err(|e| ctx(&e.to_string()))?;
        let height_m = num("camera_height_m")?;
        if height_m <= 0.0 {
            return Err(ctx(&format!("camera height {height_m} m must be > 0")));
        }
        // The sun in the camera frame; where the list gives it only in the site frame (MER
        // labels give the sun's azimuth and elevation in the site frame alone), turned into
        // the camera frame by `R_cam_from_site`, as the list's own camera-frame suns are
        // (within 1.3 degrees on the shared data's 116 frames that give both).
        let direction = |key: &str| match e.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => vec3(v).and_then(|v| v.try_normalize(1e-12)).map(Some).ok_or_else(|| ctx(&format!("`{key}` is not a non-zero 3-vector"))),
        };
        let sun_cam = match direction("sun_direction_camera")? {
            Some(s) => Some(s),
            None => direction("sun_direction_site")?.map(|s| r * s),
        };
        let sol = e.get("sol").and_then(Value::as_i64);
        out.push(RealView { image: root.join(image), sol, camera, up_cam, height_m, sun_cam, geometry: "pds", encoding: PhotoEncoding::Srgb });
    }
    Ok(out)
}

pub use tubeloc_core::AssumedView;

/// The horizontal fields of view, degrees, that training views are drawn from by default
/// ([`random_view`]).
pub const TRAINING_HFOV_DEG: (f64, f64) = (15.0, 50.0);

/// Checks a range of horizontal fields of view `(LO, HI)` in degrees: `0 < LO <= HI < 180`.
pub fn check_hfov_range(hfov_deg: (f64, f64)) -> Result<(), String> {
    let (lo, hi) = hfov_deg;
    if lo > 0.0 && lo <= hi && hi < 180.0 {
        Ok(())
    } else {
        Err("need 0 < LO <= HI < 180 degrees".into())
    }
}

/// A random assumed view for training: horizontal field of view uniform in `hfov_deg`
/// (degrees, `0 < lo <= hi < 180`), height 0.8-2.2 m, pitch 15-60 degrees, roll ±4 degrees.
pub fn random_view(rng: &mut ChaCha8Rng, hfov_deg: (f64, f64)) -> AssumedView {
    // A half-open draw (as the default sets were made), or the one field of view given.
    let hfov = if hfov_deg.0 < hfov_deg.1 { rng.random_range(hfov_deg.0..hfov_deg.1) } else { hfov_deg.0 };
    AssumedView { hfov_deg: hfov, height_m: rng.random_range(0.8..2.2), pitch_deg: rng.random_range(15.0..60.0), roll_deg: rng.random_range(-4.0..4.0) }
}

/// `view` for an image of `width x height` pixels at `image`; the sun is drawn from
/// `rng` (elevation 20-75 degrees, any azimuth).
pub fn assumed_real_view(view: &AssumedView, image: PathBuf, width: u32, height: u32, sol: Option<i64>, rng: &mut ChaCha8Rng) -> RealView {
    let camera = view.camera(width, height);
    let up_cam = view.up_cam();
    let sun_cam = Some(random_sun(rng, &up_cam));
    RealView { image, sol, camera, up_cam, height_m: view.height_m, sun_cam, geometry: "assumed", encoding: PhotoEncoding::Srgb }
}

/// A sun drawn for a frame whose sun is not known, as a unit direction in the camera frame:
/// azimuth `a` uniform about the ground's unit up direction `up_cam` (camera frame; from the
/// camera's forward direction on the ground), elevation `e` uniform in 20-75 degrees above
/// the ground: `(fwd cos a + side sin a) cos e + up sin e`.
pub fn random_sun(rng: &mut ChaCha8Rng, up_cam: &Vector3<f64>) -> Vector3<f64> {
    let (a, e) = (rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(20f64..75.0).to_radians());
    let fwd = (Vector3::z() - up_cam * up_cam.z).normalize();
    let side = up_cam.cross(&fwd);
    ((fwd * a.cos() + side * a.sin()) * e.cos() + up_cam * e.sin()).normalize()
}

/// Whether `own`, a frame's own camera-model view, sees ground wherever `assumed` (the view the
/// same frame is composited under) puts ground within `far_m` metres of the camera: a pixel
/// whose assumed ground point lies within `far_m` must look below the horizon under the frame's
/// own camera. A frame that looks at the horizon (say 10 degrees up) composited under a view
/// 30 degrees down would have tubes pasted onto its sky and far hills. The two views must be of
/// the same image size. Checked on a grid of 32 x 32 pixels.
pub fn ground_where_assumed(own: &RealView, assumed: &RealView, far_m: f64) -> bool {
    let (w, h) = (assumed.camera.width as f64, assumed.camera.height as f64);
    (0..32 * 32).all(|k| {
        let p = nalgebra::Point2::new(((k % 32) as f64 + 0.5) / 32.0 * w - 0.5, ((k / 32) as f64 + 0.5) / 32.0 * h - 0.5);
        let ray = |v: &RealView| {
            let (x, y) = v.camera.normalize(&p);
            Vector3::new(x, y, 1.0).normalize()
        };
        // Distance along the assumed ray to the assumed ground (`up · X = -height`).
        let down = -assumed.up_cam.dot(&ray(assumed));
        let assumed_ground_near = down > 1e-9 && assumed.height_m / down <= far_m;
        !assumed_ground_near || own.up_cam.dot(&ray(own)) < 0.0
    })
}

/// Leaves out of `views` each frame under an assumed view whose own camera model (in
/// `own`, matched by file name and size) does not see ground where the assumed view puts
/// ground within `far_m` metres ([`ground_where_assumed`]); frames without a model of their
/// own are kept. Returns the file names left out.
pub fn drop_sky_under_assumed_views(views: &mut Vec<RealView>, own: &[RealView], far_m: f64) -> Vec<String> {
    let mut dropped = Vec::new();
    views.retain(|v| {
        let name = v.image.file_name();
        let keep = v.geometry != "assumed" || own.iter().filter(|o| o.image.file_name() == name && (o.camera.width, o.camera.height) == (v.camera.width, v.camera.height)).all(|o| ground_where_assumed(o, v, far_m));
        if !keep {
            dropped.push(v.image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default());
        }
        keep
    });
    dropped
}

/// Which part of the real data a frame belongs to. Frames are split by sol so that no scene
/// is in two parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum RealSplit {
    /// Training backgrounds.
    Train,
    /// Choosing settings.
    Val,
    /// Reporting, once per change.
    Test,
    /// Every frame, whatever its sol, judged as validation and test frames are: for real data
    /// the model never saw (an independent check on new frames). On the shipped data it holds
    /// the training backgrounds too, so its figures are no held-out measurement there.
    All,
}

impl RealSplit {
    /// Whether a frame of `sol` belongs to this part ([`split_of_sol`]; every frame to
    /// [`RealSplit::All`]).
    pub fn holds(self, sol: Option<i64>) -> bool {
        self == RealSplit::All || split_of_sol(sol) == self
    }

    /// The part's name as `--split` takes it (`train`, `val`, `test`, `all`).
    pub fn name(self) -> &'static str {
        match self {
            RealSplit::Train => "train",
            RealSplit::Val => "val",
            RealSplit::Test => "test",
            RealSplit::All => "all",
        }
    }
}

impl std::fmt::Display for RealSplit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RealSplit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "train" => Ok(RealSplit::Train),
            "val" => Ok(RealSplit::Val),
            "test" => Ok(RealSplit::Test),
            "all" => Ok(RealSplit::All),
            _ => Err(format!("unknown split {s:?}: expected train, val, test or all")),
        }
    }
}

/// Sols of the frames with PDS camera models used for validation (MSL Navcam sols 38 and 100).
pub const VAL_SOLS: [i64; 2] = [38, 100];
/// Sols of the frames with PDS camera models used for testing (MSL Navcam 53, 344, 372, 688,
/// 729, 3192, 3423; MER-1 Navcam 5086, Pancam 5105, Hazcam 5104).
pub const TEST_SOLS: [i64; 10] = [53, 344, 372, 688, 729, 3192, 3423, 5086, 5104, 5105];

/// The split of a frame from its sol: within one sol of a validation or test sol of the
/// camera-model frames it goes there (whatever the camera: another camera may see the same
/// scene); otherwise sols with `(sol / 10) % 5 == 0` are test, `== 1` validation, the rest
/// training (the colour frames, which have no camera models). Frames of unknown sol train.
pub fn split_of_sol(sol: Option<i64>) -> RealSplit {
    let Some(s) = sol else { return RealSplit::Train };
    if VAL_SOLS.iter().any(|v| (v - s).abs() <= 1) {
        return RealSplit::Val;
    }
    if TEST_SOLS.iter().any(|v| (v - s).abs() <= 1) {
        return RealSplit::Test;
    }
    match (s / 10) % 5 {
        0 => RealSplit::Test,
        1 => RealSplit::Val,
        _ => RealSplit::Train,
    }
}

/// One row of the real data's `MANIFEST.tsv`: a file (relative to the data folder), its folder
/// kind (`backgrounds`, `negatives_val`, ...), group and sol.
#[derive(Clone, Debug)]
pub struct ManifestEntry {
    /// Path relative to the data folder.
    pub file: PathBuf,
    /// Top-level folder (`backgrounds`, `negatives_val`, `with_cameras`).
    pub split: String,
    /// Group (e.g. `msl_navcam_1024`, `msl_mastcam_marsdata`).
    pub group: String,
    /// Sol, when known.
    pub sol: Option<i64>,
    /// How the file was made from its source (`conversion` column; empty without one).
    pub conversion: String,
}

/// The pixel encoding a `MANIFEST.tsv` `conversion` names: a linear stretch of data values
/// (`... linear stretch DN LO..HI ...`, as the PDS products converted to PNG say) is
/// [`PhotoEncoding::linear_stretch`]; anything else is sRGB.
pub fn encoding_of_conversion(conversion: &str) -> PhotoEncoding {
    let stretch = conversion.split_once("linear stretch DN ").and_then(|(_, rest)| {
        let range = rest.split_whitespace().next()?;
        let (lo, hi) = range.split_once("..")?;
        PhotoEncoding::linear_stretch(lo.parse().ok()?, hi.trim_end_matches([',', ';', ')']).parse().ok()?)
    });
    stretch.unwrap_or_default()
}

/// Reads `MANIFEST.tsv` (tab-separated with a header naming `file`, `split`, `group`, `sol`).
pub fn read_manifest(path: &Path) -> Result<Vec<ManifestEntry>, SynthError> {
    let err = |message: String| SynthError::Data { path: path.to_path_buf(), message };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().ok_or_else(|| err("empty file".into()))?.split('\t').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).ok_or_else(|| err(format!("no `{name}` column")));
    let (cf, cs, cg, csol) = (col("file")?, col("split")?, col("group")?, col("sol")?);
    let cconv = header.iter().position(|h| *h == "conversion");
    let mut out = Vec::new();
    for (i, line) in lines.enumerate() {
        let f: Vec<&str> = line.split('\t').collect();
        if f.len() <= cf.max(cs).max(cg).max(csol) {
            return Err(err(format!("line {}: {} columns, expected {}", i + 2, f.len(), header.len())));
        }
        let conversion = cconv.and_then(|c| f.get(c)).map_or(String::new(), |c| c.to_string());
        out.push(ManifestEntry { file: PathBuf::from(f[cf]), split: f[cs].to_string(), group: f[cg].to_string(), sol: f[csol].trim().parse().ok(), conversion });
    }
    Ok(out)
}

/// The width, height and kind (`true`: colour) of the photo at `path`: a file of one or two
/// channels is grey by its header; one of three or four is decoded and is grey where every
/// pixel's channels are equal ([`tubeloc_core::monochrome::is_grey_rgb8`]).
fn photo_kind(path: &Path) -> Result<(u32, u32, bool), image::ImageError> {
    use image::ImageDecoder;
    let decoder = image::ImageReader::open(path)?.with_guessed_format()?.into_decoder()?;
    let (w, h) = decoder.dimensions();
    if decoder.color_type().channel_count() <= 2 {
        return Ok((w, h, false));
    }
    let img = image::DynamicImage::from_decoder(decoder)?;
    Ok((w, h, !tubeloc_core::monochrome::is_grey_rgb8(img.to_rgb8().as_raw())))
}

/// The geometry of the grey frames of a validation or test part.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GreyView {
    /// The frames with PDS camera models, each under its own camera and ground.
    #[default]
    Pds,
    /// The grey backgrounds of the part (Navcam frames, without their camera models) under
    /// [`AssumedView::NAVCAM`], as a frame with no camera model is judged
    /// ([`drop_sky_under_assumed_views`] leaves out those whose own camera model sees sky
    /// where that view puts tubes; `tubeloc synth real` applies it).
    Assumed,
    /// Both.
    Both,
}

/// Which frames of the real data a composite set is made on ([`split_views`]).
#[derive(Clone, Debug)]
pub struct FrameChoice {
    /// The part of the data, by sol.
    pub split: RealSplit,
    /// The grey frames and their geometry; `None`: no grey frame.
    pub grey: Option<GreyView>,
    /// Whether the colour frames are taken.
    pub colour: bool,
    /// Validation, test and all: frames whose smaller side is below this many pixels are left
    /// out.
    pub min_size: u32,
    /// Training: the range the views' horizontal fields of view are drawn from, degrees
    /// ([`random_view`]; checked by [`check_hfov_range`] whatever the part).
    pub training_hfov_deg: (f64, f64),
    /// The farthest distance of a tube from the camera, metres: a grey frame is left out of the
    /// assumed Navcam view where its own camera model sees no ground within it
    /// ([`drop_sky_under_assumed_views`]).
    pub far_m: f64,
    /// Seed of the training views and of the assumed views' suns.
    pub seed: u64,
}

/// The frames [`split_views`] chose, with their views, and the grey frames it left out of the
/// assumed Navcam view because their own camera models see sky where it puts tubes.
#[derive(Clone, Debug)]
pub struct ChosenFrames {
    /// The frames, PDS-geometry ones first, then the backgrounds in `MANIFEST.tsv`'s order.
    pub views: Vec<RealView>,
    /// File names of the grey frames left out of the assumed Navcam view.
    pub sky_dropped: Vec<String>,
}

/// The frames of `choice.split` in the real data folder `data` (holding `MANIFEST.tsv`,
/// `backgrounds/` and `with_cameras/`), with their views. Validation, test and all: the grey
/// frames (`choice.grey`: with PDS camera models, and / or the grey backgrounds under
/// [`AssumedView::NAVCAM`], those whose own camera model sees sky where that view puts tubes
/// within `choice.far_m` left out, record 0088) and the colour backgrounds (colour by their
/// pixels, whatever their group: Mastcam frames in the shared data) under the view
/// `--assumed-view auto` takes for them ([`AssumedView::of_frame`]: an M-100 frame under
/// `m100`, an M-34 frame or a panorama tile without a product name under
/// [`AssumedView::MAST`]), frames whose smaller side is below `choice.min_size` left out.
/// Training: every background of the split under a random assumed view drawn with
/// `choice.seed`, its field of view from `choice.training_hfov_deg` ([`random_view`]; the
/// Navcam backgrounds that are also camera-model frames fall in validation or test by their
/// sol). `with_cameras/cameras.json` is read once, where PDS frames are asked for (it must
/// exist then) or the sky check can use it.
pub fn split_views(data: &Path, choice: &FrameChoice) -> Result<ChosenFrames, SynthError> {
    let &FrameChoice { split, grey, colour, min_size, training_hfov_deg: hfov_deg, far_m, seed } = choice;
    check_hfov_range(hfov_deg).map_err(|m| SynthError::Invalid(format!("training field of view {hfov_deg:?} degrees: {m}")))?;
    let manifest = read_manifest(&data.join("MANIFEST.tsv"))?;
    let mut out = Vec::new();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let assumed_grey = matches!(grey, Some(GreyView::Assumed | GreyView::Both));
    let pds_grey = split != RealSplit::Train && matches!(grey, Some(GreyView::Pds | GreyView::Both));
    let cameras = data.join("with_cameras").join("cameras.json");
    let own = if pds_grey || (assumed_grey && cameras.exists()) { views_from_cameras_json(&cameras)? } else { Vec::new() };
    // Each PDS frame's pixel encoding from its row of the manifest, when it has one.
    let encodings: std::collections::HashMap<PathBuf, PhotoEncoding> = manifest.iter().map(|e| (data.join(&e.file), encoding_of_conversion(&e.conversion))).collect();
    if pds_grey {
        for v in &own {
            if split.holds(v.sol) && v.camera.width.min(v.camera.height) >= min_size {
                let encoding = encodings.get(&v.image).copied().unwrap_or_default();
                out.push(RealView { encoding, ..v.clone() });
            }
        }
    }
    for e in &manifest {
        if e.split != "backgrounds" || !split.holds(e.sol) {
            continue;
        }
        let path = data.join(&e.file);
        let unreadable = |er: image::ImageError| SynthError::Image { path: path.clone(), message: format!("listed in {} but not readable as an image: {er}", data.join("MANIFEST.tsv").display()) };
        // Colour or grey by the pixels, not by the group's name: a grey frame is saved with one
        // channel or with three equal ones (`monochrome::is_grey_rgb8`, what the detectors take
        // for grey).
        let (w, h, is_colour) = photo_kind(&path).map_err(unreadable)?;
        // Colour backgrounds when asked for; grey ones for training, or under the assumed
        // Navcam view, when asked for.
        let wanted = if is_colour { colour } else { grey.is_some() && (split == RealSplit::Train || assumed_grey) };
        if !wanted {
            continue;
        }
        if w.min(h) < min_size && split != RealSplit::Train {
            continue;
        }
        let view = match (split, is_colour) {
            (RealSplit::Train, _) => random_view(&mut rng, hfov_deg),
            // The view `--assumed-view auto` judges the frame under: its mast camera's by the
            // product name (M-100 frames `m100`), else the colour `mast` view.
            (_, true) => AssumedView::of_frame(&e.file.to_string_lossy(), || false).view,
            (_, false) => AssumedView::NAVCAM,
        };
        let encoding = encoding_of_conversion(&e.conversion);
        out.push(RealView { encoding, ..assumed_real_view(&view, path, w, h, e.sol, &mut rng) });
    }
    let sky_dropped = if assumed_grey { drop_sky_under_assumed_views(&mut out, &own, far_m) } else { Vec::new() };
    Ok(ChosenFrames { views: out, sky_dropped })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frames of `split` as `tubeloc synth real` chooses them, tubes up to 20 m.
    fn choose(split: RealSplit, grey: Option<GreyView>, colour: bool, min_size: u32, training_hfov_deg: (f64, f64), seed: u64) -> FrameChoice {
        FrameChoice { split, grey, colour, min_size, training_hfov_deg, far_m: 20.0, seed }
    }

    /// A frame of its own camera 10 degrees up (the Navcam frames of sol 60) sees sky where the
    /// Navcam view 30 degrees down puts tubes; 16.6 degrees down (sol 38) sees ground there up
    /// to 5 m, not up to 20 m; a frame looking down as far as the view is kept, as is one
    /// without a model of its own.
    #[test]
    fn frames_whose_own_camera_sees_sky_are_left_out_of_the_assumed_view() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut view = |pitch_deg: f64, name: &str| assumed_real_view(&AssumedView { pitch_deg, ..AssumedView::NAVCAM }, PathBuf::from(name), 1024, 1024, None, &mut rng);
        let assumed = view(30.0, "a.png");
        assert!(!ground_where_assumed(&view(-10.0, "a.png"), &assumed, 5.0));
        assert!(ground_where_assumed(&view(16.6, "a.png"), &assumed, 5.0));
        assert!(!ground_where_assumed(&view(16.6, "a.png"), &assumed, 20.0));
        assert!(ground_where_assumed(&view(30.0, "a.png"), &assumed, 20.0));
        let mut own = vec![view(-10.0, "up.png"), view(16.6, "down.png")];
        for o in &mut own {
            o.geometry = "pds";
        }
        let mut views = vec![view(30.0, "up.png"), view(30.0, "down.png"), view(30.0, "no_model.png"), own[0].clone()];
        assert_eq!(drop_sky_under_assumed_views(&mut views, &own, 5.0), vec!["up.png".to_string()]);
        let kept: Vec<_> = views.iter().map(|v| (v.image.to_string_lossy().into_owned(), v.geometry)).collect();
        assert_eq!(kept, [("down.png".to_string(), "assumed"), ("no_model.png".to_string(), "assumed"), ("up.png".to_string(), "pds")]);
    }

    /// A camera list entry whose rotation is no rotation, or whose sun direction is no
    /// direction, is refused naming the entry; a good entry is read.
    #[test]
    fn camera_list_entries_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cameras.json");
        let entry = |r: &str, sun: &str| format!(r#"{{"image": "a.png", "image_width": 1024, "image_height": 1024, "fx": 1200, "fy": 1200, "cx": 512, "cy": 512, "camera_height_m": 1.9, "sol": 40, "R_cam_from_site": {r}{sun}}}"#);
        let good = "[[1, 0, 0], [0, 0, -1], [0, 1, 0]]";
        let read = |text: String| {
            std::fs::write(&path, text).unwrap();
            views_from_cameras_json(&path)
        };
        let views = read(format!("[{}]", entry(good, r#", "sun_direction_camera": [0, -2, 0]"#))).unwrap();
        assert_eq!(views.len(), 1);
        assert!((views[0].sun_cam.unwrap() - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        assert!(read(format!("[{}]", entry(good, ""))).unwrap()[0].sun_cam.is_none());
        // Only in the site frame (MER labels): turned into the camera frame, R_cam_from_site ·
        // s, here (0.6, 0, -0.8) -> (0.6, 0.8, 0): the site's up (-z) is +y in this camera, the sun
        // 53 degrees above the ground.
        let site_only = read(format!("[{}]", entry(good, r#", "sun_direction_site": [0.6, 0, -0.8]"#))).unwrap();
        assert!((site_only[0].sun_cam.unwrap() - Vector3::new(0.6, 0.8, 0.0)).norm() < 1e-12, "{:?}", site_only[0].sun_cam);
        // The camera frame's own, where given, wins.
        let both = read(format!("[{}]", entry(good, r#", "sun_direction_site": [0.6, 0, -0.8], "sun_direction_camera": [0, -1, 0]"#))).unwrap();
        assert!((both[0].sun_cam.unwrap() - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        for (r, sun, says) in [
            ("[[0, 0, 0], [0, 0, 0], [0, 0, 0]]", "", "not a rotation"),
            ("[[1, 0, 0], [0, 1, 0], [0, 0, -1]]", "", "not a rotation"),
            (good, r#", "sun_direction_camera": [0, 0, 0]"#, "not a non-zero 3-vector"),
            (good, r#", "sun_direction_site": [0, 0]"#, "`sun_direction_site` is not a non-zero 3-vector"),
        ] {
            let e = read(format!("[{}, {}]", entry(good, ""), entry(r, sun))).unwrap_err().to_string();
            assert!(e.contains("cameras.json: entry 1:") && e.contains(says), "{e}");
        }
    }

    /// A colour photo of `w` x `h` px at `path`: Mars-coloured ground, (150, 90, 60) everywhere.
    fn save_colour_photo(path: &Path, w: u32, h: u32) {
        image::RgbImage::from_pixel(w, h, image::Rgb([150, 90, 60])).save(path).unwrap();
    }

    /// A manifest's conversion that names a linear stretch of data values gives a linear
    /// encoding, black at -255 lo / (hi - lo); any other conversion, or none, sRGB.
    #[test]
    fn a_linear_stretch_in_the_manifest_is_the_frames_encoding() {
        let pds = ">i2 1024x1024 PDS IMAGE (12-bit data in 16-bit words) -> 8-bit PNG, linear stretch DN 562.0..1959.0 (0.5/99.5 percentiles of DN>=1)";
        assert_eq!(encoding_of_conversion(pds), PhotoEncoding::linear_stretch(562.0, 1959.0).unwrap());
        for other in ["none (original bytes)", "", "linear stretch DN 10..5", "linear stretch DN x..y"] {
            assert_eq!(encoding_of_conversion(other), PhotoEncoding::Srgb, "{other}");
        }
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("backgrounds/pds")).unwrap();
        image::GrayImage::from_pixel(400, 320, image::Luma([90])).save(dir.path().join("backgrounds/pds/a.png")).unwrap();
        image::GrayImage::from_pixel(400, 320, image::Luma([90])).save(dir.path().join("backgrounds/pds/b.png")).unwrap();
        let manifest = format!("file\tsplit\tgroup\tsol\tconversion\nbackgrounds/pds/a.png\tbackgrounds\tpds\t500\t{pds}\nbackgrounds/pds/b.png\tbackgrounds\tpds\t500\tnone\n");
        std::fs::write(dir.path().join("MANIFEST.tsv"), manifest).unwrap();
        let views = split_views(dir.path(), &choose(RealSplit::Test, Some(GreyView::Assumed), false, 0, TRAINING_HFOV_DEG, 0)).unwrap().views;
        let enc: Vec<PhotoEncoding> = views.iter().map(|v| v.encoding).collect();
        assert_eq!(enc, [PhotoEncoding::linear_stretch(562.0, 1959.0).unwrap(), PhotoEncoding::Srgb]);
    }

    /// A background is colour or grey by its pixels, whatever its group is called: a grey frame
    /// saved in three equal channels (or one) in a `mastcam` group joins the grey frames under
    /// the assumed Navcam view, and a colour frame in a `navcam` group the colour ones under the
    /// view of its product name.
    #[test]
    fn a_background_is_colour_or_grey_by_its_pixels_not_its_group_name() {
        let dir = tempfile::tempdir().unwrap();
        for g in ["backgrounds/msl_mastcam_x", "backgrounds/m2020_navcam"] {
            std::fs::create_dir_all(dir.path().join(g)).unwrap();
        }
        image::RgbImage::from_pixel(400, 320, image::Rgb([90, 90, 90])).save(dir.path().join("backgrounds/msl_mastcam_x/grey3.png")).unwrap();
        image::GrayImage::from_pixel(400, 320, image::Luma([90])).save(dir.path().join("backgrounds/msl_mastcam_x/grey1.png")).unwrap();
        save_colour_photo(&dir.path().join("backgrounds/m2020_navcam/colour.png"), 400, 320);
        let manifest =
            "file\tsplit\tgroup\tsol\nbackgrounds/msl_mastcam_x/grey3.png\tbackgrounds\tmsl_mastcam_x\t500\nbackgrounds/msl_mastcam_x/grey1.png\tbackgrounds\tmsl_mastcam_x\t500\nbackgrounds/m2020_navcam/colour.png\tbackgrounds\tm2020_navcam\t500\n";
        std::fs::write(dir.path().join("MANIFEST.tsv"), manifest).unwrap();
        let names =
            |grey, colour| split_views(dir.path(), &choose(RealSplit::Test, grey, colour, 0, TRAINING_HFOV_DEG, 0)).unwrap().views.into_iter().map(|v| (v.image.file_name().unwrap().to_string_lossy().to_string(), v.camera.fx)).collect::<Vec<_>>();
        let navcam_fx = AssumedView::NAVCAM.camera(400, 320).fx;
        assert_eq!(names(Some(GreyView::Assumed), false), vec![("grey3.png".to_string(), navcam_fx), ("grey1.png".to_string(), navcam_fx)]);
        assert_eq!(names(None, true), vec![("colour.png".to_string(), AssumedView::MAST.camera(400, 320).fx)]);
    }

    /// `all` takes the frames of every sol, under the views validation and test frames get
    /// (a training sol's colour frame under the `mast` view, not a random one).
    #[test]
    fn the_all_part_takes_every_sol_under_the_judged_views() {
        let dir = tempfile::tempdir().unwrap();
        let folder = dir.path().join("backgrounds/msl_mastcam_marsdata");
        std::fs::create_dir_all(&folder).unwrap();
        for name in ["test.png", "train.png", "nosol.png"] {
            save_colour_photo(&folder.join(name), 400, 320);
        }
        let manifest = "file\tsplit\tgroup\tsol\nbackgrounds/msl_mastcam_marsdata/test.png\tbackgrounds\tmsl_mastcam_marsdata\t500\nbackgrounds/msl_mastcam_marsdata/train.png\tbackgrounds\tmsl_mastcam_marsdata\t520\nbackgrounds/msl_mastcam_marsdata/nosol.png\tbackgrounds\tmsl_mastcam_marsdata\t\n";
        std::fs::write(dir.path().join("MANIFEST.tsv"), manifest).unwrap();
        let names = |split| split_views(dir.path(), &choose(split, None, true, 300, TRAINING_HFOV_DEG, 0)).unwrap().views.into_iter().map(|v| (v.image.file_name().unwrap().to_string_lossy().to_string(), v.camera.fx)).collect::<Vec<_>>();
        let mast_fx = AssumedView::MAST.camera(400, 320).fx;
        assert_eq!(names(RealSplit::Test), vec![("test.png".to_string(), mast_fx)]);
        assert_eq!(names(RealSplit::Val), vec![]);
        assert_eq!(names(RealSplit::Train).len(), 2);
        assert_eq!(names(RealSplit::All), vec![("test.png".to_string(), mast_fx), ("train.png".to_string(), mast_fx), ("nosol.png".to_string(), mast_fx)]);
        assert!(RealSplit::All.holds(None) && RealSplit::All.holds(Some(38)) && !RealSplit::Test.holds(Some(38)));
        for split in [RealSplit::Train, RealSplit::Val, RealSplit::Test, RealSplit::All] {
            assert_eq!(split.to_string().parse::<RealSplit>(), Ok(split));
        }
        assert!("every".parse::<RealSplit>().unwrap_err().contains("train, val, test or all"));
    }

    /// A background the manifest lists but the folder lacks is named, with the manifest, in the
    /// error; one of another split is not opened at all.
    #[test]
    fn a_listed_background_that_is_missing_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let manifest = "file\tsplit\tgroup\tsol\nbackgrounds/msl_mastcam_marsdata/gone.jpg\tbackgrounds\tmsl_mastcam_marsdata\t500\nbackgrounds/msl_mastcam_marsdata/other.jpg\tbackgrounds\tmsl_mastcam_marsdata\t520\n";
        std::fs::write(dir.path().join("MANIFEST.tsv"), manifest).unwrap();
        assert_eq!((split_of_sol(Some(500)), split_of_sol(Some(520))), (RealSplit::Test, RealSplit::Train));
        let e = split_views(dir.path(), &choose(RealSplit::Test, None, true, 0, TRAINING_HFOV_DEG, 0)).unwrap_err().to_string();
        assert!(e.contains("gone.jpg: listed in") && e.contains("MANIFEST.tsv but not readable as an image"), "{e}");
        assert!(!e.contains("invalid synth parameter"), "{e}");
        assert!(split_views(dir.path(), &choose(RealSplit::Val, None, true, 0, TRAINING_HFOV_DEG, 0)).unwrap().views.is_empty());
    }

    /// Colour frames of a validation or test part are composited under the view `locate
    /// --assumed-view auto` judges them under: an M-100 frame (`SSSSMR...`) under `m100`, an
    /// M-34 frame and a panorama tile without a product name under `mast`, each camera at the
    /// frame's own size.
    #[test]
    fn colour_frames_take_the_view_of_their_product_name() {
        let dir = tempfile::tempdir().unwrap();
        let group = dir.path().join("backgrounds/msl_mastcam_marsdata");
        std::fs::create_dir_all(&group).unwrap();
        let names = ["0500MR0001230000100001E01.jpg", "0500ML0001230000100001E01.jpg", "marsscapes_500_1_t0.png"];
        let mut manifest = String::from("file\tsplit\tgroup\tsol\n");
        for n in names {
            save_colour_photo(&group.join(n), 560, 500);
            manifest += &format!("backgrounds/msl_mastcam_marsdata/{n}\tbackgrounds\tmsl_mastcam_marsdata\t500\n");
        }
        std::fs::write(dir.path().join("MANIFEST.tsv"), manifest).unwrap();
        let views = split_views(dir.path(), &choose(RealSplit::Test, None, true, 0, TRAINING_HFOV_DEG, 0)).unwrap().views;
        let fx: Vec<f64> = views.iter().map(|v| v.camera.fx).collect();
        let want = [AssumedView::M100.camera(560, 500).fx, AssumedView::MAST.camera(560, 500).fx, AssumedView::MAST.camera(560, 500).fx];
        assert_eq!(fx, want);
        // 6.8 against 20 degrees across 560 px: the M-100's focal length about 2.97 times the mast view's.
        assert!((fx[0] / fx[1] - (10f64.to_radians().tan() / 3.4f64.to_radians().tan())).abs() < 1e-9, "{fx:?}");
    }

    /// Training views take their field of view from the range given (one value gives exactly
    /// it); a range outside (0, 180) degrees or upside down is refused, naming it.
    #[test]
    fn training_views_draw_their_field_of_view_from_the_range_given() {
        let dir = tempfile::tempdir().unwrap();
        let group = dir.path().join("backgrounds/msl_mastcam_marsdata");
        std::fs::create_dir_all(&group).unwrap();
        let mut manifest = String::from("file\tsplit\tgroup\tsol\n");
        for k in 0..20 {
            save_colour_photo(&group.join(format!("f{k}.png")), 400, 300);
            manifest += &format!("backgrounds/msl_mastcam_marsdata/f{k}.png\tbackgrounds\tmsl_mastcam_marsdata\t{}\n", 520 + k % 5);
        }
        std::fs::write(dir.path().join("MANIFEST.tsv"), manifest).unwrap();
        let hfov = |v: &RealView| 2.0 * (200.0 / v.camera.fx).atan().to_degrees();
        let exact = split_views(dir.path(), &choose(RealSplit::Train, None, true, 0, (6.8, 6.8), 3)).unwrap().views;
        assert_eq!(exact.len(), 20);
        assert!(exact.iter().all(|v| (hfov(v) - 6.8).abs() < 1e-9));
        let drawn: Vec<f64> = split_views(dir.path(), &choose(RealSplit::Train, None, true, 0, (5.0, 15.0), 3)).unwrap().views.iter().map(hfov).collect();
        assert!(drawn.iter().all(|h| (5.0..15.0).contains(h)), "{drawn:?}");
        assert!(drawn.iter().any(|h| *h < 10.0) && drawn.iter().any(|h| *h >= 10.0), "{drawn:?}");
        for bad in [(0.0, 10.0), (20.0, 10.0), (10.0, 180.0)] {
            let e = split_views(dir.path(), &choose(RealSplit::Train, None, true, 0, bad, 3)).unwrap_err().to_string();
            assert!(e.contains("training field of view") && e.contains("0 < LO <= HI < 180"), "{e}");
        }
    }

    #[test]
    fn assumed_view_up_is_unit_and_pitched() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let v = assumed_real_view(&AssumedView::MAST, PathBuf::from("x.png"), 500, 400, None, &mut rng);
        assert!((v.up_cam.norm() - 1.0).abs() < 1e-12);
        // Looking 30 degrees down: the optical axis makes 30 degrees with the ground.
        assert!((v.up_cam.z + 30f64.to_radians().sin()).abs() < 1e-12, "{:?}", v.up_cam);
        let s = v.sun_cam.unwrap();
        assert!(s.dot(&v.up_cam) > 20f64.to_radians().sin() - 1e-9);
    }
}
