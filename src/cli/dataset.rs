//! `robocal dataset`: write a versioned benchmark suite with its SHA-256 manifest (see `crate::dataset`).

use super::shared::{CliError, CliResult, print_json};
use crate::dataset::{self, SUITES};
use std::path::PathBuf;

/// Arguments of `robocal dataset`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Suite to write, e.g. `iiwa7-v1` (see --list).
    #[arg(long, value_name = "NAME", required_unless_present = "list")]
    suite: Option<String>,
    /// Output folder (created if missing); an earlier suite in it is replaced as a whole, other
    /// entries are kept.
    #[arg(long, value_name = "DIR", required_unless_present = "list")]
    out: Option<PathBuf>,
    /// List the suites and exit.
    #[arg(long)]
    list: bool,
    /// Print the manifest summary as one JSON document on stdout.
    #[arg(long)]
    json: bool,
}

/// Runs `robocal dataset`.
pub fn run(args: Args) -> CliResult {
    if args.list {
        if args.json {
            return print_json(&serde_json::json!(
                SUITES
                    .iter()
                    .map(|s| serde_json::json!({
                        "name": s.name, "version": s.version, "description": s.description,
                        "datasets": s.datasets.iter().map(|d| d.name).collect::<Vec<_>>(),
                    }))
                    .collect::<Vec<_>>()
            ));
        }
        for s in SUITES {
            let names: Vec<&str> = s.datasets.iter().map(|d| d.name).collect();
            eprintln!("{}: {} [{}]", s.name, s.description, names.join(", "));
        }
        return Ok(());
    }
    let (Some(name), Some(out)) = (args.suite.as_deref(), args.out.as_ref()) else {
        return Err(CliError::Input(
            "--suite and --out are required (or --list)".into(),
        ));
    };
    let suite = dataset::find(name).ok_or_else(|| {
        CliError::Input(format!(
            "--suite {name}: unknown suite (known: {})",
            SUITES.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
        ))
    })?;
    let files = dataset::write_suite(suite, out)?;
    let bytes: u64 = files.iter().map(|f| f.bytes).sum();
    eprintln!(
        "wrote suite {} ({} datasets, {} files, {:.1} MB) to {}; verify with: cd {} && sha256sum -c MANIFEST.sha256",
        suite.name,
        suite.datasets.len(),
        files.len() + 2,
        bytes as f64 / 1e6,
        out.display(),
        out.display()
    );
    let [m, s] = dataset::manifest_paths(out);
    if args.json {
        return print_json(&serde_json::json!({
            "suite": suite.name, "out": out.display().to_string(),
            "manifest": m.display().to_string(), "checksums": s.display().to_string(),
            "files": files,
        }));
    }
    Ok(())
}
