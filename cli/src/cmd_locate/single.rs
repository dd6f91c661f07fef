//! `tubeloc locate --image`: one image (or stereo pair) in, one poses document and its overlay
//! out, then a line per tube on stdout.

use super::{locate_frame, Frame, LocateArgs, Setup};
use anyhow::{Context, Result};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use tubeloc_core::files;

/// `<out stem>.<suffix>` next to `out`.
pub fn sidecar(out: &Path, suffix: &str) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "poses".into());
    out.with_file_name(format!("{stem}.{suffix}"))
}

/// Runs `tubeloc locate` on one image (or pair); returns the number of located tubes.
pub fn run(a: &LocateArgs) -> Result<usize> {
    let t0 = std::time::Instant::now();
    let out = a.out_path()?;
    let frame = Frame { image: a.image.clone().context("--image or --images is required")?, right: a.right.clone() };
    let setup = Setup::new(a, &[frame.image.as_path()])?;
    let done = locate_frame(&setup, a, &frame, Some(t0), true)?;

    // Outputs: the overlay, then the poses, each written atomically; nothing printed before.
    let overlay_path = a.overlay.clone().unwrap_or_else(|| sidecar(out, "overlay.png"));
    for p in [out, overlay_path.as_path()] {
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    let png = done.overlay_png.as_deref().unwrap_or_default();
    // Both files appear together: a concurrent run to the same --out leaves one run's pair.
    files::write_atomic_group(&[(out, &done.json), (&overlay_path, png)]).with_context(|| format!("writing {} and {}", out.display(), overlay_path.display()))?;

    let converged = done.found.tubes.len();
    for w in &done.warnings {
        eprintln!("warning: {w}");
    }
    print_summary(&frame.image, &done.found, converged);
    eprintln!("poses -> {} (overlay {})", out.display(), overlay_path.display());
    Ok(converged)
}

/// One line per tube on stdout; a closed pipe ends the printing quietly (the files are written).
fn print_summary(image: &Path, found: &tubeloc_pipeline::LocateOutput, converged: usize) {
    let mut out = std::io::stdout().lock();
    let mut lines = vec![format!("{}: {} tube(s) located, {} detection(s) rejected, {} duplicate(s) merged", image.display(), converged, found.rejected.len(), found.merged)];
    let low: Vec<Option<(f64, f64)>> = found
        .tubes
        .iter()
        .map(|_| None)
        .chain(found.rejected.iter().map(|r| match r.reason {
            tubeloc_pipeline::Rejection::LowProbability { probability, threshold } => Some((probability, threshold)),
            _ => None,
        }))
        .collect();
    for (i, t) in found.all_tubes().enumerate() {
        let p = &t.pose;
        if let Some((pr, th)) = low[i] {
            lines.push(format!("  tube {i}: rejected (probability of a tube {pr:.3} < {th:.3}), score {:.2}", p.score));
            continue;
        }
        match i.checked_sub(found.tubes.len()).map(|k| &found.rejected[k].reason) {
            Some(tubeloc_pipeline::Rejection::IntersectsTube { other }) => {
                lines.push(format!("  tube {i}: rejected (its solid intersects tube {other}'s), score {:.2}", p.score));
                continue;
            }
            Some(tubeloc_pipeline::Rejection::WeakPoseEvidence { evidence, min }) => {
                lines.push(format!("  tube {i}: rejected (its fit's evidence makes it a tube with probability {evidence:.3} < {min:.3}), score {:.2}", p.score));
                continue;
            }
            Some(tubeloc_pipeline::Rejection::LimbsContinue { continuation, max }) => {
                lines.push(format!("  tube {i}: rejected (the edges along its limbs go on past its ends: continuation {continuation:.2} > {max:.2}; a rim or a layer of rock, not a tube), score {:.2}", p.score));
                continue;
            }
            Some(tubeloc_pipeline::Rejection::Underexposed { highlight, min }) => {
                lines.push(format!("  tube {i}: rejected (the frame is underexposed: highlights at grey level {highlight:.0} < {min:.0}), score {:.2}", p.score));
                continue;
            }
            Some(tubeloc_pipeline::Rejection::InIgnoredRegion { pixel }) => {
                lines.push(format!("  tube {i}: rejected (its centre, pixel ({:.0}, {:.0}), lies in the --ignore-mask region), score {:.2}", pixel.0, pixel.1, p.score));
                continue;
            }
            _ => {}
        }
        let c = p.centre * 1e3;
        let g = t.t_rig_grasp.translation() * 1e3;
        lines.push(match &p.failure {
            None => format!(
                "  tube {i}: centre [{:.1}, {:.1}, {:.1}] mm (cam), grasp at [{:.1}, {:.1}, {:.1}] mm (rig), axis [{:.3}, {:.3}, {:.3}], ±{:.1} mm / ±{:.2}°, seal end conf {:.2}, score {:.2}, P(tube) {:.3}{}{}",
                c.x,
                c.y,
                c.z,
                g.x,
                g.y,
                g.z,
                p.axis.x,
                p.axis.y,
                p.axis.z,
                p.centre_std_m() * 1e3,
                p.axis_std_rad().to_degrees(),
                p.end_confidence,
                p.score,
                t.probability,
                t.pose_evidence.map(|e| format!(", pose evidence {e:.3}")).unwrap_or_default(),
                t.limb_continuation.map(|c| format!(", limb continuation {c:.2}")).unwrap_or_default()
            ),
            Some(f) => format!("  tube {i}: rejected ({:?}): {}", f.reason, f.message),
        });
    }
    for l in lines {
        if let Err(e) = writeln!(out, "{l}") {
            if e.kind() != std::io::ErrorKind::BrokenPipe {
                eprintln!("warning: printing the summary: {e}");
            }
            return;
        }
    }
    let _ = out.flush();
}
