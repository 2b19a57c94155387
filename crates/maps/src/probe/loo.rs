//! Leave-one-out prediction of a probe point from its neighbourhood in one triangulation of all the active points, kept up to date as points are rejected.
//!
//! Removing point i from a Delaunay triangulation T changes T only inside i's star: the
//! triangles that fill the hole have i's Delaunay neighbours as vertices, and every other
//! triangle stays. The prediction of i ([`super::clean`]) reads the natural neighbours of p_i
//! among the others (i's neighbours in T), the Sibson weights (the hole's triangles) and the
//! gradient at each neighbour (its first and second rings in T without i). All of that lies
//! within three rings of i in T, and a triangle of T without i whose vertices all lie there
//! has an empty circumcircle among them too, so the Delaunay triangulation of i's three rings
//! (without i) holds the same stars around i's first and second rings as T without i. One
//! small triangulation per point gives the same prediction as triangulating all the others
//! again, at a cost independent of the number of points. (Where four or more points lie on
//! one circle, as on a regular raster, the Delaunay triangulation is not unique and either
//! triangulation is one of the valid choices; the Sibson weights are the same.)
//!
//! When a point is rejected it is removed from T (spade re-triangulates its hole) and only the
//! points within three rings of it before the removal see another neighbourhood: those are
//! the ones predicted again.

use super::predict::{predict_outside, predict_sibson_c1, site, Prediction};
use super::ProbePoint;
use crate::interp::{Site, Tri};
use spade::handles::FixedVertexHandle;
use spade::{Point2, PositionInTriangulation, Triangulation};

/// Rings of Delaunay neighbours a prediction reads (see the module docs).
pub(super) const RINGS: usize = 3;

/// The triangulation of the active points and where each point is in it.
pub(super) struct Loo<'a> {
    points: &'a [ProbePoint],
    tri: Tri,
    /// The vertex of each point index (`None`: rejected, or at the position of another
    /// point: a twin, see `twin_of`).
    pub(super) handle_of: Vec<Option<FixedVertexHandle>>,
    /// For a point at exactly the position of a point in the triangulation, that point.
    twin_of: Vec<Option<usize>>,
    /// For a point in the triangulation, the active points at its position that are not.
    twins: Vec<Vec<usize>>,
}

impl<'a> Loo<'a> {
    /// The triangulation of `points[active]`; `None` when the points cannot be triangulated
    /// (non-finite or out-of-range coordinates).
    pub(super) fn new(points: &'a [ProbePoint], active: &[usize]) -> Option<Loo<'a>> {
        let tri = Tri::bulk_load(active.iter().map(|&i| site(points, i)).collect()).ok()?;
        let mut loo = Loo {
            points,
            tri,
            handle_of: vec![None; points.len()],
            twin_of: vec![None; points.len()],
            twins: vec![Vec::new(); points.len()],
        };
        for v in loo.tri.vertices() {
            loo.handle_of[v.data().index] = Some(v.fix());
        }
        // Points at one position: spade keeps one of them; the others are its twins.
        for &i in active {
            if loo.handle_of[i].is_some() {
                continue;
            }
            if let PositionInTriangulation::OnVertex(h) = loo.tri.locate(position(points, i)) {
                let kept = loo.tri.vertex(h).data().index;
                loo.twin_of[i] = Some(kept);
                loo.twins[kept].push(i);
            }
        }
        Some(loo)
    }

    /// The indices of the points within `depth` rings of point `i` in the triangulation (not
    /// `i` itself), in ascending order.
    pub(super) fn rings(&self, i: usize, depth: usize) -> Vec<usize> {
        let Some(h) = self.handle_of[i] else {
            return Vec::new();
        };
        let mut seen: Vec<FixedVertexHandle> = vec![h];
        let mut frontier = vec![h];
        for _ in 0..depth {
            let mut next = Vec::new();
            for &f in &frontier {
                for e in self.tri.vertex(f).out_edges() {
                    let w = e.to().fix();
                    if !seen.contains(&w) {
                        seen.push(w);
                        next.push(w);
                    }
                }
            }
            frontier = next;
        }
        let mut out: Vec<usize> = seen[1..]
            .iter()
            .map(|&w| self.tri.vertex(w).data().index)
            .collect();
        out.sort_unstable();
        out
    }

    /// Point i's leave-one-out prediction from the others (`None` where they cannot predict
    /// it: all on one line, or i is not active).
    pub(super) fn predict(&self, i: usize) -> Option<Prediction> {
        if self.tri.all_vertices_on_line() {
            return None;
        }
        // A point at another's position is predicted by it (what the Sibson interpolant of the
        // others gives there: that point's value).
        if let Some(kept) = self.twin_of[i] {
            return Some(vec![(kept, 1.0)]);
        }
        if let Some(&twin) = self.twins[i].first() {
            return Some(vec![(twin, 1.0)]);
        }
        let h = self.handle_of[i]?;
        let ring = self.rings(i, RINGS);
        let sites: Vec<Site> = ring.iter().map(|&k| site(self.points, k)).collect();
        let local = match Tri::bulk_load(sites) {
            Ok(t) if !t.all_vertices_on_line() => t,
            // The rings alone span no area but all the others do: triangulate them all.
            _ => return self.predict_from_all_others(i),
        };
        let p = position(self.points, i);
        // In index order: the sum does not depend on where spade starts the vertex's edges.
        let mut neighbours: Vec<usize> = self
            .tri
            .vertex(h)
            .out_edges()
            .map(|e| e.to().data().index)
            .collect();
        neighbours.sort_unstable();
        predict_sibson_c1(&local, p).or_else(|| predict_outside(&local, &neighbours, p))
    }

    /// The prediction from a triangulation of every other active point (the definition; the
    /// rare fallback).
    fn predict_from_all_others(&self, i: usize) -> Option<Prediction> {
        let others: Vec<Site> = self
            .tri
            .vertices()
            .map(|v| v.data().index)
            .chain(self.twins.iter().flatten().copied())
            .filter(|&k| k != i)
            .map(|k| site(self.points, k))
            .collect();
        let tri = Tri::bulk_load(others).ok()?;
        if tri.all_vertices_on_line() {
            return None;
        }
        let p = position(self.points, i);
        let neighbours: Vec<usize> = self.handle_of[i]
            .map(|h| {
                self.tri
                    .vertex(h)
                    .out_edges()
                    .map(|e| e.to().data().index)
                    .collect()
            })
            .unwrap_or_default();
        let mut neighbours = neighbours;
        neighbours.sort_unstable();
        predict_sibson_c1(&tri, p).or_else(|| predict_outside(&tri, &neighbours, p))
    }

    /// Remove point i; returns the active points whose prediction may have changed (ascending).
    pub(super) fn remove(&mut self, i: usize) -> Vec<usize> {
        if let Some(kept) = self.twin_of[i].take() {
            // A twin leaves: only the point it shares a position with sees a change.
            self.twins[kept].retain(|&t| t != i);
            let mut out = vec![kept];
            out.extend(self.twins[kept].iter().copied());
            return out;
        }
        let Some(h) = self.handle_of[i] else {
            return Vec::new();
        };
        let mut affected = self.rings(i, RINGS);
        self.tri.remove(h);
        self.handle_of[i] = None;
        // spade moves its last vertex into the freed slot.
        if h.index() < self.tri.num_vertices() {
            let moved = self.tri.vertex(h).data().index;
            self.handle_of[moved] = Some(h);
        }
        // A twin takes the removed point's place in the triangulation.
        let twins = std::mem::take(&mut self.twins[i]);
        if let Some((&first, rest)) = twins.split_first() {
            let handle = self.tri.insert(site(self.points, first)).ok();
            self.handle_of[first] = handle;
            self.twin_of[first] = None;
            for &t in rest {
                self.twin_of[t] = Some(first);
            }
            self.twins[first] = rest.to_vec();
            affected.extend(twins.iter().copied());
            affected.extend(self.rings(first, RINGS));
        }
        affected.retain(|&k| k != i);
        affected.sort_unstable();
        affected.dedup();
        affected
    }
}

/// Point i's position in the map plane.
fn position(points: &[ProbePoint], i: usize) -> Point2<f64> {
    Point2::new(points[i].u_mm, points[i].v_mm)
}
