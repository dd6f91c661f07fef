//! Tag detection in many image files at once: `threads` files at a time, each on its own
//! single-threaded [`TagDetector`] (the C detector's worker pool races, record 0079), results in
//! the order of the files, the same as one detector reading them one after another.

use crate::detect::{DetectorConfig, TagDetection, TagDetector};
use crate::error::CalibError;
use rayon::prelude::*;
use std::path::PathBuf;

/// The tags of each file of `paths`, in order: [`DetectorConfig::threads`] files at once, each
/// read as 8-bit grey ([`crate::grey::open_grey`]) and detected by a detector of `config` on one
/// thread; `on_done` is called once per file as it finishes (for a progress bar).
///
/// The outer error is a refused `config` (nothing read); each inner one is that file's (it
/// names the file).
pub fn detect_files(config: &DetectorConfig, paths: &[PathBuf], on_done: &(dyn Fn() + Sync)) -> Result<Vec<Result<Vec<TagDetection>, CalibError>>, CalibError> {
    config.validate()?; // refuses bad settings before any file is read
    let pool = rayon::ThreadPoolBuilder::new().num_threads(config.threads as usize).build().map_err(|e| CalibError::Detector(format!("starting {} detection threads: {e}", config.threads)))?;
    Ok(pool.install(|| {
        paths
            .par_iter()
            .map_init(
                || TagDetector::new(config.clone()),
                |det, p| {
                    let found = match det {
                        Ok(det) => crate::grey::open_grey(p).and_then(|img| det.detect_image(&img).map_err(|e| CalibError::parse(p, format!("detecting tags: {e}")))),
                        Err(e) => Err(CalibError::Detector(e.to_string())),
                    };
                    on_done();
                    found
                },
            )
            .collect()
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_config_is_refused_and_an_unreadable_file_is_named() {
        let bad = DetectorConfig { families: vec![], ..Default::default() };
        assert!(matches!(detect_files(&bad, &[], &|| {}), Err(CalibError::Invalid { .. })));
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.png");
        let flat = dir.path().join("flat.png");
        image::GrayImage::from_pixel(64, 48, image::Luma([128])).save(&flat).unwrap();
        let config = DetectorConfig { threads: 2, ..Default::default() };
        let done = std::sync::atomic::AtomicUsize::new(0);
        let found = detect_files(&config, &[missing.clone(), flat], &|| {
            done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        })
        .unwrap();
        let err = found[0].as_ref().unwrap_err().to_string();
        assert!(err.contains("missing.png"), "{err}");
        assert_eq!(found[1].as_ref().unwrap().len(), 0);
        assert_eq!(done.into_inner(), 2, "each file counts once, read or not");
    }
}
