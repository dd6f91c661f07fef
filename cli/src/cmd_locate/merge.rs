//! `tubeloc locate merge DIR... --out DIR`: combines the output folders of the shards of one
//! batch run into one folder: every frame's result file (and overlay) and one summary, as one
//! unsharded run would have written them. Folders of different frame lists, a frame in two
//! folders and frames in none are refused.

use super::batch::{overlay_path, read_runs, write_runs, Shard, Summary, SUMMARY_SCHEMA};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use tubeloc_core::files;

/// Arguments of `tubeloc locate merge`.
#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The shards' output folders (each written by `tubeloc locate --images ... --shard I/N
    /// --out DIR`).
    #[arg(required = true, num_args = 1..)]
    pub dirs: Vec<PathBuf>,
    /// The merged output folder (created; may be one of the shard folders).
    #[arg(long)]
    pub out: PathBuf,
}

/// Copies `rel` from `from` to `to` (atomically), unless both are the same folder.
fn copy_into(from: &Path, to: &Path, rel: &str, same: bool) -> Result<()> {
    if same {
        return Ok(());
    }
    let src = from.join(rel);
    let bytes = std::fs::read(&src).with_context(|| format!("reading {}", src.display()))?;
    let dst = to.join(rel);
    files::write_atomic(&dst, &bytes).with_context(|| format!("writing {}", dst.display()))
}

/// The shards `0..count` none of `present` holds, as "I/N" words.
fn missing_shards(present: &BTreeSet<Shard>, count: usize) -> Vec<String> {
    (0..count).filter(|i| !present.contains(&Shard { index: *i, count })).map(|i| format!("{i}/{count}")).collect()
}

/// Runs `tubeloc locate merge`.
pub fn run(a: MergeArgs) -> Result<()> {
    let summaries: Vec<Summary> = a.dirs.iter().map(|d| Summary::load(d)).collect::<Result<_>>()?;
    let (first_dir, first) = (&a.dirs[0], &summaries[0]);
    for (d, s) in a.dirs.iter().zip(&summaries) {
        if (s.frames_in_list, &s.list_digest) != (first.frames_in_list, &first.list_digest) {
            bail!(
                "{} is a batch over another frame list ({} frames, list digest {}) than {} ({} frames, list digest {}): merge the shards of one run",
                d.display(),
                s.frames_in_list,
                s.list_digest,
                first_dir.display(),
                first.frames_in_list,
                first.list_digest
            );
        }
    }
    // Every frame once.
    let mut by_frame: BTreeMap<usize, (usize, &super::batch::FrameEntry)> = BTreeMap::new();
    for (i, s) in summaries.iter().enumerate() {
        for e in &s.frames {
            if e.frame >= s.frames_in_list {
                bail!("{}: frame {} is beyond the list's {} frames", a.dirs[i].join("summary.json").display(), e.frame, s.frames_in_list);
            }
            if let Some((j, _)) = by_frame.insert(e.frame, (i, e)) {
                bail!("frame {} ({}) is in both {} and {}: the folders overlap (each shard I/N once)", e.frame, e.image.display(), a.dirs[j].display(), a.dirs[i].display());
            }
        }
    }
    let missing: Vec<usize> = (0..first.frames_in_list).filter(|k| !by_frame.contains_key(k)).collect();
    if let Some(k) = missing.first() {
        let present: BTreeSet<Shard> = summaries.iter().map(|s| s.shard).collect();
        let counts: BTreeSet<usize> = present.iter().map(|s| s.count).collect();
        let hint = match counts.iter().next() {
            Some(&n) if counts.len() == 1 => format!("; missing shard(s): {}", missing_shards(&present, n).join(", ")),
            _ => String::new(),
        };
        bail!("{} of the list's {} frames are in none of the folders (the first is frame {k}){hint}", missing.len(), first.frames_in_list);
    }

    std::fs::create_dir_all(a.out.join("frames")).with_context(|| format!("creating {}", a.out.join("frames").display()))?;
    let out_canon = a.out.canonicalize().with_context(|| format!("reading {}", a.out.display()))?;
    let same: Vec<bool> = a.dirs.iter().map(|d| d.canonicalize().map(|c| c == out_canon).unwrap_or(false)).collect();
    let mut frames = Vec::with_capacity(by_frame.len());
    for (i, e) in by_frame.into_values() {
        if let Some(rel) = &e.result {
            copy_into(&a.dirs[i], &a.out, rel, same[i])?;
            let overlay = overlay_path(&e.image);
            if a.dirs[i].join(&overlay).exists() {
                copy_into(&a.dirs[i], &a.out, &overlay, same[i])?;
            }
        }
        frames.push(e.clone());
    }
    let mut runs = Vec::new();
    for d in &a.dirs {
        runs.extend(read_runs(d)?);
    }
    let merged = Summary {
        schema: SUMMARY_SCHEMA.into(),
        shard: Shard { index: 0, count: 1 },
        frames_in_list: first.frames_in_list,
        list_digest: first.list_digest.clone(),
        located: frames.iter().map(|e| e.located).sum(),
        failed: frames.iter().filter(|e| e.error.is_some()).count(),
        frames,
    };
    merged.save(&a.out)?;
    write_runs(&a.out, runs)?;
    crate::out::outln!("{}: {} frames from {} folder(s), {} tube(s) located, {} frame(s) failed; summary {}", a.out.display(), merged.frames.len(), a.dirs.len(), merged.located, merged.failed, a.out.join("summary.json").display());
    if merged.failed > 0 {
        eprintln!("warning: {} frame(s) failed in their shards (see the summary); rerun those shards to retry them, then merge again", merged.failed);
    }
    Ok(())
}
