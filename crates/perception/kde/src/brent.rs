//! Brent's bracketed root finder, step for step as SciPy's `brentq` (its C `brentq.c`), because
//! the KDEpy-compatible mode must land on the same roots as KDEpy; plus a golden-section
//! minimiser for Botev's no-root fallback.

/// Stopping rules of [`brentq`]; the defaults are SciPy's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrentOptions {
    /// Absolute tolerance on the root.
    pub xtol: f64,
    /// Relative tolerance on the root.
    pub rtol: f64,
    /// Iterations before giving up.
    pub max_iter: usize,
}

impl Default for BrentOptions {
    fn default() -> Self {
        Self {
            xtol: 2e-12,
            rtol: 4.0 * f64::EPSILON,
            max_iter: 100,
        }
    }
}

/// How a bracketed root search ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RootSearch {
    /// A root within tolerance.
    Converged(f64),
    /// The iteration limit was reached; the last iterate.
    NotConverged(f64),
    /// `f(a)` and `f(b)` have the same sign: the interval brackets no root.
    NoSignChange,
}

/// Finds a root of `f` in `[xa, xb]`, which must bracket a sign change.
pub fn brentq(mut f: impl FnMut(f64) -> f64, xa: f64, xb: f64, opts: BrentOptions) -> RootSearch {
    let (mut xpre, mut xcur) = (xa, xb);
    let (mut fpre, mut fcur) = (f(xpre), f(xcur));
    if fpre == 0.0 {
        return RootSearch::Converged(xpre);
    }
    if fcur == 0.0 {
        return RootSearch::Converged(xcur);
    }
    if fpre.is_sign_negative() == fcur.is_sign_negative() {
        return RootSearch::NoSignChange;
    }
    let (mut xblk, mut fblk) = (0.0, 0.0);
    let (mut spre, mut scur) = (0.0_f64, 0.0_f64);
    for _ in 0..opts.max_iter {
        if fpre != 0.0 && fcur != 0.0 && fpre.is_sign_negative() != fcur.is_sign_negative() {
            xblk = xpre;
            fblk = fpre;
            spre = xcur - xpre;
            scur = spre;
        }
        if fblk.abs() < fcur.abs() {
            xpre = xcur;
            xcur = xblk;
            xblk = xpre;
            fpre = fcur;
            fcur = fblk;
            fblk = fpre;
        }
        let delta = (opts.xtol + opts.rtol * xcur.abs()) / 2.0;
        let sbis = (xblk - xcur) / 2.0;
        if fcur == 0.0 || sbis.abs() < delta {
            return RootSearch::Converged(xcur);
        }
        if spre.abs() > delta && fcur.abs() < fpre.abs() {
            let stry = if xpre == xblk {
                // secant step
                -fcur * (xcur - xpre) / (fcur - fpre)
            } else {
                // inverse quadratic interpolation
                let dpre = (fpre - fcur) / (xpre - xcur);
                let dblk = (fblk - fcur) / (xblk - xcur);
                -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            };
            if 2.0 * stry.abs() < spre.abs().min(3.0 * sbis.abs() - delta) {
                spre = scur;
                scur = stry;
            } else {
                spre = sbis;
                scur = sbis;
            }
        } else {
            spre = sbis;
            scur = sbis;
        }
        xpre = xcur;
        fpre = fcur;
        if scur.abs() > delta {
            xcur += scur;
        } else {
            xcur += if sbis > 0.0 { delta } else { -delta };
        }
        fcur = f(xcur);
    }
    RootSearch::NotConverged(xcur)
}

/// Golden-section search for a minimiser of `f` on `[a, b]` to absolute tolerance `tol`.
pub(crate) fn minimise_golden(
    mut f: impl FnMut(f64) -> f64,
    mut a: f64,
    mut b: f64,
    tol: f64,
) -> f64 {
    let inv_phi = (5.0_f64.sqrt() - 1.0) / 2.0;
    let mut c = b - inv_phi * (b - a);
    let mut d = a + inv_phi * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    while (b - a).abs() > tol {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - inv_phi * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + inv_phi * (b - a);
            fd = f(d);
        }
    }
    (a + b) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_cube_root_of_two() {
        match brentq(|x| x * x * x - 2.0, 0.0, 2.0, BrentOptions::default()) {
            RootSearch::Converged(x) => assert!((x - 2f64.cbrt()).abs() < 1e-11),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn reports_missing_bracket() {
        assert_eq!(
            brentq(|x| x * x + 1.0, -1.0, 1.0, BrentOptions::default()),
            RootSearch::NoSignChange
        );
    }

    #[test]
    fn root_at_an_end_is_returned() {
        assert_eq!(
            brentq(|x| x, 0.0, 1.0, BrentOptions::default()),
            RootSearch::Converged(0.0)
        );
    }

    #[test]
    fn golden_section_finds_parabola_minimum() {
        let x = minimise_golden(|x| (x - 0.03).powi(2), 0.0, 0.1, 1e-12);
        assert!((x - 0.03).abs() < 1e-9);
    }
}
