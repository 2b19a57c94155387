//! The delivered map's honest hold-out figure: a nested choice between the network and the kriging, so that no held-out point both picks the winner and judges it.
//!
//! The pipeline delivers whichever of the two fits the held-out points better (the lower RMS
//! of its misses, a tie to the network). Reporting the winner's RMS on those same points
//! reports the least of two noisy figures, which is biased low. Here each held-out point i is
//! judged by the kind the *other* held-out points choose (leave-one-out over the choice), and
//! the figure is the RMS of those misses: an estimate of the error of the whole procedure
//! "choose on held-out points, then deliver", which is what the user gets.

/// RMS of the misses of the kind chosen without each point, µm; `None` when the two lists
/// differ in length or are empty. With a single held-out point nothing is left to choose on:
/// the network's miss is taken (the tie rule).
pub fn nested_holdout_rmse(network_um: &[f64], kriging_um: &[f64]) -> Option<f64> {
    let n = network_um.len();
    if n == 0 || (!kriging_um.is_empty() && kriging_um.len() != n) {
        return None;
    }
    if kriging_um.is_empty() {
        // No kriging baseline: the network is delivered without a choice.
        return errmap_maps::map::rms_um(network_um);
    }
    let sq_net: f64 = network_um.iter().map(|r| r * r).sum();
    let sq_kri: f64 = kriging_um.iter().map(|r| r * r).sum();
    let mut sq = 0.0;
    for i in 0..n {
        let (without_net, without_kri) = (
            sq_net - network_um[i].powi(2),
            sq_kri - kriging_um[i].powi(2),
        );
        let miss = if without_kri < without_net {
            kriging_um[i]
        } else {
            network_um[i]
        };
        sq += miss * miss;
    }
    Some((sq / n as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_point_is_judged_by_the_choice_of_the_others() {
        // Network misses 1, 1, 4; kriging 2, 2, 0. On all three the kriging wins (8 < 18) and
        // its own RMS would be √(8/3) ≈ 1.63. Nested: without point 0 → net 17 vs kri 4:
        // kriging, miss 2; without point 1 → kriging, miss 2; without point 2 → net 2 vs kri 8:
        // network, miss 4. RMS √((4 + 4 + 16)/3) = √8.
        let got = nested_holdout_rmse(&[1.0, 1.0, 4.0], &[2.0, 2.0, 0.0]).unwrap();
        assert!((got - 8f64.sqrt()).abs() < 1e-12, "{got}");
        // Never below the better kind's own RMS here: the choice costs what it costs.
        assert!(got > (8.0f64 / 3.0).sqrt());
        // One kind better everywhere: its own RMS.
        let same = nested_holdout_rmse(&[1.0, -1.0, 1.0], &[2.0, 2.0, -2.0]).unwrap();
        assert!((same - 1.0).abs() < 1e-12);
        // No kriging baseline: the network's RMS; mismatched lists: none.
        assert_eq!(nested_holdout_rmse(&[3.0, 4.0], &[]), Some(12.5f64.sqrt()));
        assert_eq!(nested_holdout_rmse(&[1.0], &[1.0, 2.0]), None);
        assert_eq!(nested_holdout_rmse(&[], &[]), None);
    }
}
