//! # Output folders written whole or not at all, by one writer, never over foreign files
//!
//! Why (issue 17): an output folder used again kept the files the new run did not rewrite
//! (an old `filter.tbl` beside new tables was then uplinked), two writers into one folder left
//! a `telemetry.bin` of one run beside the metadata of the other, and a work folder was
//! deleted whatever it held. Every command that writes a folder (`sim-harness run`,
//! `ground-tool calibrate` / `diagnose`, `calibration-loop`) goes through [`OutputDir`]:
//!
//! 1. **One writer.** A lock file `.NAME.lock` beside the folder is created with `O_EXCL`
//!    ([`std::fs::OpenOptions::create_new`]); a second writer fails at once with the holder's
//!    process id ([`Busy`], exit code 1). A lock whose process is gone (Linux `/proc`) is
//!    taken over.
//! 2. **Never over foreign files.** An existing non-empty folder is replaced only when it is a
//!    previous output of the same tool (its [`MARKER`] names the tool) or with `--force`;
//!    otherwise [`InputError`] (exit code 2) says so and how to proceed.
//! 3. **Whole or nothing.** The new content is written into a temporary sibling
//!    `.NAME.tmp-PID` and renamed into place by [`OutputDir::commit`] (the old folder is first
//!    renamed aside and removed after): a reader sees the old folder or the new one, never a
//!    mix; a failed run leaves the old folder as it was and removes its temporary sibling.

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::InputError;

/// File in every output folder naming the tool that wrote it (JSON: `tool`, `format`).
pub const MARKER: &str = ".gro-output.json";

/// Another process is writing into the same output folder (exit code 1: retry later).
#[derive(Debug, thiserror::Error)]
#[error("{folder} is being written by another process (pid {pid}, lock file {lock}); wait for it to finish, or remove the lock file if that process no longer exists")]
pub struct Busy {
    /// The output folder.
    pub folder: String,
    /// Process id in the lock file.
    pub pid: String,
    /// The lock file.
    pub lock: String,
}

/// An output folder being written (see the module doc).
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    staging: PathBuf,
    lock: PathBuf,
    tool: String,
    done: bool,
}

fn sibling(target: &Path, suffix: &str) -> anyhow::Result<PathBuf> {
    let name = target
        .file_name()
        .ok_or_else(|| InputError::msg(format!("--out {}: not a folder name", target.display())))?;
    let parent = target
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."));
    Ok(parent.join(format!(".{}{suffix}", name.to_string_lossy())))
}

/// The tool named by `dir`'s [`MARKER`], if any.
#[must_use]
pub fn written_by(dir: &Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join(MARKER)).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v["tool"].as_str().map(str::to_owned)
}

fn take_lock(lock: &Path, target: &Path) -> anyhow::Result<()> {
    for attempt in 0..2 {
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(lock)
        {
            Ok(mut f) => {
                use std::io::Write;
                writeln!(f, "{}", std::process::id())
                    .with_context(|| format!("writing the lock file {}", lock.display()))?;
                return Ok(());
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let pid = std::fs::read_to_string(lock)
                    .unwrap_or_default()
                    .trim()
                    .to_owned();
                let gone = !pid.is_empty()
                    && Path::new("/proc/self").exists()
                    && !Path::new("/proc").join(&pid).exists();
                if gone && attempt == 0 {
                    // The writer died without removing its lock: take it over.
                    let _ = std::fs::remove_file(lock);
                    continue;
                }
                return Err(Busy {
                    folder: target.display().to_string(),
                    pid: if pid.is_empty() {
                        "unknown".into()
                    } else {
                        pid
                    },
                    lock: lock.display().to_string(),
                }
                .into());
            }
            Err(e) => {
                return Err(anyhow::Error::new(e)
                    .context(format!("cannot create the lock file {}", lock.display())))
            }
        }
    }
    Err(Busy {
        folder: target.display().to_string(),
        pid: "unknown".into(),
        lock: lock.display().to_string(),
    }
    .into())
}

impl OutputDir {
    /// Start writing `target` as `tool` (e.g. `"ground-tool calibrate"`); `force` allows
    /// replacing a non-empty folder that another tool (or a person) wrote; `inputs` are the
    /// folders or files the command reads, which `target` must not contain.
    ///
    /// # Errors
    /// [`Busy`] when another writer holds the lock; [`InputError`] when `target` is a file,
    /// contains the current folder or an input, or is a non-empty folder not written by `tool`
    /// and `force` is off; I/O errors.
    pub fn begin(target: &Path, tool: &str, force: bool, inputs: &[&Path]) -> anyhow::Result<Self> {
        if let Ok(t) = target.canonicalize() {
            let cwd = std::env::current_dir()
                .ok()
                .and_then(|c| c.canonicalize().ok());
            let mut protected: Vec<(String, PathBuf)> = cwd
                .map(|c| ("the current folder".to_owned(), c))
                .into_iter()
                .collect();
            for i in inputs {
                if let Ok(c) = i.canonicalize() {
                    protected.push((format!("the input {}", i.display()), c));
                }
            }
            if let Some((what, _)) = protected.iter().find(|(_, p)| p.starts_with(&t)) {
                return Err(InputError::msg(format!(
                    "--out {} contains {what}: replacing it would delete it; choose another output folder",
                    target.display()
                ))
                .into());
            }
        }
        let lock = sibling(target, ".lock")?;
        let staging = sibling(target, &format!(".tmp-{}", std::process::id()))?;
        if let Some(parent) = lock.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        take_lock(&lock, target)?;
        // From here on, Drop removes the lock.
        let out = Self {
            target: target.to_path_buf(),
            staging,
            lock,
            tool: tool.to_owned(),
            done: false,
        };
        if target.exists() {
            if !target.is_dir() {
                return Err(InputError::msg(format!(
                    "--out {} is a file, not a folder: choose a folder",
                    target.display()
                ))
                .into());
            }
            let empty = std::fs::read_dir(target)
                .with_context(|| format!("cannot read {}", target.display()))?
                .next()
                .is_none();
            let ours = written_by(target).as_deref() == Some(tool);
            if !(empty || ours || force) {
                let other = written_by(target).map_or_else(
                    || "no `.gro-output.json` names the tool that wrote it".to_owned(),
                    |t| format!("it was written by `{t}`"),
                );
                return Err(InputError::msg(format!(
                    "--out {} is not empty and is not a previous output of `{tool}` ({other}): choose a new or empty folder, or pass --force to replace its whole content",
                    target.display()
                ))
                .into());
            }
        }
        if out.staging.exists() {
            // Our own process id: left by nothing else.
            std::fs::remove_dir_all(&out.staging)
                .with_context(|| format!("cannot remove {}", out.staging.display()))?;
        }
        std::fs::create_dir_all(&out.staging)
            .with_context(|| format!("cannot create {}", out.staging.display()))?;
        Ok(out)
    }

    /// Where to write the new content (the temporary sibling).
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The folder the content will have after [`Self::commit`].
    #[must_use]
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Write the marker and rename the new content into place (the old folder, if any, is
    /// renamed aside first and then removed).
    ///
    /// # Errors
    /// I/O errors (the old folder is then still in place, or renamed back).
    pub fn commit(mut self) -> anyhow::Result<()> {
        let marker = serde_json::json!({ "tool": self.tool, "format": 1 });
        std::fs::write(
            self.staging.join(MARKER),
            serde_json::to_string_pretty(&marker)? + "\n",
        )
        .with_context(|| format!("cannot write {}", self.staging.join(MARKER).display()))?;
        let old = sibling(&self.target, &format!(".old-{}", std::process::id()))?;
        let had_old = self.target.exists();
        if had_old {
            std::fs::rename(&self.target, &old).with_context(|| {
                format!(
                    "cannot move the previous {} aside to {}",
                    self.target.display(),
                    old.display()
                )
            })?;
        }
        if let Err(e) = std::fs::rename(&self.staging, &self.target) {
            if had_old {
                let _ = std::fs::rename(&old, &self.target);
            }
            return Err(anyhow::Error::new(e).context(format!(
                "cannot rename {} to {}",
                self.staging.display(),
                self.target.display()
            )));
        }
        self.done = true;
        if had_old {
            std::fs::remove_dir_all(&old)
                .with_context(|| format!("cannot remove the previous output {}", old.display()))?;
        }
        Ok(())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
        let _ = std::fs::remove_file(&self.lock);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("outdir-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let _ = std::fs::create_dir_all(&d);
        d
    }

    #[test]
    fn replaces_its_own_output_whole_and_refuses_foreign_folders() {
        let root = scratch("own");
        let out = root.join("o");
        let w = OutputDir::begin(&out, "t", false, &[]).unwrap();
        std::fs::write(w.path().join("old.tbl"), b"x").unwrap();
        w.commit().unwrap();
        assert_eq!(written_by(&out).as_deref(), Some("t"));
        // Second run of the same tool: nothing of the first one is left.
        let w = OutputDir::begin(&out, "t", false, &[]).unwrap();
        std::fs::write(w.path().join("new.tbl"), b"y").unwrap();
        w.commit().unwrap();
        assert!(!out.join("old.tbl").exists() && out.join("new.tbl").exists());
        // Another tool: refused without --force, and nothing touched.
        let e = OutputDir::begin(&out, "u", false, &[]).unwrap_err();
        assert!(crate::is_input_error(&e), "{e:#}");
        assert!(out.join("new.tbl").exists());
        // A failed run (dropped without commit) leaves the old folder as it was.
        let w = OutputDir::begin(&out, "t", false, &[]).unwrap();
        std::fs::write(w.path().join("half.tbl"), b"z").unwrap();
        drop(w);
        assert!(out.join("new.tbl").exists() && !out.join("half.tbl").exists());
        // --force replaces a foreign folder.
        let foreign = root.join("f");
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join("mine.txt"), b"keep").unwrap();
        assert!(OutputDir::begin(&foreign, "t", false, &[]).is_err());
        assert!(foreign.join("mine.txt").exists());
        let w = OutputDir::begin(&foreign, "t", true, &[]).unwrap();
        w.commit().unwrap();
        assert!(!foreign.join("mine.txt").exists());
        // --force never replaces a folder holding an input.
        let run = foreign.join("run");
        std::fs::create_dir_all(&run).unwrap();
        let e = OutputDir::begin(&foreign, "x", true, &[&run]).unwrap_err();
        assert!(crate::is_input_error(&e) && run.exists(), "{e:#}");
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_second_writer_fails_cleanly() {
        let root = scratch("busy");
        let out = root.join("o");
        let first = OutputDir::begin(&out, "t", false, &[]).unwrap();
        let second = OutputDir::begin(&out, "t", false, &[]).unwrap_err();
        assert!(second.downcast_ref::<Busy>().is_some(), "{second:#}");
        assert!(!crate::is_input_error(&second));
        first.commit().unwrap();
        // The lock is gone with the first writer.
        assert!(OutputDir::begin(&out, "t", false, &[]).is_ok());
        let _ = std::fs::remove_dir_all(&root);
    }
}
