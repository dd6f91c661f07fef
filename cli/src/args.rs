//! Value parsers for the numeric command-line arguments, used as clap `value_parser`s so a bad
//! number is refused while the command line is parsed: exit code 2 and a message naming the
//! flag (`error: invalid value 'NaN' for '--sigma-d <SIGMA_D>': must be a finite number`),
//! before any input is read or any output written. NaN and infinities are never accepted.
//!
//! Checks that involve two arguments (`--ring-inner` at most `--ring-outer`) run at the start of
//! the subcommand and return [`usage`], which `main` reports like clap's own errors (exit 2).
//! Some parsers are here for the subcommands that do not use them yet (locate, refine).
#![allow(dead_code)]

use clap::error::ErrorKind;
use tubeloc_core::FrameView;

fn parse_f64(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("{s:?} is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err("must be a finite number".into())
    }
}

/// Any finite number.
pub fn finite_f64(s: &str) -> Result<f64, String> {
    parse_f64(s)
}

/// A finite number > 0.
pub fn positive_f64(s: &str) -> Result<f64, String> {
    let v = parse_f64(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("must be > 0, got {v}"))
    }
}

/// A finite number >= 0.
pub fn non_negative_f64(s: &str) -> Result<f64, String> {
    let v = parse_f64(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("must be >= 0, got {v}"))
    }
}

/// A number in [0, 1].
pub fn unit_interval(s: &str) -> Result<f64, String> {
    in_closed(s, 0.0, 1.0)
}

/// An 8-bit grey level in [0, 255].
pub fn grey_level(s: &str) -> Result<f64, String> {
    in_closed(s, 0.0, 255.0).map_err(|_| format!("{s:?}: expected a grey level in [0, 255]"))
}

/// A fisheye resampling scale (a focal length ratio) in [0.2, 4].
pub fn fisheye_scale(s: &str) -> Result<f64, String> {
    in_closed(s, 0.2, 4.0).map_err(|_| format!("{s:?}: expected a focal length scale in [0.2, 4]"))
}

/// A finite number in `[lo, hi]`; the message names the interval and the value.
fn in_closed(s: &str, lo: f64, hi: f64) -> Result<f64, String> {
    let v = parse_f64(s)?;
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be in [{lo}, {hi}], got {v}"))
    }
}

/// A number in [0, 100] (a percentage).
pub fn percent(s: &str) -> Result<f64, String> {
    in_closed(s, 0.0, 100.0)
}

/// `f32` versions of the parsers above (the value is also finite as an `f32`).
fn to_f32(v: f64) -> Result<f32, String> {
    let f = v as f32;
    if f.is_finite() {
        Ok(f)
    } else {
        Err(format!("{v} is out of range"))
    }
}

/// Any finite number (`f32`).
pub fn finite_f32(s: &str) -> Result<f32, String> {
    to_f32(finite_f64(s)?)
}

/// A finite number > 0 (`f32`).
pub fn positive_f32(s: &str) -> Result<f32, String> {
    to_f32(positive_f64(s)?)
}

/// A finite number >= 0 (`f32`).
pub fn non_negative_f32(s: &str) -> Result<f32, String> {
    to_f32(non_negative_f64(s)?)
}

/// A number in [0, 1] (`f32`).
pub fn unit_interval_f32(s: &str) -> Result<f32, String> {
    to_f32(unit_interval(s)?)
}

/// A number in [0, 100] (`f32`).
pub fn percent_f32(s: &str) -> Result<f32, String> {
    to_f32(percent(s)?)
}

fn parse_u64(s: &str) -> Result<u64, String> {
    s.trim().parse::<u64>().map_err(|_| format!("{s:?} is not a whole number >= 0"))
}

/// A whole number >= 1.
pub fn positive_usize(s: &str) -> Result<usize, String> {
    let v = parse_u64(s)?;
    if v == 0 {
        return Err("must be at least 1".into());
    }
    usize::try_from(v).map_err(|_| format!("{v} is too large"))
}

/// A whole number >= 1 (`u32`).
pub fn positive_u32(s: &str) -> Result<u32, String> {
    let v = positive_usize(s)?;
    u32::try_from(v).map_err(|_| format!("{v} is too large (at most {})", u32::MAX))
}

/// A whole number >= 1 (`u64`).
pub fn positive_u64(s: &str) -> Result<u64, String> {
    let v = parse_u64(s)?;
    if v == 0 {
        Err("must be at least 1".into())
    } else {
        Ok(v)
    }
}

/// A whole number >= 1 (`u8`).
pub fn positive_u8(s: &str) -> Result<u8, String> {
    let v = positive_usize(s)?;
    u8::try_from(v).map_err(|_| format!("{v} is too large (at most {})", u8::MAX))
}

/// A shard `I/N` of a batch job: `0 <= I < N`.
pub fn shard(s: &str) -> Result<(usize, usize), String> {
    let (a, b) = s.split_once('/').ok_or_else(|| format!("{s:?}: expected I/N, e.g. 0/4"))?;
    let i: usize = a.trim().parse().map_err(|_| format!("{s:?}: I is not a whole number"))?;
    let n: usize = b.trim().parse().map_err(|_| format!("{s:?}: N is not a whole number"))?;
    if n == 0 || i >= n {
        return Err(format!("{s:?}: need 0 <= I < N"));
    }
    Ok((i, n))
}

/// A tube-range band "NEAR:FAR" (metres, `0 < NEAR < FAR`, finite) or "off", checked when the
/// command line is parsed; the text is kept and read by
/// [`crate::cmd_detect_learned::parse_range_band`].
pub fn range_band(s: &str) -> Result<String, String> {
    crate::cmd_detect_learned::parse_range_band(s).map_err(|e| format!("{e:#}"))?;
    Ok(s.to_string())
}

/// A Line2D ground-consistency band "MIN:MAX" (ratios of a match's template distance to the
/// ground's distance along its ray, `0 < MIN <= MAX`, finite) or "off", checked when the
/// command line is parsed; the text is kept and read by [`parse_ground_range`].
pub fn ground_range(s: &str) -> Result<String, String> {
    parse_ground_range(s)?;
    Ok(s.to_string())
}

/// The band of [`ground_range`]'s text: `None` for "off".
pub fn parse_ground_range(s: &str) -> Result<Option<tubeloc_detect::line2d::GroundRange>, String> {
    if s.trim() == "off" {
        return Ok(None);
    }
    let (a, b) = s.split_once(':').ok_or_else(|| format!("{s:?}: expected MIN:MAX (ratios) or off"))?;
    let (lo, hi) = (parse_f64(a.trim())?, parse_f64(b.trim())?);
    tubeloc_detect::line2d::GroundRange::new(lo, hi).map(Some).map_err(|e| format!("{s:?}: {e}"))
}

/// A range "NEAR:FAR" in metres with `0 <= NEAR < FAR`, finite (composite placement).
pub fn range_m(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("{s:?}: expected NEAR:FAR in metres"))?;
    let (near, far) = (parse_f64(a.trim())?, parse_f64(b.trim())?);
    if !(near.is_finite() && far.is_finite() && near >= 0.0 && far > near) {
        return Err(format!("{s:?}: need 0 <= NEAR < FAR, finite"));
    }
    Ok((near, far))
}

/// An AprilTag quad decimation factor: 1, 1.5 or a whole number up to 64
/// ([`tubeloc_calib::detect::check_decimation`]).
pub fn decimation(s: &str) -> Result<f32, String> {
    let v = to_f32(parse_f64(s)?)?;
    tubeloc_calib::detect::check_decimation(v)?;
    Ok(v)
}

/// A command-line error found after parsing (two arguments that do not go together): `main`
/// reports it like clap's own errors, with exit code 2. `message` names the flags.
pub fn usage(message: impl std::fmt::Display) -> anyhow::Error {
    anyhow::Error::new(clap::Error::raw(ErrorKind::ArgumentConflict, format!("{message}\n")))
}

/// Checks `a <= b` for two flags' values; a [`usage`] error naming both otherwise.
pub fn require_at_most<T: PartialOrd + std::fmt::Display>(a: (&str, T), b: (&str, T)) -> anyhow::Result<()> {
    if a.1 <= b.1 {
        Ok(())
    } else {
        Err(usage(format!("{} ({}) must not exceed {} ({})", a.0, a.1, b.0, b.1)))
    }
}

/// A resampling limit in [1, 8] (`--max-upsample`: the library's scale clamps factors to 8).
pub fn upsample_limit(s: &str) -> Result<f64, String> {
    in_closed(s.trim(), 1.0, 8.0).map_err(|e| format!("{s:?}: {e}"))
}

/// Line2D far-search factors `(colour, grey)`, each in [1, 4]: "K" for both kinds of image,
/// or "COLOUR:GREY".
pub fn far_scale(s: &str) -> Result<(f64, f64), String> {
    let one = |t: &str| in_closed(t.trim(), 1.0, 4.0).map_err(|e| format!("{s:?}: {e}"));
    match s.split_once(':') {
        Some((c, g)) => Ok((one(c)?, one(g)?)),
        None => one(s).map(|k| (k, k)),
    }
}

/// A view assumed for frames without a camera model (`--assumed-view`): a named view
/// (`navcam`, `mast`, ..., [`tubeloc_core::AssumedView::by_name`]), one given by its numbers,
/// `HFOV_DEG,HEIGHT_M,PITCH_DEG` ([`tubeloc_core::AssumedView::parse`]), or `auto`: each
/// frame's from its product name or its kind ([`tubeloc_core::AssumedView::of_frame`]).
#[derive(Clone, Debug, PartialEq)]
pub enum AssumedViewArg {
    /// One view for every frame: as given (a name, or the numbers), and its geometry.
    View(String, tubeloc_core::AssumedView),
    /// The view of the mast camera a frame's product name names, otherwise `navcam` for a grey
    /// frame and `mast` for a colour one (as `tubeloc bench` judges real frames).
    Auto,
}

/// The warning for a frame whose product name names a camera no mast view fits
/// ([`FrameView::unfit`]), naming the file at `image`, the camera and the view taken instead;
/// `None` otherwise.
pub fn unfit_camera_warning(frame: &FrameView, image: &std::path::Path) -> Option<String> {
    frame.unfit.map(|c| {
        format!(
            "{} comes from the {} (by its product name): no mast view fits that camera, so it is judged under the {} view of its kind; give its camera model (--rig, or --label-cameras with its PDS label) for poses and scale that hold",
            image.display(),
            c.name(),
            frame.name
        )
    })
}

impl AssumedViewArg {
    /// Whether the view depends on the frame (`auto`).
    pub fn by_frame(&self) -> bool {
        matches!(self, AssumedViewArg::Auto)
    }

    /// The size of the image at `image` and its view ([`AssumedViewArg::for_frame`]): `auto`
    /// decodes the image to tell grey from colour (as `tubeloc bench` does) where its product
    /// name names no mast camera; otherwise only its size is read. The error names the file.
    pub fn frame_view(&self, image: &std::path::Path) -> Result<((u32, u32), FrameView), String> {
        let reading = |e: String| format!("reading {}: {e}", image.display());
        let name = image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let by_pixels = self.by_frame() && tubeloc_core::RoverCamera::of_product(&name).and_then(|c| c.view()).is_none();
        let (size, grey) = match by_pixels {
            true => tubeloc_detect::input::open_eight_bit(image).map(|im| ((im.width(), im.height()), tubeloc_detect::input::rgb8_of(&im).info.grey)).map_err(|e| reading(e.to_string()))?,
            false => (tubeloc_detect::input::image_size(image).map_err(|e| reading(e.to_string()))?, true),
        };
        Ok((size, self.for_frame(&name, grey)))
    }

    /// The view of the frame in the file `file_name`, grey or not: the view as given (its name
    /// as given: `navcam`, `mast`, or the numbers), or with `auto`
    /// [`tubeloc_core::AssumedView::of_frame`].
    pub fn for_frame(&self, file_name: &str, grey: bool) -> FrameView {
        match self {
            AssumedViewArg::View(spec, view) => FrameView { name: spec.clone(), view: *view, unfit: None },
            AssumedViewArg::Auto => tubeloc_core::AssumedView::of_frame(file_name, || grey),
        }
    }
}

/// Parses `--assumed-view`: a named view, `auto`, or `HFOV_DEG,HEIGHT_M,PITCH_DEG`.
pub fn assumed_view(s: &str) -> Result<AssumedViewArg, String> {
    if s.trim() == "auto" {
        return Ok(AssumedViewArg::Auto);
    }
    let view = tubeloc_core::AssumedView::parse(s).map_err(|e| match s.contains(',') || s.trim().starts_with("mastcam-z-") {
        true => e.to_string(),
        false => format!("unknown view {:?}: expected {}, auto, or HFOV_DEG,HEIGHT_M,PITCH_DEG (e.g. 90,2,25)", s.trim(), tubeloc_core::AssumedView::names()),
    })?;
    let spec = s.split(',').map(str::trim).collect::<Vec<_>>().join(",");
    Ok(AssumedViewArg::View(spec, view))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parsers_refuse_nan_infinities_and_out_of_range() {
        for s in ["NaN", "nan", "inf", "-inf", "infinity", "1e400", "x", ""] {
            assert!(finite_f64(s).is_err(), "{s}");
            assert!(positive_f32(s).is_err(), "{s}");
        }
        assert_eq!(finite_f64("-2.5"), Ok(-2.5));
        assert!(positive_f64("0").is_err() && positive_f64("1e-9").is_ok());
        assert!(non_negative_f64("-0.1").is_err() && non_negative_f64("0").is_ok());
        assert!(unit_interval("1.01").is_err() && unit_interval("1").is_ok() && unit_interval("0").is_ok());
        assert!(percent("101").is_err() && percent("80").is_ok());
        assert!(positive_f32("1e39").is_err(), "overflows f32");
        assert!(positive_usize("0").is_err() && positive_usize("-1").is_err() && positive_usize("3").is_ok());
        assert!(positive_u8("256").is_err() && positive_u8("255").is_ok());
        assert_eq!(shard("1/4"), Ok((1, 4)));
        for s in ["3/2", "2/2", "0/0", "1", "a/2", "-1/2"] {
            assert!(shard(s).is_err(), "{s}");
        }
        assert_eq!(far_scale("1.4"), Ok((1.4, 1.4)));
        assert_eq!(far_scale("1:1.4"), Ok((1.0, 1.4)));
        assert_eq!(upsample_limit("2.5"), Ok(2.5));
        assert!(upsample_limit("0.9").is_err() && upsample_limit("9").is_err() && upsample_limit("nan").is_err());
        for s in ["0.9", "1:5", "1:", ":1.4", "1.4:x", "1:1:1"] {
            assert!(far_scale(s).is_err(), "{s}");
        }
        let (c, g) = far_scale(crate::cmd_detect_line2d::DEFAULT_FAR_SCALE).unwrap();
        let p = tubeloc_detect::line2d::MatchParams::default();
        assert_eq!((c, g), (p.far_scale, p.far_scale_grey), "--far-scale's default is the library's");
        assert_eq!(parse_ground_range("off"), Ok(None));
        // The flag's default is the library's.
        assert_eq!(parse_ground_range(crate::cmd_detect_line2d::DEFAULT_GROUND_RANGE), Ok(Some(tubeloc_detect::line2d::GroundRange::default())));
        assert_eq!(parse_ground_range("0.5:1.5").unwrap().map(|g| (g.min_ratio, g.max_ratio)), Some((0.5, 1.5)));
        for s in ["1.5:0.5", "0:1", "-1:1", "1", "a:b", "1:inf"] {
            assert!(ground_range(s).is_err(), "{s}");
        }
        assert!(decimation("200").is_err() && decimation("2.5").is_err() && decimation("1.5").is_ok() && decimation("NaN").is_err());
        assert!(require_at_most(("--a", 2), ("--b", 6)).is_ok() && require_at_most(("--a", 6), ("--b", 6)).is_ok());
        assert!(require_at_most(("--a", 7), ("--b", 6)).unwrap_err().to_string().contains("--a (7) must not exceed --b (6)"));
    }

    #[test]
    fn assumed_views_are_named_given_by_their_numbers_or_by_product_or_kind() {
        for (name, view) in tubeloc_core::AssumedView::NAMED {
            let v = assumed_view(name).unwrap();
            assert!(!v.by_frame());
            assert_eq!(v.for_frame("NLB_462567646EDR_F0402448NCAM00385M_.jpg", false), FrameView { name: name.to_string(), view, unfit: None });
        }
        let v = assumed_view("96, 2,20").unwrap();
        let f = v.for_frame("x.png", false);
        assert_eq!((f.name.as_str(), f.view.hfov_deg, f.view.height_m, f.view.pitch_deg), ("96,2,20", 96.0, 2.0, 20.0));
        let z = assumed_view("mastcam-z-48").unwrap().for_frame("x.png", true);
        assert_eq!((z.name.as_str(), z.view), ("mastcam-z-48", tubeloc_core::AssumedView::mastcam_z(48.0)));
        let auto = assumed_view("auto").unwrap();
        assert!(auto.by_frame());
        // Frames without a product name: by kind.
        let (g, c) = (auto.for_frame("x.png", true), auto.for_frame("x.png", false));
        assert_eq!((g.name.as_str(), g.view, c.name.as_str(), c.view), ("navcam", tubeloc_core::AssumedView::NAVCAM, "mast", tubeloc_core::AssumedView::MAST));
        // A product name names the camera, whatever the pixels.
        let m100 = auto.for_frame("0079MR0005910210103981E01.jpg", false);
        assert_eq!((m100.name.as_str(), m100.view, m100.unfit), ("m100", tubeloc_core::AssumedView::M100, None));
        let nav = auto.for_frame("NLF_0053_0671642352_402ECM_N0032046NCAM00500_01_295J.png", false);
        assert_eq!((nav.name.as_str(), nav.view), ("m2020-navcam", tubeloc_core::AssumedView::M2020_NAVCAM));
        assert!(unfit_camera_warning(&m100, std::path::Path::new("a.jpg")).is_none());
        // A Hazcam frame: the kind's view, and a note naming the file and the camera.
        let haz = auto.for_frame("RLB_701384675RAS_F0933408RHAZ00337M1.png", true);
        assert_eq!((haz.name.as_str(), haz.view), ("navcam", tubeloc_core::AssumedView::NAVCAM));
        let note = unfit_camera_warning(&haz, std::path::Path::new("d/RLB_701384675RAS_F0933408RHAZ00337M1.png")).unwrap();
        assert!(note.contains("d/RLB_701384675RAS") && note.contains("MSL Hazcam") && note.contains("navcam view"), "{note}");
        let e = assumed_view("hazcam").unwrap_err();
        assert!(e.contains("HFOV_DEG,HEIGHT_M,PITCH_DEG") && e.contains("auto") && e.contains("m2020-navcam"), "{e}");
        assert!(assumed_view("mastcam-z-200").unwrap_err().contains("26 to 110"));
    }
}
