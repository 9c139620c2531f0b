//! A YOLO segmentation model on a backend: image in, instances out.

use std::path::{Path, PathBuf};
use std::time::Instant;

use voxpan_core::{ColorImage, LabelImage};

use crate::YoloError;
use crate::backend::{Backend, BackendKind, BackendOptions, Tensor, open_backend};
use crate::letterbox::Letterbox;
use crate::model::ModelInfo;
use crate::postprocess::{Detection, Grid, Protos, candidates, label_image, nms};

/// How a model is loaded and its detections kept.
#[derive(Clone, Debug, PartialEq)]
pub struct YoloOptions {
    pub backend: BackendKind,
    /// Input size (square) the model must take: an error for a fixed-size model of another
    /// size; the size used for a model whose input size is open. `None`: the model's.
    pub input_size: Option<usize>,
    /// Detections scoring at most this are dropped (default 0.25).
    pub confidence: f32,
    /// Non-maximum suppression drops a detection overlapping a better one of its class by
    /// more than this IoU (default 0.45).
    pub iou: f32,
    /// At most this many detections per image, best first (default 100).
    pub max_detections: usize,
    /// Inference threads; 0: the backend's default.
    pub threads: usize,
    /// The ONNX Runtime library (default `$ORT_DYLIB_PATH`).
    pub ort_library: Option<PathBuf>,
}

impl Default for YoloOptions {
    fn default() -> Self {
        Self {
            backend: BackendKind::Auto,
            input_size: None,
            confidence: 0.25,
            iou: 0.45,
            max_detections: 100,
            threads: 0,
            ort_library: None,
        }
    }
}

impl YoloOptions {
    /// Checks the thresholds; the message names the option.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(format!(
                "confidence = {}: expected a number in (0, 1)",
                self.confidence
            ));
        }
        if !(self.iou > 0.0 && self.iou <= 1.0) {
            return Err(format!("iou = {}: expected a number in (0, 1]", self.iou));
        }
        if !(1..=u16::MAX as usize).contains(&self.max_detections) {
            return Err(format!(
                "max_detections = {}: expected 1..=65535 (one label id each)",
                self.max_detections
            ));
        }
        if let Some(s) = self.input_size
            && (s == 0 || s % 32 != 0)
        {
            return Err(format!(
                "input_size = {s}: expected a positive multiple of 32 (YOLO's largest stride)"
            ));
        }
        Ok(())
    }
}

/// The raw outputs of one inference, checked against the model's geometry.
#[derive(Clone, Debug)]
pub struct RawOutputs {
    /// Candidates, `[1, N, F]` (YOLOv5) or `[1, F, N]` (YOLOv8).
    pub detections: Tensor,
    /// Prototype masks, `[1, M, H/4, W/4]`.
    pub protos: Tensor,
}

/// Milliseconds the steps of the last image took.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct YoloTimes {
    /// Letterboxing into the input tensor.
    pub preprocess: f64,
    /// The network.
    pub inference: f64,
    /// Decoding, NMS, masks and the label image.
    pub postprocess: f64,
}

/// An image's instances: the detections (input pixels, best first) and their masks as one
/// label image of the image's size.
#[derive(Clone, Debug)]
pub struct ImageInstances {
    pub letterbox: Letterbox,
    pub detections: Vec<Detection>,
    /// Ids 1, 2, ...; 0 where no mask is.
    pub labels: LabelImage,
    /// Per id (from 1) the index of its detection; detections whose mask lost every pixel to
    /// better ones have no id.
    pub owners: Vec<usize>,
}

impl ImageInstances {
    /// The detection of label id `id`.
    pub fn detection(&self, id: u16) -> Option<&Detection> {
        let k = *self.owners.get(usize::from(id).checked_sub(1)?)?;
        self.detections.get(k)
    }

    /// A detection's box in image pixels `[x1, y1, x2, y2]`, clipped to the image.
    pub fn image_box(&self, detection: &Detection) -> [f64; 4] {
        let b = detection.bbox.map(f64::from);
        let (x1, y1) = self.letterbox.to_image(b[0], b[1]);
        let (x2, y2) = self.letterbox.to_image(b[2], b[3]);
        let (w, h) = (self.letterbox.image.0 as f64, self.letterbox.image.1 as f64);
        [
            x1.clamp(0.0, w),
            y1.clamp(0.0, h),
            x2.clamp(0.0, w),
            y2.clamp(0.0, h),
        ]
    }
}

/// A YOLO segmentation model loaded on a backend.
pub struct Yolo {
    path: PathBuf,
    backend: Box<dyn Backend>,
    info: ModelInfo,
    options: YoloOptions,
    input: Vec<f32>,
    times: YoloTimes,
}

impl Yolo {
    /// Loads `path` on the backend `options` asks for and checks that it is a YOLO
    /// segmentation model (one warm-up inference reads its output shapes). Errors name the
    /// file and what is wrong with it.
    pub fn open(path: &Path, options: &YoloOptions) -> Result<Self, YoloError> {
        options.validate().map_err(YoloError::Options)?;
        let kind = options.backend.resolve()?;
        if !path.is_file() {
            let message = if path.is_dir() {
                "a folder, not a model: give the .onnx file".into()
            } else {
                "no such file".into()
            };
            return Err(YoloError::Model {
                path: path.to_owned(),
                message,
            });
        }
        let backend = open_backend(
            kind,
            path,
            &BackendOptions {
                threads: options.threads,
                ort_library: options.ort_library.clone(),
                input_size: options.input_size.map(|s| (s, s)),
            },
        )?;
        Self::with_backend(path, backend, options)
    }

    /// A model already loaded on `backend` (any [`Backend`]); `path` names it in messages.
    pub fn with_backend(
        path: &Path,
        backend: Box<dyn Backend>,
        options: &YoloOptions,
    ) -> Result<Self, YoloError> {
        options.validate().map_err(YoloError::Options)?;
        let bad = |message: String| YoloError::Model {
            path: path.to_owned(),
            message,
        };
        let declared = backend.input_shape().to_vec();
        let input = match declared[..] {
            [b, Some(3), h, w] if b.is_none_or(|b| b == 1) => match (w, h, options.input_size) {
                (Some(w), Some(h), Some(s)) if (w, h) != (s, s) => {
                    return Err(bad(format!(
                        "the model takes {w}x{h} input, not the {s}x{s} asked for (a fixed-size \
                         model needs an export at that size, e.g. yolov5s-seg-{s}.onnx from \
                         tools/yolo/fetch_weights.sh)"
                    )));
                }
                (Some(w), Some(h), _) => (w, h),
                (_, _, Some(s)) => (s, s),
                _ => imgsz(backend.metadata().get("imgsz")).unwrap_or((640, 640)),
            },
            _ => {
                let dims: Vec<String> = declared
                    .iter()
                    .map(|d| d.map_or("?".into(), |d| d.to_string()))
                    .collect();
                return Err(bad(format!(
                    "not an image model: its input is [{}], expected [1, 3, H, W]",
                    dims.join(", ")
                )));
            }
        };
        let mut yolo = Self {
            path: path.to_owned(),
            info: ModelInfo {
                layout: crate::Layout::V8,
                input,
                names: Vec::new(),
                candidates: 0,
                mask_dim: 0,
                protos: (0, 0),
            },
            backend,
            options: options.clone(),
            input: Vec::new(),
            times: YoloTimes::default(),
        };
        // The output shapes are only certain once the model has run (exporters leave them
        // open): a gray image tells them, and warms the backend up.
        let gray = vec![crate::letterbox::PAD_VALUE as f32 / 255.0; 3 * input.0 * input.1];
        let outputs = yolo.run_backend(&gray)?;
        let (detections, protos) = split_outputs(&outputs).map_err(&bad)?;
        yolo.info = ModelInfo::from_shapes(
            input,
            &detections.shape,
            &protos.shape,
            yolo.backend.metadata(),
        )
        .map_err(|e| bad(format!("not a YOLO segmentation model: {e}")))?;
        Ok(yolo)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    pub fn options(&self) -> &YoloOptions {
        &self.options
    }

    /// The backend's name ("onnxruntime", "tract").
    pub fn backend_name(&self) -> &str {
        self.backend.name()
    }

    /// The model's metadata properties.
    pub fn metadata(&self) -> &std::collections::BTreeMap<String, String> {
        self.backend.metadata()
    }

    /// How long the steps of the last [`instances`](Self::instances) took.
    pub fn times(&self) -> YoloTimes {
        self.times
    }

    fn run_backend(&mut self, input: &[f32]) -> Result<Vec<Tensor>, YoloError> {
        let (w, h) = self.info.input;
        self.backend
            .run(input, [1, 3, h, w])
            .map_err(|e| YoloError::Inference {
                path: self.path.clone(),
                message: e.to_string(),
            })
    }

    /// The network's raw outputs for an input tensor `[1, 3, H, W]` (`3 H W` values).
    pub fn raw(&mut self, input: &[f32]) -> Result<RawOutputs, YoloError> {
        let (w, h) = self.info.input;
        if input.len() != 3 * w * h {
            return Err(YoloError::Options(format!(
                "input has {} values, the model takes 3 x {h} x {w}",
                input.len()
            )));
        }
        let outputs = self.run_backend(input)?;
        let inconsistent = |message: String| YoloError::Inference {
            path: self.path.clone(),
            message,
        };
        let (detections, protos) = split_outputs(&outputs).map_err(inconsistent)?;
        let info = &self.info;
        let fields = info.layout.box_fields() + info.classes() + info.mask_dim;
        let want_det = match info.layout {
            crate::Layout::V5 => [1, info.candidates, fields],
            crate::Layout::V8 => [1, fields, info.candidates],
        };
        let want_protos = [1, info.mask_dim, info.protos.1, info.protos.0];
        if detections.shape != want_det || protos.shape != want_protos {
            return Err(inconsistent(format!(
                "outputs changed shape: {:?} and {:?}, first {want_det:?} and {want_protos:?}",
                detections.shape, protos.shape
            )));
        }
        Ok(RawOutputs {
            detections: detections.clone(),
            protos: protos.clone(),
        })
    }

    /// The detections in raw outputs, after the confidence threshold and NMS, best first.
    pub fn detections(&self, raw: &RawOutputs) -> Vec<Detection> {
        let o = &self.options;
        nms(
            candidates(&self.info, &raw.detections.data, o.confidence),
            o.iou,
            o.max_detections,
        )
    }

    /// The prototype masks of raw outputs.
    pub fn protos<'a>(&self, raw: &'a RawOutputs) -> Protos<'a> {
        Protos {
            data: &raw.protos.data,
            dim: self.info.mask_dim,
            width: self.info.protos.0,
            height: self.info.protos.1,
        }
    }

    /// Letterboxes `image`, runs the network and returns the instances at the image's size.
    pub fn instances(&mut self, image: &ColorImage) -> Result<ImageInstances, YoloError> {
        let t = Instant::now();
        let (w, h) = self.info.input;
        let letterbox = Letterbox::new(image.width(), image.height(), w, h)
            .ok_or_else(|| YoloError::Options("the image is empty".into()))?;
        let mut input = std::mem::take(&mut self.input);
        letterbox.fill_input(image, &mut input);
        let preprocess = ms(t);
        let t = Instant::now();
        let raw = self.raw(&input);
        self.input = input;
        let raw = raw?;
        let inference = ms(t);
        let t = Instant::now();
        let detections = self.detections(&raw);
        let (labels, owners) = label_image(
            &detections,
            &self.protos(&raw),
            self.info.input,
            &Grid::image(&letterbox),
        );
        self.times = YoloTimes {
            preprocess,
            inference,
            postprocess: ms(t),
        };
        Ok(ImageInstances {
            letterbox,
            detections,
            labels,
            owners,
        })
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The detection output (rank 3) and the prototypes (rank 4) among a model's outputs.
fn split_outputs(outputs: &[Tensor]) -> Result<(&Tensor, &Tensor), String> {
    let of_rank =
        |r: usize| -> Vec<&Tensor> { outputs.iter().filter(|t| t.shape.len() == r).collect() };
    match (&of_rank(3)[..], &of_rank(4)[..]) {
        (&[d], &[p]) if outputs.len() == 2 => Ok((d, p)),
        _ => {
            let shapes: Vec<String> = outputs.iter().map(|t| format!("{:?}", t.shape)).collect();
            Err(format!(
                "not a YOLO segmentation model: expected two outputs, detections [1, ·, ·] and \
                 prototypes [1, 32, H/4, W/4]; it has {} output(s): {}",
                outputs.len(),
                shapes.join(", ")
            ))
        }
    }
}

/// `imgsz` metadata, `"[H, W]"` or `"640"`, as `(W, H)`.
fn imgsz(value: Option<&String>) -> Option<(usize, usize)> {
    let v: Vec<usize> = value?
        .trim_matches(|c| c == '[' || c == ']' || c == '(' || c == ')')
        .split(',')
        .map(|s| s.trim().parse().ok())
        .collect::<Option<_>>()?;
    match v[..] {
        [s] => Some((s, s)),
        [h, w] => Some((w, h)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// A backend that returns fixed outputs: tests post-processing and the checks without
    /// any inference engine.
    pub(crate) struct Fixed {
        pub shape: Vec<Option<usize>>,
        pub metadata: BTreeMap<String, String>,
        pub outputs: Vec<Tensor>,
    }

    impl Backend for Fixed {
        fn name(&self) -> &str {
            "fixed"
        }
        fn input_shape(&self) -> &[Option<usize>] {
            &self.shape
        }
        fn metadata(&self) -> &BTreeMap<String, String> {
            &self.metadata
        }
        fn run(
            &mut self,
            _: &[f32],
            _: [usize; 4],
        ) -> Result<Vec<Tensor>, crate::backend::BackendError> {
            Ok(self.outputs.clone())
        }
    }

    fn zeros(shape: &[usize]) -> Tensor {
        Tensor {
            shape: shape.to_vec(),
            data: vec![0.0; shape.iter().product()],
        }
    }

    fn fixed(shape: [Option<usize>; 4], outputs: Vec<Tensor>) -> Box<dyn Backend> {
        let metadata = [("names".to_string(), "{0: 'a', 1: 'b'}".to_string())].into();
        Box::new(Fixed {
            shape: shape.to_vec(),
            metadata,
            outputs,
        })
    }

    #[test]
    fn opens_any_backend_and_reads_the_geometry() {
        let b = fixed(
            [Some(1), Some(3), Some(64), Some(96)],
            vec![zeros(&[1, 38, 126]), zeros(&[1, 32, 16, 24])],
        );
        let y = Yolo::with_backend(Path::new("m.onnx"), b, &YoloOptions::default()).unwrap();
        let info = y.info();
        assert_eq!(
            (info.input, info.candidates, info.classes()),
            ((96, 64), 126, 2)
        );
    }

    #[test]
    fn errors_name_the_file_and_the_problem() {
        let path = Path::new("dir/m.onnx");
        let cases: Vec<(Box<dyn Backend>, YoloOptions, &str)> = vec![
            (
                fixed(
                    [Some(1), Some(3), Some(64), Some(96)],
                    vec![zeros(&[1, 38, 126])],
                ),
                YoloOptions::default(),
                "1 output(s): [1, 38, 126]",
            ),
            (
                fixed([Some(1), Some(1), Some(64), Some(96)], vec![]),
                YoloOptions::default(),
                "input is [1, 1, 64, 96]",
            ),
            (
                fixed(
                    [Some(1), Some(3), Some(64), Some(64)],
                    vec![zeros(&[1, 38, 126]), zeros(&[1, 32, 16, 16])],
                ),
                YoloOptions {
                    input_size: Some(320),
                    ..YoloOptions::default()
                },
                "takes 64x64 input, not the 320x320",
            ),
            (
                fixed(
                    [Some(1), Some(3), Some(64), Some(64)],
                    vec![zeros(&[1, 39, 126]), zeros(&[1, 32, 16, 16])],
                ),
                YoloOptions::default(),
                "names lists 2 classes",
            ),
        ];
        for (backend, options, says) in cases {
            let e = Yolo::with_backend(path, backend, &options)
                .err()
                .unwrap()
                .to_string();
            assert!(e.starts_with("dir/m.onnx: ") && e.contains(says), "{e}");
        }
        let e = YoloOptions {
            confidence: 1.5,
            ..YoloOptions::default()
        }
        .validate()
        .unwrap_err();
        assert!(e.contains("confidence = 1.5"), "{e}");
    }

    #[test]
    fn open_input_sizes_come_from_the_options_or_the_metadata() {
        let outs = || vec![zeros(&[1, 38, 100]), zeros(&[1, 32, 8, 8])];
        let open = [Some(1), Some(3), None, None];
        let y = Yolo::with_backend(
            Path::new("m.onnx"),
            fixed(open, outs()),
            &YoloOptions {
                input_size: Some(320),
                ..YoloOptions::default()
            },
        )
        .unwrap();
        assert_eq!(y.info().input, (320, 320));
        assert_eq!(imgsz(Some(&"[128, 160]".to_string())), Some((160, 128)));
        assert_eq!(imgsz(Some(&"640".to_string())), Some((640, 640)));
        assert_eq!(imgsz(Some(&"x".to_string())), None);
    }
}
