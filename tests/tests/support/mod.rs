//! What the integration tests of this crate share.

use std::path::{Path, PathBuf};

/// A folder `name` under the tests' target tmp folder, its previous content removed (a later
/// test run replaces it, nothing accumulates). Not created.
pub fn fresh_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    d
}
