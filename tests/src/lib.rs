//! Integration tests across tubeloc crates live in `tests/tests/`.
