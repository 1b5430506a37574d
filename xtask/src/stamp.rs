//! The stamp every artefact carries: git revision, host (name, cores), mode, seeds and the
//! time the run started, so a number can always be traced to what produced it.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use serde::{Deserialize, Serialize};

/// Provenance of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Stamp {
    /// `git rev-parse --short HEAD` (with `-dirty` when the work tree has changes), or
    /// `unknown`.
    pub git_revision: String,
    /// Host name, or `unknown`.
    pub host: String,
    /// Cores available to the process.
    pub nproc: usize,
    /// `quick` or `full`.
    pub mode: String,
    /// Seeds by what they drive.
    pub seeds: BTreeMap<String, u64>,
    /// Start of the run, seconds since the Unix epoch.
    pub started_unix: u64,
}

fn git(root: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .args(args)
        .current_dir(root)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// The git revision of the work tree at `root`.
pub fn git_revision(root: &Path) -> String {
    match git(root, &["rev-parse", "--short", "HEAD"]) {
        Some(rev) if !rev.is_empty() => {
            let dirty = git(root, &["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty { format!("{rev}-dirty") } else { rev }
        }
        _ => "unknown".into(),
    }
}

/// The host name (from `/etc/hostname`, `$HOSTNAME` or `hostname`).
pub fn host_name() -> String {
    let read = std::fs::read_to_string("/etc/hostname")
        .ok()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty());
    read.or_else(|| std::env::var("HOSTNAME").ok().filter(|s| !s.is_empty()))
        .or_else(|| {
            Command::new("hostname")
                .output()
                .ok()
                .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
                .filter(|s| !s.is_empty())
        })
        .unwrap_or_else(|| "unknown".into())
}

impl Stamp {
    /// Stamp of a run starting now.
    pub fn now(root: &Path, mode: &str, seeds: BTreeMap<String, u64>) -> Self {
        Self {
            git_revision: git_revision(root),
            host: host_name(),
            nproc: std::thread::available_parallelism().map_or(1, |n| n.get()),
            mode: mode.into(),
            seeds,
            started_unix: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
        }
    }

    /// One Markdown line.
    pub fn markdown(&self) -> String {
        let seeds: Vec<String> = self
            .seeds
            .iter()
            .map(|(k, v)| format!("{k} = {v}"))
            .collect();
        format!(
            "Revision `{}`, host `{}` ({} cores), mode `{}`, started at Unix time {}; seeds: {}.",
            self.git_revision,
            self.host,
            self.nproc,
            self.mode,
            self.started_unix,
            seeds.join(", ")
        )
    }
}
