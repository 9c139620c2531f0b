use std::path::PathBuf;

use voxpan_io::IoError;

/// A dataset or one of its frames could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error(transparent)]
    Io(#[from] IoError),
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("frame {frame}: {source}")]
    Frame {
        frame: String,
        #[source]
        source: Box<DatasetError>,
    },
    #[error(
        "{0}: neither a flat dataset (run folder with NNNNNN_depth.tiff) nor TUM RGB-D (rgb.txt, depth.txt)"
    )]
    Unrecognised(PathBuf),
    #[error("{0}: does not exist")]
    Missing(PathBuf),
    #[error("{0}: no usable frame")]
    NoFrames(PathBuf),
}

impl DatasetError {
    pub(crate) fn invalid(path: &std::path::Path, message: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.to_owned(),
            message: message.into(),
        }
    }

    /// The error itself, without the frame wrapper [`FrameSource::load`](crate::FrameSource)
    /// adds (for callers that name the frame themselves).
    pub fn without_frame(self) -> Self {
        match self {
            Self::Frame { source, .. } => *source,
            other => other,
        }
    }

    pub(crate) fn in_frame(self, frame: &str) -> Self {
        Self::Frame {
            frame: frame.to_owned(),
            source: Box::new(self),
        }
    }
}
