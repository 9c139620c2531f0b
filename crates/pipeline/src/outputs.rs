//! What a run leaves in its output folder: the map file, its meshes (by RGB, instance and
//! class; one per instance), the effective configuration and, on request, the refined masks.

use std::path::{Path, PathBuf};
use std::time::Instant;

use voxpan_map::{Coloring, MapError, PanopticMap};
use voxpan_perception::Perceived;

use crate::{Config, Mapped};

/// A file of the output folder that could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("cannot create {path}: {source}")]
    Folder {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    File(#[from] voxpan_io::IoError),
    #[error(transparent)]
    Map(#[from] MapError),
}

/// What [`write_outputs`] wrote.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Outputs {
    /// Paths relative to the output folder.
    pub files: Vec<String>,
    pub triangles: usize,
    pub vertices: usize,
    /// Milliseconds of the final mesh extraction.
    pub mesh_ms: f64,
}

pub(crate) fn create_folder(path: &Path) -> Result<(), OutputError> {
    std::fs::create_dir_all(path).map_err(|source| OutputError::Folder {
        path: path.to_owned(),
        source,
    })
}

/// A name safe in a file name: letters, digits, `-` and `_` kept, anything else `_`.
fn file_safe(name: &str) -> String {
    let cleaned: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    cleaned.to_lowercase()
}

/// The file name of instance `id`'s mesh: `NNNN_<class name>.ply`, the class named by the
/// map's label table when it knows it, else by number (`class7`), else `unknown`.
pub fn instance_file_name(map: &PanopticMap, id: u16) -> String {
    let class = match map.class_of(id) {
        Some(c) => map
            .class_name(c)
            .map(file_safe)
            .unwrap_or_else(|| format!("class{c}")),
        None => "unknown".to_owned(),
    };
    format!("{id:04}_{class}.ply")
}

/// Writes `config.toml` into `out` (created if needed).
pub fn write_config(out: &Path, config: &Config) -> Result<(), OutputError> {
    create_folder(out)?;
    let text = config.to_toml();
    voxpan_io::write_atomically(&out.join("config.toml"), |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

/// Writes a frame's refined label image as `out/refined/<frame id>.png`.
pub fn write_refined(out: &Path, perceived: &Perceived) -> Result<(), OutputError> {
    if let Some(s) = &perceived.segments {
        let dir = out.join("refined");
        create_folder(&dir)?;
        voxpan_io::write_label_png(&dir.join(format!("{}.png", perceived.frame.id)), &s.labels)?;
    }
    Ok(())
}

/// Writes the map and its meshes into `out`: `map.voxpan`, `mesh_rgb.ply`,
/// `mesh_instance.ply`, `mesh_class.ply` and, when configured, `instances/NNNN_<class>.ply`.
/// Records the mesh time in the report.
pub fn write_outputs(
    out: &Path,
    mapped: &mut Mapped,
    config: &Config,
) -> Result<Outputs, OutputError> {
    create_folder(out)?;
    let map: &mut PanopticMap = &mut mapped.map;
    let t = Instant::now();
    let mesh = map.mesh(Coloring::Rgb);
    let mesh_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut outputs = Outputs {
        triangles: mesh.triangles.len(),
        vertices: mesh.vertices.len(),
        mesh_ms,
        ..Outputs::default()
    };
    let mut write = |name: String, m: &voxpan_core::Mesh| -> Result<(), OutputError> {
        voxpan_io::write_ply(&out.join(&name), m, "voxpan TSDF mesh")?;
        outputs.files.push(name);
        Ok(())
    };
    write("mesh_rgb.ply".into(), &mesh)?;
    write(
        "mesh_instance.ply".into(),
        &mesh.colored_by(|id| voxpan_map::id_color(id as u32)),
    )?;
    let class_color = |id: u16| voxpan_map::id_color(map.class_of(id).map_or(0, |c| c + 1));
    write("mesh_class.ply".into(), &mesh.colored_by(class_color))?;
    if config.output.instance_meshes {
        create_folder(&out.join("instances"))?;
        for (id, part) in mesh.split_by_instance() {
            write(format!("instances/{}", instance_file_name(map, id)), &part)?;
        }
    }
    map.save(&out.join("map.voxpan"))?;
    outputs.files.push("map.voxpan".into());
    mapped.report.triangles = outputs.triangles;
    mapped.report.stage_ms.insert("mesh".into(), mesh_ms);
    Ok(outputs)
}
