//! The map saved where asked: at exit, and between two frames on the save service's call.

use std::path::PathBuf;

use voxpan_map::PanopticMap;

use super::map::SharedMap;
use super::{Log, NodeError};

/// Saves the map where asked, then reports.
pub(super) fn save(map: &PanopticMap, path: Option<&PathBuf>, log: &Log) -> Result<(), NodeError> {
    if let Some(path) = path {
        map.save(path).map_err(|source| NodeError::Save {
            path: path.clone(),
            source,
        })?;
        log(&format!("map saved to {}", path.display()));
    }
    Ok(())
}

/// The save service's answer: the map saved to `--save` between two frames (atomically and
/// consolidated, as at exit), or why not.
pub(super) fn save_now(shared: &SharedMap, path: Option<&PathBuf>, log: &Log) -> (bool, String) {
    let Some(path) = path else {
        return (
            false,
            "no --save PATH was given to this node: nowhere to save".into(),
        );
    };
    // Copied under the lock, consolidated and written after it is released, so that a slow
    // disk stalls neither integration nor the mailbox. Consolidated as at exit (and as
    // `voxpan run` saves): the file is the map a run over the same frames would write, while
    // the live map goes on without consolidation's joins and filled holes.
    let mut map = {
        let guard = shared.lock().unwrap_or_else(|p| p.into_inner());
        let Some(map) = guard.as_ref() else {
            return (
                false,
                "the node is stopping; the map is saved as it exits".into(),
            );
        };
        map.clone()
    };
    map.consolidate();
    let (bytes, instances) = (map.to_bytes(), map.instance_count());
    match voxpan_io::write_atomically(path, |out| out.write_all(&bytes)) {
        Ok(()) => {
            let line = format!(
                "map saved to {} ({instances} instances) on request",
                path.display()
            );
            log(&line);
            (true, line)
        }
        Err(e) => (false, format!("cannot save the map: {e}")),
    }
}
