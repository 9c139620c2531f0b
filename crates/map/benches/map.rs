//! Map speed on real flat frames (`../shared/data/flat`) at 2 cm voxels, truncation 2 voxels,
//! 5 m range: integration per frame on 1 and 2 threads, full mesh extraction of the fused map,
//! and incremental re-meshing after one more frame.

use std::sync::OnceLock;

use voxpan_dataset::{FlatDataset, Frame, FrameSource};
use voxpan_io::flat_sample_dir;
use voxpan_map::{Layer, MeshLayer, TsdfConfig, TsdfIntegrator};

fn main() {
    if flat_sample_dir().is_none() {
        eprintln!(
            "map bench: the flat sample (../shared/data/flat) is missing; nothing to measure"
        );
        return;
    }
    divan::main();
}

const VOXEL: f64 = 0.02;

fn frames() -> &'static Vec<Frame> {
    static FRAMES: OnceLock<Vec<Frame>> = OnceLock::new();
    FRAMES.get_or_init(|| {
        let dataset = FlatDataset::open(&flat_sample_dir().expect("checked in main")).unwrap();
        (0..dataset.len())
            .step_by(5)
            .map(|i| dataset.load(i).unwrap())
            .collect()
    })
}

fn integrator() -> TsdfIntegrator {
    TsdfIntegrator::new(TsdfConfig {
        truncation_voxels: 2.0,
        max_range: 5.0,
        ..TsdfConfig::default()
    })
}

/// Fuses one frame's depth and colour (no labels).
fn fuse(integrator: &TsdfIntegrator, layer: &mut Layer, f: &Frame) {
    integrator.integrate(
        layer,
        &f.depth,
        Some(&f.color),
        None,
        &f.pose,
        &f.intrinsics,
    );
}

/// The map after fusing every 5th frame of the sample.
fn fused() -> Layer {
    let mut layer = Layer::new(VOXEL);
    let integrator = integrator();
    for f in frames() {
        fuse(&integrator, &mut layer, f);
    }
    layer
}

#[divan::bench(args = [1, 2])]
fn integrate_frame(bencher: divan::Bencher, threads: usize) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let frames = frames();
    let mut layer = fused();
    let integrator = integrator();
    let mut next = 0;
    bencher.bench_local(|| {
        let f = &frames[next % frames.len()];
        next += 1;
        pool.install(|| fuse(&integrator, &mut layer, f))
    });
}

#[divan::bench]
fn full_mesh(bencher: divan::Bencher) {
    let layer = fused();
    bencher
        .with_inputs(|| {
            let mut l = layer.clone();
            l.blocks.values_mut().for_each(|b| b.updated = true);
            (l, MeshLayer::default())
        })
        .bench_local_values(|(mut l, mut m)| m.update(&mut l));
}

#[divan::bench]
fn incremental_mesh_after_one_frame(bencher: divan::Bencher) {
    let frames = frames();
    let mut layer = fused();
    let mut meshes = MeshLayer::default();
    meshes.update(&mut layer);
    let integrator = integrator();
    let mut next = 0;
    bencher
        .with_inputs(|| {
            let f = &frames[next % frames.len()];
            next += 1;
            fuse(&integrator, &mut layer, f);
            let snapshot = layer.clone();
            // The clone carries this frame's flags; the original starts clean for the next.
            layer.blocks.values_mut().for_each(|b| b.updated = false);
            snapshot
        })
        .bench_local_values(|mut l| meshes.update(&mut l));
}
