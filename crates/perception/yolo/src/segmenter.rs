//! The network as voxpan's [`Segmenter`]: a frame's colour image in, its segments out.

use std::collections::BTreeSet;
use std::path::Path;

use voxpan_core::{Annotations, ClassInfo, ClassTable, ColorImage, Frame, Segment, Segments};
use voxpan_perception::{SegmentError, Segmenter};

use crate::{ImageInstances, Yolo, YoloError, YoloOptions};

/// A YOLO segmentation model as a [`Segmenter`]. Each frame's instances become segments 1, 2,
/// ... in descending score, with the model's class id and score; COCO's classes are all
/// countable, so every class is a thing unless listed as stuff.
pub struct YoloSegmenter {
    yolo: Yolo,
    name: String,
    classes: ClassTable,
}

impl YoloSegmenter {
    /// Loads the model at `path` (see [`Yolo::open`]); classes named in `stuff` are stuff.
    pub fn open(path: &Path, options: &YoloOptions, stuff: &[String]) -> Result<Self, YoloError> {
        Self::new(Yolo::open(path, options)?, stuff)
    }

    /// Wraps a loaded model; classes named in `stuff` are stuff (an unknown name is an error
    /// that lists the model's classes).
    pub fn new(yolo: Yolo, stuff: &[String]) -> Result<Self, YoloError> {
        let names = &yolo.info().names;
        let stuff: BTreeSet<&str> = stuff.iter().map(String::as_str).collect();
        if let Some(unknown) = stuff.iter().find(|s| !names.iter().any(|n| n == *s)) {
            return Err(YoloError::Model {
                path: yolo.path().to_owned(),
                message: format!(
                    "stuff class {unknown:?} is not one of the model's classes ({})",
                    names.join(", ")
                ),
            });
        }
        let classes = ClassTable {
            entries: names
                .iter()
                .enumerate()
                .map(|(id, name)| {
                    let info = ClassInfo {
                        class_id: id as u32,
                        is_thing: !stuff.contains(name.as_str()),
                        name: name.clone(),
                        color: palette(id),
                    };
                    (id as u32, info)
                })
                .collect(),
        };
        let stem = yolo
            .path()
            .file_stem()
            .map_or("yolo".into(), |s| s.to_string_lossy().into_owned());
        let name = format!("{stem} ({})", yolo.backend_name());
        Ok(Self {
            yolo,
            name,
            classes,
        })
    }

    pub fn yolo(&self) -> &Yolo {
        &self.yolo
    }

    /// The model's classes, with thing/stuff as configured.
    pub fn class_table(&self) -> &ClassTable {
        &self.classes
    }

    /// An image's segments and the instances they come from.
    pub fn segment_image(
        &mut self,
        image: &ColorImage,
    ) -> Result<(Segments, ImageInstances), YoloError> {
        let instances = self.yolo.instances(image)?;
        let segments = instances
            .owners
            .iter()
            .enumerate()
            .map(|(k, &d)| {
                let d = &instances.detections[d];
                Segment {
                    id: k as u16 + 1,
                    class_id: Some(d.class as u32),
                    is_thing: self.classes.get(d.class as u32).map(|c| c.is_thing),
                    score: Some(d.score),
                }
            })
            .collect();
        let segments = Segments {
            labels: instances.labels.clone(),
            segments,
        };
        Ok((segments, instances))
    }
}

impl Segmenter for YoloSegmenter {
    fn name(&self) -> &str {
        &self.name
    }

    fn segment(&mut self, frame: &Frame) -> Result<Option<Segments>, SegmentError> {
        Ok(Some(self.segment_image(&frame.color)?.0))
    }

    fn classes(&self) -> Option<&ClassTable> {
        Some(&self.classes)
    }

    /// The colour image only: a dataset's stored masks and ground truth go undecoded.
    fn reads(&self) -> Annotations {
        Annotations::NONE
    }
}

/// A colour per class for meshes and overlays: well spread hues from a fixed sequence.
fn palette(id: usize) -> [u8; 3] {
    // The golden angle apart on the hue circle; full saturation, bright.
    let h = (id as f64 * 0.618_033_988_75).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r, g, b].map(|c| (55.0 + 200.0 * c) as u8)
}
