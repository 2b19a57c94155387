//! Training values from dense points: each training node takes the points in its cell (a local plane fitted through them), instead of an interpolation of every point, when the points are dense enough for it.
//!
//! Sparse probe points (about one per training cell or fewer) are interpolated onto the
//! training grid (natural neighbour, …): there is at most one point per cell to learn from, and
//! the interpolant fills the cells between them. A scan gives many points per cell: an
//! interpolant evaluated at the node passes through the noise of the two or three points next
//! to it and ignores the rest, and triangulating every point costs O(n log n) with gradients at
//! every site. Binning instead uses every point once: the node's value is the value at the node
//! of the least-squares plane through the points of its cell (the square of one training
//! spacing centred on the node), so the noise of its m points averages down by about √m and a
//! slope across the cell does not bias the value where the points are off-centre (a cell cut
//! by the edge of the scan). With fewer than [`PLANE_MIN_POINTS`] points or a degenerate
//! layout the mean is taken. O(n) time, O(nodes) memory beyond the points.
//!
//! The choice ([`choose`]): bin when the points average at least [`BIN_MIN_POINTS_PER_CELL`]
//! per occupied cell, interpolate otherwise. Training on the points themselves would cost
//! epochs × n (a 1 M-point scan × 400 epochs is minutes on these cores) for no more
//! information than the bins carry at the training spacing; decimating would drop points and
//! keep their noise.

use super::Grid;

/// Points per occupied training cell from which a part is binned instead of interpolated.
pub const BIN_MIN_POINTS_PER_CELL: f64 = 4.0;

/// Points a cell needs for its plane; fewer take the mean.
pub const PLANE_MIN_POINTS: usize = 6;

/// How a part's training values were made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrainingSource {
    /// Interpolated from the points at every training node inside their hull.
    Interpolated,
    /// The points of each training cell fitted by a plane, evaluated at the node.
    Binned,
}

/// The cell (node index) a point falls in: the nearest node; `None` off the grid by more than
/// half a spacing.
fn cell_of(grid: &Grid, u_mm: f64, v_mm: f64) -> Option<usize> {
    let i = ((u_mm - grid.u0_mm) / grid.step_mm).round();
    let j = ((v_mm - grid.v0_mm) / grid.step_mm).round();
    (i >= 0.0 && j >= 0.0 && (i as usize) < grid.nu && (j as usize) < grid.nv)
        .then(|| j as usize * grid.nu + i as usize)
}

/// Bin when the points average at least [`BIN_MIN_POINTS_PER_CELL`] per occupied cell.
pub fn choose(points_uve: &[[f64; 3]], grid: &Grid) -> TrainingSource {
    let mut occupied = vec![false; grid.len()];
    let mut cells = 0usize;
    let mut on_grid = 0usize;
    for p in points_uve {
        if let Some(c) = cell_of(grid, p[0], p[1]) {
            on_grid += 1;
            if !occupied[c] {
                occupied[c] = true;
                cells += 1;
            }
        }
    }
    if cells > 0 && on_grid as f64 >= BIN_MIN_POINTS_PER_CELL * cells as f64 {
        TrainingSource::Binned
    } else {
        TrainingSource::Interpolated
    }
}

/// Running sums of one cell's least-squares plane `e = a + b·du + c·dv` (du, dv from the node).
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    n: f64,
    u: f64,
    v: f64,
    uu: f64,
    uv: f64,
    vv: f64,
    e: f64,
    ue: f64,
    ve: f64,
}

impl Sums {
    fn add(&mut self, du: f64, dv: f64, e: f64) {
        self.n += 1.0;
        self.u += du;
        self.v += dv;
        self.uu += du * du;
        self.uv += du * dv;
        self.vv += dv * dv;
        self.e += e;
        self.ue += du * e;
        self.ve += dv * e;
    }

    /// The plane's value at the node (du = dv = 0), or the mean when the plane is not
    /// determined (too few points, all on a line).
    fn value(&self) -> Option<f64> {
        if self.n == 0.0 {
            return None;
        }
        let mean = self.e / self.n;
        if (self.n as usize) < PLANE_MIN_POINTS {
            return Some(mean);
        }
        // Centred normal equations: [suu suv; suv svv]·[b c] = [sue sve], a = ē − b·ū − c·v̄.
        let (mu, mv) = (self.u / self.n, self.v / self.n);
        let suu = self.uu - self.n * mu * mu;
        let suv = self.uv - self.n * mu * mv;
        let svv = self.vv - self.n * mv * mv;
        let sue = self.ue - self.n * mu * mean;
        let sve = self.ve - self.n * mv * mean;
        let det = suu * svv - suv * suv;
        // A layout close to a line (relative to the spread of the points) keeps the mean.
        if det.is_nan() || det <= 1e-6 * (suu + svv).powi(2) {
            return Some(mean);
        }
        let b = (sue * svv - sve * suv) / det;
        let c = (sve * suu - sue * suv) / det;
        let a = mean - b * mu - c * mv;
        a.is_finite().then_some(a)
    }
}

/// Each node's value from the points of its cell (`Sums::value`); `None` for an empty cell.
/// Coordinates are taken relative to the node in units of the spacing, so the sums stay well
/// scaled.
pub fn binned_nodes(points_uve: &[[f64; 3]], grid: &Grid) -> Vec<Option<f64>> {
    let mut sums = vec![Sums::default(); grid.len()];
    for p in points_uve {
        if let Some(c) = cell_of(grid, p[0], p[1]) {
            let (u, v) = grid.node(c % grid.nu, c / grid.nu);
            sums[c].add((p[0] - u) / grid.step_mm, (p[1] - v) / grid.step_mm, p[2]);
        }
    }
    sums.iter().map(Sums::value).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Grid {
        Grid {
            u0_mm: 0.0,
            v0_mm: 0.0,
            step_mm: 10.0,
            nu: 4,
            nv: 3,
        }
    }

    #[test]
    fn a_plane_is_recovered_at_the_nodes_from_off_centre_points() {
        // e = 2 + 0.3·u − 0.1·v: whatever the points' layout in a cell, the plane through them
        // is e itself, so the node gets e(node) exactly, while the mean of the points would not.
        let e = |u: f64, v: f64| 2.0 + 0.3 * u - 0.1 * v;
        let mut pts = Vec::new();
        for c in 0..12 {
            let (u0, v0) = ((c % 4) as f64 * 10.0, (c / 4) as f64 * 10.0);
            // Eight points in the upper-right quarter of the cell only.
            for k in 0..8 {
                let (du, dv) = (0.5 + 0.6 * (k % 4) as f64, 0.7 + 1.9 * (k / 4) as f64);
                pts.push([u0 + du, v0 + dv, e(u0 + du, v0 + dv)]);
            }
        }
        let nodes = binned_nodes(&pts, &grid());
        for (c, value) in nodes.iter().enumerate() {
            let (u, v) = grid().node(c % 4, c / 4);
            assert!(
                (value.unwrap() - e(u, v)).abs() < 1e-9,
                "node {c}: {value:?}"
            );
        }
        assert_eq!(choose(&pts, &grid()), TrainingSource::Binned);
    }

    #[test]
    fn few_points_take_the_mean_and_sparse_points_are_interpolated() {
        // Two points in node (1, 1)'s cell (10 ± 5, 10 ± 5): the mean; the other cells empty.
        let pts = [[11.0, 12.0, 4.0], [8.0, 9.0, 6.0], [100.0, 100.0, 9.0]];
        let nodes = binned_nodes(&pts, &grid());
        assert_eq!(nodes[4 + 1], Some(5.0));
        assert_eq!(nodes.iter().flatten().count(), 1);
        // Collinear points (six on one line) keep the mean too.
        let line: Vec<[f64; 3]> = (0..6).map(|k| [0.8 * k as f64, 0.0, k as f64]).collect();
        assert_eq!(binned_nodes(&line, &grid())[0], Some(2.5));
        // One point per cell is not dense.
        let sparse: Vec<[f64; 3]> = (0..12)
            .map(|c| [(c % 4) as f64 * 10.0, (c / 4) as f64 * 10.0, 1.0])
            .collect();
        assert_eq!(choose(&sparse, &grid()), TrainingSource::Interpolated);
    }
}
