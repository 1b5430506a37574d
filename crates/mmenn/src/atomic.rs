//! Atomic output: write to a temporary file in the target's directory, flush, then rename
//! over the target, so a reader never sees a half-written file; and whole output folders
//! that are all-or-nothing ([`StagedDir`]): a run writes into a fresh folder beside
//! `--out`, which replaces `--out` in one rename at the end, with a manifest naming the
//! run's files written last.
//!
//! Temporary names carry the writer's process id: `.NAME.PID.tmp` for files,
//! `.NAME.PID.staging` and `.NAME.PID.old` for folders. Whatever a killed run leaves
//! behind (its process no longer running) is removed by the next write into the same
//! folder.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{MmennError, Result};

/// Whether process `pid` is running. Without `/proc` (not Linux) every process counts
/// as running, so nothing of another process is ever removed.
fn pid_alive(pid: u32) -> bool {
    let proc_dir = Path::new("/proc");
    !proc_dir.is_dir() || proc_dir.join(pid.to_string()).exists()
}

/// `(NAME, PID, SUFFIX)` of a temporary name `.NAME.PID.SUFFIX` with one of `suffixes`.
fn temp_parts<'a>(file: &'a str, suffixes: &[&str]) -> Option<(&'a str, u32, &'a str)> {
    let rest = file.strip_prefix('.')?;
    let (head, suffix) = rest.rsplit_once('.')?;
    if !suffixes.contains(&suffix) {
        return None;
    }
    let (name, pid) = head.rsplit_once('.')?;
    let pid: u32 = pid.parse().ok()?;
    (!name.is_empty()).then_some((name, pid, suffix))
}

/// Remove the temporary files and folders in `dir` (`.NAME.PID.tmp`, `.NAME.PID.staging`,
/// `.NAME.PID.old`) whose writing process is no longer running; when `only` is given,
/// only those for that `NAME`. Returns how many were removed. Errors are ignored: a
/// leftover that cannot be removed is harmless.
pub fn clean_stale_temps(dir: &Path, only: Option<&str>) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(file) = file.to_str() else { continue };
        let Some((name, pid, suffix)) = temp_parts(file, &["tmp", "staging", "old"]) else {
            continue;
        };
        if only.is_some_and(|o| o != name) || pid == std::process::id() || pid_alive(pid) {
            continue;
        }
        let path = entry.path();
        let ok = if suffix == "tmp" {
            std::fs::remove_file(&path).is_ok()
        } else {
            std::fs::remove_dir_all(&path).is_ok()
        };
        removed += usize::from(ok);
    }
    removed
}

/// Whether `dir` is a [`StagedDir`] staging folder of this process (`.NAME.PID.staging`
/// with our PID): nobody else reads it, and it is put in place by one rename as a whole.
fn is_own_staging(dir: &Path) -> bool {
    dir.file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| temp_parts(n, &["staging"]))
        .is_some_and(|(_, pid, _)| pid == std::process::id())
}

/// Write `bytes` to `path` atomically (temp file + fsync + rename in the same directory).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// [`write_atomic`] with the contents streamed by `fill` into the temporary file.
///
/// Directly inside this process's own staging folder (see [`StagedDir`]) the file is
/// written in place and fsynced, without a temporary name and a rename: the folder is
/// private until [`StagedDir::commit`] renames it as a whole, which is the atomic step
/// (the fsync makes the contents durable before that rename).
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let io = |source| MmennError::Io {
        path: path.to_path_buf(),
        source,
    };
    if is_own_staging(&dir) {
        let result = (|| {
            let mut f = std::fs::File::create(path)?;
            fill(&mut f)?;
            f.sync_all()
        })();
        return result.map_err(io);
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    // Leftovers of killed writers of the same file go first.
    clean_stale_temps(&dir, Some(&name));
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        fill(&mut f)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}

/// Create an output directory (and parents) if it does not exist.
pub fn ensure_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| MmennError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

/// File name of the manifest a [`StagedDir`] writes last: the command and the files of
/// the run.
pub const RUN_MANIFEST: &str = ".mmenn-run.json";

/// Format tag of [`RUN_MANIFEST`].
pub const RUN_FORMAT: &str = "mmenn-run/1";

/// The manifest of a completed run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunManifest {
    /// Always [`RUN_FORMAT`].
    pub format: String,
    /// The command that wrote the folder (`estimate`, `fit`, …).
    pub command: String,
    /// Files of the run, relative to the folder, sorted (the manifest itself excluded).
    pub files: Vec<String>,
}

/// The manifest of the run that wrote `dir`, if it has a readable one.
pub fn read_manifest(dir: &Path) -> Option<RunManifest> {
    let text = std::fs::read_to_string(dir.join(RUN_MANIFEST)).ok()?;
    serde_json::from_str::<RunManifest>(&text)
        .ok()
        .filter(|m| m.format == RUN_FORMAT)
}

/// How a [`StagedDir`] may replace an existing folder.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StageOptions {
    /// The command writing the folder (recorded in the manifest).
    pub command: String,
    /// Replace a folder holding files of another command's run or files that mmenn did
    /// not write, and files in `protect` with different contents.
    pub force: bool,
    /// Files the run reads: the folder may never be one that holds one of them.
    pub inputs: Vec<PathBuf>,
    /// Names of files in the folder that must not silently change: when the folder
    /// already holds one with different contents, commit refuses unless `force`.
    pub protect: Vec<String>,
}

/// An output folder written all-or-nothing: files go into [`StagedDir::path`] (a fresh
/// folder `.NAME.PID.staging` beside the target); [`StagedDir::commit`] writes the
/// manifest and puts the folder in place of the target with renames, so the target is
/// always either the previous run's complete folder or this run's. Dropped without a
/// commit (an error), the staging folder is removed and the target is untouched.
///
/// A target that exists must be empty, or hold the manifest of a run of the same
/// command, unless [`StageOptions::force`]; it may never hold one of the run's input files.
#[derive(Debug)]
pub struct StagedDir {
    target: PathBuf,
    staging: PathBuf,
    options: StageOptions,
    committed: bool,
}

fn out_err(path: &Path, reason: String) -> MmennError {
    MmennError::OutputDir {
        path: path.to_path_buf(),
        reason,
    }
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> MmennError + '_ {
    move |source| MmennError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Every file under `dir`, as `/`-joined paths relative to it, sorted.
fn list_files(dir: &Path) -> Result<Vec<String>> {
    let mut out = Vec::new();
    let mut stack = vec![(dir.to_path_buf(), String::new())];
    while let Some((d, prefix)) = stack.pop() {
        for entry in std::fs::read_dir(&d).map_err(io_err(&d))? {
            let entry = entry.map_err(io_err(&d))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            let rel = if prefix.is_empty() {
                name
            } else {
                format!("{prefix}/{name}")
            };
            if entry.file_type().map_err(io_err(&d))?.is_dir() {
                stack.push((entry.path(), rel));
            } else {
                out.push(rel);
            }
        }
    }
    out.sort();
    Ok(out)
}

impl StagedDir {
    /// Check the target and create the staging folder beside it (parents created as
    /// needed); stale temporaries of killed runs beside and inside the target are removed.
    pub fn begin(target: &Path, options: StageOptions) -> Result<Self> {
        let target = std::path::absolute(target).map_err(io_err(target))?;
        let (Some(parent), Some(name)) = (target.parent(), target.file_name()) else {
            return Err(out_err(&target, "the output must name a folder".into()));
        };
        let name = name.to_string_lossy().into_owned();
        if name == "." || name == ".." {
            return Err(out_err(&target, "the output must name a folder".into()));
        }
        ensure_dir(parent)?;
        clean_stale_temps(parent, Some(&name));
        if target.exists() {
            if !target.is_dir() {
                return Err(out_err(&target, "exists and is not a folder".into()));
            }
            clean_stale_temps(&target, None);
            let canon = target.canonicalize().map_err(io_err(&target))?;
            for input in &options.inputs {
                if let Ok(i) = input.canonicalize()
                    && i.starts_with(&canon)
                {
                    return Err(out_err(
                        &target,
                        format!(
                            "holds the input file {}; write the results elsewhere",
                            input.display()
                        ),
                    ));
                }
            }
            let held = list_files(&target)?;
            if !held.is_empty() && !options.force {
                match read_manifest(&target) {
                    Some(m) if m.command == options.command => {}
                    Some(m) => {
                        return Err(out_err(
                            &target,
                            format!(
                                "holds the results of `mmenn {}`; choose another folder or \
                                 pass --force to replace it",
                                m.command
                            ),
                        ));
                    }
                    None => {
                        return Err(out_err(
                            &target,
                            format!(
                                "holds {} file(s) that mmenn did not write (e.g. {}); choose \
                                 another folder or pass --force to replace it",
                                held.len(),
                                held[0]
                            ),
                        ));
                    }
                }
            }
        }
        let staging = parent.join(format!(".{name}.{}.staging", std::process::id()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(io_err(&staging))?;
        }
        std::fs::create_dir(&staging).map_err(io_err(&staging))?;
        Ok(Self {
            target,
            staging,
            options,
            committed: false,
        })
    }

    /// The folder to write this run's files into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The folder the results will be in after [`StagedDir::commit`].
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Write the manifest and put the staged folder in place of the target. Returns the
    /// files of the run.
    pub fn commit(mut self) -> Result<Vec<String>> {
        let files = list_files(&self.staging)?;
        if self.target.is_dir() && !self.options.force {
            for name in &self.options.protect {
                let old = self.target.join(name);
                let new = self.staging.join(name);
                if old.exists() && std::fs::read(&old).ok() != std::fs::read(&new).ok() {
                    return Err(out_err(
                        &self.target,
                        format!(
                            "already holds a different {name}; choose another folder or pass \
                             --force to replace it"
                        ),
                    ));
                }
            }
        }
        let manifest = RunManifest {
            format: RUN_FORMAT.into(),
            command: self.options.command.clone(),
            files: files.clone(),
        };
        write_atomic(
            &self.staging.join(RUN_MANIFEST),
            serde_json::to_string_pretty(&manifest)?.as_bytes(),
        )?;
        let parent = self
            .staging
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let name = self
            .target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if self.target.exists() {
            let old = parent.join(format!(".{name}.{}.old", std::process::id()));
            std::fs::rename(&self.target, &old).map_err(io_err(&self.target))?;
            if let Err(source) = std::fs::rename(&self.staging, &self.target) {
                // Put the previous folder back.
                let _ = std::fs::rename(&old, &self.target);
                return Err(MmennError::Io {
                    path: self.target.clone(),
                    source,
                });
            }
            self.committed = true;
            let _ = std::fs::remove_dir_all(&old);
        } else {
            std::fs::rename(&self.staging, &self.target).map_err(io_err(&self.target))?;
            self.committed = true;
        }
        Ok(files)
    }
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_whole_file_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("mmenn-atomic-{}", std::process::id()));
        ensure_dir(&dir).unwrap();
        let p = dir.join("a.txt");
        write_atomic(&p, b"first version, longer").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        let leftovers = std::fs::read_dir(&dir)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .ends_with(".tmp")
            })
            .count();
        assert_eq!(leftovers, 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Inside this process's staging folder files are written in place (no temporary
    /// name is ever left there, so none can reach the committed folder), and the commit
    /// still delivers every file whole.
    #[test]
    fn staged_files_are_written_in_place_and_committed_whole() {
        let root = std::env::temp_dir().join(format!("mmenn-staged-{}", std::process::id()));
        let target = root.join("out");
        let staged = StagedDir::begin(
            &target,
            StageOptions {
                command: "test".into(),
                ..StageOptions::default()
            },
        )
        .unwrap();
        assert!(is_own_staging(staged.path()));
        assert!(!is_own_staging(&root));
        write_atomic(&staged.path().join("a.txt"), b"alpha").unwrap();
        write_atomic_with(&staged.path().join("b.txt"), |f| f.write_all(b"beta")).unwrap();
        assert_eq!(
            list_files(staged.path()).unwrap(),
            vec!["a.txt".to_string(), "b.txt".to_string()]
        );
        let files = staged.commit().unwrap();
        assert_eq!(files, vec!["a.txt".to_string(), "b.txt".to_string()]);
        assert_eq!(std::fs::read(target.join("a.txt")).unwrap(), b"alpha");
        assert_eq!(std::fs::read(target.join("b.txt")).unwrap(), b"beta");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn missing_directory_is_an_io_error_naming_the_path() {
        let p = std::env::temp_dir()
            .join("mmenn-no-such-dir-xyz")
            .join("f.csv");
        match write_atomic(&p, b"x") {
            Err(MmennError::Io { path, .. }) => assert_eq!(path, p),
            other => panic!("expected Io error, got {other:?}"),
        }
    }
}
