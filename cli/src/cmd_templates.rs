//! `tubeloc templates`: build and inspect Line2D template libraries.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use tubeloc_core::{CameraModel, TubeMaterial, TubeMesh, TubeModel};
use tubeloc_detect::line2d::mesh::MeshShape;
use tubeloc_detect::line2d::render::Pinhole;
use tubeloc_detect::line2d::{LibraryEstimate, LibraryParams, TemplateLibrary, ViewParams};

/// Subcommands of `tubeloc templates`.
#[derive(clap::Subcommand)]
pub enum TemplatesCmd {
    /// Render the tube model from many viewpoints and write a template library (.tlt).
    Build(BuildArgs),
    /// Fit the Line2D clutter verifier on training composites and choose its threshold on
    /// validation composites (writes the verifier JSON).
    FitVerifier(Box<crate::cmd_line2d_verifier::FitArgs>),
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
    #[arg(long, default_value = "1.0:4.0:0.1", value_parser = distance_range)]
    distances: (f64, f64, f64),
    /// Angle between adjacent icosahedron viewpoints, degrees (0 < step <= 90).
    #[arg(long, default_value_t = 10.0, value_parser = step_deg_arg)]
    step_deg: f64,
    /// In-plane (camera roll) step, degrees.
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::positive_f64)]
    inplane_step_deg: f64,
    /// In-plane angles span +-this, degrees.
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::non_negative_f64)]
    inplane_range_deg: f64,
    /// Views whose tube-axis directions differ by less than this are duplicates (symmetry), degrees.
    #[arg(long, default_value_t = 6.0, value_parser = crate::args::non_negative_f64)]
    dedupe_tol_deg: f64,
    /// Features per template and pyramid level (not capped at 63; at most 4096).
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=4096))]
    features: u32,
    /// Refuse to build a library estimated (from the arguments, before any work) to hold more
    /// templates than this. The default library has 8308.
    #[arg(long, default_value_t = DEFAULT_MAX_TEMPLATES, value_parser = crate::args::positive_usize)]
    max_templates: usize,
    /// Refuse to build a library whose build is estimated to need more memory than this, GiB.
    #[arg(long, default_value_t = DEFAULT_MAX_MEMORY_GIB, value_parser = crate::args::positive_f64)]
    max_memory_gib: f64,
    /// Camera JSON (or a PDS3 label: its linearized camera; a fisheye's linear part, which `locate` resamples into) whose focal lengths the templates
    /// are rendered with (default: the paper's camera at half resolution, fx = fy ~ 1720 px).
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

/// Default of `--max-templates`: 24 times the default library.
const DEFAULT_MAX_TEMPLATES: usize = 200_000;
/// Default of `--max-memory-gib`.
const DEFAULT_MAX_MEMORY_GIB: f64 = 8.0;
/// Candidate views (sphere vertices times in-plane angles) and axis comparisons of the symmetry
/// deduplication beyond which the view sampling itself would take minutes: always refused.
const MAX_VIEW_CANDIDATES: f64 = 2e6;
const MAX_DEDUPE_COMPARISONS: f64 = 2e10;

/// `--distances MIN:MAX:STEP`: finite, `0 < MIN <= MAX`, `STEP > 0`.
fn distance_range(s: &str) -> std::result::Result<(f64, f64, f64), String> {
    let v: Vec<f64> = s.split(':').map(crate::args::finite_f64).collect::<std::result::Result<_, _>>().map_err(|e| format!("{s:?}: expected MIN:MAX:STEP in metres ({e})"))?;
    if v.len() != 3 {
        return Err(format!("{s:?}: expected MIN:MAX:STEP in metres"));
    }
    if !(v[0] > 0.0 && v[1] >= v[0] && v[2] > 0.0) {
        return Err(format!("{s:?}: need 0 < MIN <= MAX and STEP > 0"));
    }
    Ok((v[0], v[1], v[2]))
}

/// `--step-deg`: in (0, 90].
fn step_deg_arg(s: &str) -> std::result::Result<f64, String> {
    let v = crate::args::positive_f64(s)?;
    if v <= 90.0 {
        Ok(v)
    } else {
        Err(format!("must be in (0, 90], got {v}"))
    }
}

/// A count for a message: plain below a billion, scientific above.
fn count(x: f64) -> String {
    if x < 1e9 {
        format!("{}", x.round() as u64)
    } else {
        format!("{x:.2e}")
    }
}

/// Refuses a library too large to build, from the estimate alone (exit 2, with the estimate).
fn check_size(est: &LibraryEstimate, max_templates: usize, max_memory_gib: f64) -> Result<()> {
    let v = &est.views;
    let gib = est.peak_bytes / (1u64 << 30) as f64;
    let what = format!("up to {} templates ({} distances x {} view rotations) needing about {} GiB", count(est.templates), count(v.distances), count(v.rotations), if gib < 1e6 { format!("{gib:.1}") } else { format!("{gib:.2e}") });
    if v.candidates > MAX_VIEW_CANDIDATES || v.comparisons > MAX_DEDUPE_COMPARISONS {
        return Err(crate::args::usage(format!(
            "--step-deg / --inplane-step-deg / --dedupe-tol-deg sample the views too finely: {} candidate views and {} axis comparisons (limits {} and {}); the library would hold {what}",
            count(v.candidates),
            count(v.comparisons),
            count(MAX_VIEW_CANDIDATES),
            count(MAX_DEDUPE_COMPARISONS)
        )));
    }
    let mut over = Vec::new();
    if est.templates > max_templates as f64 {
        over.push(format!("the limit of {max_templates} templates (--max-templates)"));
    }
    if gib > max_memory_gib {
        over.push(format!("the limit of {max_memory_gib} GiB (--max-memory-gib)"));
    }
    if !over.is_empty() {
        return Err(crate::args::usage(format!("the library would hold {what}: above {}; use a coarser --distances or --step-deg", over.join(" and "))));
    }
    Ok(())
}

/// Runs `tubeloc templates`.
pub fn run(args: TemplatesArgs) -> Result<()> {
    match args.cmd {
        TemplatesCmd::Build(a) => build(a),
        TemplatesCmd::FitVerifier(a) => crate::cmd_line2d_verifier::run(*a),
        TemplatesCmd::Info { path } => {
            let lib = TemplateLibrary::load(&path).with_context(|| format!("reading {}", path.display()))?;
            let p = &lib.params;
            crate::out::outln!("{}: {} templates", path.display(), lib.len());
            crate::out::outln!("camera fx {:.2} fy {:.2} cx {:.2} cy {:.2}", p.camera.fx, p.camera.fy, p.camera.cx, p.camera.cy);
            crate::out::outln!("views {:?}", p.views);
            crate::out::outln!("features per level {}", p.features);
            let nf: usize = lib.templates.iter().map(|t| t.levels[0].features.len()).sum();
            crate::out::outln!("mean level-0 features {:.1}", nf as f64 / lib.len().max(1) as f64);
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
        // A fisheye label's linear part: the camera of the image `locate` resamples it into.
        Some(p) => match tubeloc_calib::interchange::pds_label::read_resampled_label_camera(p).with_context(|| format!("reading {}", p.display()))? {
            Some((c, fisheye)) => {
                if fisheye.is_some() {
                    eprintln!("{}: a fisheye (CAHVORE): templates for its linear camera, which `tubeloc locate` resamples its images into", p.display());
                }
                c.camera.model
            }
            None => tubeloc_core::CameraModel::load_json(p).with_context(|| format!("reading {}", p.display()))?,
        },
        None => LibraryParams::default_camera(),
    };
    let (dist_min, dist_max, dist_step) = a.distances;
    let params = LibraryParams {
        camera: Pinhole { fx: cam.fx, fy: cam.fy, cx: cam.cx, cy: cam.cy },
        views: ViewParams { step_deg: a.step_deg, inplane_step_deg: a.inplane_step_deg, inplane_range_deg: a.inplane_range_deg, dedupe_tol_deg: a.dedupe_tol_deg, dist_min, dist_max, dist_step },
        features: a.features,
    };
    let (length, radius) = match &shape {
        Some(m) => (m.length(), m.vertices.iter().map(|v| v.x.hypot(v.y)).fold(0.0, f64::max)),
        None => (tube.length, tube.max_radius()),
    };
    let est = params.estimate(length, radius)?;
    check_size(&est, a.max_templates, a.max_memory_gib)?;
    build_and_save(&params, shape.as_ref(), &tube, est.peak_bytes, &a.out)
}

/// Builds the library of the parametric tube model with `views` for `camera`'s focal lengths
/// and writes it to `out`, under the command line's default size limits (what `tubeloc
/// templates build --camera CAM --out OUT` does with the view options of `views`).
pub(crate) fn build_for_camera(camera: &CameraModel, views: ViewParams, out: &Path) -> Result<()> {
    let params = LibraryParams { camera: Pinhole { fx: camera.fx, fy: camera.fy, cx: camera.cx, cy: camera.cy }, views, ..LibraryParams::default() };
    let tube = TubeModel::default();
    let est = params.estimate(tube.length, tube.max_radius())?;
    check_size(&est, DEFAULT_MAX_TEMPLATES, DEFAULT_MAX_MEMORY_GIB)?;
    build_and_save(&params, None, &tube, est.peak_bytes, out)
}

/// Renders the templates (the mesh `shape` when given, else `tube`) with a progress bar and
/// writes the library to `out`.
fn build_and_save(params: &LibraryParams, shape: Option<&MeshShape>, tube: &TubeModel, peak_bytes: f64, out: &Path) -> Result<()> {
    let total = tubeloc_detect::line2d::viewpoints::generate_views(&params.views)?.len();
    eprintln!("building {total} templates (estimated peak memory {:.2} GiB)", peak_bytes / (1u64 << 30) as f64);
    let bar = ProgressBar::new(total as u64);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} templates {elapsed} (eta {eta})").unwrap_or_else(|_| ProgressStyle::default_bar()));
    let lib = match shape {
        Some(m) => TemplateLibrary::build_from_mesh(m, params, &|n| bar.set_position(n as u64))?,
        None => TemplateLibrary::build(tube, params, &|n| bar.set_position(n as u64))?,
    };
    bar.finish_and_clear();
    lib.save(out).with_context(|| format!("writing {}", out.display()))?;
    eprintln!("{} templates -> {}", lib.len(), out.display());
    Ok(())
}
