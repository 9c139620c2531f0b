//! The synthetic benchmark of the refinement rules: sequences whose masks over-cover only, and
//! with the full error mix, at several error strengths.

use voxpan_dataset::open_dataset;
use voxpan_refine::Rule;
use voxpan_sim::{MaskErrors, SynthConfig, generate};

use super::{EvalError, MaskOptions, MaskRow, Predictions, score_masks};

/// Error strengths the sweep visits.
pub const SWEEP_STRENGTHS: [f64; 4] = [0.5, 1.0, 1.5, 2.0];

/// A kind of mask error: the model that makes it at a given strength.
type ErrorModel = fn(f64) -> MaskErrors;

/// One sequence of the sweep, scored under every rule.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SweepRow {
    /// `over-cover` or `mix`.
    pub errors: &'static str,
    pub strength: f64,
    pub rows: Vec<MaskRow>,
}

/// Generates each sequence (`frames` frames of 320×240, seed 11) into a temporary folder,
/// scores it under every rule, and removes it. `progress(k, n, errors, strength)` is called
/// before each sequence.
pub fn sweep(
    frames: usize,
    options: MaskOptions,
    progress: impl Fn(usize, usize, &str, f64),
) -> Result<Vec<SweepRow>, EvalError> {
    if frames == 0 {
        return Err(EvalError::Other(
            "the sweep needs at least one frame per sequence".into(),
        ));
    }
    let root = std::env::temp_dir().join(format!("voxpan-sweep-{}", std::process::id()));
    let kinds: [(&'static str, ErrorModel); 2] = [
        ("over-cover", MaskErrors::over_cover_only),
        ("mix", MaskErrors::new),
    ];
    let sequences: Vec<(&'static str, ErrorModel, f64)> = kinds
        .iter()
        .flat_map(|&(mode, errors)| SWEEP_STRENGTHS.map(|s| (mode, errors, s)))
        .collect();
    let mut out = Vec::new();
    for (k, &(errors, model, strength)) in sequences.iter().enumerate() {
        progress(k + 1, sequences.len(), errors, strength);
        let dir = root.join(format!("{errors}-{strength}"));
        let config = SynthConfig {
            frames,
            width: 320,
            height: 240,
            seed: 11,
            masks: model(strength),
            ..SynthConfig::default()
        };
        let scored = generate(&dir, &config, |_| {})
            .map_err(EvalError::from)
            .and_then(|_| {
                let source = open_dataset(&dir)?;
                let selected: Vec<usize> = (0..source.len()).collect();
                score_masks(
                    source.as_ref(),
                    &selected,
                    &Predictions::Rules(Rule::ALL.to_vec()),
                    options,
                    || {},
                )
            });
        // The sequences are large and reproducible from the seed: never leave them behind.
        let _ = std::fs::remove_dir_all(&dir);
        out.push(SweepRow {
            errors,
            strength,
            rows: scored?.rows,
        });
    }
    let _ = std::fs::remove_dir_all(&root);
    Ok(out)
}
