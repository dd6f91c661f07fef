//! The shipped learned model, embedded in the library when it is built, so that a program using
//! it (an installed or copied `tubeloc`) needs no data folder at run time.
//!
//! The bytes are those of `data/models/tubenet.safetensors` (see `data/models/README.md` for the
//! command that trains it); they are checked like any model file (format, version, checksum,
//! tensor shapes) when parsed.

use super::{LearnedError, LearnedModel};
use std::path::Path;

/// The file the embedded bytes come from, relative to the workspace root; names the model in
/// error messages and reports.
pub const SHIPPED_MODEL_NAME: &str = "data/models/tubenet.safetensors";

/// The shipped model's safetensors bytes (`tubeloc train`'s format).
pub const SHIPPED_MODEL_BYTES: &[u8] = include_bytes!("../../../data/models/tubenet.safetensors");

/// Parses the embedded shipped model.
pub fn shipped_model() -> Result<LearnedModel, LearnedError> {
    LearnedModel::from_bytes(SHIPPED_MODEL_BYTES, Path::new(SHIPPED_MODEL_NAME))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_model_is_the_shipped_file_and_parses() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(SHIPPED_MODEL_NAME);
        assert_eq!(std::fs::read(&file).unwrap(), SHIPPED_MODEL_BYTES, "the embedded bytes are the file's");
        let embedded = shipped_model().unwrap();
        let loaded = LearnedModel::load(&file).unwrap();
        assert_eq!(embedded.to_bytes().unwrap(), loaded.to_bytes().unwrap());
    }
}
