//! Real PDS3 products decoded against the PNGs made from them for `../shared/data/real_mars`
//! (`backgrounds/pds_products`: the data stretched linearly from DN `lo..hi` to 0..255, as its
//! `MANIFEST.tsv` says). The products themselves are not in the shared data: this runs when
//! `TUBELOC_PDS_PRODUCTS` names a folder holding them (the `.IMG` files of the MarsRaw/vicar-rs
//! test data), and is skipped otherwise:
//!
//! ```sh
//! TUBELOC_PDS_PRODUCTS=DIR cargo test --release -p tubeloc-detect --test integration pds3_products:: -- --ignored
//! ```

use std::path::{Path, PathBuf};

fn shared() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars")
}

#[test]
#[ignore = "needs TUBELOC_PDS_PRODUCTS: a folder with the real PDS3 products"]
fn real_products_decode_to_the_data_of_their_pngs() {
    let dir = PathBuf::from(std::env::var("TUBELOC_PDS_PRODUCTS").expect("TUBELOC_PDS_PRODUCTS names the products' folder"));
    let manifest = std::fs::read_to_string(shared().join("MANIFEST.tsv")).unwrap();
    let mut checked = 0;
    for line in manifest.lines().filter(|l| l.starts_with("backgrounds/pds_products/")) {
        let cols: Vec<&str> = line.split('\t').collect();
        let png = shared().join(cols[0]);
        let product = cols.iter().find(|c| c.to_ascii_lowercase().ends_with(".img")).map(|c| Path::new(c).file_name().unwrap().to_owned()).unwrap();
        let path = dir.join(&product);
        if !path.exists() {
            eprintln!("skipped: {} is not in {}", product.to_string_lossy(), dir.display());
            continue;
        }
        // "linear stretch DN 562.0..1959.0".
        let stretch = cols.iter().find(|c| c.contains("linear stretch DN")).unwrap();
        let range = stretch.split("linear stretch DN ").nth(1).unwrap().split_whitespace().next().unwrap();
        let (lo, hi) = range.split_once("..").unwrap();
        let (lo, hi): (f64, f64) = (lo.parse().unwrap(), hi.parse().unwrap());
        let img = tubeloc_detect::input::open_image(&path).unwrap();
        let data = img.as_luma16().expect("12-bit data in 16-bit samples");
        let expected = image::open(&png).unwrap().to_luma8();
        assert_eq!(data.dimensions(), expected.dimensions(), "{}", path.display());
        let mut worst = 0i32;
        for (d, e) in data.pixels().zip(expected.pixels()) {
            let v = ((d.0[0] as f64 - lo) / (hi - lo) * 255.0).clamp(0.0, 255.0);
            worst = worst.max((v.round() as i32 - e.0[0] as i32).abs());
        }
        eprintln!("{}: {}x{}, largest difference {worst} DN", product.to_string_lossy(), data.width(), data.height());
        assert!(worst <= 1, "{}: {worst}", path.display());
        assert_eq!(tubeloc_detect::input::image_size(&path).unwrap(), data.dimensions());
        checked += 1;
    }
    assert!(checked > 0, "no product found in {}", dir.display());
}
