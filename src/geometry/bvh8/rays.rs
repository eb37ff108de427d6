//! Shadow segments prepared for the walks: one ray ([`SegmentRay`]) or the sixteen
//! rays of a pair as lanes ([`SegmentPacket`]), in f32, clipped to the normalized box.

use glam::{DVec3, Vec3A};
use wide::{f32x16 as Lanes16, f32x4, f32x8};

/// Segments are clipped to the box ±`CLIP` (the triangles lie within ±0.5) before
/// their f32 set-up, which bounds the coordinates, and so the rounding errors, of
/// every traversal.
pub(crate) const CLIP: f64 = 1.0;

/// A shadow segment prepared for the traversal, f32: its end points (clipped to
/// ±[`CLIP`]) for the triangle filter, and its inverse direction with origin ×
/// inverse direction for the slab tests (t ∈ [0, 1] over the clipped segment).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SegmentRay {
    p0: [f32; 3],
    p1: [f32; 3],
    inv: [f32; 3],
    oi: [f32; 3],
}

impl SegmentRay {
    /// The segment from `f` to `f + d` (normalized frame), clipped to ±[`CLIP`];
    /// `None` when nothing of it lies in that box (then no triangle can meet it).
    pub(crate) fn new(f: DVec3, d: DVec3) -> Option<Self> {
        let [p0, p1, dd] = clipped_f32(f, d)?;
        let inv = inverse(Vec3A::from_array(dd));
        Some(SegmentRay {
            p0,
            p1,
            inv: inv.to_array(),
            oi: (Vec3A::from_array(p0) * inv).to_array(),
        })
    }
}

/// [`clip`] in f32: the clipped start, end, and end − start (taken in f64).
#[inline(always)]
fn clipped_f32(f: DVec3, d: DVec3) -> Option<[[f32; 3]; 3]> {
    let (p0, p1) = clip(f, d)?;
    Some([p0, p1, p1 - p0].map(|p| p.as_vec3().to_array()))
}

/// The end points of the segment from `f` to `f + d` clipped to ±[`CLIP`] (the
/// segment itself when it lies inside); `None` when nothing of it is inside.
#[inline(always)]
fn clip(f: DVec3, d: DVec3) -> Option<(DVec3, DVec3)> {
    let (mut a, mut b) = (0.0f64, 1.0f64);
    if f.abs().max_element() > CLIP || (f + d).abs().max_element() > CLIP {
        for k in 0..3 {
            if d[k] == 0.0 {
                if f[k].abs() > CLIP {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d[k];
            let (t0, t1) = ((-CLIP - f[k]) * inv, (CLIP - f[k]) * inv);
            a = a.max(t0.min(t1));
            b = b.min(t0.max(t1));
        }
        if a.is_nan() || b.is_nan() || a > b {
            return None;
        }
    }
    Some((f + d * a, f + d * b))
}

/// 1/dd per component; a zero (or vanishing) component gets a large finite inverse
/// of the same sign instead, which keeps the slab products free of ∞ − ∞.
#[inline(always)]
fn inverse(dd: Vec3A) -> Vec3A {
    let i = Vec3A::ONE / dd;
    let big = Vec3A::splat(INV_MAX).copysign(dd);
    Vec3A::select(i.abs().cmplt(Vec3A::splat(INV_MAX)), i, big)
}

/// Largest inverse direction component (see [`inverse`]).
const INV_MAX: f32 = 1e30;

/// Slab parameters the boxes must overlap: a little beyond [0, 1], since the boxes
/// are padded ([`super::BOX_PAD`]) and the segment's ends may lie on them.
pub(crate) const T_MIN: f32 = -1e-3;
pub(crate) const T_MAX: f32 = 1.0 + 1e-3;

/// One [`SegmentRay`] as lanes: its slab terms over the eight children of a node,
/// its end points over the four triangles of a block.
pub(crate) struct RayLanes {
    pub(crate) inv: [f32x8; 3],
    pub(crate) oi: [f32x8; 3],
    /// Row of [`super::Node::b`] holding the near / far side of the boxes along each axis.
    pub(crate) near: [usize; 3],
    pub(crate) far: [usize; 3],
    pub(crate) p0: [f32x4; 3],
    pub(crate) p1: [f32x4; 3],
}

impl RayLanes {
    pub(crate) fn new(r: &SegmentRay) -> Self {
        let near = [0, 1, 2].map(|k| if r.inv[k] >= 0.0 { k } else { k + 3 });
        RayLanes {
            inv: r.inv.map(f32x8::splat),
            oi: r.oi.map(f32x8::splat),
            near,
            far: near.map(|row| (row + 3) % 6),
            p0: r.p0.map(f32x4::splat),
            p1: r.p1.map(f32x4::splat),
        }
    }
}

/// Most segments a [`SegmentPacket`] holds, one per lane of its vectors (sixteen
/// f32: two AVX registers, or one AVX-512 register when built for it).
pub(crate) const PACKET: usize = 16;

/// Up to [`PACKET`] shadow segments walked together ([`super::Bvh8::any_hit_packet`]), one
/// per lane: the rays of one pair of patches start and end close to each other, so
/// they pass through mostly the same nodes, and a node is then fetched and tested once
/// for all of them, with no chain of dependent steps per ray.
pub(crate) struct SegmentPacket {
    pub(crate) inv: [Lanes16; 3],
    pub(crate) oi: [Lanes16; 3],
    pub(crate) p0: [Lanes16; 3],
    pub(crate) p1: [Lanes16; 3],
    /// Lanes that hold a segment.
    pub(crate) lanes: u32,
}

impl SegmentPacket {
    /// The segments from `f` to `f + d` (normalized frame), in lanes `0..ends.len()`;
    /// the set-up of [`SegmentRay::new`] for all of them at once. A segment with
    /// nothing inside ±[`CLIP`] leaves its lane empty (never blocked).
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    pub(crate) fn new(ends: &[(DVec3, DVec3)]) -> Self {
        assert!(ends.len() <= PACKET, "{} segments in a packet", ends.len());
        // p0, p1, p1 − p0; per axis; per lane.
        let mut v = [[[0f32; PACKET]; 3]; 3];
        let mut lanes = 0;
        for (l, &(f, d)) in ends.iter().enumerate() {
            let Some(ends) = clipped_f32(f, d) else {
                continue;
            };
            lanes |= 1 << l;
            for (rows, x) in v.iter_mut().zip(ends) {
                for k in 0..3 {
                    rows[k][l] = x[k];
                }
            }
        }
        let [p0, p1, dd] = v.map(|rows| rows.map(Lanes16::from));
        // `inverse`, lane by lane (an empty lane has dd = 0, so 1e30; whatever it
        // meets is masked out by `lanes`).
        let inv = dd.map(|dd| {
            let i = Lanes16::ONE / dd;
            let keep = i.abs().simd_lt(Lanes16::splat(INV_MAX));
            let big = (dd & Lanes16::splat(-0.0)) | Lanes16::splat(INV_MAX);
            (keep & i) | (!keep & big)
        });
        SegmentPacket {
            inv,
            oi: [0, 1, 2].map(|k| p0[k] * inv[k]),
            p0,
            p1,
            lanes,
        }
    }
}

/// The slots of `mask` in the order a walk pushes them: the last first, so that the
/// first (the child with most triangles) is popped next.
#[inline(always)]
pub(crate) fn last_first(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let s = 31 - mask.leading_zeros();
            mask &= !(1 << s);
            s as usize
        })
    })
}
