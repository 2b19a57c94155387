//! The reduce step of a sharded batch: every part leaves its training-set nodes and map values bit-exact in `reduce.json`, and from them the family statistics, network and toolpaths are rebuilt as an unsharded run builds them.
//!
//! The family network is fitted to the node-wise mean of the parts' training sets, summed in
//! batch order, and starts from the same initial weights as in the unsharded batch, so on the
//! CPU trainer the reduce writes the same bytes.

use super::part_record::Marks;
pub use super::part_record::{PartReduce, REDUCE_FILE};
use super::run::{compensate_one, training_set, write_family, Settings, ToolpathPlan};
use super::summary::{FamilySummary, ToolpathSummary};
use super::train_step::{initial_network, Role};
use errmap_core::error::{Error, Result};
use errmap_core::geom::Domain;
use errmap_maps::interp::Grid;
use errmap_maps::map::{family_stats, ErrorMap, FittedModel};
use errmap_maps::nn::Trainer;
use std::path::Path;

/// Node-wise mean of the parts' training sets (nodes where every part has a value), summed
/// in the order given — the batch order of the unsharded run.
pub fn family_mean_nodes(nodes: &[&[Option<f64>]], len: usize) -> Vec<Option<f64>> {
    (0..len)
        .map(|k| {
            let vals: Option<Vec<f64>> = nodes.iter().map(|p| p[k]).collect();
            vals.map(|v| v.iter().sum::<f64>() / v.len() as f64)
        })
        .collect()
}

/// What the reduce adds to a merged summary.
#[derive(Debug, Default)]
pub struct FamilyOutcome {
    pub family: Option<FamilySummary>,
    pub toolpaths: Vec<ToolpathSummary>,
}

/// Fit the family network to the mean of `parts` (batch order), write the family folder
/// `dir` (mean, std, model) and compensate the family toolpaths.
pub fn reduce_family(
    parts: &[PartReduce],
    s: &Settings,
    domain: &Domain,
    dir: &Path,
    toolpaths: Option<&ToolpathPlan>,
    trainer: &dyn Trainer,
) -> Result<FamilyOutcome> {
    let train_grid = Grid::covering(domain, s.spacing_mm)?;
    let grid = Grid::covering(domain, s.grid_step_mm)?;
    for p in parts {
        let u_len_ok = p.map_u_um.as_ref().is_none_or(|u| u.len() == grid.len());
        if p.train_nodes.len() != train_grid.len() || p.map_e_um.len() != grid.len() || !u_len_ok {
            return Err(Error::usage(
                format!("part '{}' was mapped on another grid", p.part),
                "merge the shards of one job (same domain, spacing and grid step)",
            ));
        }
    }
    if parts.is_empty() {
        return Ok(FamilyOutcome::default());
    }
    let nodes: Vec<&[Option<f64>]> = parts.iter().map(|p| p.train_nodes.as_slice()).collect();
    let mean_nodes = family_mean_nodes(&nodes, train_grid.len());
    if mean_nodes.iter().flatten().count() < 3 {
        return Ok(FamilyOutcome::default());
    }
    let (set, norm) = training_set(&train_grid, &mean_nodes, domain);
    s.model.validate()?;
    let initial = initial_network(&s.model, &Role::Family);
    let net = trainer
        .train_from(vec![initial], std::slice::from_ref(&set), &s.model)?
        .pop()
        .ok_or_else(|| Error::Internal("the trainer returned no family network".into()))?;
    let domains: Vec<_> = parts
        .iter()
        .map(|p| (p.hull_mm.as_ref(), p.surface_mm))
        .collect();
    let model = FittedModel::new("family", s.normal, *domain, norm, net).with_domains(&domains);
    let maps: Vec<ErrorMap> = parts
        .iter()
        .map(|p| ErrorMap {
            grid,
            normal: s.normal,
            values: p.map_e_um.clone(),
        })
        .collect();
    let refs: Vec<&ErrorMap> = maps.iter().collect();
    let Some((mean, std)) = family_stats(&refs) else {
        return Ok(FamilyOutcome::default());
    };
    let mut marks = Marks::default();
    for p in parts {
        marks.probes.extend_from_slice(&p.marks.probes);
        marks.rejected.extend_from_slice(&p.marks.rejected);
    }
    let u_parts: Option<Vec<&[f64]>> = parts.iter().map(|p| p.map_u_um.as_deref()).collect();
    let (family, model) = write_family(dir, &mean, &std, model, u_parts, maps.len(), &marks, s)?;
    let mut out = FamilyOutcome {
        family: Some(family),
        toolpaths: Vec::new(),
    };
    if let Some(tp) = toolpaths.filter(|tp| !tp.per_part) {
        for f in &tp.files {
            out.toolpaths
                .push(compensate_one(f, dir, "family", &model, tp));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reduce_file_keeps_every_bit() {
        let dir = tempfile::tempdir().unwrap();
        let p = PartReduce {
            part: "p01".into(),
            holdout_fit: true,
            train_nodes: vec![
                None,
                Some(0.1 + 0.2),
                Some(-1e-300),
                Some(f64::MIN_POSITIVE),
            ],
            map_e_um: vec![1.0 / 3.0, -0.0, 12_345.678_901_234_567],
            map_u_um: Some(vec![0.1, 2.0 / 3.0, 0.0]),
            hull_mm: Some(vec![[0.1, 0.2], [600.0 / 7.0, 1.0 / 3.0], [5.5, 290.0]]),
            surface_mm: Some([4.999_999_999_999_999, 5.0]),
            marks: Marks {
                probes: vec![(0.1, 1.0 / 3.0), (2.5, -7.25)],
                rejected: vec![(600.0 / 7.0, 0.2)],
            },
        };
        p.write(dir.path()).unwrap();
        let back = PartReduce::read(&dir.path().join(REDUCE_FILE)).unwrap();
        assert_eq!(back, p);
        assert_eq!(back.map_e_um[1].to_bits(), (-0.0f64).to_bits());
    }

    #[test]
    fn family_mean_needs_every_part() {
        let a = [Some(1.0), None, Some(3.0)];
        let b = [Some(2.0), Some(5.0), Some(4.0)];
        assert_eq!(
            family_mean_nodes(&[&a, &b], 3),
            vec![Some(1.5), None, Some(3.5)]
        );
    }
}
