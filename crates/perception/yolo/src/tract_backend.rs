//! The tract backend (cargo feature `tract`): pure Rust, nothing to install; slower than ONNX
//! Runtime on the same cores.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::Factoid;
use tract_onnx::tract_hir::internal::DimLike;

use crate::YoloError;
use crate::backend::{Backend, BackendError, BackendOptions, Tensor as Output};

/// One model, optimised and planned by tract.
pub struct TractBackend {
    plan: Arc<TypedRunnableModel>,
    name: String,
    input_shape: Vec<Option<usize>>,
    metadata: BTreeMap<String, String>,
}

impl TractBackend {
    pub fn open(model: &Path, options: &BackendOptions) -> Result<Self, YoloError> {
        let bad_model = |message: String| YoloError::Model {
            path: model.to_owned(),
            message,
        };
        let mut inference = tract_onnx::onnx()
            .model_for_path(model)
            .map_err(|e| bad_model(format!("tract cannot load it: {e:#}")))?;
        if inference.inputs.len() != 1 {
            return Err(bad_model(format!(
                "expected one input (the image), the model has {}",
                inference.inputs.len()
            )));
        }
        let fact = inference
            .input_fact(0)
            .map_err(|e| bad_model(format!("tract: {e:#}")))?;
        let input_shape: Vec<Option<usize>> = fact
            .shape
            .dims()
            .map(|d| d.concretize().and_then(|d| d.to_usize().ok()))
            .collect();
        // tract plans for one input size: a model that leaves it open gets the one asked for.
        if let (Some((w, h)), true) = (options.input_size, input_shape.iter().any(Option::is_none))
        {
            inference
                .set_input_fact(
                    0,
                    InferenceFact::dt_shape(f32::datum_type(), tvec![1, 3, h, w]),
                )
                .map_err(|e| bad_model(format!("tract: {e:#}")))?;
        }
        let mut metadata = BTreeMap::new();
        for (key, value) in &inference.properties {
            if let (Some(key), Ok(plain)) = (
                key.strip_prefix("onnx.metadata_props."),
                value.try_as_plain_ram(),
            ) && let Ok(text) = plain.to_scalar::<String>()
            {
                metadata.insert(key.to_owned(), text.clone());
            }
        }
        let plan = inference
            .into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(|e| bad_model(format!("tract cannot plan it: {e:#}")))?;
        Ok(Self {
            plan,
            name: "tract".into(),
            input_shape,
            metadata,
        })
    }
}

impl Backend for TractBackend {
    fn name(&self) -> &str {
        &self.name
    }

    fn input_shape(&self) -> &[Option<usize>] {
        &self.input_shape
    }

    fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    fn run(&mut self, input: &[f32], shape: [usize; 4]) -> Result<Vec<Output>, BackendError> {
        let tensor = Tensor::from_shape(&shape, input)?;
        let outputs = self.plan.run(tvec![tensor.into_tvalue()])?;
        outputs
            .iter()
            .map(|v| {
                Ok(Output {
                    shape: v.shape().to_vec(),
                    data: v.try_as_plain_ram()?.as_slice::<f32>()?.to_vec(),
                })
            })
            .collect::<TractResult<Vec<_>>>()
            .map_err(|e| format!("{e:#}").into())
    }
}
