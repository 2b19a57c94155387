//! Scattered-point interpolation on the map plane: Delaunay surface (spade), natural-neighbour, Sibson C1 and linear resampling onto grids.
//!
//! A [`Surface`] is the Delaunay triangulation of scattered sites `(u, v, e)` with a gradient
//! estimated at every site. It answers these methods inside the convex hull of the sites and
//! `None` outside it (never an extrapolated number):
//!
//! - [`Method::NaturalNeighbour`]: Sibson's natural-neighbour (C0) interpolant.
//! - [`Method::SibsonC1`]: Sibson's C1 interpolant, which blends the natural-neighbour value
//!   with the linear extrapolations `e_j + ∇e_j·(p − p_j)` of the neighbours (Sibson 1981,
//!   flatness 0.5; spade's `interpolate_gradient`).
//! - [`Method::Linear`]: barycentric interpolation on the Delaunay triangle.
//! - [`Method::Kriging`]: the posterior mean of a Gaussian process (Matérn 5/2 with a nugget,
//!   hyper-parameters by maximum likelihood; see [`kriging`]) of all sites, inside the hull.
//!
//! The three interpolants (natural-neighbour, Sibson C1, linear) reproduce a plane exactly
//! (linear precision); kriging smooths through its nugget, so it need not pass through the sites. [`resample`] evaluates a surface on
//! a regular [`Grid`] in parallel (rayon over blocks of rows, each block with its own copy of the
//! triangulation so spade's walk hint and interpolation buffers stay local to one thread).

mod gradient;

pub mod baseline;
pub mod bin;
pub mod kriging;
pub mod local;
mod sweep;

use errmap_core::error::{Error, Result};
use errmap_core::geom::Domain;
use rayon::prelude::*;
use spade::{DelaunayTriangulation, FloatTriangulation, HasPosition, Point2, Triangulation};

pub(crate) use gradient::{gradient_coefficients, quadratic_gradient};

/// Interpolation method. Names on the command line and in job files: `natural-neighbour`,
/// `sibson-c1`, `linear`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Sibson's natural-neighbour interpolant: smooth except at the sites, never overshoots the data.
    #[default]
    NaturalNeighbour,
    /// Sibson's C1 interpolant with gradients from local quadratic fits: smooth at the sites too,
    /// follows curvature better, can overshoot near sharp features.
    SibsonC1,
    /// Barycentric interpolation on the Delaunay triangles: fastest, creased along triangle edges.
    Linear,
    /// Ordinary kriging (Gaussian process, Matérn 5/2 + nugget, maximum likelihood): smooths
    /// through probe noise; an O(n³) solve, at most 4000 points.
    Kriging,
}

impl Method {
    /// The name used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Method::NaturalNeighbour => "natural-neighbour",
            Method::SibsonC1 => "sibson-c1",
            Method::Linear => "linear",
            Method::Kriging => "kriging",
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One site of the triangulation: position, value and estimated gradient.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Site {
    pub(crate) position: Point2<f64>,
    pub(crate) e: f64,
    pub(crate) grad: [f64; 2],
    /// Index of the (first) input point this site came from.
    pub(crate) index: usize,
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.position
    }
}

pub(crate) type Tri = DelaunayTriangulation<Site>;

/// Sibson C1 flatness: 0.5 is Sibson's original C1 interpolant (spade's documentation).
const SIBSON_FLATNESS: f64 = 0.5;

/// A triangulated set of scattered sites `(u_mm, v_mm, e)` that can be sampled anywhere inside
/// its convex hull. `e` is in whatever unit the caller uses (errmap uses µm).
#[derive(Debug, Clone)]
pub struct Surface {
    tri: Tri,
    /// Bounding box of the sites, a cheap first test before locating a point.
    bbox: Domain,
    /// The kriging of the sites, fitted on first use (`Err`: why it could not be).
    kriging: std::sync::OnceLock<std::result::Result<kriging::Kriging, String>>,
    /// The hull's edges with the values at their ends: the answer for points on the hull,
    /// where spade's exact path can give no value or NaN.
    hull: Vec<HullEdge>,
    /// Distances below this (1e-9 of the sites' extent) count as on the hull.
    hull_eps: f64,
}

/// Refuses a site with a non-finite coordinate or value.
fn check_finite(points_uve: &[[f64; 3]]) -> Result<()> {
    for p in points_uve {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(Error::numeric(
                format!("interpolation site {p:?} is not a finite number"),
                "remove NaN or infinite values before interpolating",
            ));
        }
    }
    Ok(())
}

/// The sites sorted by position, positions snapped to a lattice of 1e-12 of the sites'
/// extent and sites at the same snapped position merged (their values averaged), so a
/// site's value is not decided by insertion order and two sites a rounding error apart
/// (a corner written twice, `3` and `3.0000000000000004`) cannot make a sliver triangle
/// that breaks every interpolant near it.
fn merged_sites(points_uve: &[[f64; 3]]) -> Vec<Site> {
    let quantum = snap_quantum(points_uve);
    let snap = |x: f64| {
        if quantum > 0.0 {
            (x / quantum).round() * quantum
        } else {
            x
        }
    };
    let mut sorted: Vec<(usize, [f64; 3])> = points_uve
        .iter()
        .map(|p| [snap(p[0]), snap(p[1]), p[2]])
        .enumerate()
        .collect();
    sorted.sort_by(|(_, a), (_, b)| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let mut sites: Vec<Site> = Vec::with_capacity(sorted.len());
    let mut count = 0.0;
    for (index, p) in sorted {
        match sites.last_mut() {
            Some(last) if last.position.x == p[0] && last.position.y == p[1] => {
                count += 1.0;
                last.e += (p[2] - last.e) / count;
            }
            _ => {
                count = 1.0;
                sites.push(Site {
                    position: Point2::new(p[0], p[1]),
                    e: p[2],
                    grad: [0.0, 0.0],
                    index,
                });
            }
        }
    }
    sites
}

/// The bounding box of the sites.
fn sites_bbox(sites: &[Site]) -> Domain {
    let mut bbox = Domain {
        u_min_mm: f64::INFINITY,
        v_min_mm: f64::INFINITY,
        u_max_mm: f64::NEG_INFINITY,
        v_max_mm: f64::NEG_INFINITY,
    };
    for s in sites {
        bbox.u_min_mm = bbox.u_min_mm.min(s.position.x);
        bbox.u_max_mm = bbox.u_max_mm.max(s.position.x);
        bbox.v_min_mm = bbox.v_min_mm.min(s.position.y);
        bbox.v_max_mm = bbox.v_max_mm.max(s.position.y);
    }
    bbox
}

/// The Delaunay triangulation of the sites; refuses sites that all lie on one line.
fn triangulate(sites: Vec<Site>) -> Result<Tri> {
    let tri = Tri::bulk_load(sites).map_err(|e| {
        Error::numeric(
            format!("cannot triangulate the sites: {e}"),
            "coordinates must be finite and between 1e-30 and 1e30 in magnitude (or zero)",
        )
    })?;
    if tri.all_vertices_on_line() {
        return Err(Error::numeric(
            "all interpolation sites lie on one line: no surface can be spanned",
            "measure points off that line so they span an area",
        ));
    }
    Ok(tri)
}

/// The convex hull's edges with the values at their ends.
fn hull_edges(tri: &Tri) -> Vec<HullEdge> {
    tri.convex_hull()
        .map(|e| {
            let [a, b] = e.positions();
            HullEdge {
                a: [a.x, a.y],
                b: [b.x, b.y],
                ea: e.from().data().e,
                eb: e.to().data().e,
            }
        })
        .collect()
}

/// One edge of the convex hull: its ends and their values.
#[derive(Debug, Clone, Copy)]
struct HullEdge {
    a: [f64; 2],
    b: [f64; 2],
    ea: f64,
    eb: f64,
}

impl Surface {
    /// Triangulate the sites and estimate a gradient at each. Sites at exactly the same
    /// position are merged (their values averaged). Errors: fewer than 3 distinct sites,
    /// non-finite numbers, all sites on one line.
    pub fn new(points_uve: &[[f64; 3]]) -> Result<Surface> {
        let mut surface = Self::without_gradients(points_uve)?;
        let handles: Vec<_> = surface.tri.fixed_vertices().collect();
        let grads: Vec<[f64; 2]> = handles
            .iter()
            .map(|&h| quadratic_gradient(&surface.tri, h))
            .collect();
        for (h, g) in handles.into_iter().zip(grads) {
            surface.tri.vertex_data_mut(h).grad = g;
        }
        Ok(surface)
    }

    /// The triangulation alone (all gradients zero): what leave-one-out prediction builds
    /// many times, estimating gradients only where it needs them.
    pub(crate) fn without_gradients(points_uve: &[[f64; 3]]) -> Result<Surface> {
        check_finite(points_uve)?;
        let sites = merged_sites(points_uve);
        if sites.len() < 3 {
            return Err(Error::numeric(
                format!(
                    "{} distinct site(s): interpolation needs at least 3 not on one line",
                    sites.len()
                ),
                "measure at least 3 points spread over the surface",
            ));
        }
        let bbox = sites_bbox(&sites);
        let tri = triangulate(sites)?;
        let hull = hull_edges(&tri);
        let extent = bbox.width_mm().max(bbox.height_mm());
        Ok(Surface {
            tri,
            bbox,
            kriging: std::sync::OnceLock::new(),
            hull,
            hull_eps: 1e-9 * extent,
        })
    }

    /// The value on the hull at a point within [`Surface::hull_eps`] of it: linear between the
    /// ends of the nearest edge, which is what every method gives on the hull (a point on a
    /// hull edge has only the edge's two ends as natural neighbours). `None` further out.
    fn hull_value(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        let eps = self.hull_eps;
        if u_mm < self.bbox.u_min_mm - eps
            || u_mm > self.bbox.u_max_mm + eps
            || v_mm < self.bbox.v_min_mm - eps
            || v_mm > self.bbox.v_max_mm + eps
        {
            return None;
        }
        let mut best: Option<(f64, f64)> = None;
        for h in &self.hull {
            let (du, dv) = (h.b[0] - h.a[0], h.b[1] - h.a[1]);
            let len2 = du * du + dv * dv;
            if len2 == 0.0 {
                continue;
            }
            let t = (((u_mm - h.a[0]) * du + (v_mm - h.a[1]) * dv) / len2).clamp(0.0, 1.0);
            let dist = (u_mm - (h.a[0] + t * du)).hypot(v_mm - (h.a[1] + t * dv));
            if dist <= eps && best.is_none_or(|(d, _)| dist < d) {
                best = Some((dist, h.ea + t * (h.eb - h.ea)));
            }
        }
        best.map(|(_, e)| e).filter(|e| e.is_finite())
    }

    /// On the hull (within [`Surface::hull_eps`]) the hull's value, else `compute()` when it is
    /// finite. spade's exact path gives None, NaN or a value off the edge's line for points a
    /// rounding error puts on the hull.
    fn hull_first(
        &self,
        u_mm: f64,
        v_mm: f64,
        compute: impl FnOnce() -> Option<f64>,
    ) -> Option<f64> {
        self.hull_value(u_mm, v_mm)
            .or_else(|| compute().filter(|e| e.is_finite()))
    }

    /// Number of distinct sites.
    pub fn num_sites(&self) -> usize {
        self.tri.num_vertices()
    }

    /// Bounding box of the sites.
    pub fn bounding_box(&self) -> Domain {
        self.bbox
    }

    /// Interpolated value at `(u_mm, v_mm)`; `None` outside the convex hull of the sites
    /// (and for kriging, when the sites cannot be kriged: see [`Surface::kriging`]).
    pub fn sample(&self, method: Method, u_mm: f64, v_mm: f64) -> Option<f64> {
        let k = match method {
            Method::Kriging => Some(self.kriging().ok()?),
            _ => None,
        };
        self.hull_first(u_mm, v_mm, || {
            Sampler::new(&self.tri, k).sample(method, &self.bbox, u_mm, v_mm)
        })
    }

    /// The kriging of the (merged) sites, fitted once on first use.
    pub fn kriging(&self) -> Result<&kriging::Kriging> {
        self.kriging
            .get_or_init(|| {
                let sites: Vec<[f64; 3]> = self
                    .tri
                    .vertices()
                    .map(|v| {
                        let d = v.data();
                        [d.position.x, d.position.y, d.e]
                    })
                    .collect();
                kriging::Kriging::fit(&sites).map_err(|e| e.to_string())
            })
            .as_ref()
            .map_err(|m| Error::numeric(format!("kriging: {m}"), "choose another [interp] method"))
    }
}

/// The lattice sites are snapped to: 1e-12 of the larger extent of the points (0 for none).
fn snap_quantum(points_uve: &[[f64; 3]]) -> f64 {
    let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in points_uve {
        u0 = u0.min(p[0]);
        u1 = u1.max(p[0]);
        v0 = v0.min(p[1]);
        v1 = v1.max(p[1]);
    }
    let extent = (u1 - u0).max(v1 - v0);
    if extent.is_finite() && extent > 0.0 {
        1e-12 * extent
    } else {
        0.0
    }
}

/// Interpolation state for one thread: spade's buffers, reused from one query to the next.
struct Sampler<'a> {
    nn: spade::NaturalNeighbor<'a, Tri>,
    bary: spade::Barycentric<'a, Tri>,
    kriging: Option<&'a kriging::Kriging>,
}

impl<'a> Sampler<'a> {
    fn new(tri: &'a Tri, kriging: Option<&'a kriging::Kriging>) -> Self {
        Sampler {
            nn: tri.natural_neighbor(),
            bary: tri.barycentric(),
            kriging,
        }
    }

    fn sample(&self, method: Method, bbox: &Domain, u_mm: f64, v_mm: f64) -> Option<f64> {
        if !u_mm.is_finite() || !v_mm.is_finite() || !bbox.contains(u_mm, v_mm) {
            return None;
        }
        let p = Point2::new(u_mm, v_mm);
        match method {
            Method::NaturalNeighbour => self.nn.interpolate(|v| v.data().e, p),
            Method::SibsonC1 => {
                self.nn
                    .interpolate_gradient(|v| v.data().e, |v| v.data().grad, SIBSON_FLATNESS, p)
            }
            Method::Linear => self.bary.interpolate(|v| v.data().e, p),
            // Inside the hull only, like the others: the hull test is the barycentric one.
            Method::Kriging => {
                let k = self.kriging?;
                self.bary
                    .interpolate(|_| 0.0, p)
                    .map(|_| k.predict(u_mm, v_mm))
            }
        }
    }
}

/// A regular grid over the map plane: node `(i, j)` is at `(u0 + i·step, v0 + j·step)`,
/// `i < nu`, `j < nv`; node index `j·nu + i` (u fastest).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grid {
    /// u of the first column of nodes (`i = 0`), mm; the domain's lower u edge.
    pub u0_mm: f64,
    /// v of the first row of nodes (`j = 0`), mm; the domain's lower v edge.
    pub v0_mm: f64,
    /// Node spacing, the same along u and v, mm.
    pub step_mm: f64,
    /// Number of nodes along u.
    pub nu: usize,
    /// Number of nodes along v.
    pub nv: usize,
}

/// Largest grid [`Grid::covering`] accepts: 50 M nodes is 400 MB of f64 already.
pub const MAX_GRID_NODES: usize = 50_000_000;

impl Grid {
    /// The grid starting at the domain's lower corner with nodes every `step_mm` up to and
    /// including its upper edges (when the extent is a multiple of the step; otherwise the last
    /// node lies inside by less than one step).
    pub fn covering(domain: &Domain, step_mm: f64) -> Result<Grid> {
        if !(step_mm.is_finite() && step_mm > 0.0) {
            return Err(Error::usage(
                format!("grid step {step_mm} mm is not a positive number"),
                "give a step such as 0.5 (mm)",
            ));
        }
        let values = [
            domain.u_min_mm,
            domain.v_min_mm,
            domain.u_max_mm,
            domain.v_max_mm,
        ];
        if !values.iter().all(|x| x.is_finite())
            || domain.u_max_mm < domain.u_min_mm
            || domain.v_max_mm < domain.v_min_mm
        {
            return Err(Error::usage(
                format!(
                    "domain {},{},{},{} is not a rectangle with min ≤ max",
                    domain.u_min_mm, domain.v_min_mm, domain.u_max_mm, domain.v_max_mm
                ),
                "write the domain as UMIN,VMIN,UMAX,VMAX in mm",
            ));
        }
        // A tolerance of 1e-9 steps keeps 600 / 0.5 at 1201 nodes despite rounding.
        let count = |extent: f64| (extent / step_mm + 1e-9).floor() + 1.0;
        let (nu_f, nv_f) = (count(domain.width_mm()), count(domain.height_mm()));
        if nu_f * nv_f > MAX_GRID_NODES as f64 {
            return Err(Error::usage(
                format!(
                    "a {step_mm} mm step over {} × {} mm gives {:.0} × {:.0} = {:.3e} nodes, more than the limit of {MAX_GRID_NODES}",
                    domain.width_mm(),
                    domain.height_mm(),
                    nu_f,
                    nv_f,
                    nu_f * nv_f
                ),
                "use a larger step or a smaller domain",
            ));
        }
        Ok(Grid {
            u0_mm: domain.u_min_mm,
            v0_mm: domain.v_min_mm,
            step_mm,
            nu: nu_f as usize,
            nv: nv_f as usize,
        })
    }

    /// Plane coordinates `(u_mm, v_mm)` of node `(i, j)`.
    pub fn node(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.u0_mm + i as f64 * self.step_mm,
            self.v0_mm + j as f64 * self.step_mm,
        )
    }

    /// Number of nodes, `nu · nv`.
    pub fn len(&self) -> usize {
        self.nu * self.nv
    }

    /// True when the grid has no nodes.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Rows per parallel work item: enough to amortise copying the triangulation, small enough to
/// balance the rows that cross the hull against the empty ones.
const ROWS_PER_BLOCK: usize = 8;

/// Sibson's C1 interpolant at `p` from natural-neighbour weights: items are
/// `(position, value, gradient, weight)` of each natural neighbour. Flatness 0.5, i.e. the C1
/// weights are w_j / |p − p_j| (Sibson 1981; the formula of spade's `interpolate_gradient`).
pub(crate) fn sibson_c1(
    p: [f64; 2],
    neighbours: impl Iterator<Item = ([f64; 2], f64, [f64; 2], f64)>,
) -> Option<f64> {
    let (mut sum_c0, mut sum_c1, mut sum_c1_weights, mut alpha, mut beta) =
        (0.0, 0.0, 0.0, 0.0, 0.0);
    for (q, e, g, w) in neighbours {
        let (du, dv) = (p[0] - q[0], p[1] - q[1]);
        let r2 = du * du + dv * dv;
        if r2 == 0.0 {
            return Some(e);
        }
        let c1_weight = w / r2.sqrt();
        let zeta = e + du * g[0] + dv * g[1];
        alpha += c1_weight * r2;
        beta += w * r2;
        sum_c1_weights += c1_weight;
        sum_c1 += zeta * c1_weight;
        sum_c0 += e * w;
    }
    alpha /= sum_c1_weights;
    sum_c1 /= sum_c1_weights;
    let value = (alpha * sum_c0 + beta * sum_c1) / (alpha + beta);
    value.is_finite().then_some(value)
}

/// Interpolate the surface at every node of the grid (index `j·nu + i`); `None` where the node
/// lies outside the convex hull of the sites.
///
/// Natural-neighbour and Sibson C1 weights come from a sweep along each row over the sites'
/// circumcircles (see `sweep.rs`), with spade's exact path for nodes on or next to the hull and
/// other near-degenerate cases; linear uses spade's barycentric interpolation.
pub fn resample(surface: &Surface, method: Method, grid: &Grid) -> Vec<Option<f64>> {
    let mut out = vec![None; grid.len()];
    if grid.is_empty() {
        return out;
    }
    let krig = match method {
        Method::Kriging => match surface.kriging() {
            Ok(k) => Some(k),
            Err(_) => return out,
        },
        _ => None,
    };
    let sweep = sweep::Sweep::new(&surface.tri);
    out.par_chunks_mut(grid.nu * ROWS_PER_BLOCK)
        .enumerate()
        .for_each(|(block, chunk)| {
            // A private copy: spade's walk hint lives in the triangulation, and sharing it
            // between threads would make every walk start from another thread's last point.
            let tri = surface.tri.clone();
            let sampler = Sampler::new(&tri, krig);
            let mut buf = sweep::RowBuffers::default();
            for (k, row) in chunk.chunks_mut(grid.nu).enumerate() {
                let j = block * ROWS_PER_BLOCK + k;
                let v_mm = grid.v0_mm + j as f64 * grid.step_mm;
                let eps = surface.hull_eps;
                if v_mm < surface.bbox.v_min_mm - eps || v_mm > surface.bbox.v_max_mm + eps {
                    continue;
                }
                let span = match method {
                    Method::Linear | Method::Kriging => Some(None),
                    _ => sweep.start_row(v_mm, &mut buf),
                };
                let Some(span) = span else {
                    continue;
                };
                for (i, cell) in row.iter_mut().enumerate() {
                    let u_mm = grid.u0_mm + i as f64 * grid.step_mm;
                    let Some(span) = span else {
                        *cell = surface.hull_first(u_mm, v_mm, || {
                            sampler.sample(method, &surface.bbox, u_mm, v_mm)
                        });
                        continue;
                    };
                    *cell = match sweep.node(u_mm, v_mm, span, &mut buf) {
                        sweep::Node::Outside => None,
                        sweep::Node::Fallback => surface.hull_first(u_mm, v_mm, || {
                            sampler.sample(method, &surface.bbox, u_mm, v_mm)
                        }),
                        sweep::Node::Weights => {
                            let weights = buf.weights.iter().map(|&(k, w)| (sweep.site(k), w));
                            match method {
                                Method::SibsonC1 => sibson_c1(
                                    [u_mm, v_mm],
                                    weights.map(|(s, w)| {
                                        ([s.position.x, s.position.y], s.e, s.grad, w)
                                    }),
                                ),
                                _ => Some(weights.map(|(s, w)| s.e * w).sum()),
                            }
                        }
                    };
                    *cell = cell.filter(|e| e.is_finite());
                }
            }
        });
    out
}
