//! Rover cameras told from their image products' file names.
//!
//! Raw rover images come without a camera model, but their file names follow each mission's
//! product naming convention, whose first fields name the instrument:
//!
//! - Curiosity (MSL) engineering cameras, OPGS names: `NLB_428032368EDR_F0090738NCAM00385M_`:
//!   instrument (2 letters: `N?` Navcam, `F?` front and `R?` rear Hazcam), configuration `A`
//!   or `B`, `_`, 9-digit spacecraft clock;
//! - Curiosity Mastcam, MAHLI, MARDI, MMM names: `0079MR0005910210103981E01`: 4-digit sol,
//!   instrument (`ML` Mastcam left, M-34; `MR` right, M-100; `MH` MAHLI; `MD` MARDI);
//! - Perseverance (Mars 2020): `ZL0_0053_0671642352_402ECM_N0032046ZCAM05025_110085J01`:
//!   instrument (`N?` Navcam, `Z?` Mastcam-Z, `F?`/`R?` Hazcams, ...), filter or
//!   configuration, `_`, 4-digit sol, venue, 10-digit clock; a Mastcam-Z name carries the zoom
//!   focal length in mm as the first three digits of its last field (`110`);
//! - Spirit and Opportunity (MER): `1n579700548ffld2fcp1981l0m1`: rover (`1` Opportunity, `2`
//!   Spirit), camera (`n` Navcam, `p` Pancam, `f`/`r` Hazcams, `m` Microscopic Imager),
//!   9-digit clock.
//!
//! Each mast camera gets the level-ground view of [`AssumedView`] with its own field of view
//! (the instrument papers' figures) at its mast height, looking 30 degrees down as the other
//! assumed views do. The field of view is the whole frame's: an image is taken to be the full
//! frame, at its own size (full resolution or downsampled); a subframe or tile needs its
//! camera model (its PDS label).

use crate::AssumedView;

/// A rover camera named by an image product's file name.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RoverCamera {
    /// Curiosity Navcam: 45 x 45 degrees, 1024 px, about 1.9 m above the ground
    /// ([`AssumedView::NAVCAM`]).
    MslNavcam,
    /// Curiosity Mastcam left, M-34 (34 mm): 20 x 15 degrees ([`AssumedView::MAST`]).
    MslMastcamLeft,
    /// Curiosity Mastcam right, M-100 (100 mm): 6.8 x 5.1 degrees.
    MslMastcamRight,
    /// Perseverance Navcam: 96 x 73 degrees, on the mast about 2 m above the ground.
    M2020Navcam,
    /// Perseverance Mastcam-Z at the zoom focal length its name gives, mm (26 to 110):
    /// 25.6 degrees wide at 26 mm, 6.2 at 110 mm, about 2 m above the ground.
    M2020MastcamZ {
        /// Zoom focal length, mm.
        focal_mm: u32,
    },
    /// Spirit and Opportunity Navcam: 45 x 45 degrees, about 1.5 m above the ground.
    MerNavcam,
    /// Spirit and Opportunity Pancam: 16 x 16 degrees, about 1.5 m above the ground.
    MerPancam,
    /// A camera that no mast view fits: a Hazcam (fisheye, on the rover's body), an arm
    /// camera or a descent camera; its mission and instrument, as a reader names them.
    Other {
        /// `MSL`, `Mars 2020` or `MER`.
        mission: &'static str,
        /// The instrument (`Hazcam`, `MAHLI`, ...).
        instrument: &'static str,
    },
}

impl RoverCamera {
    /// The camera whose product `file_name` names (the file's name, with or without its
    /// folder and extension; any case), or `None` where the name follows none of the
    /// conventions above or names an instrument that takes no surface images.
    pub fn of_product(file_name: &str) -> Option<RoverCamera> {
        let name = std::path::Path::new(file_name).file_name()?.to_string_lossy().to_ascii_uppercase();
        let b = name.as_bytes();
        let digits = |r: std::ops::Range<usize>| b.len() >= r.end && b[r].iter().all(u8::is_ascii_digit);
        let letters = |r: std::ops::Range<usize>| b.len() >= r.end && b[r].iter().all(u8::is_ascii_uppercase);
        // MSL MMM: SSSS + ML|MR|MH|MD + sequence digits.
        if digits(0..4) && letters(4..6) && digits(6..7) {
            return match &name[4..6] {
                "ML" => Some(RoverCamera::MslMastcamLeft),
                "MR" => Some(RoverCamera::MslMastcamRight),
                "MH" => Some(RoverCamera::Other { mission: "MSL", instrument: "MAHLI" }),
                "MD" => Some(RoverCamera::Other { mission: "MSL", instrument: "MARDI" }),
                _ => None,
            };
        }
        // MER: rover 1|2, camera letter, 9-digit clock.
        if matches!(b.first(), Some(b'1' | b'2')) && letters(1..2) && digits(2..11) {
            return match b[1] {
                b'N' => Some(RoverCamera::MerNavcam),
                b'P' => Some(RoverCamera::MerPancam),
                b'F' | b'R' => Some(RoverCamera::Other { mission: "MER", instrument: "Hazcam" }),
                b'M' => Some(RoverCamera::Other { mission: "MER", instrument: "Microscopic Imager" }),
                _ => None,
            };
        }
        // MSL OPGS: II + A|B + _ + 9-digit clock + product type.
        if letters(0..2) && matches!(b.get(2), Some(b'A' | b'B')) && b.get(3) == Some(&b'_') && digits(4..13) && letters(13..14) {
            return match b[0] {
                b'N' => Some(RoverCamera::MslNavcam),
                b'F' | b'R' => Some(RoverCamera::Other { mission: "MSL", instrument: "Hazcam" }),
                _ => None,
            };
        }
        // Mars 2020: II + filter/configuration + _ + 4-digit sol + venue + 10-digit clock + _.
        if letters(0..2) && b.get(3) == Some(&b'_') && digits(4..8) && digits(9..19) && b.get(19) == Some(&b'_') {
            return match &name[0..2] {
                "NL" | "NR" => Some(RoverCamera::M2020Navcam),
                "ZL" | "ZR" => {
                    let last = name.split('_').nth(5)?;
                    let focal_mm: u32 = last.get(0..3)?.parse().ok()?;
                    (26..=110).contains(&focal_mm).then_some(RoverCamera::M2020MastcamZ { focal_mm })
                }
                "FL" | "FR" | "RL" | "RR" => Some(RoverCamera::Other { mission: "Mars 2020", instrument: "Hazcam" }),
                "WS" => Some(RoverCamera::Other { mission: "Mars 2020", instrument: "WATSON" }),
                "SI" => Some(RoverCamera::Other { mission: "Mars 2020", instrument: "SuperCam RMI" }),
                "CC" => Some(RoverCamera::Other { mission: "Mars 2020", instrument: "CacheCam" }),
                _ => None,
            };
        }
        None
    }

    /// The camera's name as `--assumed-view` takes it (`navcam`, `mast`, `m100`,
    /// `m2020-navcam`, `mastcam-z-F` with `F` the focal length in mm, `mer-navcam`,
    /// `mer-pancam`), or its mission and instrument for a camera without a view.
    pub fn name(&self) -> String {
        match self {
            RoverCamera::MslNavcam => "navcam".into(),
            RoverCamera::MslMastcamLeft => "mast".into(),
            RoverCamera::MslMastcamRight => "m100".into(),
            RoverCamera::M2020Navcam => "m2020-navcam".into(),
            RoverCamera::M2020MastcamZ { focal_mm } => format!("mastcam-z-{focal_mm}"),
            RoverCamera::MerNavcam => "mer-navcam".into(),
            RoverCamera::MerPancam => "mer-pancam".into(),
            RoverCamera::Other { mission, instrument } => format!("{mission} {instrument}"),
        }
    }

    /// The level-ground view of the camera, or `None` for a camera no mast view fits.
    pub fn view(&self) -> Option<AssumedView> {
        match self {
            RoverCamera::MslNavcam => Some(AssumedView::NAVCAM),
            RoverCamera::MslMastcamLeft => Some(AssumedView::MAST),
            RoverCamera::MslMastcamRight => Some(AssumedView::M100),
            RoverCamera::M2020Navcam => Some(AssumedView::M2020_NAVCAM),
            RoverCamera::M2020MastcamZ { focal_mm } => Some(AssumedView::mastcam_z(*focal_mm as f64)),
            RoverCamera::MerNavcam => Some(AssumedView::MER_NAVCAM),
            RoverCamera::MerPancam => Some(AssumedView::MER_PANCAM),
            RoverCamera::Other { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn product_names_of_the_shared_data_name_their_cameras() {
        for (file, camera) in [
            ("NLB_462567646EDR_F0402448NCAM00385M_.jpg", Some(RoverCamera::MslNavcam)),
            ("NRB_680874728RAD_F0900232NCAM00354M1.png", Some(RoverCamera::MslNavcam)),
            ("negatives_val/x/NLA_400871510EDR_F0040404NCAM00409M_.jpg", Some(RoverCamera::MslNavcam)),
            ("RLB_701384675RAS_F0933408RHAZ00337M1.png", Some(RoverCamera::Other { mission: "MSL", instrument: "Hazcam" })),
            ("0079MR0005910210103981E01.jpg", Some(RoverCamera::MslMastcamRight)),
            ("0402ML1667000000E1.jpg", Some(RoverCamera::MslMastcamLeft)),
            ("ZL0_0053_0671642352_402ECM_N0032046ZCAM05025_110085J01.png", Some(RoverCamera::M2020MastcamZ { focal_mm: 110 })),
            ("ZR0_0897_0746567741_568ECM_N0440820ZCAM08906_1100LMJ02-rjcal-rad.jpg", Some(RoverCamera::M2020MastcamZ { focal_mm: 110 })),
            ("ZL0_0180_0682919878_394IOF_N0062666ZCAM03014_048085A02.png", Some(RoverCamera::M2020MastcamZ { focal_mm: 48 })),
            ("NLF_0053_0671642352_402ECM_N0032046NCAM00500_01_295J.png", Some(RoverCamera::M2020Navcam)),
            ("FLF_0053_0671642352_402ECM_N0032046FHAZ00200_01_295J.png", Some(RoverCamera::Other { mission: "Mars 2020", instrument: "Hazcam" })),
            ("1n579700548ffld2fcp1981l0m1.png", Some(RoverCamera::MerNavcam)),
            ("1p581379812rsdd2fcp2398l2m1.png", Some(RoverCamera::MerPancam)),
            ("1f581291004ednd2fcp1121r0m1.png", Some(RoverCamera::Other { mission: "MER", instrument: "Hazcam" })),
            ("marsscapes_551_1_t0_x453_y55_s493.jpg", None),
            ("000037_NRB_701384494RAD_F0933408NCAM00200M1_0.png", None),
            ("scene_0001.png", None),
            ("ZL0_0053_0671642352_402ECM_N0032046ZCAM05025_999085J01.png", None),
            ("", None),
        ] {
            assert_eq!(RoverCamera::of_product(file), camera, "{file}");
        }
    }

    #[test]
    fn mast_cameras_have_their_instruments_fields_of_view() {
        let hfov = |c: RoverCamera| c.view().unwrap().hfov_deg;
        assert_eq!(hfov(RoverCamera::MslNavcam), 45.0);
        assert_eq!(hfov(RoverCamera::MslMastcamLeft), 20.0);
        assert_eq!(hfov(RoverCamera::MslMastcamRight), 6.8);
        assert_eq!(hfov(RoverCamera::M2020Navcam), 96.0);
        assert!((hfov(RoverCamera::M2020MastcamZ { focal_mm: 26 }) - 25.6).abs() < 1e-9);
        assert!((hfov(RoverCamera::M2020MastcamZ { focal_mm: 110 }) - 6.2).abs() < 0.1);
        assert!(RoverCamera::Other { mission: "MSL", instrument: "Hazcam" }.view().is_none());
        // Each named camera's view is the one its name parses to.
        for c in [RoverCamera::MslNavcam, RoverCamera::MslMastcamLeft, RoverCamera::MslMastcamRight, RoverCamera::M2020Navcam, RoverCamera::M2020MastcamZ { focal_mm: 63 }, RoverCamera::MerNavcam, RoverCamera::MerPancam] {
            assert_eq!(AssumedView::parse(&c.name()).unwrap(), c.view().unwrap(), "{}", c.name());
        }
    }
}
