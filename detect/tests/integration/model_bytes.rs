//! The same model gives the same bytes (hardening issue, item 7): the safetensors metadata is
//! written in key order, not in a `HashMap`'s randomly seeded order.

use tubeloc_detect::learned::{LearnedModel, Preprocess};

#[test]
fn same_model_same_bytes_and_sorted_metadata() {
    let model = LearnedModel::new(Preprocess::default(), 4, 3).unwrap();
    let first = model.to_bytes().unwrap();
    // Every `HashMap` gets new hash keys, so unsorted metadata changed order between calls.
    for _ in 0..16 {
        assert!(model.to_bytes().unwrap() == first, "to_bytes is not byte-stable");
    }
    let n = u64::from_le_bytes(first[..8].try_into().unwrap()) as usize;
    assert_eq!(n % 8, 0, "header not 8-byte aligned");
    let header = std::str::from_utf8(&first[8..8 + n]).unwrap();
    assert!(header.starts_with("{\"__metadata__\":{"), "{header:.80}");
    let keys = ["\"checksum\"", "\"format\"", "\"format_version\"", "\"meta\""];
    let pos: Vec<usize> = keys.iter().map(|k| header.find(k).unwrap_or_else(|| panic!("{k} missing"))).collect();
    assert!(pos.windows(2).all(|w| w[0] < w[1]), "metadata keys not sorted: {pos:?}");
    // Still a valid model file, identical after a save/load round trip; two saves, same bytes.
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.safetensors"), dir.path().join("b.safetensors"));
    model.save(&a).unwrap();
    let back = LearnedModel::load(&a).unwrap();
    back.save(&b).unwrap();
    assert!(std::fs::read(&a).unwrap() == first);
    assert!(std::fs::read(&b).unwrap() == first, "save -> load -> save changed the bytes");
    // Another model with the same seed: the same bytes too.
    assert!(LearnedModel::new(Preprocess::default(), 4, 3).unwrap().to_bytes().unwrap() == first);
}
