//! Views assumed for frames that come without a camera model: a level-ground pinhole geometry
//! (field of view, height, downward look, roll) from which each frame's camera and ground follow
//! at the frame's own size.
//!
//! Camera frame as everywhere: x right, y down, z ahead. A camera pitched down by `p` and
//! rolled by `r` about z sees the ground's up direction as `R_z(r) (0, -cos p, -sin p)`, and
//! the ground plane `n · X = d` with `n` that direction and `d = -height`.

use crate::{CameraModel, CoreError, GroundPlane, Pose, Rig, RigCamera, RoverCamera};
use nalgebra::Vector3;

/// An assumed camera for a frame without a camera model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AssumedView {
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Camera height above the ground, metres.
    pub height_m: f64,
    /// Angle of the optical axis below the horizon, degrees.
    pub pitch_deg: f64,
    /// Roll about the optical axis, degrees.
    pub roll_deg: f64,
}

/// The view a frame is judged under: its name as a frame document gives it (`navcam`, `m100`,
/// `mastcam-z-110`, or the numbers as given), its geometry, and the camera the frame's product
/// name names where no mast view fits it (the view is then its kind's).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameView {
    /// The view's name.
    pub name: String,
    /// The view.
    pub view: AssumedView,
    /// The camera the product name names that no mast view fits (a Hazcam, an arm camera).
    pub unfit: Option<RoverCamera>,
}

impl AssumedView {
    /// A mast science camera (the colour test frames' documented view): 1.9 m above the
    /// ground, looking 30 degrees down, with a 20 degree field of view (the ground at the image
    /// centre is 3.8 m away).
    pub const MAST: AssumedView = AssumedView { hfov_deg: 20.0, height_m: 1.9, pitch_deg: 30.0, roll_deg: 0.0 };

    /// A mast navigation camera (how grey Navcam-like frames without a model are judged): 1.9
    /// m above the ground, looking 30 degrees down, with a 45 degree field of view.
    pub const NAVCAM: AssumedView = AssumedView { hfov_deg: 45.0, height_m: 1.9, pitch_deg: 30.0, roll_deg: 0.0 };

    /// Curiosity's Mastcam right, M-100 (100 mm): 6.8 degrees wide, 1.9 m above the ground,
    /// looking 30 degrees down.
    pub const M100: AssumedView = AssumedView { hfov_deg: 6.8, height_m: 1.9, pitch_deg: 30.0, roll_deg: 0.0 };

    /// Perseverance's Navcam: 96 degrees wide, on the mast about 2 m above the ground, looking
    /// 30 degrees down.
    pub const M2020_NAVCAM: AssumedView = AssumedView { hfov_deg: 96.0, height_m: 2.0, pitch_deg: 30.0, roll_deg: 0.0 };

    /// Spirit's and Opportunity's Navcam: 45 degrees wide, about 1.5 m above the ground,
    /// looking 30 degrees down.
    pub const MER_NAVCAM: AssumedView = AssumedView { hfov_deg: 45.0, height_m: 1.5, pitch_deg: 30.0, roll_deg: 0.0 };

    /// Spirit's and Opportunity's Pancam: 16 degrees wide, about 1.5 m above the ground,
    /// looking 30 degrees down.
    pub const MER_PANCAM: AssumedView = AssumedView { hfov_deg: 16.0, height_m: 1.5, pitch_deg: 30.0, roll_deg: 0.0 };

    /// The named views, as the command line and Python name them (besides `mastcam-z-F`,
    /// [`AssumedView::mastcam_z`]).
    pub const NAMED: [(&'static str, AssumedView); 6] =
        [("navcam", AssumedView::NAVCAM), ("mast", AssumedView::MAST), ("m100", AssumedView::M100), ("m2020-navcam", AssumedView::M2020_NAVCAM), ("mer-navcam", AssumedView::MER_NAVCAM), ("mer-pancam", AssumedView::MER_PANCAM)];

    /// The shortest and longest zoom focal lengths of Perseverance's Mastcam-Z, mm.
    pub const MASTCAM_Z_FOCAL_MM: (f64, f64) = (26.0, 110.0);

    /// Perseverance's Mastcam-Z at zoom focal length `focal_mm` (26 to 110 mm): the field of
    /// view scales from 25.6 degrees at 26 mm as `2 atan(tan(12.8°) · 26 / f)` (6.15 degrees
    /// at 110 mm); on the mast about 2 m above the ground, looking 30 degrees down.
    pub fn mastcam_z(focal_mm: f64) -> AssumedView {
        let half = (12.8f64.to_radians().tan() * Self::MASTCAM_Z_FOCAL_MM.0 / focal_mm).atan();
        AssumedView { hfov_deg: 2.0 * half.to_degrees(), height_m: 2.0, pitch_deg: 30.0, roll_deg: 0.0 }
    }

    /// The named view a frame without a camera model is judged under by its kind (how `tubeloc
    /// synth real` composites colour frames, and what `--assumed-view auto` takes for a frame
    /// without a product name): [`AssumedView::NAVCAM`] for a grey frame, [`AssumedView::MAST`]
    /// for a colour one; with its name.
    pub fn of_kind(grey: bool) -> (&'static str, AssumedView) {
        if grey {
            ("navcam", AssumedView::NAVCAM)
        } else {
            ("mast", AssumedView::MAST)
        }
    }

    /// The view `--assumed-view auto` takes for the frame in the file `file_name`, grey or
    /// not: the view of the mast camera its product name names ([`RoverCamera::of_product`],
    /// [`RoverCamera::view`]), otherwise the named view of its kind
    /// ([`AssumedView::of_kind`]), with the camera the name names where it is one no mast view
    /// fits (a Hazcam, an arm camera: a caller should say so). `grey` is asked only when the
    /// name names no such mast camera.
    pub fn of_frame(file_name: &str, grey: impl FnOnce() -> bool) -> FrameView {
        let camera = RoverCamera::of_product(file_name);
        match camera.and_then(|c| c.view().map(|v| (c.name(), v))) {
            Some((name, view)) => FrameView { name, view, unfit: None },
            None => {
                let (name, view) = Self::of_kind(grey());
                FrameView { name: name.to_string(), view, unfit: camera }
            }
        }
    }

    /// The view called `name` (one of [`AssumedView::NAMED`], or `mastcam-z-F` with `F` the
    /// zoom focal length in mm, 26 to 110); the error lists the names.
    pub fn by_name(name: &str) -> Result<AssumedView, CoreError> {
        if let Some(f) = name.strip_prefix("mastcam-z-") {
            let (lo, hi) = Self::MASTCAM_Z_FOCAL_MM;
            return match f.parse::<f64>() {
                Ok(f) if (lo..=hi).contains(&f) => Ok(Self::mastcam_z(f)),
                _ => Err(CoreError::invalid("assumed view", format!("{name:?}: the Mastcam-Z focal length must be a number of mm from {lo} to {hi}"))),
            };
        }
        Self::NAMED.iter().find(|(n, _)| *n == name).map(|(_, v)| *v).ok_or_else(|| CoreError::invalid("assumed view", format!("unknown view {name:?}: expected one of {}", Self::names())))
    }

    /// The names [`AssumedView::by_name`] takes, for messages: `navcam, mast, ..., mastcam-z-F`.
    pub fn names() -> String {
        Self::NAMED.iter().map(|(n, _)| *n).chain(["mastcam-z-F"]).collect::<Vec<_>>().join(", ")
    }

    /// The view `spec` names: a named view ([`AssumedView::by_name`]), or one given as
    /// `HFOV_DEG,HEIGHT_M,PITCH_DEG` (horizontal field of view in degrees, in (1, 170); camera
    /// height above level ground in metres, in (0, 100]; angle of the optical axis below the
    /// horizon in degrees, in (0, 90]: the image centre sees the ground), e.g. `90,2,25` for a
    /// wide mast camera. The error names the part at fault and the forms taken.
    pub fn parse(spec: &str) -> Result<AssumedView, CoreError> {
        let spec = spec.trim();
        if !spec.contains(',') {
            return Self::by_name(spec).map_err(|e| match spec.starts_with("mastcam-z-") {
                true => e,
                false => CoreError::invalid("assumed view", format!("unknown view {spec:?}: expected one of {}, or HFOV_DEG,HEIGHT_M,PITCH_DEG (e.g. 90,2,25)", Self::names())),
            });
        }
        let parts: Vec<&str> = spec.split(',').map(str::trim).collect();
        let bad = |m: String| CoreError::invalid("assumed view", format!("{spec:?}: {m}"));
        let [hfov, height, pitch] = parts[..] else {
            return Err(bad(format!("{} numbers, expected three: HFOV_DEG,HEIGHT_M,PITCH_DEG", parts.len())));
        };
        let number = |t: &str, what: &str, ok: &dyn Fn(f64) -> bool, range: &str| -> Result<f64, CoreError> {
            let v: f64 = t.parse().map_err(|_| bad(format!("{what} {t:?} is not a number")))?;
            if !(v.is_finite() && ok(v)) {
                return Err(bad(format!("{what} {v} is outside {range}")));
            }
            Ok(v)
        };
        Ok(AssumedView {
            hfov_deg: number(hfov, "the field of view", &|v| v > 1.0 && v < 170.0, "(1, 170) degrees")?,
            height_m: number(height, "the camera height", &|v| v > 0.0 && v <= 100.0, "(0, 100] metres")?,
            pitch_deg: number(pitch, "the downward look", &|v| v > 0.0 && v <= 90.0, "(0, 90] degrees below the horizon (the image centre must see the ground)")?,
            roll_deg: 0.0,
        })
    }

    /// The camera of an image of `width x height` pixels under this view: a pinhole with the
    /// view's horizontal field of view, its principal point at the image centre.
    pub fn camera(&self, width: u32, height: u32) -> CameraModel {
        CameraModel::from_hfov(width, height, self.hfov_deg)
    }

    /// Unit up direction of the level ground in the camera frame: `(0, -cos p, -sin p)` for a
    /// camera pitched down by `p`, turned about z by the roll.
    pub fn up_cam(&self) -> Vector3<f64> {
        let (p, r) = (self.pitch_deg.to_radians(), self.roll_deg.to_radians());
        let up = Vector3::new(0.0, -p.cos(), -p.sin());
        Vector3::new(r.cos() * up.x - r.sin() * up.y, r.sin() * up.x + r.cos() * up.y, up.z)
    }

    /// The ground under the camera in its frame, as `(n, d)` with `n · X = d` and `n` up:
    /// `(up, -height)`.
    pub fn ground(&self) -> (Vector3<f64>, f64) {
        (self.up_cam(), -self.height_m)
    }

    /// [`AssumedView::ground`] as a [`GroundPlane`].
    pub fn ground_plane(&self) -> Result<GroundPlane, CoreError> {
        let (n, d) = self.ground();
        GroundPlane::new(n, d)
    }

    /// A one-camera rig for an image of `width x height` pixels under this view (the camera
    /// named `name`, at the rig's origin) and the ground in its frame; refused as an invalid
    /// rig for an empty image.
    pub fn rig(&self, name: &str, width: u32, height: u32) -> Result<(Rig, GroundPlane), CoreError> {
        let camera = RigCamera { name: name.to_string(), model: self.camera(width, height), t_rig_cam: Pose::identity() };
        let rig = Rig { cameras: vec![camera], stereo_pairs: Vec::new() };
        rig.validate()?;
        Ok((rig, self.ground_plane()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ground_lies_below_the_camera_along_the_view() {
        let v = AssumedView::NAVCAM;
        let (rig, ground) = v.rig("f.jpg", 1024, 768).unwrap();
        let m = &rig.cameras[0].model;
        assert_eq!((m.width, m.height), (1024, 768));
        assert!((m.fx - 512.0 / 22.5f64.to_radians().tan()).abs() < 1e-9);
        // The optical axis meets the ground at height / sin(pitch) ahead.
        let z = ground.offset / ground.normal.z;
        assert!((z - 1.9 / 30f64.to_radians().sin()).abs() < 1e-9, "{z}");
        // The camera centre is 1.9 m above the ground.
        assert!((ground.normal.dot(&Vector3::zeros()) - ground.offset - 1.9).abs() < 1e-12);
        assert!(v.rig("empty", 0, 0).is_err(), "an empty image has no camera");
        assert_eq!(AssumedView::by_name("mast").unwrap(), AssumedView::MAST);
        let e = AssumedView::by_name("hazcam").unwrap_err().to_string();
        assert!(e.contains("hazcam") && e.contains("navcam, mast, m100") && e.contains("mastcam-z-F"), "{e}");
        assert!((AssumedView::by_name("mastcam-z-26").unwrap().hfov_deg - 25.6).abs() < 1e-9);
        for bad in ["mastcam-z-25", "mastcam-z-111", "mastcam-z-x", "mastcam-z-NaN"] {
            let e = AssumedView::parse(bad).unwrap_err().to_string();
            assert!(e.contains("26 to 110"), "{bad}: {e}");
        }
        // A view given by its numbers.
        let wide = AssumedView::parse(" 90, 2 ,25").unwrap();
        assert_eq!(wide, AssumedView { hfov_deg: 90.0, height_m: 2.0, pitch_deg: 25.0, roll_deg: 0.0 });
        assert_eq!(AssumedView::parse("navcam").unwrap(), v);
        for (spec, says) in
            [("hazcam", "HFOV_DEG,HEIGHT_M,PITCH_DEG"), ("90,2", "2 numbers"), ("90,x,25", "\"x\" is not a number"), ("180,2,25", "field of view 180"), ("90,0,25", "camera height 0"), ("90,2,-5", "below the horizon"), ("90,2,NaN", "NaN")]
        {
            let e = AssumedView::parse(spec).unwrap_err().to_string();
            assert!(e.contains(says), "{spec}: {e}");
        }
        // A roll turns the up direction about the optical axis and keeps it a unit vector.
        let rolled = AssumedView { roll_deg: 90.0, ..v };
        let up = rolled.up_cam();
        assert!((up.norm() - 1.0).abs() < 1e-12 && (up.x - 30f64.to_radians().cos()).abs() < 1e-12, "{up}");
    }
}
