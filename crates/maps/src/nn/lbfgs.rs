//! Full-batch L-BFGS (Nocedal & Wright 2006, Algorithm 7.4/7.5) with a backtracking Armijo line search: the `lbfgs` optimiser of the CPU trainers.
//!
//! Iterates in f64; the objective is evaluated at the f32 parameters a network holds, so
//! the minimiser works on exactly the function the trainers compute. One iteration costs
//! one gradient plus the extra evaluations of its line search; `model.epochs` bounds the
//! total number of evaluations, so an L-BFGS fit costs at most what Adam's would.

/// Curvature pairs kept.
pub const MEMORY: usize = 10;
/// Armijo sufficient-decrease constant c₁.
const ARMIJO_C1: f64 = 1e-4;
/// Step shrink factor of the backtracking line search.
const SHRINK: f64 = 0.5;
/// Most step halvings before an iteration gives up.
const MAX_HALVINGS: u32 = 30;

/// Why the minimiser stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The evaluation budget was spent.
    Budget,
    /// The gradient norm fell under the tolerance.
    Converged,
    /// No step along the search direction decreased the objective (a minimum to f32
    /// precision, or a non-finite objective).
    NoProgress,
}

/// The outcome: the best point found, its objective, evaluations used and why it stopped.
#[derive(Debug, Clone)]
pub struct Minimum {
    /// The last accepted point, the lowest found (`x0` when no step was accepted).
    pub x: Vec<f64>,
    /// The objective at `x`.
    pub value: f64,
    /// Objective evaluations spent, the one at `x0` included.
    pub evaluations: u32,
    /// Why the minimiser stopped.
    pub stop: Stop,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Minimises `objective` (value and gradient at x) from `x0` with at most `max_evaluations`
/// evaluations; stops early when ‖∇f‖ ≤ `gradient_tolerance`.
pub fn minimize(
    mut objective: impl FnMut(&[f64]) -> (f64, Vec<f64>),
    x0: Vec<f64>,
    max_evaluations: u32,
    gradient_tolerance: f64,
) -> Minimum {
    let mut x = x0;
    let (mut f, mut g) = objective(&x);
    let mut evaluations = 1;
    let mut pairs: std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)> =
        std::collections::VecDeque::new();
    let done = |value: f64, x: Vec<f64>, evaluations: u32, stop: Stop| Minimum {
        x,
        value,
        evaluations,
        stop,
    };
    if !f.is_finite() {
        return done(f, x, evaluations, Stop::NoProgress);
    }
    loop {
        if dot(&g, &g).sqrt() <= gradient_tolerance {
            return done(f, x, evaluations, Stop::Converged);
        }
        let mut d = two_loop_direction(&g, &pairs);
        let mut slope = dot(&g, &d);
        if slope >= 0.0 {
            // Not a descent direction (lost curvature): restart from steepest descent.
            pairs.clear();
            d = g.iter().map(|v| -v).collect();
            slope = -dot(&g, &g);
        }
        // The first step of a fresh memory is scaled to a unit move.
        let mut step = if pairs.is_empty() {
            1.0 / dot(&d, &d).sqrt().max(1e-300)
        } else {
            1.0
        };
        let mut accepted = None;
        for _ in 0..MAX_HALVINGS {
            if evaluations >= max_evaluations {
                return done(f, x, evaluations, Stop::Budget);
            }
            let trial: Vec<f64> = x.iter().zip(&d).map(|(xi, di)| xi + step * di).collect();
            let (ft, gt) = objective(&trial);
            evaluations += 1;
            if ft.is_finite() && ft <= f + ARMIJO_C1 * step * slope {
                accepted = Some((trial, ft, gt));
                break;
            }
            step *= SHRINK;
        }
        let Some((x_new, f_new, g_new)) = accepted else {
            return done(f, x, evaluations, Stop::NoProgress);
        };
        let s: Vec<f64> = x_new.iter().zip(&x).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = g_new.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        // Keep only pairs of positive curvature, so the implied Hessian stays positive definite.
        if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
            if pairs.len() == MEMORY {
                pairs.pop_front();
            }
            pairs.push_back((s, y, 1.0 / sy));
        }
        x = x_new;
        f = f_new;
        g = g_new;
        if evaluations >= max_evaluations {
            return done(f, x, evaluations, Stop::Budget);
        }
    }
}

/// −H·g by the two-loop recursion over the stored pairs (oldest first), with the initial
/// Hessian scaled by sᵀy / yᵀy of the newest pair.
fn two_loop_direction(
    g: &[f64],
    pairs: &std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)>,
) -> Vec<f64> {
    let mut q = g.to_vec();
    let mut alphas = Vec::with_capacity(pairs.len());
    for (s, y, rho) in pairs.iter().rev() {
        let alpha = rho * dot(s, &q);
        q.iter_mut().zip(y).for_each(|(qi, yi)| *qi -= alpha * yi);
        alphas.push(alpha);
    }
    if let Some((s, y, _)) = pairs.back() {
        let gamma = dot(s, y) / dot(y, y).max(1e-300);
        q.iter_mut().for_each(|qi| *qi *= gamma);
    }
    for ((s, y, rho), alpha) in pairs.iter().zip(alphas.iter().rev()) {
        let beta = rho * dot(y, &q);
        q.iter_mut()
            .zip(s)
            .for_each(|(qi, si)| *qi += (alpha - beta) * si);
    }
    q.iter_mut().for_each(|qi| *qi = -*qi);
    q
}

/// Fits `net` by L-BFGS on the objective `loss_gradient` gives at f32 parameters (mean
/// squared error and its gradient), with at most `max_evaluations` evaluations. Returns
/// the final mean squared error; the network keeps the best parameters found.
pub fn fit_network(
    net: &mut super::Mlp,
    max_evaluations: u32,
    mut loss_gradient: impl FnMut(&[f32]) -> (f64, Vec<f32>),
) -> (f64, Stop) {
    let x0: Vec<f64> = net.params.iter().map(|&p| p as f64).collect();
    let mut as_f32 = vec![0.0f32; x0.len()];
    let result = minimize(
        |x| {
            as_f32.iter_mut().zip(x).for_each(|(p, v)| *p = *v as f32);
            let (loss, grad) = loss_gradient(&as_f32);
            (loss, grad.iter().map(|&g| g as f64).collect())
        },
        x0,
        max_evaluations,
        GRADIENT_TOLERANCE,
    );
    net.params
        .iter_mut()
        .zip(&result.x)
        .for_each(|(p, v)| *p = *v as f32);
    (result.value, result.stop)
}

/// [`fit_network`] for network `k` of a batch with at most `config.epochs` evaluations; a
/// fit that ends on a non-finite loss is the usual divergence error.
pub fn fit_network_checked(
    net: &mut super::Mlp,
    config: &super::ModelConfig,
    k: usize,
    loss_gradient: impl FnMut(&[f32]) -> (f64, Vec<f32>),
) -> errmap_core::Result<()> {
    let (loss, _) = fit_network(net, config.epochs, loss_gradient);
    if loss.is_finite() {
        Ok(())
    } else {
        Err(super::diverged(k, config.epochs))
    }
}

/// ‖∇MSE‖ at which a fit counts as converged (targets are standardised to unit spread).
pub const GRADIENT_TOLERANCE: f64 = 1e-7;
