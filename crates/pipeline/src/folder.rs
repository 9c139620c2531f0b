//! The output folder of a run, written so that it never ends up half-written or mixed:
//!
//! - a lock (an OS lock on `.voxpan.lock`, which holds the process id) refuses a second run
//!   into the same folder while the first is alive, naming it; the OS lets go of a killed
//!   run's lock, so the next run takes it;
//! - every file is written into a staging folder (`.voxpan-staging`), each one atomically;
//! - [`RunFolder::commit`] moves the previous run's files aside, moves the new ones in, and
//!   writes `manifest.json` last (the commit point: the files, the configuration, whether the
//!   run completed); then the previous files are deleted. A run that dies before the manifest
//!   is written is rolled back by the next run: the previous outputs come back whole.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::OutputError;

const LOCK: &str = ".voxpan.lock";
const STAGING: &str = ".voxpan-staging";
const PREVIOUS: &str = ".voxpan-previous";
/// The manifest: the last file a run writes.
pub const MANIFEST: &str = "manifest.json";

/// What `manifest.json` records.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// voxpan's version.
    pub voxpan: String,
    /// What was mapped.
    pub input: String,
    /// True when every selected frame was processed (mapped or skipped with a reason) and
    /// every output written; false when the run was stopped early (Ctrl-C): the outputs hold
    /// what was built until then (after mapping: the map and meshes, without scores or
    /// report).
    pub completed: bool,
    /// Frames mapped and skipped.
    pub frames: usize,
    pub skipped: usize,
    /// The files of this run, relative to the folder.
    pub files: Vec<String>,
    /// The effective configuration.
    pub config: toml::Value,
}

/// An output folder being written by this process.
pub struct RunFolder {
    dir: PathBuf,
    files: Vec<String>,
    committed: bool,
    /// Held (locked) while the folder is this run's.
    lock: std::fs::File,
}

fn folder_error(path: &Path, source: std::io::Error) -> OutputError {
    OutputError::Folder {
        path: path.to_owned(),
        source,
    }
}

/// Takes the folder's lock: an OS lock on `.voxpan.lock` (released when the file is closed or
/// the process dies, so a killed run never leaves the folder locked), holding the holder's
/// process id for the message a second run gets.
fn lock(dir: &Path) -> Result<std::fs::File, OutputError> {
    let path = dir.join(LOCK);
    loop {
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| folder_error(&path, e))?;
        match file.try_lock() {
            Ok(()) => {
                // A holder removes the file as it lets go: the lock taken may be on a file no
                // longer at the path; then take the one there now.
                if !voxpan_io::is_file_at(&file, &path) {
                    continue;
                }
                use std::io::Write;
                file.set_len(0)
                    .and_then(|()| write!(file, "{}", std::process::id()))
                    .map_err(|e| folder_error(&path, e))?;
                return Ok(file);
            }
            Err(std::fs::TryLockError::WouldBlock) => {
                let holder = std::fs::read_to_string(&path).unwrap_or_default();
                return Err(OutputError::Locked {
                    path: dir.to_owned(),
                    holder: match holder.trim().parse::<u32>() {
                        Ok(pid) => format!("process {pid}"),
                        Err(_) => "another process".into(),
                    },
                });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(folder_error(&path, e)),
        }
    }
}

impl RunFolder {
    /// Creates (if needed) and locks `dir`, rolls back what a dead run left, and prepares an
    /// empty staging folder.
    pub fn open(dir: &Path) -> Result<Self, OutputError> {
        std::fs::create_dir_all(dir).map_err(|e| folder_error(dir, e))?;
        let lock = lock(dir)?;
        let folder = Self {
            dir: dir.to_owned(),
            files: Vec::new(),
            committed: false,
            lock,
        };
        folder.recover()?;
        let staging = dir.join(STAGING);
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| folder_error(&staging, e))?;
        }
        std::fs::create_dir_all(&staging).map_err(|e| folder_error(&staging, e))?;
        Ok(folder)
    }

    /// Undoes a commit a dead run did not finish: if the previous run's files were moved
    /// aside but no new manifest was written, they go back.
    fn recover(&self) -> Result<(), OutputError> {
        let previous = self.dir.join(PREVIOUS);
        if !previous.exists() {
            return Ok(());
        }
        let aside: Option<Manifest> = read_manifest(&previous.join(MANIFEST));
        let current: Option<Manifest> = read_manifest(&self.dir.join(MANIFEST));
        if let Some(old) = aside.filter(|old| current.as_ref() == Some(old)) {
            // The old manifest is still current: the new run never committed. Put the files
            // it moved aside back.
            for name in &old.files {
                let (from, to) = (previous.join(name), self.dir.join(name));
                if from.exists() {
                    if let Some(parent) = to.parent() {
                        std::fs::create_dir_all(parent).map_err(|e| folder_error(parent, e))?;
                    }
                    std::fs::rename(&from, &to).map_err(|e| folder_error(&from, e))?;
                }
            }
        }
        std::fs::remove_dir_all(&previous).map_err(|e| folder_error(&previous, e))
    }

    /// Where to write `name` (a path relative to the folder) during the run.
    pub fn path(&self, name: &str) -> Result<PathBuf, OutputError> {
        let path = self.dir.join(STAGING).join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| folder_error(parent, e))?;
        }
        Ok(path)
    }

    /// Records that `name` was written (it becomes part of the run's outputs).
    pub fn record(&mut self, name: &str) {
        if !self.files.iter().any(|f| f == name) {
            self.files.push(name.to_owned());
        }
    }

    /// The files recorded so far.
    pub fn recorded(&self) -> impl Iterator<Item = &str> {
        self.files.iter().map(String::as_str)
    }

    /// The folder itself (where the outputs will be after [`commit`](Self::commit)).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Fails with the free space named when the folder's file system has less than `bytes`
    /// free (Linux; elsewhere it does not check).
    pub fn check_space(&self, bytes: u64) -> Result<(), OutputError> {
        if let Some(free) = free_bytes(&self.dir)
            && free < bytes
        {
            return Err(OutputError::Space {
                path: self.dir.clone(),
                needed: bytes,
                free,
            });
        }
        Ok(())
    }

    /// Replaces the previous run's outputs by this run's, with `manifest` written last.
    pub fn commit(mut self, mut manifest: Manifest) -> Result<(), OutputError> {
        let staging = self.dir.join(STAGING);
        let previous = self.dir.join(PREVIOUS);
        std::fs::create_dir_all(&previous).map_err(|e| folder_error(&previous, e))?;
        // The previous run's files (and its manifest) aside.
        if let Some(old) = read_manifest(&self.dir.join(MANIFEST)) {
            for name in old
                .files
                .iter()
                .chain(std::iter::once(&MANIFEST.to_owned()))
            {
                let from = self.dir.join(name);
                if from.exists() {
                    let to = previous.join(name);
                    if let Some(parent) = to.parent() {
                        std::fs::create_dir_all(parent).map_err(|e| folder_error(parent, e))?;
                    }
                    std::fs::rename(&from, &to).map_err(|e| folder_error(&from, e))?;
                    remove_empty_parents(&from, &self.dir);
                }
            }
            // Keep a copy of the old manifest in place until the new one replaces it: a crash
            // from here on restores the old outputs.
            std::fs::copy(previous.join(MANIFEST), self.dir.join(MANIFEST))
                .map_err(|e| folder_error(&self.dir, e))?;
        }
        for name in &self.files {
            let (from, to) = (staging.join(name), self.dir.join(name));
            if let Some(parent) = to.parent() {
                std::fs::create_dir_all(parent).map_err(|e| folder_error(parent, e))?;
            }
            std::fs::rename(&from, &to).map_err(|e| folder_error(&from, e))?;
        }
        manifest.files = self.files.clone();
        let text = serde_json::to_string_pretty(&manifest).expect("plain data");
        voxpan_io::write_atomically(&self.dir.join(MANIFEST), |w| w.write_all(text.as_bytes()))?;
        self.committed = true;
        let _ = std::fs::remove_dir_all(&previous);
        let _ = std::fs::remove_dir_all(&staging);
        Ok(())
    }
}

impl Drop for RunFolder {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(self.dir.join(STAGING));
        }
        // Removed while still held, then let go (when `lock` closes): a run waiting on this
        // file sees it gone and takes the path's new one.
        let _ = std::fs::remove_file(self.dir.join(LOCK));
        let _ = self.lock.unlock();
    }
}

/// Removes the folders between `file` and `root` that moving `file` left empty (a previous
/// run's `refined/` must not outlive its files).
fn remove_empty_parents(file: &Path, root: &Path) {
    let mut dir = file.parent();
    while let Some(d) = dir {
        if d == root || std::fs::remove_dir(d).is_err() {
            break;
        }
        dir = d.parent();
    }
}

fn read_manifest(path: &Path) -> Option<Manifest> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// Free bytes on the file system holding `path`.
fn free_bytes(path: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = std::ffi::CString::new(path.as_os_str().as_bytes()).ok()?;
        let mut stats: libc::statvfs = unsafe { std::mem::zeroed() };
        // SAFETY: `c` is a valid NUL-terminated path and `stats` a writable statvfs.
        if unsafe { libc::statvfs(c.as_ptr(), &mut stats) } != 0 {
            return None;
        }
        Some(stats.f_bavail as u64 * stats.f_frsize as u64)
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest() -> Manifest {
        Manifest {
            voxpan: "test".into(),
            input: "in".into(),
            completed: true,
            frames: 1,
            skipped: 0,
            files: vec![],
            config: toml::Value::Table(Default::default()),
        }
    }

    fn write(folder: &mut RunFolder, name: &str, text: &str) {
        std::fs::write(folder.path(name).unwrap(), text).unwrap();
        folder.record(name);
    }

    #[test]
    fn a_second_run_is_refused_while_the_first_holds_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let first = RunFolder::open(dir.path()).unwrap();
        let err = RunFolder::open(dir.path()).err().unwrap();
        let me = format!("process {}", std::process::id());
        assert!(err.to_string().contains(&me), "{err}");
        drop(first);
        assert!(!dir.path().join(LOCK).exists());
        // A lock file nobody holds (its run was killed) is taken over, whatever it says.
        std::fs::write(dir.path().join(LOCK), "1").unwrap();
        assert!(RunFolder::open(dir.path()).is_ok());
    }

    #[test]
    fn of_many_runs_starting_at_once_one_holds_the_folder_at_a_time() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let dir = tempfile::tempdir().unwrap();
        let (inside, most, taken) = (
            AtomicUsize::new(0),
            AtomicUsize::new(0),
            AtomicUsize::new(0),
        );
        let start = std::sync::Barrier::new(8);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    start.wait();
                    // Each run retries until it has held the folder once: every one must
                    // get it (none is locked out for good), never two at a time.
                    for _ in 0..1_000_000 {
                        if let Ok(folder) = RunFolder::open(dir.path()) {
                            let now = inside.fetch_add(1, Ordering::SeqCst) + 1;
                            most.fetch_max(now, Ordering::SeqCst);
                            taken.fetch_add(1, Ordering::SeqCst);
                            std::thread::yield_now();
                            inside.fetch_sub(1, Ordering::SeqCst);
                            drop(folder);
                            break;
                        }
                        std::thread::yield_now();
                    }
                });
            }
        });
        assert_eq!(
            most.load(Ordering::SeqCst),
            1,
            "two runs held the folder at once"
        );
        assert_eq!(
            taken.load(Ordering::SeqCst),
            8,
            "a run never got the folder"
        );
        assert!(!dir.path().join(LOCK).exists());
    }

    #[test]
    fn outputs_are_replaced_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let mut run = RunFolder::open(dir.path()).unwrap();
        write(&mut run, "a.txt", "old a");
        write(&mut run, "sub/b.txt", "old b");
        run.commit(manifest()).unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join("sub/b.txt")).unwrap(),
            "old b"
        );
        // A run that dies before committing leaves the old outputs as they were.
        let mut dying = RunFolder::open(dir.path()).unwrap();
        write(&mut dying, "a.txt", "new a");
        drop(dying);
        assert_eq!(
            std::fs::read_to_string(dir.path().join("a.txt")).unwrap(),
            "old a"
        );
        assert!(!dir.path().join(STAGING).exists());
        // A run that died in the middle of its commit (old files moved aside, new manifest
        // not yet written) is rolled back by the next run.
        std::fs::create_dir_all(dir.path().join(PREVIOUS).join("sub")).unwrap();
        std::fs::rename(
            dir.path().join("sub/b.txt"),
            dir.path().join(PREVIOUS).join("sub/b.txt"),
        )
        .unwrap();
        std::fs::copy(
            dir.path().join(MANIFEST),
            dir.path().join(PREVIOUS).join(MANIFEST),
        )
        .unwrap();
        let next = RunFolder::open(dir.path()).unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join("sub/b.txt")).unwrap(),
            "old b"
        );
        drop(next);
        // A new run replaces every file: the old run's extra file goes.
        let mut run = RunFolder::open(dir.path()).unwrap();
        write(&mut run, "a.txt", "new a");
        run.commit(manifest()).unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join("a.txt")).unwrap(),
            "new a"
        );
        assert!(!dir.path().join("sub/b.txt").exists());
        let m = read_manifest(&dir.path().join(MANIFEST)).unwrap();
        assert_eq!(m.files, vec!["a.txt".to_owned()]);
        assert!(!dir.path().join(LOCK).exists());
    }

    #[test]
    fn too_little_space_is_an_error_naming_both_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let folder = RunFolder::open(dir.path()).unwrap();
        assert!(folder.check_space(1).is_ok());
        let err = folder.check_space(u64::MAX).unwrap_err().to_string();
        assert!(err.contains("free"), "{err}");
    }
}
