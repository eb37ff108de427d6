//! Patches: the unit of the form-factor matrix.
//!
//! A patch is a planar triangle or planar convex quad cut from one scene face by
//! subdivision. Row/column `i` of the matrix is patch `i` of a [`PatchSet`]. The same
//! table is stored in the `.ffz` file (so a solver needs nothing but the file), loaded
//! by the solver and drawn by the renderer.

use glam::DVec3;

/// One patch. Faces are one-sided: the front is the side the corners wind
/// counter-clockwise around, and `normal` points out of it.
#[derive(Clone, Debug, PartialEq)]
pub struct Patch {
    /// Corners, counter-clockwise seen from the front; only the first `n_corners` count.
    pub corners: [DVec3; 4],
    /// 3 (triangle) or 4 (planar convex quad).
    pub n_corners: u8,
    /// Unit normal of the front side.
    pub normal: DVec3,
    /// Area (scene units squared).
    pub area: f64,
    /// Index into [`PatchSet::groups`]: the OBJ group/object the patch came from.
    pub group: u32,
    /// Index of the scene face the patch was cut from (used to skip self-occlusion).
    pub face: u32,
    /// Diffuse reflectance per RGB channel (MTL `Kd`), each in [0, 1).
    pub rho: [f32; 3],
    /// Emitted exitance per RGB channel (MTL `Ke`), radiosity units.
    pub emission: [f32; 3],
}

impl Patch {
    /// The corners that count (3 or 4).
    #[inline]
    pub fn corners(&self) -> &[DVec3] {
        &self.corners[..self.n_corners as usize]
    }

    /// Area-weighted centroid (for a triangle or a planar quad).
    pub fn centroid(&self) -> DVec3 {
        let c = self.corners();
        if c.len() == 3 {
            return (c[0] + c[1] + c[2]) / 3.0;
        }
        // Split the quad along the diagonal 0-2 and weight the two triangle centroids.
        let a1 = (c[1] - c[0]).cross(c[2] - c[0]).length();
        let a2 = (c[2] - c[0]).cross(c[3] - c[0]).length();
        let g1 = (c[0] + c[1] + c[2]) / 3.0;
        let g2 = (c[0] + c[2] + c[3]) / 3.0;
        if a1 + a2 > 0.0 {
            (g1 * a1 + g2 * a2) / (a1 + a2)
        } else {
            (g1 + g2) * 0.5
        }
    }

    /// True when the patch neither reflects nor emits in any channel: a gathering
    /// solve never needs its row.
    pub fn is_inert(&self) -> bool {
        self.rho.iter().all(|&r| r == 0.0) && self.emission.iter().all(|&e| e == 0.0)
    }
}

/// All patches of a scene, with the group names they refer to.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchSet {
    pub patches: Vec<Patch>,
    pub groups: Vec<String>,
}

impl PatchSet {
    pub fn len(&self) -> usize {
        self.patches.len()
    }

    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }

    /// Bounding box of all (finite) patch corners; `None` when there is none.
    pub(crate) fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for c in self
            .patches
            .iter()
            .flat_map(|p| p.corners())
            .filter(|c| c.is_finite())
        {
            lo = lo.min(*c);
            hi = hi.max(*c);
        }
        (lo.x <= hi.x).then_some((lo, hi))
    }

    /// Length of the bounding box diagonal (0 for an empty or degenerate set): the
    /// scene size that relative tolerances scale with.
    pub(crate) fn diagonal(&self) -> f64 {
        self.bounds().map_or(0.0, |(lo, hi)| (hi - lo).length())
    }

    /// Name of the group of patch `i`.
    pub fn group_name(&self, i: usize) -> &str {
        &self.groups[self.patches[i].group as usize]
    }

    /// Hash of everything that determines the matrix and the solve: corners, normals,
    /// areas, groups, materials. Two runs agree on it exactly when they describe the
    /// same patches; it is stored in the `.ffz` header and checked on resume and by
    /// MPI workers.
    pub fn content_hash(&self) -> u64 {
        let mut h = xxhash_rust::xxh3::Xxh3::new();
        h.update(&(self.patches.len() as u64).to_le_bytes());
        for g in &self.groups {
            h.update(&(g.len() as u64).to_le_bytes());
            h.update(g.as_bytes());
        }
        for p in &self.patches {
            h.update(&[p.n_corners]);
            for c in p.corners() {
                for x in c.to_array() {
                    h.update(&x.to_le_bytes());
                }
            }
            for x in p.normal.to_array() {
                h.update(&x.to_le_bytes());
            }
            h.update(&p.area.to_le_bytes());
            h.update(&p.group.to_le_bytes());
            h.update(&p.face.to_le_bytes());
            for x in p.rho.iter().chain(p.emission.iter()) {
                h.update(&x.to_le_bytes());
            }
        }
        h.digest()
    }

    /// Total emitted power per channel, Σ A_i E_i.
    pub fn emitted_power(&self) -> [f64; 3] {
        let mut s = [0.0; 3];
        for p in &self.patches {
            for (c, s) in s.iter_mut().enumerate() {
                *s += p.area * p.emission[c] as f64;
            }
        }
        s
    }
}
