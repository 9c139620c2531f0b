use voxpan_core::{ColorImage, DepthImage, LabelImage};

use crate::{Rand, Scene};

/// What an active depth camera (RealSense-like) does to the true depth. Each effect can be
/// switched off; `SensorModel::ideal()` switches all off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorModel {
    /// Gaussian noise with σ = 1 mm + 2 mm·z² (about 1 % at 1 m, 1.6 cm at 3 m).
    pub noise: bool,
    /// Round to whole millimetres (a 16-bit millimetre depth stream).
    pub quantise: bool,
    /// Missing depth: at depth edges, on dark and on specular surfaces.
    pub holes: bool,
    /// Beyond this range (metres) the sensor returns nothing.
    pub max_range: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            noise: true,
            quantise: true,
            holes: true,
            max_range: 6.0,
        }
    }
}

impl SensorModel {
    /// Exact depth, every effect off (range limit too).
    pub fn ideal() -> Self {
        Self {
            noise: false,
            quantise: false,
            holes: false,
            max_range: f64::INFINITY,
        }
    }

    /// The measured depth for the true `depth`.
    pub fn measure(
        &self,
        depth: &DepthImage,
        color: &ColorImage,
        instances: &LabelImage,
        scene: &Scene,
        rng: &mut Rand,
    ) -> DepthImage {
        let (w, h) = depth.dims();
        let specular: Vec<bool> = {
            let mut by_id = vec![false; u16::MAX as usize + 1];
            for o in &scene.objects {
                by_id[o.instance_id as usize] = o.specular;
            }
            by_id
        };
        DepthImage::from_fn(w, h, |x, y| {
            let z = *depth.get(x, y) as f64;
            if z <= 0.0 || z > self.max_range {
                return 0.0;
            }
            if self.holes {
                let edge = [(0i64, 1i64), (1, 0), (0, -1), (-1, 0)]
                    .iter()
                    .any(|&(dx, dy)| {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        nx >= 0
                            && ny >= 0
                            && (nx as usize) < w
                            && (ny as usize) < h
                            && ((*depth.get(nx as usize, ny as usize) as f64) - z).abs() > 0.08 * z
                    });
                let [r, g, b] = *color.get(x, y);
                let luminance = 0.299 * r as f64 + 0.587 * g as f64 + 0.114 * b as f64;
                let shiny = specular[*instances.get(x, y) as usize];
                if (edge && rng.chance(0.6))
                    || (luminance < 45.0 && rng.chance(0.8))
                    || (shiny && rng.chance(0.4))
                {
                    return 0.0;
                }
            }
            let mut measured = z;
            if self.noise {
                measured += (0.001 + 0.002 * z * z) * rng.normal();
            }
            if self.quantise {
                measured = (measured * 1000.0).round() / 1000.0;
            }
            measured.max(0.0) as f32
        })
    }
}
