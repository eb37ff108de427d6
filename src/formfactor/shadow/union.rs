//! The union of the shadows at one point: F(x → B_j(x)), the form factor from x to the
//! part of P_j that the casters and solids hide from it ([`blocked_at`]). Each shadow is
//! P_j clipped by its cone, minus the cones of the shadows before it, so the union is
//! cut into disjoint convex pieces whose closed-form factors add up. Also the working
//! memory of the whole route ([`ShadowScratch`]), reused from point to point and pair
//! to pair.

use std::collections::BinaryHeap;

use glam::DVec3;

use super::caster::Caster;
use super::cone::{usable, Cone, Piece, SolidShadow};
use super::lambert::point_polygon;
use super::triangles::Open;
use crate::formfactor::shadow::solids::Solid;

/// Most pieces the union of the shadows of one point may be cut into before the
/// pair goes to rays.
const MAX_PIECES: usize = 256;

/// Working memory of [`blocked_at`] and [`super::integral::blocked_integral`], reused.
#[derive(Debug, Default)]
pub(crate) struct ShadowScratch {
    clip: Clip,
    /// The cone of the caster or solid at hand.
    cone: Cone,
    pub(super) active: Vec<Caster>,
    pub(super) loose: Vec<Caster>,
    pub(super) cells: Vec<Piece>,
    /// The outer rule's open triangles.
    pub(super) open: BinaryHeap<Open>,
}

/// Working memory of [`shadow_part`].
#[derive(Debug, Default)]
struct Clip {
    /// The cones of the shadows so far at this point.
    cones: Vec<Cone>,
    pieces: Vec<Piece>,
    next: Vec<Piece>,
    /// The shadow being clipped.
    shadow: Piece,
    /// Working memory of the clips.
    spare: Piece,
}

/// F(x → B_j(x)): the form factor from the point `x` (unit normal `n`) to the part of
/// `receiver` (P_j) that the `casters` and `solids` hide from it. None when the union of the
/// shadows needs more than [`MAX_PIECES`] pieces, or a piece more vertices than a
/// [`Piece`] holds.
pub(crate) fn blocked_at(
    x: DVec3,
    n: DVec3,
    receiver: &Piece,
    casters: &[Caster],
    solids: &[&Solid],
    tol: f64,
    s: &mut ShadowScratch,
) -> Option<f64> {
    let ShadowScratch { clip, cone, .. } = s;
    clip.cones.clear();
    let mut total = 0.0;
    for k in solids {
        match Cone::of_solid(x, k, receiver, tol, cone) {
            SolidShadow::Nothing => {}
            SolidShadow::Cone => shadow_part(x, n, receiver, cone, tol, clip, &mut total)?,
            SolidShadow::Triangles => {
                for t in &k.triangles {
                    if cone.set_triangle(x, t, tol) {
                        shadow_part(x, n, receiver, cone, tol, clip, &mut total)?;
                    }
                }
            }
        }
    }
    for t in casters {
        if cone.set_triangle(x, t, tol) {
            shadow_part(x, n, receiver, cone, tol, clip, &mut total)?;
        }
    }
    Some(total)
}

/// Adds to `total` F(x → ·) of the part of `receiver` in `cone` and outside the cones
/// of the shadows before it (`clip.cones`), to which `cone` is then added.
fn shadow_part(
    x: DVec3,
    n: DVec3,
    receiver: &Piece,
    cone: &Cone,
    tol: f64,
    clip: &mut Clip,
    total: &mut f64,
) -> Option<()> {
    if cone.misses(receiver, tol) {
        return Some(());
    }
    // This shadow on P_j, then minus the cones of the shadows before it. The first
    // clip writes the receiver's kept part straight into `shadow` (no copy of it first).
    let Clip {
        cones,
        pieces,
        next,
        shadow,
        spare,
    } = clip;
    let mut halves = cone.halves().iter();
    match halves.next() {
        Some(h) => {
            if receiver.n == receiver.v.len() {
                return None;
            }
            receiver.clip_front_into(h.normal, h.offset, tol, shadow);
        }
        None => *shadow = *receiver,
    }
    if usable(shadow) {
        for h in halves {
            if shadow.n == shadow.v.len() {
                return None;
            }
            shadow.clip_front_in_place(h.normal, h.offset, tol, spare);
            if !usable(shadow) {
                break;
            }
        }
    }
    let earlier = cones.len();
    cones.push(*cone);
    if !usable(shadow) {
        return Some(());
    }
    if earlier == 0 {
        *total += point_polygon(x, n, shadow.verts());
        return Some(());
    }
    pieces.clear();
    pieces.push(*shadow);
    for c in &cones[..earlier] {
        next.clear();
        for piece in pieces.iter() {
            if !subtract(piece, c, tol, next, spare) {
                return None;
            }
        }
        std::mem::swap(pieces, next);
        if pieces.is_empty() {
            break;
        }
        if pieces.len() > MAX_PIECES {
            return None;
        }
    }
    for piece in pieces.iter() {
        *total += point_polygon(x, n, piece.verts());
    }
    Some(())
}

/// Appends the convex pieces of `p` outside the cone `c` to `out`; false when a piece
/// would have more vertices than a [`Piece`] holds. `spare`: working memory.
fn subtract(p: &Piece, c: &Cone, tol: f64, out: &mut Vec<Piece>, spare: &mut Piece) -> bool {
    if c.misses(p, tol) {
        out.push(*p);
        return true;
    }
    let mut inside = *p;
    for h in c.halves() {
        if inside.n == inside.v.len() {
            return false;
        }
        inside.clip_front_into(-h.normal, -h.offset, tol, spare);
        if usable(spare) {
            out.push(*spare);
        }
        inside.clip_front_in_place(h.normal, h.offset, tol, spare);
        if !usable(&inside) {
            return true;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::clip::Polygon;
    use crate::formfactor::shadow::fixtures::{casters_of_square, square};
    use glam::dvec3;

    /// A convex solid, whole, hides what its triangles hide one by one, from points on
    /// the floor (beside and under a box without a bottom), on walls, on the ceiling
    /// and on the boxes' own faces, of receivers that include the boxes' faces.
    #[test]
    fn a_convex_solid_hides_what_its_triangles_hide() {
        use crate::formfactor::sampling::SplitMix64;
        use crate::formfactor::shadow::solids::{tests::box_triangles, Solids};
        let tris: Vec<[DVec3; 3]> = [
            box_triangles(dvec3(1.0, 0.0, 1.0), dvec3(2.0, 1.5, 2.5), true),
            box_triangles(dvec3(2.5, 0.5, 0.5), dvec3(3.0, 2.5, 1.0), false),
        ]
        .concat();
        let found = Solids::find(&tris, 1e-9);
        assert_eq!(found.solids.len(), 2);
        let solids: Vec<&Solid> = found.solids.iter().collect();
        let one_by_one: Vec<Caster> = tris.iter().filter_map(|t| Caster::new(*t)).collect();
        // Planes as (origin, u, v): the rectangle origin + [0,1]² (u, v); normal u × v.
        let rect = |o: [f64; 3], u: [f64; 3], v: [f64; 3]| {
            (DVec3::from(o), DVec3::from(u), DVec3::from(v))
        };
        let floor = rect([0.0; 3], [0.0, 0.0, 4.0], [4.0, 0.0, 0.0]);
        let ceiling = rect([0.0, 3.0, 0.0], [4.0, 0.0, 0.0], [0.0, 0.0, 4.0]);
        let east = rect([4.0, 0.0, 0.0], [0.0, 0.0, 4.0], [0.0, 3.0, 0.0]);
        let west = rect([0.0; 3], [0.0, 3.0, 0.0], [0.0, 0.0, 4.0]);
        let south = rect([0.0; 3], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]);
        let roof = rect([1.0, 1.5, 1.0], [0.0, 0.0, 1.5], [1.0, 0.0, 0.0]);
        let box_west = rect([1.0, 0.0, 1.0], [0.0, 0.0, 1.5], [0.0, 1.5, 0.0]);
        let box_east = rect([3.0, 0.5, 0.5], [0.0, 2.0, 0.0], [0.0, 0.0, 0.5]);
        let pairs = [
            (floor, ceiling),
            (floor, east),
            (floor, box_west),
            (ceiling, floor),
            (west, east),
            (west, box_west),
            (east, floor),
            (south, ceiling),
            (roof, ceiling),
            (box_east, east),
            (box_east, ceiling),
        ];
        let mut rng = SplitMix64::new(7);
        let (mut compared, mut whole, mut shaded) = (0, 0, 0);
        for ((oi, ui, vi), (oj, uj, vj)) in pairs {
            let ni = ui.cross(vi).normalize();
            let nj = uj.cross(vj);
            let pj = Polygon::new(&[oj, oj + uj, oj + uj + vj, oj + vj]);
            let pj_piece = Piece::new(pj.verts());
            for _ in 0..400 {
                let x = oi + rng.next_f64() * ui + rng.next_f64() * vi;
                if nj.dot(x - oj) <= 1e-9 {
                    continue; // the engine clips P_i to P_j's front
                }
                let mut s = ShadowScratch::default();
                let a = blocked_at(x, ni, &pj_piece, &[], &solids, 1e-12, &mut s).unwrap();
                let b = blocked_at(x, ni, &pj_piece, &one_by_one, &[], 1e-12, &mut s).unwrap();
                assert!((a - b).abs() <= 1e-10, "x {x}: solids {a}, triangles {b}");
                compared += 1;
                shaded += usize::from(b > 1e-6);
                let receiver = Piece::new(pj.verts());
                let mut cone = Cone::EMPTY;
                whole += solids
                    .iter()
                    .filter(|k| {
                        !matches!(
                            Cone::of_solid(x, k, &receiver, 1e-12, &mut cone),
                            SolidShadow::Triangles
                        )
                    })
                    .count();
            }
        }
        // The solids were used whole nearly everywhere, and there were shadows.
        assert!(
            whole >= 2 * compared * 95 / 100,
            "whole {whole} of {}",
            2 * compared
        );
        assert!(shaded >= compared / 4, "shaded {shaded} of {compared}");
    }

    #[test]
    fn a_parallel_square_blocker_casts_its_scaled_square() {
        // From x = (0.3, 0, 0.4), a blocker at height 0.5 over [0.25, 0.75]² casts the
        // square [0.5 − x, 1.5 − x] on the plane y = 1 (scale 2 about x): on the unit
        // receiver that is [0.2, 1] × [0.1, 1].
        let x = dvec3(0.3, 0.0, 0.4);
        let pj = square(0.0, 1.0, 0.0, 1.0, 1.0);
        let pj_piece = Piece::new(pj.verts());
        let casters = casters_of_square(0.25, 0.75, 0.25, 0.75, 0.5);
        let mut s = ShadowScratch::default();
        let got = blocked_at(x, DVec3::Y, &pj_piece, &casters, &[], 1e-12, &mut s).unwrap();
        let shadow = square(0.2, 1.0, 0.1, 1.0, 1.0);
        let want = point_polygon(x, DVec3::Y, shadow.verts());
        assert!((got - want).abs() < 1e-14, "{got} vs {want}");
        // The two triangles' shadows share the diagonal: nothing counted twice.
        let x = dvec3(0.5, 0.0, 0.5);
        let got = blocked_at(x, DVec3::Y, &pj_piece, &casters, &[], 1e-12, &mut s).unwrap();
        let want = point_polygon(x, DVec3::Y, square(0.0, 1.0, 0.0, 1.0, 1.0).verts());
        assert!((got - want).abs() < 1e-14, "{got} vs {want}");
    }

    #[test]
    fn overlapping_shadows_count_once_and_behind_or_beyond_count_nothing() {
        let x = dvec3(0.5, 0.0, 0.5);
        let pj = square(0.0, 1.0, 0.0, 1.0, 1.0);
        let pj_piece = Piece::new(pj.verts());
        let mut s = ShadowScratch::default();
        let one = casters_of_square(0.4, 0.6, 0.4, 0.6, 0.5);
        let alone = blocked_at(x, DVec3::Y, &pj_piece, &one, &[], 1e-12, &mut s).unwrap();
        // The same square again, and a smaller one inside its shadow cone.
        let mut many = one.clone();
        many.extend(casters_of_square(0.4, 0.6, 0.4, 0.6, 0.5));
        many.extend(casters_of_square(0.47, 0.53, 0.47, 0.53, 0.8));
        let got = blocked_at(x, DVec3::Y, &pj_piece, &many, &[], 1e-12, &mut s).unwrap();
        assert!((got - alone).abs() < 1e-15, "{got} vs {alone}");
        // Below x, or beyond the receiver's plane: no shadow.
        let behind = casters_of_square(0.0, 1.0, 0.0, 1.0, -0.5);
        let beyond = casters_of_square(0.0, 1.0, 0.0, 1.0, 1.5);
        for c in [behind, beyond] {
            assert_eq!(
                blocked_at(x, DVec3::Y, &pj_piece, &c, &[], 1e-12, &mut s),
                Some(0.0)
            );
        }
    }
}
