//! Convex solids among the occluder triangles, for exact visibility ([`super`]).
//!
//! A box made of twelve triangles casts twelve shadows, and the shadow clipping cuts
//! their union into disjoint pieces: each shadow minus the cones of all the shadows
//! before it, work that grows with the square of the casters. Seen from a point x
//! outside it, a convex solid K blocks exactly the segments that enter it, and the
//! points y whose segment from x meets K form one convex set: y in the cone from x
//! spanned by K's silhouette (the edges between faces that x sees and faces it does
//! not) and beyond the plane of every face x sees (a segment enters K through the face
//! that is hit last among the faces it sees). So a box's shadow on P_j is P_j cut by at
//! most nine planes, one piece, where its triangles gave up to twelve shadows and their
//! union.
//!
//! **Which components are solids.** The triangles are joined where they share an edge
//! (vertices within the plane tolerance of each other); a component is a solid when
//! - every edge belongs to one or two of its triangles, the edges with one form a single
//!   closed loop, and the surface has the topology of a sphere (V − E + F = 2, the loop
//!   counted as a face);
//! - every vertex lies behind or on the plane of every triangle and of the loop (all
//!   within a tolerance), and the vertices' mean lies strictly behind all of them.
//!
//! Such a surface is the boundary of the convex hull of its vertices. The loop, if any,
//! is an **open face**: a box standing on the floor with no bottom (the Cornell blocks,
//! the city's buildings). It blocks nothing itself, but a segment cannot enter and
//! leave a convex solid through the same plane, so every segment through K still meets
//! a real face, and the shadow is the same as a closed box's. The one difference is a
//! point x on the open face (the floor under the box): every segment from it into K's
//! side of that plane leaves through a real face, so it sees nothing there.
//!
//! Components that are not solids (walls, a single quad, an L-shaped building) keep
//! their triangles as separate casters, as before; a solid too is cut triangle by
//! triangle at a point strictly inside it, or where a silhouette plane is undefined
//! (x on the line of an edge).

use std::collections::HashMap;

use glam::DVec3;

use super::caster::Caster;
pub(crate) use super::caster::NO_SOLID;

/// Most triangles of a component examined as a solid.
const MAX_TRIANGLES: usize = 64;
/// Most faces (distinct planes, the open face included) of a solid.
pub(crate) const MAX_FACES: usize = 16;
/// Most edges between two faces of a solid.
const MAX_EDGES: usize = 40;

/// A face's plane, `normal · y = offset`, the unit normal pointing out of the solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Face {
    pub(crate) normal: DVec3,
    pub(crate) offset: f64,
    /// The open face (a loop of boundary edges): blocks nothing itself.
    pub(crate) open: bool,
}

/// An edge between two faces (indices into [`Solid::faces`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SolidEdge {
    pub(crate) a: DVec3,
    pub(crate) b: DVec3,
    pub(crate) faces: [u8; 2],
}

/// A convex solid made of occluder triangles (module docs).
#[derive(Clone, Debug)]
pub(crate) struct Solid {
    pub(crate) faces: Vec<Face>,
    pub(crate) edges: Vec<SolidEdge>,
    /// A point strictly inside (the vertices' mean).
    pub(crate) centre: DVec3,
    /// Its triangles as casters, for the points where the solid cannot be used whole.
    pub(crate) triangles: Vec<Caster>,
}

/// The solids of an occluder mesh, and which solid each triangle belongs to.
#[derive(Clone, Debug, Default)]
pub(crate) struct Solids {
    pub(crate) solids: Vec<Solid>,
    /// Per triangle (the index of the candidate lists): its solid, or [`NO_SOLID`].
    pub(crate) of: Vec<u32>,
}

impl Solids {
    /// Finds the convex solids among `tris` (world units); `tol`: length under which a
    /// point counts as on a plane.
    pub(crate) fn find(tris: &[[DVec3; 3]], tol: f64) -> Solids {
        // Vertices within `tol` of each other are one (a quad's far corner computed as
        // a + (b − a) need not equal b bit for bit): a grid of cells 4·tol wide, each
        // vertex looked up in its cell and the 26 around it.
        let cell = 4.0 * tol.max(f64::MIN_POSITIVE);
        let key = |p: DVec3| (p / cell).floor().as_i64vec3().to_array();
        let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        let mut verts: Vec<DVec3> = Vec::new();
        let mut id = |p: DVec3| {
            let k = key(p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let near = [k[0] + dx, k[1] + dy, k[2] + dz];
                        if let Some(found) = grid.get(&near).and_then(|c| {
                            c.iter()
                                .copied()
                                .find(|&v| verts[v as usize].distance(p) <= tol)
                        }) {
                            return found;
                        }
                    }
                }
            }
            verts.push(p);
            let v = verts.len() as u32 - 1;
            grid.entry(k).or_default().push(v);
            v
        };
        let corners: Vec<[u32; 3]> = tris.iter().map(|t| t.map(&mut id)).collect();
        // Triangles by undirected edge, then components by shared edges.
        let mut by_edge: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
        for (k, c) in corners.iter().enumerate() {
            for e in 0..3 {
                let (a, b) = (c[e], c[(e + 1) % 3]);
                by_edge
                    .entry((a.min(b), a.max(b)))
                    .or_default()
                    .push(k as u32);
            }
        }
        let mut parent: Vec<u32> = (0..tris.len() as u32).collect();
        fn root(parent: &mut [u32], mut k: u32) -> u32 {
            while parent[k as usize] != k {
                parent[k as usize] = parent[parent[k as usize] as usize];
                k = parent[k as usize];
            }
            k
        }
        for owners in by_edge.values() {
            for w in owners.windows(2) {
                let (a, b) = (root(&mut parent, w[0]), root(&mut parent, w[1]));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut components: HashMap<u32, Vec<u32>> = HashMap::new();
        for k in 0..tris.len() as u32 {
            components.entry(root(&mut parent, k)).or_default().push(k);
        }
        // In order of each component's first triangle, so solid ids are deterministic.
        let mut components: Vec<Vec<u32>> = components.into_values().collect();
        components.sort_by_key(|c| c[0]);
        let mut out = Solids {
            solids: Vec::new(),
            of: vec![NO_SOLID; tris.len()],
        };
        for members in components {
            if let Some(solid) = solid_of(&members, &corners, &verts, &by_edge, tris, tol) {
                for &k in &members {
                    out.of[k as usize] = out.solids.len() as u32;
                }
                out.solids.push(solid);
            }
        }
        out
    }
}

/// The unit normal and offset of the plane of `p`, oriented away from `inside`; None
/// when `p` is degenerate or `inside` is not strictly behind it.
fn outward_plane(p: &[DVec3], inside: DVec3, tol: f64) -> Option<(DVec3, f64)> {
    // Newell's normal: exact for a planar polygon, well defined for a loop.
    let mut n = DVec3::ZERO;
    for k in 0..p.len() {
        let (a, b) = (p[k], p[(k + 1) % p.len()]);
        n += (a - inside).cross(b - inside);
    }
    let len = n.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let mut n = n / len;
    let mut o = n.dot(p[0]);
    let d = n.dot(inside) - o;
    if d.abs() <= tol {
        return None;
    }
    if d > 0.0 {
        (n, o) = (-n, -o);
    }
    Some((n, o))
}

/// The faces of the solid made of `members`: their triangles' outward planes, merged
/// where equal, and each member's face; `None` past [`MAX_FACES`] or for a triangle
/// without an outward plane.
fn merged_faces(
    members: &[u32],
    tris: &[[DVec3; 3]],
    centre: DVec3,
    tol: f64,
) -> Option<(Vec<Face>, HashMap<u32, u8>)> {
    let mut faces: Vec<Face> = Vec::new();
    let mut face_of: HashMap<u32, u8> = HashMap::new();
    for &k in members {
        let (n, o) = outward_plane(&tris[k as usize], centre, tol)?;
        let f = match faces
            .iter()
            .position(|f| !f.open && f.normal.dot(n) > 1.0 - 1e-12 && (f.offset - o).abs() <= tol)
        {
            Some(f) => f,
            None => {
                faces.push(Face {
                    normal: n,
                    offset: o,
                    open: false,
                });
                faces.len() - 1
            }
        };
        face_of.insert(k, f as u8);
        if faces.len() > MAX_FACES {
            return None;
        }
    }
    Some((faces, face_of))
}

/// The solid the triangles `members` form, if they form one (module docs).
fn solid_of(
    members: &[u32],
    corners: &[[u32; 3]],
    verts: &[DVec3],
    by_edge: &HashMap<(u32, u32), Vec<u32>>,
    tris: &[[DVec3; 3]],
    tol: f64,
) -> Option<Solid> {
    if members.len() < 3 || members.len() > MAX_TRIANGLES {
        return None;
    }
    let mut vids: Vec<u32> = members.iter().flat_map(|&k| corners[k as usize]).collect();
    vids.sort_unstable();
    vids.dedup();
    let centre = vids.iter().map(|&v| verts[v as usize]).sum::<DVec3>() / vids.len() as f64;
    // Edges: shared by two triangles (inner) or one (the open face's loop).
    let mut edges: Vec<(u32, u32)> = members
        .iter()
        .flat_map(|&k| {
            let c = corners[k as usize];
            (0..3).map(move |e| (c[e].min(c[(e + 1) % 3]), c[e].max(c[(e + 1) % 3])))
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let mut boundary: Vec<(u32, u32)> = Vec::new();
    for e in &edges {
        match by_edge[e].len() {
            1 => boundary.push(*e),
            2 => {}
            _ => return None,
        }
    }
    if corners_repeat(members, corners) {
        return None;
    }
    let open = !boundary.is_empty();
    let euler = vids.len() as i64 - edges.len() as i64 + members.len() as i64 + i64::from(open);
    if euler != 2 {
        return None;
    }
    // Faces: the triangles' planes, merged where equal.
    let (mut faces, face_of) = merged_faces(members, tris, centre, tol)?;
    let mut solid_edges: Vec<SolidEdge> = Vec::new();
    for e in &edges {
        let owners = &by_edge[e];
        if owners.len() == 2 {
            let (f, g) = (face_of[&owners[0]], face_of[&owners[1]]);
            if f != g {
                solid_edges.push(SolidEdge {
                    a: verts[e.0 as usize],
                    b: verts[e.1 as usize],
                    faces: [f, g],
                });
            }
        }
    }
    if open {
        let lp = boundary_loop(&boundary)?;
        let pts: Vec<DVec3> = lp.iter().map(|&v| verts[v as usize]).collect();
        let (n, o) = outward_plane(&pts, centre, tol)?;
        if pts.iter().any(|p| (n.dot(*p) - o).abs() > tol)
            || faces
                .iter()
                .any(|f| f.normal.dot(n) > 1.0 - 1e-12 && (f.offset - o).abs() <= tol)
        {
            return None;
        }
        faces.push(Face {
            normal: n,
            offset: o,
            open: true,
        });
        if faces.len() > MAX_FACES {
            return None;
        }
        let open_face = (faces.len() - 1) as u8;
        for e in &boundary {
            solid_edges.push(SolidEdge {
                a: verts[e.0 as usize],
                b: verts[e.1 as usize],
                faces: [face_of[&by_edge[e][0]], open_face],
            });
        }
    }
    if solid_edges.len() > MAX_EDGES {
        return None;
    }
    // Convex: every vertex behind or on every face, the centre strictly behind.
    let convex = faces.iter().all(|f| {
        vids.iter()
            .all(|&v| f.normal.dot(verts[v as usize]) - f.offset <= tol)
            && f.normal.dot(centre) - f.offset < -tol
    });
    if !convex {
        return None;
    }
    Some(Solid {
        faces,
        edges: solid_edges,
        centre,
        triangles: members
            .iter()
            .filter_map(|&k| Caster::new(tris[k as usize]))
            .collect(),
    })
}

/// True when a triangle of `members` repeats a corner (degenerate after welding).
fn corners_repeat(members: &[u32], corners: &[[u32; 3]]) -> bool {
    members.iter().any(|&k| {
        let c = corners[k as usize];
        c[0] == c[1] || c[1] == c[2] || c[2] == c[0]
    })
}

/// The vertices of the single closed loop the `edges` form, in order; None when they
/// form no loop or more than one.
fn boundary_loop(edges: &[(u32, u32)]) -> Option<Vec<u32>> {
    let mut next: HashMap<u32, Vec<u32>> = HashMap::new();
    for &(a, b) in edges {
        next.entry(a).or_default().push(b);
        next.entry(b).or_default().push(a);
    }
    if next.values().any(|n| n.len() != 2) {
        return None;
    }
    let start = edges[0].0;
    let (mut prev, mut cur) = (start, edges[0].1);
    let mut lp = vec![start];
    while cur != start {
        lp.push(cur);
        let n = &next[&cur];
        let step = if n[0] == prev { n[1] } else { n[0] };
        (prev, cur) = (cur, step);
        if lp.len() > edges.len() {
            return None;
        }
    }
    (lp.len() == edges.len()).then_some(lp)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::dvec3;

    /// The triangles of the box [lo, hi] (two per face), without its bottom (y = lo.y)
    /// when `open`.
    pub(crate) fn box_triangles(lo: DVec3, hi: DVec3, open: bool) -> Vec<[DVec3; 3]> {
        let c = |i: usize| {
            dvec3(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        };
        // Faces as corner indices (bit 0: x, bit 1: y, bit 2: z), bottom first.
        let faces = [
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
            [0, 2, 3, 1],
            [4, 5, 7, 6],
        ];
        faces
            .iter()
            .skip(usize::from(open))
            .flat_map(|f| [[c(f[0]), c(f[1]), c(f[2])], [c(f[0]), c(f[2]), c(f[3])]])
            .collect()
    }

    #[test]
    fn closed_and_open_boxes_are_solids() {
        for open in [false, true] {
            let mut tris = box_triangles(dvec3(0.0, 0.0, 0.0), dvec3(1.0, 2.0, 3.0), open);
            // One copy of a corner off by far less than the tolerance: the same vertex.
            tris[3][1] += DVec3::splat(1e-13);
            let s = Solids::find(&tris, 1e-9);
            assert_eq!(s.solids.len(), 1, "open {open}");
            let solid = &s.solids[0];
            assert_eq!(solid.faces.len(), 6);
            assert_eq!(
                solid.faces.iter().filter(|f| f.open).count(),
                usize::from(open)
            );
            assert_eq!(solid.edges.len(), 12, "the diagonals are not edges");
            assert!(s.of.iter().all(|&k| k == 0));
            // Outward normals: each face's plane has the centre behind it.
            for f in &solid.faces {
                assert!(f.normal.dot(solid.centre) < f.offset);
            }
        }
    }

    #[test]
    fn what_is_not_a_convex_solid_keeps_its_triangles() {
        let b = |lo: [f64; 3], hi: [f64; 3], open| {
            box_triangles(DVec3::from(lo), DVec3::from(hi), open)
        };
        // A box missing two faces: its boundary is one loop, but not a planar one.
        let mut two_missing = b([0.0; 3], [1.0; 3], true);
        two_missing.truncate(8);
        // An L: two boxes sharing a face's area but not its edges (a T-junction).
        let mut l_shape = b([0.0; 3], [2.0, 1.0, 1.0], false);
        l_shape.extend(b([0.0, 1.0, 0.0], [1.0, 2.0, 1.0], false));
        // A flat quad, both sides (the obstructed plates' blocker).
        let q = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 1.0),
            dvec3(0.0, 0.0, 1.0),
        ];
        let flat = vec![
            [q[0], q[1], q[2]],
            [q[0], q[2], q[3]],
            [q[0], q[2], q[1]],
            [q[0], q[3], q[2]],
        ];
        for (name, tris) in [
            ("two faces missing", two_missing),
            ("L shape", l_shape),
            ("flat quad", flat),
            ("dented roof", roof(-0.3)),
        ] {
            assert_eq!(Solids::find(&tris, 1e-9).solids.len(), 0, "{name}");
        }
        // The roof's four triangles in one plane are one face; raised, four faces.
        for (rise, faces, edges) in [(0.0, 6, 12), (0.3, 9, 16)] {
            let s = Solids::find(&roof(rise), 1e-9);
            assert_eq!(s.solids.len(), 1, "rise {rise}");
            assert_eq!(
                (s.solids[0].faces.len(), s.solids[0].edges.len()),
                (faces, edges)
            );
        }
    }

    /// The unit cube with its top (y = 1) fanned from a centre vertex raised by `rise`
    /// (negative: a dent).
    fn roof(rise: f64) -> Vec<[DVec3; 3]> {
        let mut tris = box_triangles(DVec3::ZERO, DVec3::ONE, false);
        tris.drain(2..4); // the top face
        let top = centre_fan(
            [
                dvec3(0.0, 1.0, 0.0),
                dvec3(0.0, 1.0, 1.0),
                dvec3(1.0, 1.0, 1.0),
                dvec3(1.0, 1.0, 0.0),
            ],
            dvec3(0.5, 1.0 + rise, 0.5),
        );
        tris.extend(top);
        tris
    }

    fn centre_fan(q: [DVec3; 4], c: DVec3) -> Vec<[DVec3; 3]> {
        (0..4).map(|k| [q[k], q[(k + 1) % 4], c]).collect()
    }
}
