//! What the CLI tests that draw their cases from a seed share: the seed, a scratch folder and a
//! `robocal` run that must succeed.
#![allow(dead_code)]

use std::path::PathBuf;

/// The repository (the root package's folder).
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// An empty folder `<temp>/<prefix>_<process id>_<name>` (emptied when it exists).
pub fn scratch_dir(prefix: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("{prefix}_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs robocal with `args`, asserting exit 0 (the message has stderr); `(stdout, stderr)`.
pub fn robocal_ok(args: &[&str]) -> (String, String) {
    let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal");
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
    (out, err)
}

/// Runs robocal with `args`, whatever its exit; `(exit code, stderr)`.
pub fn robocal_status(args: &[&str]) -> (Option<i32>, String) {
    let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The run's seed: `ROBOCAL_TEST_SEED`, or drawn from the clock.
pub fn seed() -> u64 {
    std::env::var("ROBOCAL_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos() as u64
        })
}

/// Runs `robocal generate --scenario SCENARIO --out OUT` with `extra` flags (asserting exit 0);
/// the measurement file it wrote.
pub fn generate(scenario: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> PathBuf {
    let mut args = vec![
        "generate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    robocal_ok(&args);
    out.join("measurements.parquet")
}
