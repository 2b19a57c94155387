//! The diagnosis model: the radial signature of each machine error against angle ψ and direction sense σ (+1 ccw, −1 cw), each column scaled so its coefficient is in the term's unit (derivations in docs/circular.md).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// One column of the least-squares design.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Column {
    /// Mean radius (µm): 1.
    Constant,
    /// Centre offset along the first / second axis (µm): cos ψ, sin ψ.
    CentreFirst,
    CentreSecond,
    /// Squareness S (µm/m): −(R·10⁻³/2)·sin 2ψ.
    Squareness,
    /// Scale mismatch M = first − second (µm/m): (R·10⁻³/2)·cos 2ψ.
    ScaleMismatch,
    /// Backlash of the first axis (µm): w(φ₁)·cos φ₁, φ₁ = (σψ) mod π, w = ½ once the play is
    /// taken up (σ·½·sgn(sin ψ)·cos ψ for an ideal step).
    BacklashFirst,
    /// Backlash of the second axis (µm): w(φ₂)·cos φ₂, φ₂ = (σ(ψ − π/2)) mod π.
    BacklashSecond,
    /// Reversal spike of the first axis (µm): exp(−R·φ₁/λ₁)·|cos ψ|, φ₁ = (σψ) mod π.
    SpikeFirst,
    /// Reversal spike of the second axis (µm): exp(−R·φ₂/λ₂)·|sin ψ|, φ₂ = (σ(ψ − π/2)) mod π.
    SpikeSecond,
    /// Servo mismatch as a radial amplitude k (µm): σ·sin 2ψ; Δτ (ms) = 120·k / feed.
    Servo,
    /// Cyclic error of the first axis (µm): cos ψ · sin / cos (2π·R·cos ψ / P₁).
    CyclicFirstSin,
    CyclicFirstCos,
    /// Cyclic error of the second axis (µm): sin ψ · sin / cos (2π·R·sin ψ / P₂).
    CyclicSecondSin,
    CyclicSecondCos,
}

/// The nonlinear settings of the model: radius, decays and periods.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shape {
    pub radius_mm: f64,
    /// Decay length of each axis' reversal spike along the path.
    pub spike_decay_mm: [f64; 2],
    /// Period of each axis' cyclic error; `None` leaves the term out.
    pub cyclic_period_mm: [Option<f64>; 2],
    /// Lost motion of each axis that shapes a positive backlash: after a reversal the axis
    /// stands until the command has come back by it, w(φ) = min(R(1 − cos φ)/play − ½, ½);
    /// 0 gives the ideal step w = ½.
    pub backlash_play_mm: [f64; 2],
    /// Fit the servo-mismatch column (needs both directions).
    pub servo: bool,
}

impl Shape {
    /// The columns of the design, in a fixed order.
    ///
    /// The first nine repeat the enum's first nine variants on purpose: this list is the
    /// design's column order (the coefficients and their standard errors follow it), the enum
    /// only names the kinds.
    pub fn columns(&self) -> Vec<Column> {
        use Column::*;
        let mut cols = vec![
            Constant,
            CentreFirst,
            CentreSecond,
            Squareness,
            ScaleMismatch,
            BacklashFirst,
            BacklashSecond,
            SpikeFirst,
            SpikeSecond,
        ];
        if self.servo {
            cols.push(Servo);
        }
        if self.cyclic_period_mm[0].is_some() {
            cols.extend([CyclicFirstSin, CyclicFirstCos]);
        }
        if self.cyclic_period_mm[1].is_some() {
            cols.extend([CyclicSecondSin, CyclicSecondCos]);
        }
        cols
    }

    /// Value of a column at angle `psi_rad` in the direction of sense `sigma` (±1).
    pub fn value(&self, col: Column, psi_rad: f64, sigma: f64) -> f64 {
        use Column::*;
        let r = self.radius_mm;
        let (s, c) = psi_rad.sin_cos();
        match col {
            Constant => 1.0,
            CentreFirst => c,
            CentreSecond => s,
            Squareness => -(r * 1e-3 / 2.0) * (2.0 * psi_rad).sin(),
            ScaleMismatch => (r * 1e-3 / 2.0) * (2.0 * psi_rad).cos(),
            BacklashFirst => {
                let phi = (sigma * psi_rad).rem_euclid(PI);
                ramp(r, phi, self.backlash_play_mm[0]) * phi.cos()
            }
            BacklashSecond => {
                let phi = (sigma * (psi_rad - FRAC_PI_2)).rem_euclid(PI);
                ramp(r, phi, self.backlash_play_mm[1]) * phi.cos()
            }
            SpikeFirst => {
                let phi = (sigma * psi_rad).rem_euclid(PI);
                (-r * phi / self.spike_decay_mm[0]).exp() * c.abs()
            }
            SpikeSecond => {
                let phi = (sigma * (psi_rad - FRAC_PI_2)).rem_euclid(PI);
                (-r * phi / self.spike_decay_mm[1]).exp() * s.abs()
            }
            Servo => sigma * (2.0 * psi_rad).sin(),
            CyclicFirstSin | CyclicFirstCos => {
                let p = self.cyclic_period_mm[0].unwrap_or(f64::INFINITY);
                c * wave(col == CyclicFirstSin, TAU * r * c / p)
            }
            CyclicSecondSin | CyclicSecondCos => {
                let p = self.cyclic_period_mm[1].unwrap_or(f64::INFINITY);
                s * wave(col == CyclicSecondSin, TAU * r * s / p)
            }
        }
    }
}

/// Error along the outward direction of the last reversal, per µm of backlash: −½ while the
/// play is taken up, then ½.
fn ramp(radius_mm: f64, phi: f64, play_mm: f64) -> f64 {
    if play_mm > 0.0 {
        (radius_mm * (1.0 - phi.cos()) / play_mm - 0.5).min(0.5)
    } else {
        0.5
    }
}

fn wave(sine: bool, arg: f64) -> f64 {
    if sine {
        arg.sin()
    } else {
        arg.cos()
    }
}
