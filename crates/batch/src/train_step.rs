//! The batch's training step: every network's starting weights (seeded from the job seed and the network's name, never its position), the optional warm start of each part from the family network, and the hold-out stopping groups (a part's hold-out and delivered networks).

use errmap_core::error::{Diagnostic, Result};
use errmap_maps::nn::stop::{train_until_holdout_stops, GroupOutcome, Holdout, StopGroup};
use errmap_maps::nn::{
    network_seed, Mlp, ModelConfig, Normalisation, Stop, Trainer, TrainingSet, WarmStart,
};

/// Stable 64-bit FNV-1a of a name.
pub fn fnv1a(text: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The role of a network in a batch, which names its seed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Role {
    /// A part's fit on all clean points.
    Delivered(String),
    /// A part's fit without its held-out points.
    Holdout(String),
    /// The family network (fit to the mean of the parts).
    Family,
}

impl Role {
    /// The name its seed derives from; the prefixes keep a part named "family" apart from
    /// the family network.
    pub fn seed_name(&self) -> String {
        match self {
            Role::Delivered(part) => format!("part:{part}"),
            Role::Holdout(part) => format!("holdout:{part}"),
            Role::Family => "family".into(),
        }
    }
}

/// The starting network of `role`: Glorot-uniform from (job seed, role name), so a part gets
/// the same network in a sharded and an unsharded run.
pub fn initial_network(config: &ModelConfig, role: &Role) -> Mlp {
    Mlp::init(
        &config.layer_sizes(),
        config.activation,
        network_seed(config.seed ^ fnv1a(&role.seed_name()), 0),
    )
}

/// The batch's networks, and per network the hold-out stopping outcome of the groups it
/// judged (`stop = "holdout"`; `None` otherwise).
#[derive(Debug, Clone)]
pub struct Trained {
    pub nets: Vec<Mlp>,
    pub stops: Vec<Option<GroupOutcome>>,
}

/// Trains every network of the batch. Without a warm start, all in one trainer call (one per
/// segment with `stop = "holdout"`). With `warm_start = "family"`, the family network first
/// (`epochs` steps), then every part's networks from it, rescaled to each part's targets, for
/// `warm_epochs` steps. With `stop = "holdout"`, a part's hold-out network (`holdouts[k]`: its
/// held-out points) and its delivered network stop together at the hold-out network's best
/// check; the family network, which has no held-out points, trains its full steps.
#[cfg(test)]
pub fn train_all(
    trainer: &dyn Trainer,
    sets: &[TrainingSet],
    norms: &[Normalisation],
    roles: &[Role],
    config: &ModelConfig,
    holdouts: &[Option<Holdout>],
) -> Result<Trained> {
    let family = roles.iter().position(|r| *r == Role::Family);
    let (WarmStart::Family, Some(f)) = (config.warm_start, family) else {
        return train_parts(trainer, sets, norms, roles, config, holdouts, None);
    };
    let family_net = train_family(trainer, &sets[f], config)?;
    let others: Vec<usize> = (0..sets.len()).filter(|&k| k != f).collect();
    let pick = |k: &usize| (sets[*k].clone(), norms[*k].clone(), roles[*k].clone());
    let (part_sets, part_norms, part_roles): (Vec<_>, Vec<_>, Vec<_>) = others
        .iter()
        .map(pick)
        .fold(Default::default(), |mut acc, (s, n, r)| {
            acc.0.push(s);
            acc.1.push(n);
            acc.2.push(r);
            acc
        });
    let part_holdouts: Vec<Option<Holdout>> = others
        .iter()
        .map(|&k| holdouts.get(k).cloned().flatten())
        .collect();
    let trained = train_parts(
        trainer,
        &part_sets,
        &part_norms,
        &part_roles,
        config,
        &part_holdouts,
        Some((&family_net, &norms[f])),
    )?;
    let mut out = Trained {
        nets: vec![family_net.clone(); sets.len()],
        stops: vec![None; sets.len()],
    };
    for (i, k) in others.into_iter().enumerate() {
        out.nets[k] = trained.nets[i].clone();
        out.stops[k] = trained.stops[i].clone();
    }
    Ok(out)
}

/// The family network alone: `epochs` steps from its own initial weights (seeded by its name),
/// so every run (whole, sharded, resumed, merged) fits the same network to the same mean.
pub fn train_family(trainer: &dyn Trainer, set: &TrainingSet, config: &ModelConfig) -> Result<Mlp> {
    let initial = initial_network(config, &Role::Family);
    trainer
        .train_from(vec![initial], std::slice::from_ref(set), config)?
        .pop()
        .ok_or_else(|| Diagnostic::Internal("trainer returned no family network".into()))
}

/// The networks of some parts (`sets`, `norms`, `roles`, `holdouts` one per network) in one
/// trainer call: from their own initial weights, or with `warm` (the family network and its
/// normalisation) from it, rescaled to each part's targets, for `warm_epochs` steps.
pub fn train_parts(
    trainer: &dyn Trainer,
    sets: &[TrainingSet],
    norms: &[Normalisation],
    roles: &[Role],
    config: &ModelConfig,
    holdouts: &[Option<Holdout>],
    warm: Option<(&Mlp, &Normalisation)>,
) -> Result<Trained> {
    let all: Vec<usize> = (0..sets.len()).collect();
    let Some((family_net, family_norm)) = warm.filter(|_| config.warm_start == WarmStart::Family)
    else {
        let initial: Vec<Mlp> = roles.iter().map(|r| initial_network(config, r)).collect();
        return fit(trainer, initial, sets, roles, config, holdouts, &all);
    };
    let warm_config = ModelConfig {
        epochs: config.warm_epochs,
        loss_every: config.loss_every.min(config.warm_epochs),
        ..config.clone()
    };
    let starts: Vec<Mlp> = norms
        .iter()
        .map(|n| rescaled(family_net, family_norm, n))
        .collect();
    fit(trainer, starts, sets, roles, &warm_config, holdouts, &all)
}

/// The networks `batch` (indices into `roles` and `holdouts`) trained from `initial` on
/// `sets` (one per index), by `config.stop`; results indexed like `batch`.
fn fit(
    trainer: &dyn Trainer,
    initial: Vec<Mlp>,
    sets: &[TrainingSet],
    roles: &[Role],
    config: &ModelConfig,
    holdouts: &[Option<Holdout>],
    batch: &[usize],
) -> Result<Trained> {
    if config.stop != Stop::Holdout {
        let nets = trainer.train_from(initial, sets, config)?;
        let stops = vec![None; nets.len()];
        return Ok(Trained { nets, stops });
    }
    let groups = stop_groups(roles, holdouts, batch);
    let (nets, outcomes) = train_until_holdout_stops(trainer, initial, sets, &groups, config)?;
    let mut stops = vec![None; nets.len()];
    for (group, outcome) in groups.iter().zip(outcomes) {
        stops[group.judge] = Some(outcome);
    }
    Ok(Trained { nets, stops })
}

/// One group per part with held-out points: its hold-out network judges, its delivered
/// network stops with it. Indices are positions in `batch`.
fn stop_groups(roles: &[Role], holdouts: &[Option<Holdout>], batch: &[usize]) -> Vec<StopGroup> {
    let at = |role: &Role| batch.iter().position(|&k| roles[k] == *role);
    batch
        .iter()
        .enumerate()
        .filter_map(|(i, &k)| {
            let Role::Holdout(part) = &roles[k] else {
                return None;
            };
            let holdout = holdouts.get(k)?.clone()?;
            let mut members = vec![i];
            members.extend(at(&Role::Delivered(part.clone())));
            Some(StopGroup {
                judge: i,
                members,
                holdout,
            })
        })
        .collect()
}

/// The same function as `net` (trained for targets standardised by `from`), for targets
/// standardised by `to`: e = mean_f + std_f·y = mean_t + std_t·y', so the linear output
/// layer becomes W' = W·std_f/std_t, b' = (b·std_f + mean_f − mean_t)/std_t. Inputs are
/// scaled over the same domain in every network of a batch.
pub fn rescaled(net: &Mlp, from: &Normalisation, to: &Normalisation) -> Mlp {
    let mut out = net.clone();
    let spans = errmap_maps::nn::layer_spans(&net.layer_sizes);
    if let Some(last) = spans.last() {
        let ratio = from.e_std_um / to.e_std_um;
        for w in &mut out.params[last.weight_offset..last.bias_offset] {
            *w = (*w as f64 * ratio) as f32;
        }
        let b = &mut out.params[last.bias_offset];
        *b = ((*b as f64 * from.e_std_um + from.e_mean_um - to.e_mean_um) / to.e_std_um) as f32;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::geom::Domain;
    use errmap_maps::nn::{mse, Activation, FastCpuTrainer};

    fn domain() -> Domain {
        errmap_maps::nn::workload::plate_domain()
    }

    #[test]
    fn seeds_follow_names_not_positions() {
        let c = ModelConfig::default();
        let a = initial_network(&c, &Role::Delivered("p1".into()));
        assert_eq!(a, initial_network(&c, &Role::Delivered("p1".into())));
        for other in [
            Role::Holdout("p1".into()),
            Role::Delivered("p2".into()),
            Role::Delivered("family".into()),
            Role::Family,
        ] {
            assert_ne!(a.params, initial_network(&c, &other).params, "{other:?}");
        }
    }

    #[test]
    fn a_rescaled_network_gives_the_same_errors_in_micrometres() {
        let net = Mlp::init(&[2, 8, 8, 1], Activation::Tanh, 5);
        let from = Normalisation {
            e_mean_um: 3.0,
            e_std_um: 12.0,
            ..Normalisation::new(&domain(), &[])
        };
        let to = Normalisation {
            e_mean_um: -1.5,
            e_std_um: 4.0,
            ..from.clone()
        };
        let moved = rescaled(&net, &from, &to);
        for x in [[0.0f32, 0.0], [0.5, -0.3], [-0.9, 0.8]] {
            let a = from.unscale_output(net.forward(x));
            let b = to.unscale_output(moved.forward(x));
            assert!((a - b).abs() < 1e-5 * a.abs().max(1.0), "{a} vs {b}");
        }
    }

    #[test]
    fn parts_warm_started_from_the_family_fit_better_in_the_same_steps() {
        // Three parts of one family (the plate field, part-dependent tilt); the "family" set is
        // their first part. Same normalisation for all, so the rescale is the identity.
        let sets = errmap_maps::nn::workload::plate_family(3, 384);
        let norms = vec![Normalisation::new(&domain(), &[0.0, 2.0]); 3];
        let roles = vec![
            Role::Family,
            Role::Delivered("a".into()),
            Role::Delivered("b".into()),
        ];
        let scratch = ModelConfig {
            hidden: vec![16, 16],
            epochs: 40,
            loss_every: 40,
            ..ModelConfig::default()
        };
        let warm = ModelConfig {
            epochs: 300,
            warm_start: WarmStart::Family,
            warm_epochs: 40,
            ..scratch.clone()
        };
        let cold = train_all(&FastCpuTrainer, &sets, &norms, &roles, &scratch, &[])
            .unwrap()
            .nets;
        let hot = train_all(&FastCpuTrainer, &sets, &norms, &roles, &warm, &[])
            .unwrap()
            .nets;
        for k in 1..3 {
            let (c, h) = (mse(&cold[k], &sets[k]), mse(&hot[k], &sets[k]));
            assert!(h < 0.25 * c, "part {k}: warm {h:e}, scratch {c:e}");
        }
    }
}
