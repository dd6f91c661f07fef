//! The frames of a batch run: read from a folder or a list file, sorted, paired with their right
//! frames, named by their image file stems, and split into shards.

use super::Frame;
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tubeloc_detect::input::{has_image_extension, IMAGE_EXTENSIONS};

/// The image paths of `--images`/`--right-images` (`flag` names it in errors), sorted: a
/// folder's image files ([`tubeloc_detect::input::IMAGE_EXTENSIONS`], not its subfolders; a
/// PDS3 product's detached `.lbl` label in place of its `.img` of the same stem), or a list
/// file's lines (paths relative to the list's folder; blank lines and lines starting with `#`
/// skipped).
pub fn image_paths(arg: &Path, flag: &str) -> Result<Vec<PathBuf>> {
    let mut paths = Vec::new();
    if arg.is_dir() {
        paths = tubeloc_detect::input::image_files(arg).with_context(|| format!("{flag} {}: reading the folder", arg.display()))?;
    } else {
        if (has_image_extension(arg) || has_extension(arg, "lbl")) && arg.is_file() {
            bail!("{flag} {}: an image file; {flag} takes a folder of images or a list file of image paths (for one image, give {})", arg.display(), if flag.starts_with("--right") { "--right" } else { "--image" });
        }
        let text = std::fs::read_to_string(arg).with_context(|| format!("{flag} {}: not a folder, and not readable as a list file", arg.display()))?;
        let base = arg.parent().unwrap_or(Path::new(""));
        for line in text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')) {
            paths.push(base.join(line));
        }
    }
    if paths.is_empty() {
        bail!("{flag} {}: no images (a folder's image files: {}; or a list file of image paths)", arg.display(), IMAGE_EXTENSIONS.map(|e| format!(".{e}")).join(" "));
    }
    paths.sort();
    Ok(paths)
}

/// Whether `path`'s extension is `ext` (any case).
fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

/// The frames of a batch run in sorted order: the left images, each paired with the right image
/// of the same rank when `right` is given. Refuses lists of different lengths and two frames
/// whose image file stems (their result names) are equal.
pub fn frame_list(images: &Path, right: Option<&Path>) -> Result<Vec<Frame>> {
    let left = image_paths(images, "--images")?;
    let right = match right {
        Some(r) => {
            let list = image_paths(r, "--right-images")?;
            if list.len() != left.len() {
                bail!("--right-images {} has {} images but --images {} has {}: each left frame needs its right frame", r.display(), list.len(), images.display(), left.len());
            }
            list.into_iter().map(Some).collect()
        }
        None => vec![None; left.len()],
    };
    let frames: Vec<Frame> = left.into_iter().zip(right).map(|(image, right)| Frame { image, right }).collect();
    let mut seen: BTreeMap<String, &Path> = BTreeMap::new();
    for f in &frames {
        let name = result_name(&f.image);
        if let Some(other) = seen.insert(name.clone(), &f.image) {
            bail!("--images {}: frames {} and {} would both write frames/{name}.json: image file names must be unique in a batch", images.display(), other.display(), f.image.display());
        }
    }
    Ok(frames)
}

/// The name of a frame's result files: its image file stem.
pub fn result_name(image: &Path) -> String {
    image.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The indices of the frames of shard `index` of `count`: frame k goes to shard k mod count.
pub fn shard_indices(frames: usize, (index, count): (usize, usize)) -> impl Iterator<Item = usize> {
    (index..frames).step_by(count.max(1))
}

/// A digest of the frame list (CRC-32 of its paths, left and right, one a line, hex): equal in
/// every shard of one batch, so `merge` can refuse shards of different lists.
pub fn list_digest(frames: &[Frame]) -> String {
    let mut h = crc32fast::Hasher::new();
    for f in frames {
        h.update(f.image.to_string_lossy().as_bytes());
        if let Some(r) = &f.right {
            h.update(b"\t");
            h.update(r.to_string_lossy().as_bytes());
        }
        h.update(b"\n");
    }
    format!("{:08x}", h.finalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_the_frames_by_rank_modulo_the_count() {
        let all: Vec<usize> = (0..3).flat_map(|i| shard_indices(10, (i, 3))).collect();
        let mut sorted = all.clone();
        sorted.sort();
        assert_eq!(sorted, (0..10).collect::<Vec<_>>());
        assert_eq!(shard_indices(10, (1, 3)).collect::<Vec<_>>(), [1, 4, 7]);
        assert_eq!(shard_indices(2, (3, 4)).count(), 0);
    }

    #[test]
    fn a_list_file_is_read_relative_to_its_folder_sorted_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let list = dir.path().join("list.txt");
        std::fs::write(&list, "# frames\nb/f2.png\n\n a/f1.png \n").unwrap();
        let frames = frame_list(&list, None).unwrap();
        assert_eq!(frames.iter().map(|f| f.image.clone()).collect::<Vec<_>>(), [dir.path().join("a/f1.png"), dir.path().join("b/f2.png")]);
        std::fs::write(&list, "a/f1.png\nb/f1.png\n").unwrap();
        let e = frame_list(&list, None).unwrap_err().to_string();
        assert!(e.contains("frames/f1.json") && e.contains("unique"), "{e}");
        let right = dir.path().join("right.txt");
        std::fs::write(&right, "r1.png\n").unwrap();
        std::fs::write(&list, "a/f1.png\nb/f2.png\n").unwrap();
        let e = frame_list(&list, Some(&right)).unwrap_err().to_string();
        assert!(e.contains("has 1 images but --images") && e.contains("has 2"), "{e}");
        std::fs::write(&list, "# nothing\n").unwrap();
        let e = frame_list(&list, None).unwrap_err().to_string();
        assert!(e.contains("no images"), "{e}");
        // One image given where a folder or list is expected: says so, and names --image.
        let png = dir.path().join("frame.PNG");
        std::fs::write(&png, [0x89, b'P', b'N', b'G']).unwrap();
        let e = frame_list(&png, None).unwrap_err().to_string();
        assert!(e.contains("frame.PNG: an image file") && e.contains("give --image"), "{e}");
        std::fs::write(&list, "a/f1.png\n").unwrap();
        let e = frame_list(&list, Some(&png)).unwrap_err().to_string();
        assert!(e.contains("--right-images") && e.contains("give --right"), "{e}");
    }

    #[test]
    fn a_folder_lists_every_image_format_and_a_detached_label_in_place_of_its_product() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.tif", "b.PGM", "c.IMG", "c.LBL", "d.img", "e.lbl", "f.webp", "g.bmp", "notes.txt", "h.ppm"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        std::fs::create_dir(dir.path().join("sub.png")).unwrap();
        let names: Vec<String> = image_paths(dir.path(), "--images").unwrap().iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
        assert_eq!(names, ["a.tif", "b.PGM", "c.LBL", "d.img", "f.webp", "g.bmp", "h.ppm"]);
        // A label given where a folder or list is expected is an image, not a list file.
        let e = image_paths(&dir.path().join("c.LBL"), "--images").unwrap_err().to_string();
        assert!(e.contains("c.LBL: an image file") && e.contains("give --image"), "{e}");
        let empty = tempfile::tempdir().unwrap();
        std::fs::write(empty.path().join("readme.md"), b"x").unwrap();
        let e = image_paths(empty.path(), "--images").unwrap_err().to_string();
        assert!(e.contains("no images") && e.contains(".tiff") && e.contains(".pgm"), "{e}");
    }
}
