//! The adaptive outer rule over P_i's cells ([`Run`]): each cell is settled whole when
//! it can be (hidden whole by one caster or solid, or lit), else fanned into triangles
//! that the 19-point rule estimates with the embedded 7-point rule's difference as the
//! error; the triangle with the largest error is cut into four until the errors add up
//! to the tolerance (globally adaptive, as QUADPACK's QAG).

use std::collections::BinaryHeap;

use glam::DVec3;

use super::caster::Caster;
use super::cone::Piece;
use super::hidden::{hides, segments_may_cross, solid_hides};
use super::lambert::point_polygon;
use super::pair::Pair;
use super::triangles::{Cell, Open};
use super::union::{blocked_at, ShadowScratch};
use crate::formfactor::clip::{Polygon, MAX_VERTS};
use crate::formfactor::contour::area_form_factor;
use crate::formfactor::quadrature::{gauss_table, LAURIE, RADON};
use crate::formfactor::shadow::solids::Solid;

/// The state of one outer integral.
pub(super) struct Run<'p, 'a> {
    pub(super) pair: &'p Pair<'a>,
    /// The casters that belong to no solid, and the solids.
    pub(super) loose: &'p [Caster],
    pub(super) solids: &'p [&'a Solid],
    /// P_j as a [`Piece`], for [`blocked_at`].
    pub(super) receiver: Piece,
    pub(super) points: u32,
    /// Points after which the rule stops refining.
    pub(super) max_points: u32,
    /// Depth at which a triangle is not refined again.
    pub(super) max_depth: u32,
    /// Triangles put in the open list so far (each gets the next number).
    pub(super) seq: u64,
    /// The errors of the triangles put in the open list since [`Run::integrate`] last
    /// took them into its running sum.
    pub(super) added: f64,
}

impl Run<'_, '_> {
    /// Whether no caster can cross a segment from the convex cell `w` to P_j.
    fn lit(&self, w: &[DVec3]) -> bool {
        let p = self.pair;
        !p.casters
            .iter()
            .any(|c| segments_may_cross(w, p.pj.verts(), &c.v, p.tol))
    }

    /// What the convex cell `w` (three vertices or more) blocks when one caster or one
    /// convex solid hides all of P_j from all of it: ∫_cell F(x → P_j) dA_x, the
    /// unoccluded contour integral from it to P_j, per fan triangle when it has more
    /// vertices than a [`Polygon`]. None when it is not so hidden, or the value comes out
    /// negative or not finite (the rule then takes the cell). The tests are on vertex
    /// pairs and fail fast, unlike [`Run::lit`]'s separating axes.
    fn hidden(&self, w: &[DVec3]) -> Option<f64> {
        let p = self.pair;
        let q = p.pj.verts();
        let hidden = p.casters.iter().any(|c| hides(w, q, c, p.tol))
            || self.solids.iter().any(|k| solid_hides(w, q, k, p.tol));
        if !hidden {
            return None;
        }
        let contour = |poly: &Polygon| area_form_factor(poly, p.pj, gauss_table(), p.params);
        let value = if w.len() <= MAX_VERTS {
            contour(&Polygon::new(w))
        } else {
            (1..w.len() - 1)
                .map(|k| contour(&Polygon::new(&[w[0], w[k], w[k + 1]])))
                .sum()
        };
        (value.is_finite() && value >= 0.0).then_some(value)
    }
}

/// The point of triangle `t` with barycentric coordinates `b`.
fn barycentric(t: &[DVec3; 3], b: [f64; 3]) -> DVec3 {
    b[0] * t[0] + b[1] * t[1] + b[2] * t[2]
}

impl Run<'_, '_> {
    /// The degree-8 estimate on triangle `t` and its error: the 19 points of
    /// [`LAURIE`], of which the first seven also give [`RADON`]'s degree-5 value.
    fn cell(&mut self, t: [DVec3; 3], s: &mut ShadowScratch) -> Option<Cell> {
        let area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        let p = self.pair;
        let (mut high, mut low, mut dark_free) = (0.0, 0.0, true);
        for (k, (b, w)) in LAURIE.into_iter().enumerate() {
            let g = blocked_at(
                barycentric(&t, b),
                p.ni,
                &self.receiver,
                self.loose,
                self.solids,
                p.tol,
                s,
            )?;
            high += w * g;
            if let Some(&(_, w5)) = RADON.get(k) {
                low += w5 * g;
            }
            dark_free &= g == 0.0;
        }
        self.points += LAURIE.len() as u32;
        Some(Cell {
            t,
            area,
            value: high * area,
            err: (high - low).abs() * area,
            dark_free,
        })
    }

    /// What the triangle of `c` could hold when its samples see no shadow: twice its
    /// area times the largest unoccluded F(x → P_j) over the samples (a shadow may hide
    /// between them). Asked only when such a triangle goes into the open list: the
    /// first triangles of a lit cell ([`Run::start`]) never need it.
    fn could_hold(&self, c: &Cell) -> f64 {
        let p = self.pair;
        let lit_max = LAURIE
            .iter()
            .map(|&(b, _)| point_polygon(barycentric(&c.t, b), p.ni, p.pj.verts()))
            .fold(0.0f64, f64::max);
        2.0 * c.area * lit_max
    }

    /// Settles the cells that need no rule and puts the first triangles of the others
    /// (each cell fanned) in `open`; returns what the settled cells block. A cell is
    /// settled when one caster or solid hides all of P_j from it ([`Run::hidden`]), or
    /// when it is lit ([`Run::lit`]): that takes separating-axis tests, so it is asked
    /// only when none of the first samples on the cell sees a shadow. None: as
    /// [`Run::cell`].
    pub(super) fn start(
        &mut self,
        cells: &[Piece],
        open: &mut BinaryHeap<Open>,
        s: &mut ShadowScratch,
    ) -> Option<f64> {
        let mut settled = 0.0;
        let mut first: Vec<Cell> = Vec::new();
        for c in cells {
            let w = c.verts();
            if w.len() < 3 {
                continue;
            }
            if let Some(x) = self.hidden(w) {
                settled += x;
                continue;
            }
            first.clear();
            for k in 1..w.len() - 1 {
                first.push(self.cell([w[0], w[k], w[k + 1]], s)?);
            }
            if first.iter().all(|c| c.dark_free) && self.lit(w) {
                continue;
            }
            for &cell in &first {
                self.push(open, cell, 0);
            }
        }
        Some(settled)
    }

    /// Puts triangle `c` (at refinement depth `depth`) in the open list with its error.
    /// A triangle whose samples all see no shadow has value 0 and as its error what it
    /// could hold ([`Run::could_hold`]); when that is 0 it is dropped. Any other carries
    /// its rules' difference.
    fn push(&mut self, open: &mut BinaryHeap<Open>, c: Cell, depth: u32) {
        let err = if c.dark_free {
            self.could_hold(&c)
        } else {
            c.err
        };
        if c.dark_free && err <= 0.0 {
            return;
        }
        self.seq += 1;
        self.added += err;
        open.push(Open {
            err,
            seq: self.seq,
            cell: c,
            depth,
        });
    }

    /// Refines the open triangle with the largest error until the errors sum to at
    /// most `tol` (globally adaptive, as QUADPACK's QAG does on an interval: the
    /// tolerance goes where the error is, not in proportion to area), then returns
    /// `settled` plus the open triangles' values, and whether the tolerance was met.
    /// A triangle is refined by cutting it at its edge midpoints into four, each
    /// estimated afresh.
    pub(super) fn integrate(
        &mut self,
        open: &mut BinaryHeap<Open>,
        settled: f64,
        tol: f64,
        s: &mut ShadowScratch,
    ) -> Option<(f64, bool)> {
        let (mut done, mut unmet) = (settled, 0.0);
        let exact = |open: &BinaryHeap<Open>| open.iter().map(|o| o.err).sum::<f64>();
        // A running sum of the open errors, added up afresh every so often and before
        // it is believed (subtracting drifts by rounding).
        let mut err = exact(open);
        self.added = 0.0;
        let mut steps = 0u32;
        // The target: the open errors plus those of triangles kept at the deepest level.
        while self.points < self.max_points {
            if err + unmet <= tol || steps % 1024 == 1023 {
                err = exact(open);
                if err + unmet <= tol {
                    break;
                }
            }
            steps += 1;
            let Some(top) = open.pop() else { break };
            if !top.err.is_finite() {
                return None; // no estimate to refine (it should not happen): rays
            }
            err -= top.err;
            // A triangle that sees no shadow: 0 exactly when nothing crosses between it
            // and P_j (at any depth), else its children decide.
            if top.cell.dark_free && self.lit(&top.cell.t) {
                continue;
            }
            if top.depth + 1 >= self.max_depth {
                done += top.cell.value;
                unmet += top.err;
                continue;
            }
            let t = top.cell.t;
            let m = [
                0.5 * (t[0] + t[1]),
                0.5 * (t[1] + t[2]),
                0.5 * (t[2] + t[0]),
            ];
            for child in [
                [t[0], m[0], m[2]],
                [m[0], t[1], m[1]],
                [m[2], m[1], t[2]],
                [m[0], m[1], m[2]],
            ] {
                let c = self.cell(child, s)?;
                self.push(open, c, top.depth + 1);
            }
            err += std::mem::take(&mut self.added);
        }
        let err = exact(open);
        let value = done + open.iter().map(|o| o.cell.value).sum::<f64>();
        // A value that is not a number (it should not happen) is no estimate: rays.
        value.is_finite().then_some((value, err + unmet <= tol))
    }
}
