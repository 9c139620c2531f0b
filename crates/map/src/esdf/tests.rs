//! The distance field against brute force: the exact distance from every voxel to the nearest
//! site, on analytic scenes built voxel by voxel, and incremental updates against rebuilds.

use super::*;
use crate::layer::TsdfVoxel;

const VOXEL: f64 = 0.05;
const TRUNCATION: f64 = 3.0 * VOXEL;

/// A layer whose blocks `[-n, n)³` hold the signed distance `sdf` (truncated), all observed.
fn layer_of(n: i32, sdf: &Sdf) -> Layer {
    let mut layer = Layer::new(VOXEL, TRUNCATION);
    for bx in -n..n {
        for by in -n..n {
            for bz in -n..n {
                fill_block(&mut layer, [bx, by, bz], sdf);
            }
        }
    }
    layer
}

fn fill_block(layer: &mut Layer, index: BlockIndex, sdf: &Sdf) {
    let voxels: Vec<TsdfVoxel> = (0..VOXELS_PER_BLOCK)
        .map(|i| {
            let d = sdf(Block::voxel_center(index, i, VOXEL)) as f32;
            layer.voxel(d.clamp(-TRUNCATION as f32, TRUNCATION as f32), 1.0, [0; 3])
        })
        .collect();
    let (block, _) = layer.get_or_allocate(index);
    for (i, v) in voxels.into_iter().enumerate() {
        block.voxels.set(i, v);
    }
}

fn built(layer: &Layer, max_distance: f64) -> Esdf {
    let mut esdf = Esdf::new(VOXEL, max_distance);
    esdf.update(layer, &layer.sorted_indices());
    esdf
}

/// Per voxel of the field: its distance magnitude in voxels and the exact one (the nearest
/// site's centre by brute force, capped at the field's reach).
fn against_brute_force(esdf: &Esdf) -> Vec<(f64, f64)> {
    let sites: Vec<VoxelIndex> = esdf
        .voxels()
        .map(|(v, _)| v)
        .filter(|v| esdf.site(*v))
        .collect();
    assert!(!sites.is_empty());
    let reach = esdf.max_distance() as f64 / VOXEL;
    esdf.voxels()
        .map(|(v, d)| {
            let exact = sites
                .iter()
                .map(|s| (0..3).map(|a| ((v[a] - s[a]) as f64).powi(2)).sum::<f64>())
                .fold(f64::INFINITY, f64::min)
                .sqrt()
                .min(reach);
            (d.abs() as f64 / VOXEL, exact)
        })
        .collect()
}

/// A signed distance function of space.
type Sdf = dyn Fn(Point3<f64>) -> f64;

fn sphere(centre: Point3<f64>, radius: f64) -> impl Fn(Point3<f64>) -> f64 {
    move |p| (p - centre).norm() - radius
}

#[test]
fn distances_are_the_exact_distance_to_the_nearest_site() {
    let scenes: Vec<(&str, Box<Sdf>)> = vec![
        (
            "plane",
            Box::new(|p: Point3<f64>| 0.37 * p.x + 0.52 * p.y + 0.77 * p.z - 0.013),
        ),
        (
            "sphere",
            Box::new(sphere(Point3::new(0.03, -0.05, 0.02), 0.31)),
        ),
        (
            "box",
            Box::new(|p: Point3<f64>| {
                let q = p.coords.abs() - Vector3::new(0.3, 0.2, 0.25);
                q.map(|c| c.max(0.0)).norm() + q.max().min(0.0)
            }),
        ),
    ];
    for (name, sdf) in scenes {
        let layer = layer_of(2, &sdf);
        let esdf = built(&layer, 0.6);
        let pairs = against_brute_force(&esdf);
        let worst = pairs.iter().map(|(d, e)| (d - e).abs()).fold(0.0, f64::max);
        let exact = pairs.iter().filter(|(d, e)| (d - e).abs() < 1e-4).count();
        let mean = pairs.iter().map(|(d, e)| d - e).sum::<f64>() / pairs.len() as f64;
        eprintln!(
            "{name}: worst {worst:.3} mean {mean:.4} voxels, {exact} of {} exact",
            pairs.len()
        );
        assert!(worst <= 0.5, "{name}: worst error {worst} voxels");
        assert!(exact as f64 >= 0.99 * pairs.len() as f64, "{name}");
        // Propagated distances never undercut the exact ones (they are real offsets).
        assert!(pairs.iter().all(|(d, e)| d + 1e-4 >= *e), "{name}");
    }
}

#[test]
fn inside_is_negative_and_the_surface_is_within_a_voxel() {
    let centre = Point3::new(0.0, 0.0, 0.0);
    let layer = layer_of(2, &sphere(centre, 0.3));
    let esdf = built(&layer, 1.0);
    for (v, d) in esdf.voxels() {
        let p = Point3::from(Vector3::from(v.map(|c| (c as f64 + 0.5) * VOXEL)));
        let truth = (p - centre).norm() - 0.3;
        // Sites are within a voxel of the surface: the field is that close to the truth.
        assert!(
            (d as f64 - truth).abs() <= VOXEL + 1e-6,
            "{v:?}: {d} vs {truth}"
        );
        if truth < -VOXEL {
            assert!(d < 0.0);
        }
    }
}

#[test]
fn far_voxels_read_the_reach_and_unknown_stays_unknown() {
    let layer = layer_of(2, &|p: Point3<f64>| p.z + 0.7);
    let esdf = built(&layer, 0.3);
    let far = esdf.distance(&Point3::new(0.0, 0.0, 0.7)).unwrap();
    assert_eq!(far, 0.3);
    assert_eq!(esdf.distance(&Point3::new(0.0, 0.0, 3.0)), None);
    // A block allocated but never observed answers nothing either.
    let mut layer = layer;
    layer.get_or_allocate([5, 5, 5]);
    let esdf = built(&layer, 0.3);
    assert_eq!(esdf.distance(&Point3::new(2.1, 2.1, 2.1)), None);
}

#[test]
fn gradients_point_away_from_the_surface() {
    let layer = layer_of(2, &|p: Point3<f64>| p.x - 0.1);
    let esdf = built(&layer, 1.0);
    // Outside (x > 0.1) and inside alike, the signed distance grows along +x.
    for x in [0.3, 0.45, -0.3] {
        let (d, g) = esdf
            .distance_and_gradient(&Point3::new(x, 0.013, -0.021))
            .unwrap();
        assert!((d as f64 - (x - 0.1)).abs() < VOXEL, "{x}: {d}");
        assert!((g.x - 1.0).abs() < 1e-3, "{x}: {g:?}");
        assert!(g.y.abs() < 1e-3 && g.z.abs() < 1e-3, "{g:?}");
    }
}

/// `a` and `b` hold the same blocks, and in them the same voxels: flags and offsets alike.
fn assert_same(a: &Esdf, b: &Esdf, what: &str) {
    assert_eq!(a.block_indices(), b.block_indices(), "{what}");
    for index in a.block_indices() {
        let (ours, theirs) = (&a.blocks[&index], &b.blocks[&index]);
        for i in 0..VOXELS_PER_BLOCK {
            assert_eq!(
                ours[i],
                theirs[i],
                "{what}: voxel {:?}",
                Block::voxel_index(index, i)
            );
        }
    }
}

/// Every voxel of `esdf` holds the nearest site its face neighbours offer: the one state
/// propagation can end in.
fn assert_fixed_point(esdf: &Esdf, what: &str) {
    for index in esdf.block_indices() {
        let block = &esdf.blocks[&index];
        let faces: [Option<Face>; 6] = std::array::from_fn(|d| {
            let n = step(index, DIRECTIONS[d]);
            esdf.blocks.get(&n).map(|b| Face::of(b, d ^ 1))
        });
        for (i, &voxel) in block.iter().enumerate() {
            assert_eq!(
                evaluate(block, &faces, i, voxel, esdf.max_squared),
                voxel,
                "{what}: voxel {:?}",
                Block::voxel_index(index, i)
            );
        }
    }
}

#[test]
fn incremental_updates_equal_rebuilds() {
    let first = sphere(Point3::new(-0.1, 0.0, 0.0), 0.2);
    let mut layer = layer_of(3, &first);
    let mut esdf = built(&layer, 0.8);
    // The sphere moves: the blocks it left and entered change.
    let second = sphere(Point3::new(0.25, 0.1, 0.05), 0.25);
    let mut changed = Vec::new();
    for index in layer.sorted_indices() {
        let centre = Block::voxel_center(index, 0, VOXEL);
        if first(centre).abs() < 0.8 || second(centre).abs() < 0.8 {
            fill_block(&mut layer, index, &second);
            changed.push(index);
        }
    }
    let stats = esdf.update(&layer, &changed);
    assert_fixed_point(&esdf, "moved sphere");
    assert!(
        stats.sites_removed > 0 && stats.sites_added > 0,
        "{stats:?}"
    );
    assert!(stats.raised_voxels > 0, "{stats:?}");
    assert_same(&esdf, &built(&layer, 0.8), "moved sphere");
    // A block leaves the map: its voxels go, and its neighbours forget its sites.
    let gone = changed[changed.len() / 2];
    let mut smaller = Layer::new(VOXEL, TRUNCATION);
    for index in layer.sorted_indices().into_iter().filter(|i| *i != gone) {
        fill_block(&mut smaller, index, &second);
    }
    esdf.update(&smaller, &[gone]);
    assert_eq!(esdf.block_indices(), smaller.sorted_indices());
    assert_fixed_point(&esdf, "a block dropped");
    assert_same(&esdf, &built(&smaller, 0.8), "a block dropped");
    // Nothing changed: nothing to do.
    let stats = esdf.update(&smaller, &smaller.sorted_indices());
    assert_eq!((stats.marked_blocks, stats.rounds), (0, 0));
}

mod properties {
    use proptest::prelude::*;

    use super::*;

    /// Up to three balls in the blocks `[-2, 2)³` (5 cm voxels): centres and radii in metres.
    fn balls() -> impl Strategy<Value = Vec<(Point3<f64>, f64)>> {
        prop::collection::vec(
            ((-0.5..0.5f64, -0.5..0.5f64, -0.5..0.5f64), 0.05..0.4f64)
                .prop_map(|((x, y, z), r)| (Point3::new(x, y, z), r)),
            1..=3,
        )
    }

    fn union(balls: Vec<(Point3<f64>, f64)>) -> impl Fn(Point3<f64>) -> f64 {
        move |p| {
            balls
                .iter()
                .map(|(c, r)| (p - c).norm() - r)
                .fold(f64::INFINITY, f64::min)
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Whatever the scene, whichever blocks change to another scene, and whichever
        /// block leaves the map: the update ends in the field a rebuild builds.
        #[test]
        fn an_update_ends_where_a_rebuild_does(
            first in balls(),
            second in balls(),
            changed in prop::collection::vec(0usize..64, 1..40),
            dropped in prop::option::of(0usize..64),
            reach in 0.2..0.8f64,
        ) {
            let (first, second) = (union(first), union(second));
            let mut layer = layer_of(2, &first);
            let mut esdf = built(&layer, reach);
            let indices = layer.sorted_indices();
            let mut changed: Vec<BlockIndex> = changed.iter().map(|&k| indices[k]).collect();
            changed.sort_unstable();
            changed.dedup();
            for &index in &changed {
                fill_block(&mut layer, index, &second);
            }
            if let Some(k) = dropped {
                layer.remove(&indices[k]);
                if let Err(at) = changed.binary_search(&indices[k]) {
                    changed.insert(at, indices[k]);
                }
            }
            esdf.update(&layer, &changed);
            assert_fixed_point(&esdf, "updated");
            assert_same(&esdf, &built(&layer, reach), "updated against rebuilt");
        }
    }
}
