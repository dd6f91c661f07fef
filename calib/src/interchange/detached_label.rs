//! The detached PDS3 label of a rover image saved in a common format (a raw-gallery JPEG or a
//! PNG converted from a product): the `.LBL` with the image's product name.
//!
//! Raw-gallery JPEGs carry the product name with its version character replaced by `_`
//! (`NLA_400871510EDR_F0040404NCAM00409M_.jpg` for the label
//! `NLA_400871510EDR_F0040404NCAM00409M1.LBL`); a label may also be named after the `.IMG` it
//! describes (`1n579700548ffld2fcp1981l0m1.img.lbl`). A label matches an image when, without
//! their extensions (and a label's `.img`), ignoring case, their names are equal, or of equal
//! length and equal but for the last character, which the image has as `_`.

use crate::error::CalibError;
use std::path::{Path, PathBuf};

/// Whether the label file name `label` (e.g. `X1.LBL`, `x.img.lbl`) is the detached label of
/// the image file name `image` (e.g. `X_.jpg`), by the rule of the module.
pub fn label_names_image(label: &str, image: &str) -> bool {
    let lower = label.to_ascii_lowercase();
    let Some(label) = lower.strip_suffix(".lbl") else { return false };
    let label = label.strip_suffix(".img").unwrap_or(label);
    let image = image.to_ascii_lowercase();
    let image = image.rsplit_once('.').map_or(image.as_str(), |(stem, _)| stem);
    if label == image {
        return true;
    }
    let (lb, ib) = (label.as_bytes(), image.as_bytes());
    lb.len() == ib.len() && lb.len() > 1 && ib[ib.len() - 1] == b'_' && lb[..lb.len() - 1] == ib[..ib.len() - 1]
}

/// Finds detached labels for images ([`DetachedLabels::of`]), listing each folder it searches
/// once: a batch of images in one folder reads that folder once, not once per image.
#[derive(Debug, Default)]
pub struct DetachedLabels {
    /// The folder searched for every image (`--label-dir`); `None`: each image's own folder.
    dir: Option<PathBuf>,
    /// The `.lbl` files of each folder listed so far, sorted.
    listed: std::collections::BTreeMap<PathBuf, Vec<PathBuf>>,
}

impl DetachedLabels {
    /// Labels searched in `dir`, or (`None`) in each image's own folder.
    pub fn new(dir: Option<&Path>) -> Self {
        DetachedLabels { dir: dir.map(Path::to_path_buf), listed: Default::default() }
    }

    /// The folder searched for the image at `image`.
    pub fn folder_for(&self, image: &Path) -> PathBuf {
        self.dir.clone().unwrap_or_else(|| image.parent().map(Path::to_path_buf).filter(|p| !p.as_os_str().is_empty()).unwrap_or_else(|| PathBuf::from(".")))
    }

    /// The detached label of the image at `image`: the one `.LBL` of its folder
    /// ([`DetachedLabels::folder_for`]) whose name names the image ([`label_names_image`]), an
    /// exact name first. `None` where there is none; an error where the folder cannot be read,
    /// or where more than one label with the version character matches (naming them).
    pub fn of(&mut self, image: &Path) -> Result<Option<PathBuf>, CalibError> {
        let Some(name) = image.file_name().map(|n| n.to_string_lossy().into_owned()) else { return Ok(None) };
        let dir = self.folder_for(image);
        if !self.listed.contains_key(&dir) {
            let entries = std::fs::read_dir(&dir).map_err(|e| CalibError::parse(&dir, format!("reading the folder for {name}'s label: {e}")))?;
            let mut labels: Vec<PathBuf> = entries.filter_map(|e| e.ok()).map(|e| e.path()).filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("lbl"))).collect();
            labels.sort();
            self.listed.insert(dir.clone(), labels);
        }
        let mut matches: Vec<&PathBuf> = self.listed[&dir].iter().filter(|p| p.file_name().is_some_and(|l| label_names_image(&l.to_string_lossy(), &name))).collect();
        let stem = name.rsplit_once('.').map_or(name.as_str(), |(s, _)| s).to_ascii_lowercase();
        let exact = |p: &PathBuf| {
            let l = p.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
            let l = l.strip_suffix(".lbl").unwrap_or(&l).to_string();
            l.strip_suffix(".img").unwrap_or(&l) == stem
        };
        if let Some(p) = matches.iter().find(|p| exact(p)) {
            return Ok(Some((*p).clone()));
        }
        match matches.len() {
            0 => Ok(None),
            1 => Ok(matches.pop().cloned()),
            _ => Err(CalibError::parse(image, format!("{} labels name this image's product (versions): {}; give the one with --rig", matches.len(), matches.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_name_their_images_by_product_name() {
        assert!(label_names_image("NLA_400871510EDR_F0040404NCAM00409M1.LBL", "NLA_400871510EDR_F0040404NCAM00409M_.jpg"));
        assert!(label_names_image("1n579700548ffld2fcp1981l0m1.img.lbl", "1n579700548ffld2fcp1981l0m1.png"));
        assert!(label_names_image("F.lbl", "f.JPG"));
        // Another product, another version of a name without `_`, a label that is no .LBL.
        assert!(!label_names_image("NLA_400871538EDR_F0040404NCAM00409M1.LBL", "NLA_400871510EDR_F0040404NCAM00409M_.jpg"));
        assert!(!label_names_image("NLA_400871510EDR_F0040404NCAM00409M2.LBL", "NLA_400871510EDR_F0040404NCAM00409M1.png"));
        assert!(!label_names_image("NLA_400871510EDR_F0040404NCAM00409M1.txt", "NLA_400871510EDR_F0040404NCAM00409M_.jpg"));
        assert!(!label_names_image("_.lbl", "x"));
    }

    #[test]
    fn a_label_is_found_beside_its_image_or_in_a_folder() {
        let dir = tempfile::tempdir().unwrap();
        let (images, labels) = (dir.path().join("images"), dir.path().join("labels"));
        std::fs::create_dir_all(&images).unwrap();
        std::fs::create_dir_all(&labels).unwrap();
        let image = images.join("NLA_400871510EDR_F0040404NCAM00409M_.jpg");
        std::fs::write(&image, b"").unwrap();
        assert_eq!(DetachedLabels::new(None).of(&image).unwrap(), None);
        let label = labels.join("NLA_400871510EDR_F0040404NCAM00409M1.LBL");
        std::fs::write(&label, b"").unwrap();
        assert_eq!(DetachedLabels::new(Some(&labels)).of(&image).unwrap(), Some(label.clone()));
        // Two versions of the product: refused, naming both; an exact name wins over both.
        std::fs::write(labels.join("NLA_400871510EDR_F0040404NCAM00409M2.LBL"), b"").unwrap();
        let e = DetachedLabels::new(Some(&labels)).of(&image).unwrap_err().to_string();
        assert!(e.contains("2 labels") && e.contains("M1.LBL") && e.contains("M2.LBL"), "{e}");
        let exact = labels.join("NLA_400871510EDR_F0040404NCAM00409M_.lbl");
        std::fs::write(&exact, b"").unwrap();
        assert_eq!(DetachedLabels::new(Some(&labels)).of(&image).unwrap(), Some(exact));
        let e = DetachedLabels::new(Some(&dir.path().join("none"))).of(&image).unwrap_err().to_string();
        assert!(e.contains("none") && e.contains("NLA_400871510EDR_F0040404NCAM00409M_.jpg's label"), "{e}");
    }
}
