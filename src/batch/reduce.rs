//! The reduce step of a sharded batch: every part leaves its training-set nodes and map values bit-exact in `reduce.json`, and from them the family statistics, network and toolpaths are rebuilt as an unsharded run builds them.
//!
//! The family network is fitted to the node-wise mean of the parts' training sets, summed in
//! batch order, and starts from the same initial weights as in the unsharded batch, so on the
//! CPU trainer the reduce writes the same bytes.

use super::run::{compensate_one, training_set, write_family, Marks, Settings, ToolpathPlan};
use super::summary::{FamilySummary, ToolpathSummary};
use super::train_step::{initial_network, Role};
use crate::error::{Error, Location, Result};
use crate::geom::Domain;
use crate::interp::Grid;
use crate::map::{family_stats, ErrorMap, FittedModel};
use crate::nn::Trainer;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// File name of a part's reduce inputs, in its folder.
pub const REDUCE_FILE: &str = "reduce.json";
const REDUCE_FORMAT: &str = "errmap-reduce/1";

/// `reduce.json`: f64 values as the hex of their IEEE-754 bits, so nothing is rounded.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ReduceFile {
    format: String,
    part: String,
    /// Whether the part had a hold-out fit (it then trained two networks).
    holdout_fit: bool,
    /// Training-grid node values (µm), u fastest; null outside the probes' hull.
    train_nodes_bits: Vec<Option<String>>,
    /// The delivered network's map on the output grid (µm), u fastest.
    map_e_um_bits: Vec<String>,
    /// The part's measured domain (`model.json`'s `hull_mm`, `surface_mm`), for the family's.
    #[serde(default)]
    hull_mm: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    surface_mm: Option<[f64; 2]>,
    /// Kept and rejected probe points in the map plane (mm, as bits), drawn on the family maps.
    #[serde(default)]
    probes_mm_bits: Vec<[String; 2]>,
    #[serde(default)]
    rejected_mm_bits: Vec<[String; 2]>,
}

/// One part's contribution to the family.
#[derive(Debug, Clone, PartialEq)]
pub struct PartReduce {
    pub part: String,
    pub holdout_fit: bool,
    pub train_nodes: Vec<Option<f64>>,
    pub map_e_um: Vec<f64>,
    pub hull_mm: Option<Vec<[f64; 2]>>,
    pub surface_mm: Option<[f64; 2]>,
    /// The part's probe and rejected points, for the family maps.
    pub(crate) marks: Marks,
}

fn bits(v: f64) -> String {
    format!("{:016x}", v.to_bits())
}

impl PartReduce {
    pub fn write(&self, dir: &Path) -> Result<()> {
        let file = ReduceFile {
            format: REDUCE_FORMAT.into(),
            part: self.part.clone(),
            holdout_fit: self.holdout_fit,
            train_nodes_bits: self.train_nodes.iter().map(|v| v.map(bits)).collect(),
            map_e_um_bits: self.map_e_um.iter().map(|&v| bits(v)).collect(),
            hull_mm: self.hull_mm.clone(),
            surface_mm: self.surface_mm,
            probes_mm_bits: self
                .marks
                .probes
                .iter()
                .map(|&(u, v)| [bits(u), bits(v)])
                .collect(),
            rejected_mm_bits: self
                .marks
                .rejected
                .iter()
                .map(|&(u, v)| [bits(u), bits(v)])
                .collect(),
        };
        crate::io::write_json(&dir.join(REDUCE_FILE), &file)
    }

    pub fn read(path: &Path) -> Result<PartReduce> {
        let text = crate::io::read_text(path)?;
        let bad = |msg: String| {
            Error::input(
                Location::file(path),
                msg,
                "reduce.json is written by errmap batch; rerun the part's shard",
            )
        };
        let file: ReduceFile =
            serde_json::from_str(&text).map_err(|e| bad(format!("not a reduce file: {e}")))?;
        if file.format != REDUCE_FORMAT {
            return Err(bad(format!(
                "format '{}' is not {REDUCE_FORMAT}",
                file.format
            )));
        }
        let parse = |s: &str| {
            u64::from_str_radix(s, 16)
                .map(f64::from_bits)
                .map_err(|_| bad(format!("'{s}' is not the hex of an f64")))
        };
        let points = |list: &[[String; 2]]| -> Result<Vec<(f64, f64)>> {
            list.iter()
                .map(|[u, v]| Ok((parse(u)?, parse(v)?)))
                .collect()
        };
        Ok(PartReduce {
            part: file.part,
            holdout_fit: file.holdout_fit,
            train_nodes: file
                .train_nodes_bits
                .iter()
                .map(|v| v.as_deref().map(parse).transpose())
                .collect::<Result<_>>()?,
            map_e_um: file
                .map_e_um_bits
                .iter()
                .map(|v| parse(v))
                .collect::<Result<_>>()?,
            hull_mm: file.hull_mm,
            surface_mm: file.surface_mm,
            marks: Marks {
                probes: points(&file.probes_mm_bits)?,
                rejected: points(&file.rejected_mm_bits)?,
            },
        })
    }
}

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
        if p.train_nodes.len() != train_grid.len() || p.map_e_um.len() != grid.len() {
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
    let family = write_family(dir, &mean, &std, &model, maps.len(), &marks, s)?;
    let mut out = FamilyOutcome {
        family: Some(family),
        toolpaths: Vec::new(),
    };
    if let Some(tp) = toolpaths.filter(|tp| !tp.per_part) {
        for f in &tp.files {
            out.toolpaths
                .push(compensate_one(f, dir, "family", &model, &tp.settings));
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
