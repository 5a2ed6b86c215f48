//! Outputs never overwrite inputs: the one check every subcommand calls before it does any work.
//!
//! Two paths name the same file when they resolve to the same place or to the same file on disk:
//!
//! * an existing path is canonicalized (symbolic links, `.` and `..` resolved);
//! * an output that does not exist yet is its canonicalized folder joined with its file name (so
//!   `out/../data.csv` and `./data.csv` are the same);
//! * two existing files that are hard links of one another (same device and inode) are the same file,
//!   whatever their names.
//!
//! A clash is bad usage: a one-line [`CliError::Input`] (exit 2) naming the output flag, its path and
//! the input it would overwrite, before anything is written.

use super::shared::CliError;
use std::path::{Component, Path, PathBuf};

/// Where a path leads: its resolved location and, for an existing file, its device and inode.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Identity {
    /// Canonical path (existing), or canonical folder joined with the file name (not yet existing).
    location: PathBuf,
    /// `(device, inode)` of an existing file.
    inode: Option<(u64, u64)>,
}

impl Identity {
    fn same(&self, other: &Identity) -> bool {
        self.location == other.location
            || matches!((self.inode, other.inode), (Some(a), Some(b)) if a == b)
    }
}

#[cfg(unix)]
fn inode(meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn inode(_meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    None
}

/// `path` made absolute and with `.` and `..` folded lexically (the fallback when nothing of it exists).
fn lexical(path: &Path) -> PathBuf {
    let abs = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    let mut out = PathBuf::new();
    for c in abs.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// The identity of `path` (see the module docs).
fn identity(path: &Path) -> Identity {
    if let Ok(location) = std::fs::canonicalize(path) {
        let inode = std::fs::metadata(&location).ok().as_ref().and_then(inode);
        return Identity { location, inode };
    }
    // Not there (yet): its folder resolved, joined with its name.
    let location = match (path.parent(), path.file_name()) {
        (Some(parent), Some(name)) => {
            let parent = if parent.as_os_str().is_empty() {
                Path::new(".")
            } else {
                parent
            };
            match std::fs::canonicalize(parent) {
                Ok(p) => p.join(name),
                Err(_) => lexical(path),
            }
        }
        _ => lexical(path),
    };
    Identity {
        location,
        inode: None,
    }
}

/// The files a command reads, each with the flag (or scenario key) that names it.
#[derive(Debug, Default)]
pub(crate) struct Inputs {
    files: Vec<(String, PathBuf, Identity)>,
}

impl Inputs {
    /// No inputs yet.
    pub(crate) fn new() -> Inputs {
        Inputs::default()
    }

    /// Adds the input `path` named by `flag` (e.g. `--data`).
    pub(crate) fn add(&mut self, flag: &str, path: &Path) -> &mut Inputs {
        self.files
            .push((flag.to_string(), path.to_path_buf(), identity(path)));
        self
    }

    /// Adds `--robot` when it names a file rather than a built-in robot.
    pub(crate) fn add_robot(&mut self, robot: &str) -> &mut Inputs {
        let p = Path::new(robot);
        if p.exists() {
            self.add("--robot", p);
        }
        self
    }

    /// Adds the scenario file named by `flag` and the files it refers to (`[robot] urdf`,
    /// `[campaign.file] path`, relative to the scenario's folder).
    pub(crate) fn add_scenario(
        &mut self,
        flag: &str,
        path: &Path,
        scenario: &sim::scenario::Scenario,
    ) -> &mut Inputs {
        self.add(flag, path);
        let label = path.display();
        if let Some(u) = &scenario.file.robot.urdf {
            self.add(
                &format!("{flag} {label}: robot.urdf"),
                &scenario.base_dir.join(u),
            );
        }
        if let Some(f) = &scenario.file.campaign.file {
            self.add(
                &format!("{flag} {label}: campaign.file.path"),
                &scenario.base_dir.join(&f.path),
            );
        }
        self
    }

    /// Refuses the output `path` (named by `flag`) when it is one of the inputs.
    pub(crate) fn check(&self, flag: &str, path: &Path) -> Result<(), CliError> {
        self.check_as(flag, path, path)
    }

    /// Like [`Inputs::check`], for a file `path` that the output `shown` (named by `flag`) writes,
    /// e.g. a file inside an output folder, or the plot beside an output table.
    pub(crate) fn check_as(&self, flag: &str, shown: &Path, path: &Path) -> Result<(), CliError> {
        let id = identity(path);
        for (in_flag, in_path, in_id) in &self.files {
            if id.same(in_id) {
                let what = if shown == path {
                    String::new()
                } else {
                    format!(" (it writes {})", path.display())
                };
                let link = if id.location != in_id.location {
                    ", a hard link of it"
                } else {
                    ""
                };
                return Err(CliError::Input(format!(
                    "{flag} {}: would overwrite the input {in_flag} {}{link}{what}; choose another output path",
                    shown.display(),
                    in_path.display()
                )));
            }
        }
        Ok(())
    }

    /// Refuses an output folder `dir` (named by `flag`) that is an input itself, or in which one of
    /// `names` (the files the command writes there, relative to `dir`) is an input.
    pub(crate) fn check_dir(&self, flag: &str, dir: &Path, names: &[&str]) -> Result<(), CliError> {
        self.check(flag, dir)?;
        for n in names {
            self.check_as(flag, dir, &dir.join(n))?;
        }
        Ok(())
    }
}

/// Refuses two outputs that name the same file (`--out` and `--urdf-out`, say).
pub(crate) fn check_distinct(a: (&str, &Path), b: (&str, &Path)) -> Result<(), CliError> {
    if identity(a.1).same(&identity(b.1)) {
        return Err(CliError::Input(format!(
            "{} {}: the same file as {} {}; the two outputs need different paths",
            b.0,
            b.1.display(),
            a.0,
            a.1.display()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("robocal-paths-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn same_file_by_name_dots_links_and_inode() {
        let d = temp("same");
        let data = d.join("data.csv");
        std::fs::write(&data, "x").unwrap();
        std::fs::create_dir_all(d.join("sub")).unwrap();
        let mut inputs = Inputs::new();
        inputs.add("--data", &data);
        // The same name, through `..`.
        let e = inputs
            .check("--out", &d.join("sub/../data.csv"))
            .unwrap_err();
        assert_eq!(e.exit_code(), 2);
        assert!(e.to_string().contains("--data"), "{e}");
        // A hard link under another name.
        let link = d.join("link.csv");
        std::fs::hard_link(&data, &link).unwrap();
        let e = inputs.check("--out", &link).unwrap_err().to_string();
        assert!(e.contains("hard link"), "{e}");
        // A symbolic link.
        #[cfg(unix)]
        {
            let sym = d.join("sym.csv");
            std::os::unix::fs::symlink(&data, &sym).unwrap();
            assert!(inputs.check("--out", &sym).is_err());
        }
        // Another file, existing or not.
        assert!(inputs.check("--out", &d.join("other.csv")).is_ok());
        assert!(inputs.check("--out", &d.join("sub/new.csv")).is_ok());
        assert!(inputs.check("--out", &d.join("no/such/x.csv")).is_ok());
        // Inside an output folder.
        assert!(inputs.check_dir("--out", &d, &["data.csv"]).is_err());
        assert!(inputs.check_dir("--out", &d, &["m.parquet"]).is_ok());
        assert!(check_distinct(("--out", &data), ("--urdf-out", &link)).is_err());
        assert!(check_distinct(("--out", &data), ("--urdf-out", &d.join("u.urdf"))).is_ok());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
