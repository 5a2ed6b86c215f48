//! Paths shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// The repository root (the workspace folder).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The project's shared folder (`ROBOCAL_SHARED`, else `../shared` beside the checkout).
pub fn shared_dir() -> PathBuf {
    std::env::var_os("ROBOCAL_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join("..").join("shared"))
}
