//! Checks on the paths a command is given, made before it reads or writes anything.

use std::path::Path;

use anyhow::{Result, bail};

pub use voxpan_io::same_file;

/// Refuses to write `output` (the option named `option`) when it is one of `inputs`: writing
/// it would destroy what the command reads.
pub fn refuse_overwriting(option: &str, output: &Path, inputs: &[&Path]) -> Result<()> {
    if let Some(input) = inputs.iter().find(|i| same_file(output, i)) {
        bail!(
            "{option} {} is the input {}: writing it would destroy it; choose another path",
            output.display(),
            input.display()
        );
    }
    Ok(())
}

/// Refuses a folder option (`option`) that names an existing file.
pub fn refuse_file_as_folder(option: &str, folder: &Path) -> Result<()> {
    if folder.exists() && !folder.is_dir() {
        bail!(
            "{option} {} is a file: give a folder (it is created if missing)",
            folder.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_file_by_another_name_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let map = dir.path().join("m.voxpan");
        std::fs::write(&map, b"map").unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let other_spelling = dir.path().join("sub/../m.voxpan");
        let err = refuse_overwriting("--out", &other_spelling, &[&map]).unwrap_err();
        assert!(err.to_string().contains("--out") && err.to_string().contains("destroy"));
        #[cfg(unix)]
        {
            let link = dir.path().join("link.ply");
            std::os::unix::fs::symlink(&map, &link).unwrap();
            assert!(refuse_overwriting("--out", &link, &[&map]).is_err());
        }
        assert!(refuse_overwriting("--out", &dir.path().join("new.ply"), &[&map]).is_ok());
        assert!(refuse_file_as_folder("--out", &map).is_err());
        assert!(refuse_file_as_folder("--out", dir.path()).is_ok());
        assert!(refuse_file_as_folder("--out", &dir.path().join("missing")).is_ok());
    }
}
