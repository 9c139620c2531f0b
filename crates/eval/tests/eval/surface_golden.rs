//! Surface accuracy matches an independent exact implementation (trimesh's closest point, see
//! tools/surface_reference.py) on a golden case: 7,475 vertices of a reconstruction of the
//! synthetic world against its ground-truth mesh, floaters included. The two agree to about
//! 1e-8 relative (closest-point arithmetic differs in the last digits).

use std::path::Path;

use voxpan_core::nalgebra::Point3;
use voxpan_eval::surface::{TriangleIndex, accuracy};

#[test]
fn accuracy_over_every_vertex_matches_trimesh() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/surface");
    let truth = voxpan_io::read_ply(&dir.join("truth.ply")).unwrap();
    let recon = voxpan_io::read_ply(&dir.join("reconstruction.ply")).unwrap();
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("trimesh.json")).unwrap()).unwrap();
    let vertices: Vec<Point3<f64>> = recon
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    assert_eq!(
        vertices.len() as u64,
        expected["vertices"].as_u64().unwrap()
    );
    let index = TriangleIndex::new(truth.triangle_points(), 0.04);
    let got = accuracy(&vertices, &index, expected["threshold"].as_f64().unwrap());
    for (name, value) in [
        ("mean", got.mean),
        ("median", got.median),
        ("p95", got.p95),
        ("within", got.within),
    ] {
        let want = expected[name].as_f64().unwrap();
        assert!(
            (value - want).abs() <= 1e-7 * want.abs().max(1e-3),
            "{name}: {value} vs trimesh {want}"
        );
    }
}
