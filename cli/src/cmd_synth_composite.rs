//! `tubeloc synth composite`: synthetic tubes with shadows on a real photograph.

use anyhow::{bail, Context, Result};
use clap::Args;
use serde_json::{json, Map};
use std::path::PathBuf;
use std::sync::Arc;
use tubeloc_core::{files, CocoDataset, CocoImage, TubeMesh, TubeModel};
use tubeloc_synth::composite::{composite, CompositeConfig, PhotoEncoding, SpectralBand};
use tubeloc_synth::dataset::{annotation_from_truth, encode_png, pose_json, tube_category};
use tubeloc_synth::TubeShape;

/// Arguments of `tubeloc synth composite`.
#[derive(Args)]
pub struct CompositeArgs {
    /// Background photograph (PNG, JPEG, TIFF, PGM / PPM, BMP or WebP).
    #[arg(long)]
    pub background: PathBuf,
    /// Camera model JSON (CameraModel) of the photograph, or its PDS3 label; its size must match
    /// the photo.
    #[arg(long)]
    pub camera: PathBuf,
    /// Ground plane in the camera frame as "nx,ny,nz,d" (`n·X = d`, n up, metres: the same
    /// convention as `locate` and `refine`; a camera 1.5 m above level ground looking ahead
    /// has n = (0, -1, 0) and d = -1.5).
    #[arg(long, allow_hyphen_values = true)]
    pub ground: tubeloc_core::GroundPlane,
    /// Sun as "azimuth,elevation" in degrees (azimuth from the camera's forward direction on the ground, positive to the right).
    #[arg(long, default_value = "60,45", allow_hyphen_values = true)]
    pub sun: String,
    /// Number of tubes.
    #[arg(long, default_value_t = 3)]
    pub tubes: usize,
    /// Dust level of the tubes in [0, 1].
    #[arg(long, default_value_t = 0.0)]
    pub dust: f32,
    /// Seed of the placement.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Tube geometry from an OBJ mesh instead of data/tube.toml.
    #[arg(long)]
    pub tube_mesh: Option<PathBuf>,
    /// Spectral band of the photo's camera, for the tubes' albedos: `visible` (colour),
    /// `red-nir` (600-800 nm, the rovers' monochrome Navcams and Hazcams), `auto`: red-nir
    /// for a grey photo, visible for a colour one.
    #[arg(long, value_enum, default_value_t = BandArg::Auto)]
    pub band: BandArg,
    /// How the photo's pixel values encode light: `srgb` (JPEGs, browse products), or
    /// `linear:LO..HI` for a photo made by a linear stretch of data values LO..HI onto 0..255
    /// (a PDS product's DN; no light is data value 0), in which the tubes are written linearly.
    #[arg(long, default_value = "srgb", value_parser = parse_encoding)]
    pub encoding: PhotoEncoding,
    /// Output folder (images/, annotations.json, camera.json).
    #[arg(long)]
    pub out: PathBuf,
}

/// `--encoding`: `srgb` or `linear:LO..HI` ([`PhotoEncoding::linear_stretch`]).
fn parse_encoding(s: &str) -> Result<PhotoEncoding, String> {
    let bad = || format!("{s:?}: expected srgb, or linear:LO..HI with 0 <= LO < HI (the data values the photo's 0..255 stretch spans)");
    if s == "srgb" {
        return Ok(PhotoEncoding::Srgb);
    }
    let (lo, hi) = s.strip_prefix("linear:").and_then(|r| r.split_once("..")).ok_or_else(bad)?;
    let (lo, hi) = (lo.trim().parse::<f64>().map_err(|_| bad())?, hi.trim().parse::<f64>().map_err(|_| bad())?);
    PhotoEncoding::linear_stretch(lo, hi).ok_or_else(bad)
}

/// `--band` of `tubeloc synth composite`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BandArg {
    /// Red-nir for a grey photo, visible for a colour one.
    Auto,
    /// Colour cameras: the materials' sRGB albedos.
    Visible,
    /// 600-800 nm: the rovers' monochrome engineering cameras.
    RedNir,
}

fn numbers(s: &str, n: usize, what: &str) -> Result<Vec<f64>> {
    let v: Vec<f64> = s.split(',').map(|t| t.trim().parse::<f64>()).collect::<Result<_, _>>().with_context(|| format!("--{what} {s:?}: expected {n} comma-separated numbers"))?;
    if v.len() != n || v.iter().any(|x| !x.is_finite()) {
        bail!("--{what} {s:?}: expected {n} finite comma-separated numbers");
    }
    Ok(v)
}

/// Runs `tubeloc synth composite`.
pub fn run(a: CompositeArgs) -> Result<()> {
    let s = numbers(&a.sun, 2, "sun")?;
    let cam = tubeloc_calib::read_camera(&a.camera).with_context(|| format!("reading camera {}", a.camera.display()))?;
    let img = tubeloc_detect::input::open_image(&a.background).with_context(|| format!("reading background {}", a.background.display()))?.to_rgb8();
    if img.width() != cam.width || img.height() != cam.height {
        bail!("{}: photo is {}x{} but camera {} is {}x{}", a.background.display(), img.width(), img.height(), a.camera.display(), cam.width, cam.height);
    }
    let shape = match &a.tube_mesh {
        Some(p) => TubeShape::from_mesh(&TubeMesh::load_obj(p).with_context(|| format!("reading tube mesh {}", p.display()))?),
        None => TubeShape::from_model(&TubeModel::default()),
    };
    let band = match a.band {
        BandArg::Auto => SpectralBand::of_photo(tubeloc_core::monochrome::is_grey_rgb8(img.as_raw())),
        BandArg::Visible => SpectralBand::Visible,
        BandArg::RedNir => SpectralBand::RedNir,
    };
    let cfg =
        CompositeConfig { ground: (a.ground.normal, -a.ground.offset), sun_az_el_deg: (s[0], s[1]), tubes: a.tubes, dust: a.dust, seed: a.seed, tube_shape: Arc::new(shape), range_m: None, sun_cam: None, tube_gain: 1.0, band, encoding: a.encoding };
    let c = composite(img.as_raw(), &cam, &cfg)?;
    let stem = a.background.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "composite".into());
    let file_name = format!("{stem}_composite.png");
    let png = encode_png(&c.output.rgb, cam.width, cam.height).map_err(|m| anyhow::anyhow!("encoding PNG: {m}"))?;
    let mut extra = Map::new();
    extra.insert("camera".into(), serde_json::to_value(&cam)?);
    extra.insert("T_world_cam".into(), pose_json(&c.t_ground_cam));
    extra.insert("ground".into(), json!({"normal": [a.ground.normal.x, a.ground.normal.y, a.ground.normal.z], "d": a.ground.offset}));
    extra.insert("background".into(), json!(a.background.display().to_string()));
    extra.insert("sun_az_el_deg".into(), json!([s[0], s[1]]));
    let image = CocoImage { id: 1, width: cam.width, height: cam.height, file_name: file_name.clone(), extra };
    let anns = c.truth.iter().enumerate().map(|(j, t)| annotation_from_truth(j as u64 + 1, 1, &cam, t, Map::from_iter([("dust".to_string(), json!(a.dust))]))).collect();
    let ds = CocoDataset { info: Some(json!({"description": "tubeloc composite on a real photograph", "seed": a.seed})), licenses: None, images: vec![image], annotations: anns, categories: vec![tube_category()], extra: Map::new() };
    files::write_atomic(&a.out.join("images").join(&file_name), &png)?;
    files::write_json(&a.out.join("camera.json"), &cam)?;
    ds.save(&a.out.join("annotations.json"))?;
    println!("{}: {} tubes composited onto {}", a.out.display(), c.truth.len(), a.background.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_encoding_is_srgb_or_a_linear_stretch() {
        assert_eq!(parse_encoding("srgb"), Ok(PhotoEncoding::Srgb));
        assert_eq!(parse_encoding("linear:562..1959"), Ok(PhotoEncoding::linear_stretch(562.0, 1959.0).unwrap()));
        for bad in ["linear", "linear:5..5", "linear:-1..9", "linear:a..9", "gamma"] {
            let e = parse_encoding(bad).unwrap_err();
            assert!(e.contains("expected srgb, or linear:LO..HI"), "{bad}: {e}");
        }
    }
}
