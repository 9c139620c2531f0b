use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::IoError;

/// Temporary files this process has begun.
static STARTED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The temporary name `path` is written under before it is renamed into place: unique to the
/// process and the call, so that two threads (or two processes) saving one file never share it.
fn temporary_name(path: &Path) -> PathBuf {
    let n = STARTED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".partial-{}-{n}", std::process::id()));
    path.with_file_name(name)
}

/// Makes a rename in `dir` durable: the directory's entry is on disk once this returns (a
/// power cut after it cannot bring the old file back, or leave none). File systems that
/// cannot sync a directory (EINVAL) are let be.
fn sync_directory(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        match std::fs::File::open(dir)?.sync_all() {
            Err(e) if e.raw_os_error() == Some(libc_einval()) => Ok(()),
            other => other,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// EINVAL, which Linux and the BSDs share.
#[cfg(unix)]
const fn libc_einval() -> i32 {
    22
}

/// Writes a file through `write` into a temporary file beside `path`, syncs it and renames it
/// into place, then syncs the directory: readers see the old file or the whole new one, never
/// a half-written one, and after a power cut the disk holds one of the two. On error the
/// temporary file is removed and `path` is untouched.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), IoError> {
    let temporary = temporary_name(path);
    let result = (|| {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temporary)?;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        write(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&temporary, path)?;
        sync_directory(path.parent().unwrap_or(Path::new(".")))
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&temporary);
        IoError::io(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.bin");
        write_atomically(&path, |w| w.write_all(b"old")).unwrap();
        let err = write_atomically(&path, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("f.bin") && err.to_string().contains("disk full"));
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "no temporary left"
        );
    }

    #[test]
    fn threads_saving_one_file_at_once_each_write_it_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.bin");
        let contents: Vec<Vec<u8>> = (0..16u8).map(|i| vec![i; 200_000]).collect();
        std::thread::scope(|s| {
            for c in &contents {
                let path = &path;
                s.spawn(move || {
                    for _ in 0..4 {
                        write_atomically(path, |w| {
                            // In pieces, so that writers overlap.
                            for piece in c.chunks(4096) {
                                w.write_all(piece)?;
                                w.flush()?;
                            }
                            Ok(())
                        })
                        .unwrap();
                    }
                });
            }
        });
        let last = std::fs::read(&path).unwrap();
        assert!(contents.contains(&last), "the file is a mix of writes");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "no temporary left"
        );
    }
}
