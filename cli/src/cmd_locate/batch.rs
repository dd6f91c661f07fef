//! `tubeloc locate --images`: many frames in one process. The rig, the detector (model or
//! template library) and the settings are loaded once; each frame's document (the schema of a
//! one-image run, without its `run` statistics) is written atomically to
//! `OUT/frames/<image stem>.json`, and at the end `OUT/summary.json` lists every frame of the
//! shard. A frame whose result file exists and is complete is skipped, so a killed run resumes
//! where it stopped; `OUT/run.json` gets one entry (frames, seconds, frames per second per
//! core) per invocation.

use super::frames::{frame_list, list_digest, result_name, shard_indices};
use super::{locate_frame, Frame, LocateArgs, Setup, FRAME_SCHEMA};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;
use tubeloc_core::files;

/// Schema name of a batch summary.
pub const SUMMARY_SCHEMA: &str = "tubeloc.locate.batch.v1";

/// A shard `index` of `count` (frame k of the sorted list belongs to shard k mod count).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Shard {
    /// The shard's index, `0 <= index < count`.
    pub index: usize,
    /// The number of shards.
    pub count: usize,
}

/// `summary.json` of a batch output folder: every frame of its shard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Summary {
    /// [`SUMMARY_SCHEMA`].
    pub schema: String,
    /// The shard this folder holds (`0/1` for a whole or merged run).
    pub shard: Shard,
    /// Frames in the whole sorted list (all shards).
    pub frames_in_list: usize,
    /// Digest of the whole frame list ([`super::frames::list_digest`]).
    pub list_digest: String,
    /// Located tubes in all frames of this folder.
    pub located: usize,
    /// Frames that failed (their entries carry the error).
    pub failed: usize,
    /// The frames, in list order.
    pub frames: Vec<FrameEntry>,
}

/// One frame of a [`Summary`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameEntry {
    /// Rank of the frame in the sorted list.
    pub frame: usize,
    /// The (left) image.
    pub image: PathBuf,
    /// The right image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub right_image: Option<PathBuf>,
    /// The result file, relative to the output folder (`frames/<stem>.json`); absent when the
    /// frame failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub result: Option<String>,
    /// Located tubes (`status` `located`).
    pub located: usize,
    /// Rejected detections (every `status` but `located`: `fit_failed`, `low_probability`,
    /// `weak_pose_evidence`, ...).
    pub rejected: usize,
    /// Why the frame failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The warnings about the frame (its document's `warnings`: underexposed, tubes too narrow
    /// for the detector); absent when none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

impl Summary {
    /// Reads and checks `DIR/summary.json`.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join("summary.json");
        if !path.exists() {
            bail!("{}: no summary.json: the batch run writing this folder has not finished (run the same command again to resume it)", dir.display());
        }
        let s: Summary = files::read_json(&path).with_context(|| format!("reading batch summary {}", path.display()))?;
        if s.schema != SUMMARY_SCHEMA {
            bail!("{}: schema {:?}, expected {SUMMARY_SCHEMA:?}", path.display(), s.schema);
        }
        Ok(s)
    }

    /// Writes `DIR/summary.json` atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let path = dir.join("summary.json");
        files::write_atomic(&path, &serde_json::to_vec_pretty(self)?).with_context(|| format!("writing {}", path.display()))
    }
}

/// The relative path of a frame's result file in an output folder.
pub fn result_path(image: &Path) -> String {
    format!("frames/{}.json", result_name(image))
}

/// The relative path of a frame's overlay PNG in an output folder.
pub fn overlay_path(image: &Path) -> String {
    format!("frames/{}.overlay.png", result_name(image))
}

/// Counts of a finished frame's document: located tubes and rejected detections, when `path`
/// holds a complete document of `frame` (schema, image and tubes as this run would write).
fn finished_counts(path: &Path, frame: &Frame) -> Option<(usize, usize, Vec<String>)> {
    let doc: Value = serde_json::from_slice(&std::fs::read(path).ok()?).ok()?;
    let image_matches = doc["image"].as_str() == frame.image.to_str() && doc["right_image"].as_str() == frame.right.as_deref().and_then(Path::to_str);
    if doc["schema"] != FRAME_SCHEMA || !image_matches {
        return None;
    }
    let tubes = doc["tubes"].as_array()?;
    let located = tubes.iter().filter(|t| t["status"] == "located").count();
    let warnings = doc["warnings"].as_array().map(|w| w.iter().filter_map(|v| v.as_str().map(str::to_string)).collect()).unwrap_or_default();
    Some((located, tubes.len() - located, warnings))
}

/// Runs a batch (`--images`); returns the number of located tubes over the shard's frames.
pub fn run(a: &LocateArgs) -> Result<usize> {
    let t0 = Instant::now();
    let out = a.out_path()?.to_path_buf();
    let images = a.images.as_deref().context("--images is required for a batch")?;
    let frames = frame_list(images, a.right_images.as_deref())?;
    let (index, count) = a.shard.unwrap_or((0, 1));
    let shard = Shard { index, count };
    let mine: Vec<usize> = shard_indices(frames.len(), (index, count)).collect();
    let setup = Setup::new(a, &mine.iter().map(|&k| frames[k].image.as_path()).collect::<Vec<_>>())?;
    std::fs::create_dir_all(out.join("frames")).with_context(|| format!("creating {}", out.join("frames").display()))?;

    let bar = ProgressBar::new(mine.len() as u64);
    bar.set_style(ProgressStyle::with_template("locate {bar:30} {pos}/{len} frames {elapsed}<{eta} {msg}").unwrap_or_else(|_| ProgressStyle::default_bar()));
    let (mut entries, mut processed, mut skipped) = (Vec::with_capacity(mine.len()), 0usize, 0usize);
    for &k in &mine {
        let frame = &frames[k];
        let (rel, rel_overlay) = (result_path(&frame.image), overlay_path(&frame.image));
        let mut entry = FrameEntry { frame: k, image: frame.image.clone(), right_image: frame.right.clone(), result: Some(rel.clone()), located: 0, rejected: 0, error: None, warnings: Vec::new() };
        let done = finished_counts(&out.join(&rel), frame).filter(|_| !a.overlays || out.join(&rel_overlay).exists());
        if let Some((located, rejected, warnings)) = done {
            (entry.located, entry.rejected, entry.warnings) = (located, rejected, warnings);
            skipped += 1;
        } else {
            let written = locate_frame(&setup, a, frame, None, a.overlays).and_then(|o| {
                for w in &o.warnings {
                    bar.suspend(|| eprintln!("warning: frame {k}: {w}"));
                }
                if let Some(png) = &o.overlay_png {
                    files::write_atomic(&out.join(&rel_overlay), png).with_context(|| format!("writing {}", out.join(&rel_overlay).display()))?;
                }
                files::write_atomic(&out.join(&rel), &o.json).with_context(|| format!("writing {}", out.join(&rel).display()))?;
                Ok((o.found.tubes.len(), o.found.rejected.len(), o.warnings))
            });
            match written {
                Ok((located, rejected, warnings)) => (entry.located, entry.rejected, entry.warnings) = (located, rejected, warnings),
                Err(e) => {
                    bar.suspend(|| eprintln!("warning: frame {k} ({}): {e:#}", frame.image.display()));
                    (entry.result, entry.error) = (None, Some(format!("{e:#}")));
                }
            }
            processed += 1;
        }
        entries.push(entry);
        bar.inc(1);
    }
    bar.finish_and_clear();

    let failed = entries.iter().filter(|e| e.error.is_some()).count();
    let warned = entries.iter().filter(|e| !e.warnings.is_empty()).count();
    let located = entries.iter().map(|e| e.located).sum();
    let summary = Summary { schema: SUMMARY_SCHEMA.into(), shard, frames_in_list: frames.len(), list_digest: list_digest(&frames), located, failed, frames: entries };
    summary.save(&out)?;
    let seconds = t0.elapsed().as_secs_f64();
    let threads = rayon::current_num_threads();
    let fps = processed as f64 / seconds.max(1e-9);
    let run = json!({
        "shard": shard, "frames_processed": processed, "frames_skipped": skipped, "frames_failed": failed, "seconds": seconds, "threads": threads,
        "frames_per_second": fps, "frames_per_second_per_core": fps / threads as f64, "peak_rss_mb": crate::memory::peak_rss_mb(),
    });
    append_run(&out, run)?;
    crate::out::outln!(
        "{}: {} frame(s) of shard {}/{} ({} located, {} skipped as done, {failed} failed), {located} tube(s) located; summary {}",
        out.display(),
        mine.len(),
        shard.index,
        shard.count,
        processed - failed,
        skipped,
        out.join("summary.json").display()
    );
    eprintln!("{processed} frame(s) in {seconds:.1} s: {fps:.2} frames/s on {threads} thread(s), {:.3} frames/s per core", fps / threads as f64);
    if warned > 0 {
        eprintln!("{warned} frame(s) with warnings (listed in {})", out.join("summary.json").display());
    }
    if failed > 0 {
        bail!("{failed} of {} frame(s) failed (listed with their errors in {}); run the same command again to retry them", mine.len(), out.join("summary.json").display());
    }
    Ok(located)
}

/// Appends one invocation's statistics to `DIR/run.json` (`{"runs": [...]}`).
pub fn append_run(dir: &Path, run: Value) -> Result<()> {
    let mut runs = read_runs(dir)?;
    runs.push(run);
    write_runs(dir, runs)
}

/// The invocations listed in `DIR/run.json` (none when it is absent).
pub fn read_runs(dir: &Path) -> Result<Vec<Value>> {
    let path = dir.join("run.json");
    if !path.exists() {
        return Ok(Vec::new());
    }
    let doc: Value = files::read_json(&path).with_context(|| format!("reading {}", path.display()))?;
    doc["runs"].as_array().cloned().with_context(|| format!("{}: no \"runs\" list", path.display()))
}

/// Writes `DIR/run.json` atomically.
pub fn write_runs(dir: &Path, runs: Vec<Value>) -> Result<()> {
    let path = dir.join("run.json");
    files::write_atomic(&path, &serde_json::to_vec_pretty(&json!({ "runs": runs }))?).with_context(|| format!("writing {}", path.display()))
}
