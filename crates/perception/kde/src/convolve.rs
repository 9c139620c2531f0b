use std::sync::Arc;

use realfft::num_complex::Complex;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};

type ForwardPlan = Arc<dyn RealToComplex<f64>>;
type InversePlan = Arc<dyn ComplexToReal<f64>>;

/// Linear (zero-padded) convolution by real FFTs, with plans and buffers kept between calls.
pub(crate) struct FftConvolver {
    planner: RealFftPlanner<f64>,
    plans: Option<(usize, ForwardPlan, InversePlan)>,
    signal: Vec<f64>,
    kernel: Vec<f64>,
    signal_spectrum: Vec<Complex<f64>>,
    kernel_spectrum: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl FftConvolver {
    pub(crate) fn new() -> Self {
        Self {
            planner: RealFftPlanner::new(),
            plans: None,
            signal: Vec::new(),
            kernel: Vec::new(),
            signal_spectrum: Vec::new(),
            kernel_spectrum: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// The full convolution `out[i] = Σ_j signal[j] kernel[i - j]`, of length
    /// `signal.len() + kernel.len() - 1`.
    pub(crate) fn full(&mut self, signal: &[f64], kernel: &[f64], out: &mut Vec<f64>) {
        out.clear();
        if signal.is_empty() || kernel.is_empty() {
            return;
        }
        let len = signal.len() + kernel.len() - 1;
        let size = len.next_power_of_two();
        let (forward, inverse) = self.plans_for(size);

        self.signal.clear();
        self.signal.extend_from_slice(signal);
        self.signal.resize(size, 0.0);
        self.kernel.clear();
        self.kernel.extend_from_slice(kernel);
        self.kernel.resize(size, 0.0);
        self.signal_spectrum
            .resize(size / 2 + 1, Complex::default());
        self.kernel_spectrum
            .resize(size / 2 + 1, Complex::default());
        let scratch_len = forward.get_scratch_len().max(inverse.get_scratch_len());
        self.scratch.resize(scratch_len, Complex::default());

        // The lengths above match the plan, so these calls cannot fail.
        let _ = forward.process_with_scratch(
            &mut self.signal,
            &mut self.signal_spectrum,
            &mut self.scratch,
        );
        let _ = forward.process_with_scratch(
            &mut self.kernel,
            &mut self.kernel_spectrum,
            &mut self.scratch,
        );
        let scale = 1.0 / size as f64;
        for (s, k) in self.signal_spectrum.iter_mut().zip(&self.kernel_spectrum) {
            *s = *s * *k * scale;
        }
        // The inverse of a real signal's spectrum has no imaginary part at DC and Nyquist;
        // rounding can leave a trace there, which realfft rejects.
        self.signal_spectrum[0].im = 0.0;
        if let Some(last) = self.signal_spectrum.last_mut() {
            last.im = 0.0;
        }
        let _ = inverse.process_with_scratch(
            &mut self.signal_spectrum,
            &mut self.signal,
            &mut self.scratch,
        );
        out.extend_from_slice(&self.signal[..len]);
    }

    fn plans_for(
        &mut self,
        size: usize,
    ) -> (Arc<dyn RealToComplex<f64>>, Arc<dyn ComplexToReal<f64>>) {
        match &self.plans {
            Some((cached, f, i)) if *cached == size => (f.clone(), i.clone()),
            _ => {
                let f = self.planner.plan_fft_forward(size);
                let i = self.planner.plan_fft_inverse(size);
                self.plans = Some((size, f.clone(), i.clone()));
                (f, i)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_direct_convolution() {
        let signal: Vec<f64> = (0..37).map(|i| ((i * 7) % 11) as f64 - 3.0).collect();
        let kernel = [0.25, 0.5, 1.0, 0.5, 0.25];
        let mut out = Vec::new();
        FftConvolver::new().full(&signal, &kernel, &mut out);
        assert_eq!(out.len(), signal.len() + kernel.len() - 1);
        for (i, &v) in out.iter().enumerate() {
            let direct: f64 = (0..signal.len())
                .filter(|&j| i >= j && i - j < kernel.len())
                .map(|j| signal[j] * kernel[i - j])
                .sum();
            assert!((v - direct).abs() < 1e-12, "at {i}: {v} vs {direct}");
        }
    }
}
