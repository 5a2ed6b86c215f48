//! Versioned benchmark suites (`robocal dataset`): fixed scenarios, generated with fixed seeds, split
//! into training and test files, with their truth and a SHA-256 manifest.
//!
//! A suite is frozen: its scenario texts are copies kept in `suites/NAME/` and compiled into the
//! binary, its seeds and splits are constants here. The same suite written by the same software
//! version gives the same bytes (the generator is deterministic, `sim::generate`; the manifest lists
//! files in sorted order and records no time or path). A change that alters any byte needs a new suite
//! name (`-v2`), never an edit of an existing one.
//!
//! Layout of `DIR` for each dataset `D` of the suite:
//!
//! * `D/scenario.toml`: the scenario text;
//! * `D/train.parquet`, `D/test.parquet`: the measurement contract, split by pose
//!   (`calib::model::stats::split_by_pose` with the suite's test fraction and split seed);
//! * `D/measurements.parquet`: all rows (train ∪ test), `D/truth.parquet` (per row, in the order of
//!   `measurements.parquet`; join on `pose`) and `D/truth.json`, as `robocal generate` writes them;
//!
//! and `DIR/manifest.json` (suite, version, software version, datasets, every file with its size and
//! SHA-256) and `DIR/MANIFEST.sha256` (every other file, in `sha256sum -c` format).

use crate::error::CliError;
use sha2::{Digest, Sha256};
use sim::io::write_atomic;
use sim::scenario::{Overrides, Scenario};
use std::path::{Path, PathBuf};

/// One dataset of a suite.
#[derive(Clone, Copy, Debug)]
pub struct DatasetDef {
    /// Folder name inside the suite's output.
    pub name: &'static str,
    /// Scenario file name (as shipped in `suites/`).
    pub scenario_file: &'static str,
    /// Scenario text (frozen copy).
    pub scenario_text: &'static str,
    /// Generation seed (`robocal generate --seed`).
    pub seed: u64,
    /// Fraction of the poses in `test.parquet`.
    pub test_fraction: f64,
    /// Seed of the train/test split.
    pub split_seed: u64,
}

/// A versioned suite.
#[derive(Clone, Copy, Debug)]
pub struct Suite {
    /// Name with version suffix, e.g. `iiwa7-v1`.
    pub name: &'static str,
    /// Suite version (the number after `-v`).
    pub version: u32,
    /// One line for `--list`.
    pub description: &'static str,
    /// Its datasets.
    pub datasets: &'static [DatasetDef],
}

macro_rules! frozen {
    ($suite:literal, $name:literal, $file:literal, $seed:expr) => {
        DatasetDef {
            name: $name,
            scenario_file: $file,
            scenario_text: include_str!(concat!("../suites/", $suite, "/", $file)),
            seed: $seed,
            test_fraction: 0.3,
            split_seed: 0,
        }
    };
}

/// The suites this version can write.
pub const SUITES: &[Suite] = &[
    Suite {
        name: "iiwa7-v1",
        version: 1,
        description: "KUKA iiwa 7, 200 random poses each: clean (noise only), kinematic, compliance, \
                      backlash, thermal, all effects; 70/30 train/test split by pose",
        datasets: &[
            frozen!("iiwa7-v1", "clean", "iiwa7_clean.toml", 101),
            frozen!("iiwa7-v1", "kinematic", "iiwa7_kinematic.toml", 102),
            frozen!("iiwa7-v1", "compliance", "iiwa7_compliance.toml", 103),
            frozen!("iiwa7-v1", "backlash", "iiwa7_backlash.toml", 104),
            frozen!("iiwa7-v1", "thermal", "iiwa7_thermal.toml", 105),
            frozen!("iiwa7-v1", "all", "iiwa7_all.toml", 106),
        ],
    },
    Suite {
        name: "ur5-v1",
        version: 1,
        description: "UR5, 200 random poses with geometric errors; 70/30 train/test split by pose",
        datasets: &[frozen!("ur5-v1", "kinematic", "ur5_kinematic.toml", 201)],
    },
];

/// The suite called `name`.
pub fn find(name: &str) -> Option<&'static Suite> {
    SUITES.iter().find(|s| s.name == name)
}

/// Lowercase hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let d = Sha256::digest(bytes);
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// A file operation of the suite's own output that failed: a runtime failure naming the path.
fn io(path: &Path, e: impl std::fmt::Display) -> CliError {
    CliError::Runtime(format!("{}: {e}", path.display()))
}

/// One file of the written suite.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FileEntry {
    /// Path relative to the suite folder, `/`-separated.
    pub path: String,
    /// Size in bytes.
    pub bytes: u64,
    /// SHA-256, lowercase hex.
    pub sha256: String,
}

/// Writes `suite` into `out` (created if missing). The suite replaces an earlier one as a whole
/// ([`sim::io::StagedDir`]: every file is written into a staging folder beside `out`, then the set is
/// moved in; entries of `out` that are not the suite's dataset folders or manifest files are kept).
/// Returns the files written (manifest files excluded), in sorted order.
///
/// # Errors
/// Bad input when a frozen scenario is refused; a runtime failure when a file cannot be written.
pub fn write_suite(suite: &Suite, out: &Path) -> Result<Vec<FileEntry>, CliError> {
    let stage = sim::io::StagedDir::new(out)?;
    // Messages name the folder the user gave, not the staging folder.
    let (staged, shown) = (
        stage.path().display().to_string(),
        out.display().to_string(),
    );
    let files = write_suite_into(suite, stage.path()).map_err(|e| match e {
        CliError::Input(m) => CliError::Input(m.replace(&staged, &shown)),
        CliError::Runtime(m) => CliError::Runtime(m.replace(&staged, &shown)),
    })?;
    let [m, s] = manifest_paths(Path::new(""));
    let ours = |name: &str| {
        suite.datasets.iter().any(|d| d.name == name)
            || Path::new(name) == m
            || Path::new(name) == s
    };
    stage.commit(&ours)?;
    Ok(files)
}

/// Writes `suite` into the existing folder `out` (see [`write_suite`]).
fn write_suite_into(suite: &Suite, out: &Path) -> Result<Vec<FileEntry>, CliError> {
    let mut rel: Vec<String> = Vec::new();
    let mut datasets = Vec::new();
    for d in suite.datasets {
        let dir = out.join(d.name);
        let label = d.scenario_file;
        let in_suite =
            |e: sim::SimError| CliError::from(e).prefixed(&format!("suite {}", suite.name));
        let scenario = Scenario::parse(d.scenario_text, label, Path::new(".")).map_err(in_suite)?;
        let res = scenario
            .resolve(&Overrides {
                seed: Some(d.seed),
                ..Overrides::default()
            })
            .map_err(in_suite)?;
        let summary = sim::generate::generate(&res, &dir, None).map_err(in_suite)?;
        write_atomic(&dir.join("scenario.toml"), d.scenario_text.as_bytes())?;
        let all_path = dir.join(sim::generate::MEASUREMENTS_FILE);
        // The file was written a moment ago: failing to read it back is a runtime failure.
        let table = sim::measurement_table::read(&all_path)
            .map_err(|e| CliError::Runtime(e.to_string()))?;
        let (train, test) =
            calib::model::stats::split_by_pose(&table, d.test_fraction, d.split_seed);
        for (name, rows) in [("train.parquet", &train), ("test.parquet", &test)] {
            let p = dir.join(name);
            sim::measurement_table::write(&p, &table.select_rows(rows))?;
        }
        for f in [
            "scenario.toml",
            "train.parquet",
            "test.parquet",
            sim::generate::MEASUREMENTS_FILE,
            sim::generate::TRUTH_PARQUET_FILE,
            sim::generate::TRUTH_JSON_FILE,
        ] {
            rel.push(format!("{}/{f}", d.name));
        }
        let poses_of = |rows: &[usize]| {
            let mut p: Vec<i64> = rows.iter().map(|&r| table.pose[r]).collect();
            p.dedup();
            p.len()
        };
        datasets.push(serde_json::json!({
            "name": d.name,
            "scenario_file": d.scenario_file,
            "robot": summary.robot,
            "seed": d.seed,
            "poses": summary.poses,
            "rows": summary.rows,
            "noise_scale": summary.noise_scale,
            "split": {
                "rule": "calib::model::stats::split_by_pose (robocal calibrate --test-fraction F --seed S)",
                "test_fraction": d.test_fraction, "seed": d.split_seed,
                "train_rows": train.len(), "test_rows": test.len(),
                "train_poses": poses_of(&train), "test_poses": poses_of(&test),
            },
            "reproduce": format!(
                "robocal generate --scenario {}/scenario.toml --seed {} --out regenerated/{}",
                d.name, d.seed, d.name
            ),
        }));
    }
    rel.sort();
    let mut files = Vec::with_capacity(rel.len());
    for r in &rel {
        let p = out.join(r);
        let bytes = std::fs::read(&p).map_err(|e| io(&p, e))?;
        files.push(FileEntry {
            path: r.clone(),
            bytes: bytes.len() as u64,
            sha256: sha256_hex(&bytes),
        });
    }
    let manifest = serde_json::json!({
        "suite": suite.name,
        "version": suite.version,
        "description": suite.description,
        "software": {"name": "robocal", "version": env!("CARGO_PKG_VERSION")},
        "datasets": datasets,
        "files": files,
        "checksums": "MANIFEST.sha256 (sha256sum -c MANIFEST.sha256 in this folder)",
    });
    let mut text = serde_json::to_string_pretty(&manifest)
        .map_err(|e| CliError::Runtime(format!("manifest: {e}")))?;
    text.push('\n');
    let manifest_path = out.join("manifest.json");
    write_atomic(&manifest_path, text.as_bytes())?;
    let mut sums = String::new();
    let mut all = files.clone();
    all.push(FileEntry {
        path: "manifest.json".into(),
        bytes: text.len() as u64,
        sha256: sha256_hex(text.as_bytes()),
    });
    all.sort_by(|a, b| a.path.cmp(&b.path));
    for f in &all {
        sums.push_str(&format!("{}  {}\n", f.sha256, f.path));
    }
    write_atomic(&out.join("MANIFEST.sha256"), sums.as_bytes())?;
    Ok(files)
}

/// Paths of a suite's manifest files inside `out`.
pub fn manifest_paths(out: &Path) -> [PathBuf; 2] {
    [out.join("manifest.json"), out.join("MANIFEST.sha256")]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_matches_the_fips_180_examples() {
        // FIPS 180-2, appendix B.1 ("abc") and the empty message.
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(
            sha256_hex(b""),
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
        );
    }

    #[test]
    fn frozen_scenarios_parse_and_names_are_unique() {
        for s in SUITES {
            assert!(s.name.ends_with(&format!("-v{}", s.version)), "{}", s.name);
            let mut names: Vec<&str> = s.datasets.iter().map(|d| d.name).collect();
            names.sort_unstable();
            names.dedup();
            assert_eq!(names.len(), s.datasets.len());
            for d in s.datasets {
                Scenario::parse(d.scenario_text, d.scenario_file, Path::new("."))
                    .unwrap()
                    .resolve(&Overrides::default())
                    .unwrap();
            }
        }
        assert!(find("iiwa7-v1").is_some() && find("iiwa7").is_none());
    }
}
