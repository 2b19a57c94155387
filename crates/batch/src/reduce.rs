//! The reduce step of a sharded batch: every part leaves its training-set nodes and map values bit-exact in `reduce.json`, and from them the family statistics, network and toolpaths are rebuilt as an unsharded run builds them.
//!
//! The family network is fitted to the node-wise mean of the parts' training sets, summed in
//! batch order, and starts from the same initial weights as in the unsharded batch, so on the
//! CPU trainer the reduce writes the same bytes.

use crate::family_sums::{FamilyMaps, FamilyNodes};
#[cfg(test)]
use crate::part_record::Marks;
pub use crate::part_record::{PartReduce, REDUCE_FILE};
use crate::plan::{Settings, ToolpathPlan};
use crate::stages::family::{write_family_folder, FamilyInput};
use crate::stages::toolpaths::compensate_family;
use crate::stages::train::training_set;
use crate::summary::{FamilySummary, ToolpathSummary};
use crate::train_step::train_family;
use errmap_core::error::{Diagnostic, Result};
use errmap_core::geom::Domain;
use errmap_maps::interp::Grid;
use errmap_maps::nn::Trainer;
use std::path::Path;

/// What the reduce adds to a merged summary.
#[derive(Debug, Default)]
pub struct FamilyOutcome {
    pub family: Option<FamilySummary>,
    pub toolpaths: Vec<ToolpathSummary>,
}

/// The parts' reduce records, one at a time: `load(k)` reads the `k`-th of `count` (batch
/// order), so a family of any size needs memory for one record and the family's sums.
pub struct PartSource<'a> {
    /// How many parts were mapped.
    pub count: usize,
    /// Read the `k`-th part's record.
    pub load: Box<dyn Fn(usize) -> Result<PartReduce> + 'a>,
}

/// Fit the family network to the mean of the parts' training sets (batch order), write the
/// family folder `dir` (mean, std, model) and compensate the family toolpaths.
pub fn reduce_family(
    parts: &PartSource,
    s: &Settings,
    domain: &Domain,
    dir: &Path,
    toolpaths: Option<&ToolpathPlan>,
    trainer: &dyn Trainer,
) -> Result<FamilyOutcome> {
    let train_grid = Grid::covering(domain, s.spacing_mm)?;
    let grid = Grid::covering(domain, s.grid_step_mm)?;
    if parts.count == 0 {
        return Ok(FamilyOutcome::default());
    }
    let (nodes, maps) = family_sums(parts, &train_grid, grid, s)?;
    let Some(mean_nodes) = nodes.mean() else {
        return Ok(FamilyOutcome::default());
    };
    let (set, norm) = training_set(&train_grid, &mean_nodes, domain);
    s.model.validate()?;
    let net = train_family(trainer, &set, &s.model)?;
    let input = FamilyInput {
        dir,
        domain: *domain,
        network: (net, norm),
        maps: &maps,
        check_against: None,
    };
    let again = (0..parts.count).map(|k| (parts.load)(k).map(|p| p.map_e_um));
    let Some((family, model)) = write_family_folder(input, again, s)? else {
        return Ok(FamilyOutcome::default());
    };
    Ok(FamilyOutcome {
        family: Some(family),
        toolpaths: compensate_family(toolpaths, dir, &model),
    })
}

/// The family's running sums from the parts' records, each checked to be of the job's grids.
fn family_sums(
    parts: &PartSource,
    train_grid: &Grid,
    grid: Grid,
    s: &Settings,
) -> Result<(FamilyNodes, FamilyMaps)> {
    let mut nodes = FamilyNodes::new(train_grid.len());
    let mut maps = FamilyMaps::new(grid, s.normal);
    for k in 0..parts.count {
        let p = (parts.load)(k)?;
        let u_len_ok = p.map_u_um.as_ref().is_none_or(|u| u.len() == grid.len());
        if p.train_nodes.len() != train_grid.len() || p.map_e_um.len() != grid.len() || !u_len_ok {
            return Err(Diagnostic::usage(
                format!("part '{}' was mapped on another grid", p.part),
                "merge the shards of one job (same domain, spacing and grid step)",
            ));
        }
        nodes.add(&p.train_nodes);
        maps.add(
            &p.map_e_um,
            p.map_u_um.as_deref(),
            (p.hull_mm.as_ref(), p.surface_mm),
            &p.marks,
        );
    }
    Ok((nodes, maps))
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
                totals: None,
            },
        };
        p.write(dir.path()).unwrap();
        let back = PartReduce::read(&dir.path().join(REDUCE_FILE)).unwrap();
        assert_eq!(back, p);
        assert_eq!(back.map_e_um[1].to_bits(), (-0.0f64).to_bits());
    }
}
