//! `tubeloc templates`: build and inspect Line2D template libraries.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use tubeloc_core::{CameraModel, TubeMaterial, TubeMesh, TubeModel};
use tubeloc_detect::line2d::mesh::MeshShape;
use tubeloc_detect::line2d::render::Pinhole;
use tubeloc_detect::line2d::{LibraryParams, TemplateLibrary, ViewParams};

/// Subcommands of `tubeloc templates`.
#[derive(clap::Subcommand)]
pub enum TemplatesCmd {
    /// Render the tube model from many viewpoints and write a template library (.tlt).
    Build(BuildArgs),
    /// Print a summary of a template library.
    Info {
        /// Library file.
        path: PathBuf,
    },
}

/// Arguments of `tubeloc templates`.
#[derive(clap::Args)]
pub struct TemplatesArgs {
    #[command(subcommand)]
    cmd: TemplatesCmd,
}

/// Arguments of `tubeloc templates build`.
#[derive(clap::Args)]
pub struct BuildArgs {
    /// Output library file.
    #[arg(long)]
    out: PathBuf,
    /// Distances `MIN:MAX:STEP` in metres.
    #[arg(long, default_value = "1.0:4.0:0.1")]
    distances: String,
    /// Angle between adjacent icosahedron viewpoints, degrees.
    #[arg(long, default_value_t = 10.0)]
    step_deg: f64,
    /// In-plane (camera roll) step, degrees.
    #[arg(long, default_value_t = 10.0)]
    inplane_step_deg: f64,
    /// In-plane angles span +-this, degrees.
    #[arg(long, default_value_t = 10.0)]
    inplane_range_deg: f64,
    /// Views whose tube-axis directions differ by less than this are duplicates (symmetry), degrees.
    #[arg(long, default_value_t = 6.0)]
    dedupe_tol_deg: f64,
    /// Features per template and pyramid level (not capped at 63).
    #[arg(long, default_value_t = 64)]
    features: u32,
    /// Camera JSON whose focal lengths the templates are rendered with (default: the paper's
    /// camera at half resolution, fx = fy ~ 1720 px).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Tube model TOML (default: the embedded data/tube.toml).
    #[arg(long)]
    tube: Option<PathBuf>,
    /// Tube mesh (Wavefront OBJ, metres, axis +z) rendered instead of the parametric model,
    /// e.g. ../shared/data/sample_tube/sample_tube.obj.
    #[arg(long, conflicts_with = "tube")]
    tube_mesh: Option<PathBuf>,
    /// With --tube-mesh: keep the grey plastic cap of the CAD model (not flight hardware;
    /// excluded by default).
    #[arg(long)]
    mesh_keep_cap: bool,
}

fn parse_range(s: &str) -> Result<(f64, f64, f64)> {
    let v: Vec<f64> = s.split(':').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().with_context(|| format!("--distances {s:?}: expected MIN:MAX:STEP in metres"))?;
    if v.len() != 3 {
        bail!("--distances {s:?}: expected MIN:MAX:STEP in metres");
    }
    Ok((v[0], v[1], v[2]))
}

/// Runs `tubeloc templates`.
pub fn run(args: TemplatesArgs) -> Result<()> {
    match args.cmd {
        TemplatesCmd::Build(a) => build(a),
        TemplatesCmd::Info { path } => {
            let lib = TemplateLibrary::load(&path).with_context(|| format!("reading {}", path.display()))?;
            let p = &lib.params;
            println!("{}: {} templates", path.display(), lib.len());
            println!("camera fx {:.2} fy {:.2} cx {:.2} cy {:.2}", p.camera.fx, p.camera.fy, p.camera.cx, p.camera.cy);
            println!("views {:?}", p.views);
            println!("features per level {}", p.features);
            let nf: usize = lib.templates.iter().map(|t| t.levels[0].features.len()).sum();
            println!("mean level-0 features {:.1}", nf as f64 / lib.len().max(1) as f64);
            Ok(())
        }
    }
}

fn build(a: BuildArgs) -> Result<()> {
    let shape = match &a.tube_mesh {
        Some(p) => {
            let mesh = TubeMesh::load_obj(p).with_context(|| format!("reading {}", p.display()))?;
            let exclude: &[TubeMaterial] = if a.mesh_keep_cap { &[] } else { &[TubeMaterial::Plastic] };
            let shape = MeshShape::from_mesh(&mesh, exclude).with_context(|| format!("{}: no triangle left after excluding the cap", p.display()))?;
            eprintln!("mesh {}: {} triangles, length {:.1} mm", p.display(), shape.triangles.len(), shape.length() * 1000.0);
            Some(shape)
        }
        None => None,
    };
    let tube = match &a.tube {
        Some(p) => TubeModel::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => TubeModel::default(),
    };
    let cam = match &a.camera {
        Some(p) => CameraModel::load_json(p).with_context(|| format!("reading {}", p.display()))?,
        None => LibraryParams::default_camera(),
    };
    let (dist_min, dist_max, dist_step) = parse_range(&a.distances)?;
    let params = LibraryParams {
        camera: Pinhole { fx: cam.fx, fy: cam.fy, cx: cam.cx, cy: cam.cy },
        views: ViewParams { step_deg: a.step_deg, inplane_step_deg: a.inplane_step_deg, inplane_range_deg: a.inplane_range_deg, dedupe_tol_deg: a.dedupe_tol_deg, dist_min, dist_max, dist_step },
        features: a.features,
    };
    let total = tubeloc_detect::line2d::viewpoints::generate_views(&params.views)?.len();
    let bar = ProgressBar::new(total as u64);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} templates {elapsed}").unwrap_or_else(|_| ProgressStyle::default_bar()));
    let lib = match &shape {
        Some(m) => TemplateLibrary::build_from_mesh(m, &params, &|n| bar.set_position(n as u64))?,
        None => TemplateLibrary::build(&tube, &params, &|n| bar.set_position(n as u64))?,
    };
    bar.finish_and_clear();
    lib.save(&a.out).with_context(|| format!("writing {}", a.out.display()))?;
    eprintln!("{} templates -> {}", lib.len(), a.out.display());
    Ok(())
}
