//! Hole filling of a 640×480 depth frame with 5 % scattered holes plus a 60×40 missing patch
//! (as at a dark surface), separable implementation vs the direct k×k definition (baseline).

use voxpan_core::DepthImage;
use voxpan_fill::{FillParams, HoleFiller, fill_holes_naive};

fn main() {
    divan::main();
}

fn frame() -> DepthImage {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    DepthImage::from_fn(640, 480, |x, y| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let in_patch = (300..360).contains(&x) && (200..240).contains(&y);
        if in_patch || state.is_multiple_of(20) {
            0.0
        } else {
            1.0 + 0.002 * x as f32 + 0.001 * y as f32
        }
    })
}

#[divan::bench(args = [5, 9, 15])]
fn separable(bencher: divan::Bencher, k: usize) {
    let depth = frame();
    // Steady state of a stream: one filler, reused frame after frame.
    let mut filler = HoleFiller::new(FillParams::with_kernel_size(k));
    bencher
        .with_inputs(|| depth.clone())
        .bench_local_values(|mut d| filler.fill(&mut d));
}

#[divan::bench(args = [5, 9, 15])]
fn naive_baseline(bencher: divan::Bencher, k: usize) {
    let depth = frame();
    let params = FillParams::with_kernel_size(k);
    bencher
        .with_inputs(|| depth.clone())
        .bench_local_values(|mut d| fill_holes_naive(&mut d, &params));
}
