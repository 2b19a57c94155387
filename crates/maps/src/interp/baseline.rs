//! The kriging baseline a map is compared with: the exact kriging ([`super::kriging`]) up to [`EXACT_MAX_SITES`] points, the local kriging ([`super::local`]) above, so it exists at every size at O(n log n).
//!
//! The exact solve costs O(n³) for each of the ~40 (ℓ, g) trials of its likelihood search; at
//! 1,000 points that is seconds, at 4,000 minutes. The local kriging fits ℓ, g and σ² by the
//! same likelihood on a subsample of [`super::local::SUBSAMPLE`] points and predicts each
//! point from its [`super::local::NEIGHBOURS`] nearest, which on the sizes where both run
//! gives hold-out figures within a few per cent of the exact solve (docs/job.md, "The kriging
//! baseline"). Up to the threshold the exact solve is kept, so maps of probe grids keep their
//! figures.

use super::kriging::Kriging;
use super::local::LocalKriging;
use errmap_core::error::Result;

/// Most points the baseline krige exactly; above, it is local.
pub const EXACT_MAX_SITES: usize = 1000;

/// A fitted baseline.
#[derive(Debug, Clone)]
pub enum Baseline {
    /// The exact kriging of every point.
    Exact(Kriging),
    /// The local kriging of every point.
    Local(LocalKriging),
}

impl Baseline {
    /// Fit to `(u_mm, v_mm, e_um)`: exact up to [`EXACT_MAX_SITES`] points, local above.
    pub fn fit(points_uve: &[[f64; 3]]) -> Result<Baseline> {
        if points_uve.len() <= EXACT_MAX_SITES {
            Ok(Baseline::Exact(Kriging::fit(points_uve)?))
        } else {
            Ok(Baseline::Local(LocalKriging::fit(points_uve)?))
        }
    }

    /// The prediction at each point (rayon for the local kriging); `None` where a local system
    /// is singular.
    pub fn predict_many(&self, points_uv: &[[f64; 2]]) -> Vec<Option<f64>> {
        match self {
            Baseline::Exact(k) => points_uv
                .iter()
                .map(|p| Some(k.predict(p[0], p[1])))
                .collect(),
            Baseline::Local(k) => k
                .predict_many(points_uv)
                .into_iter()
                .map(|q| q.map(|q| q.e_um))
                .collect(),
        }
    }
}
