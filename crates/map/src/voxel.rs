/// One voxel of the TSDF: signed distance to the nearest surface along the camera rays (metres,
/// positive in front), its fusion weight (0 = never observed) and the fused colour.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct TsdfVoxel {
    pub distance: f32,
    pub weight: f32,
    pub color: [u8; 3],
    _pad: u8,
}

impl TsdfVoxel {
    pub fn new(distance: f32, weight: f32, color: [u8; 3]) -> Self {
        Self {
            distance,
            weight,
            color,
            _pad: 0,
        }
    }

    pub fn observed(&self) -> bool {
        self.weight > 0.0
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn twelve_bytes_per_voxel() {
        assert_eq!(std::mem::size_of::<super::TsdfVoxel>(), 12);
    }
}
