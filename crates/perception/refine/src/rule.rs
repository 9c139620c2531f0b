use voxpan_kde::KdeMethod;

/// How the depth interval of a mask is chosen, or `None` for no refinement: the one type
/// every command, configuration file and evaluation row uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rule {
    /// No refinement: masks are used as the segmenter gave them.
    None,
    /// The paper's rule: raw metric depth, absolute cut-off density `1e-6` (per metre). The
    /// cut-off depends on the depth unit, so it is not scale-invariant.
    Paper,
    /// The released code's rule: depths normalised to `[0, 1]` per mask, cut-off
    /// `max(density left of the peak) / 20`.
    Release,
    /// voxpan's rule: Botev's ISJ density of the measured depths (bandwidth never below the
    /// data's resolution, `range / distinct values`; depths beyond the far limit, 100 m, left
    /// out as no surface), split into clusters at depth gaps (density below 1 % of the uniform
    /// level `1 / range`). Each cluster weighs its pixels by how deep inside the mask they lie,
    /// since over-coverage is a rim along the mask's outline. A thing keeps its heaviest
    /// cluster; stuff keeps the span of clusters holding at least a fifth of the weight. Pixels
    /// without depth keep their label. Every quantity but the far limit is relative to the
    /// data, so metres and millimetres give the same masks (with the limit scaled).
    Default,
}

impl Rule {
    /// The KDE each rule uses unless overridden: the published rules exist to reproduce the
    /// original, so they use the KDEpy-compatible estimator.
    pub fn default_kde(self) -> KdeMethod {
        match self {
            Rule::Paper | Rule::Release => KdeMethod::Kdepy,
            Rule::Default | Rule::None => KdeMethod::Isj,
        }
    }

    /// Whether pixels without valid depth leave a refined mask. The published rules drop them
    /// (the original code zeroes them); the default keeps them: a missing measurement (dark,
    /// shiny or distant surfaces) is no evidence against the network's label.
    pub fn drops_pixels_without_depth(self) -> bool {
        matches!(self, Rule::Paper | Rule::Release)
    }

    /// Every rule, `None` first: the rows of `voxpan eval`.
    pub const ALL: [Rule; 4] = [Rule::None, Rule::Paper, Rule::Release, Rule::Default];

    pub fn name(self) -> &'static str {
        match self {
            Rule::None => "none",
            Rule::Paper => "paper",
            Rule::Release => "release",
            Rule::Default => "default",
        }
    }
}

impl std::str::FromStr for Rule {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => Ok(Rule::None),
            "paper" => Ok(Rule::Paper),
            "release" => Ok(Rule::Release),
            "default" => Ok(Rule::Default),
            other => Err(format!(
                "unknown refinement rule {other:?} (expected none, paper, release or default)"
            )),
        }
    }
}

impl std::fmt::Display for Rule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
