//! Map speed on real flat frames (`../shared/data/flat`) at 2 cm voxels, truncation 2 voxels,
//! 5 m range, through the `PanopticMap` facade: integration per frame on 1 and 2 threads, the
//! full welded mesh of the fused map, incremental re-meshing after one more frame, a ray-cast
//! view, and saving the map.

use std::sync::OnceLock;

use voxpan_core::{Frame, Segments};
use voxpan_dataset::{FlatDataset, FrameSource};
use voxpan_io::flat_sample_dir;
use voxpan_map::{Coloring, MapConfig, PanopticMap};

fn main() {
    if flat_sample_dir().is_none() {
        eprintln!(
            "map bench: the flat sample (../shared/data/flat) is missing; nothing to measure"
        );
        return;
    }
    divan::main();
}

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

fn config() -> MapConfig {
    let mut c = MapConfig::default();
    c.tsdf.voxel_size = 0.02;
    c.tsdf.truncation_voxels = 2.0;
    c.tsdf.max_range = 5.0;
    c
}

/// Fuses one frame's depth and colour (no segments).
fn fuse(map: &mut PanopticMap, f: &Frame) {
    map.integrate(f.view(), None::<&Segments>).unwrap();
}

/// The map after fusing every 5th frame of the sample.
fn fused() -> PanopticMap {
    static MAP: OnceLock<PanopticMap> = OnceLock::new();
    MAP.get_or_init(|| {
        let mut map = PanopticMap::new(config()).unwrap();
        for f in frames() {
            fuse(&mut map, f);
        }
        map
    })
    .clone()
}

#[divan::bench(args = [1, 2])]
fn integrate_frame(bencher: divan::Bencher, threads: usize) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let frames = frames();
    let mut map = fused();
    let mut next = 0;
    bencher.bench_local(|| {
        let f = &frames[next % frames.len()];
        next += 1;
        pool.install(|| fuse(&mut map, f))
    });
}

#[divan::bench]
fn full_mesh(bencher: divan::Bencher) {
    bencher
        .with_inputs(fused)
        .bench_local_values(|mut map| map.mesh(Coloring::Rgb));
}

#[divan::bench]
fn incremental_mesh_after_one_frame(bencher: divan::Bencher) {
    let frames = frames();
    let mut map = fused();
    map.update_mesh();
    let mut next = 0;
    bencher
        .with_inputs(|| {
            let f = &frames[next % frames.len()];
            next += 1;
            fuse(&mut map, f);
            let snapshot = map.clone();
            // The clone carries this frame's changes; the original starts clean for the next.
            map.update_mesh();
            snapshot
        })
        .bench_local_values(|mut m| m.update_mesh());
}

#[divan::bench]
fn render_view(bencher: divan::Bencher) {
    let map = fused();
    let f = &frames()[3];
    bencher.bench_local(|| map.render(&f.intrinsics, &f.pose));
}

#[divan::bench]
fn save_map(bencher: divan::Bencher) {
    let map = fused();
    bencher.bench_local(|| map.to_bytes());
}
