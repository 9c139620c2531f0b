//! Whether two names, or an open file and a name, are one file: by device and inode on Unix,
//! so that `..`, links and other spellings of one path are told apart from other files.

use std::fs::File;
use std::path::Path;

#[cfg(unix)]
fn same_identity(a: &std::fs::Metadata, b: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::MetadataExt;
    a.dev() == b.dev() && a.ino() == b.ino()
}

/// Whether `a` and `b` name one existing file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        matches!(
            (std::fs::metadata(a), std::fs::metadata(b)),
            (Ok(a), Ok(b)) if same_identity(&a, &b)
        )
    }
    #[cfg(not(unix))]
    {
        matches!(
            (std::fs::canonicalize(a), std::fs::canonicalize(b)),
            (Ok(a), Ok(b)) if a == b
        )
    }
}

/// Whether the open `file` is the file at `path` now (elsewhere than Unix: assumed).
pub fn is_file_at(file: &File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        matches!(
            (file.metadata(), std::fs::metadata(path)),
            (Ok(a), Ok(b)) if same_identity(&a, &b)
        )
    }
    #[cfg(not(unix))]
    {
        let _ = (file, path);
        true
    }
}
