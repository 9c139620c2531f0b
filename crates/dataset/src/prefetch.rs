use std::sync::mpsc::sync_channel;
use std::sync::Arc;

use crate::{DatasetError, Frame, FrameSource};

/// Decodes the frames `indices` of `source` in order on a background thread, up to `ahead`
/// frames before the consumer (PNG/TIFF decoding is a large share of per-frame cost). Dropping
/// the iterator stops the thread after its current frame.
pub fn prefetch(
    source: Arc<dyn FrameSource>,
    indices: Vec<usize>,
    ahead: usize,
) -> impl Iterator<Item = (usize, Result<Frame, DatasetError>)> {
    let (tx, rx) = sync_channel(ahead.max(1));
    std::thread::spawn(move || {
        for i in indices {
            if tx.send((i, source.load(i))).is_err() {
                break;
            }
        }
    });
    rx.into_iter()
}
