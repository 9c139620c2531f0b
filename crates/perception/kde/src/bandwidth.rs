//! What a bandwidth selection yields, shared by the ISJ solver and the estimator.

/// Which KDE to run; see the crate docs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum KdeMethod {
    /// Botev et al.'s ISJ as published; scale-equivariant.
    Isj,
    /// KDEpy 1.1.x `FFTKDE(bw="ISJ")` with the original code's patch, to reproduce its results.
    Kdepy,
}

/// Why a bandwidth is not the root of the ISJ fixed-point equation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BandwidthFallback {
    /// [`KdeMethod::Isj`]: no root in any bracket up to `[0, 0.1]`; `t*` minimises
    /// `|t - ξγ(t)|` on `[0, 0.1]` (what Botev's `kde.m` does).
    MinimisedResidual,
    /// [`KdeMethod::Kdepy`]: no root with a bracket below 1; `t* = 0.01` (the released code's
    /// patch of KDEpy, which otherwise raises).
    ReleasedDefault,
}

impl std::fmt::Display for BandwidthFallback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::MinimisedResidual => "no ISJ root, residual minimised",
            Self::ReleasedDefault => "no ISJ root, the released code's t = 0.01",
        })
    }
}

/// A selected bandwidth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bandwidth {
    /// Kernel standard deviation, in data units.
    pub value: f64,
    /// The fixed point `t*` (squared bandwidth in units of the ISJ grid's scale).
    pub t_star: f64,
    /// Botev's `N`: distinct values among those used.
    pub n_unique: usize,
    /// Set when `t*` is a fallback rather than a root.
    pub fallback: Option<BandwidthFallback>,
    /// Set when the bandwidth was raised to the data's resolution (see
    /// [`Kde::with_resolution_floor`]).
    pub floored: bool,
}

impl KdeMethod {
    pub fn name(self) -> &'static str {
        match self {
            KdeMethod::Isj => "isj",
            KdeMethod::Kdepy => "kdepy",
        }
    }
}

impl std::str::FromStr for KdeMethod {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "isj" => Ok(KdeMethod::Isj),
            "kdepy" => Ok(KdeMethod::Kdepy),
            other => Err(format!("unknown KDE {other:?} (expected isj or kdepy)")),
        }
    }
}

impl std::fmt::Display for KdeMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
