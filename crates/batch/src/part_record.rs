//! A part's reduce record, `reduce.json`: its training-set nodes, map values and measured points, bit-exact, written by its shard and read by the reduce step.

use errmap_core::error::{Diagnostic, Location, Result};
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
    /// The map's u(E) on the output grid (µm), u fastest; absent in records of an errmap that
    /// did not compute it, or when the part's points could not be kriged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    map_u_um_bits: Option<Vec<String>>,
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
    pub map_u_um: Option<Vec<f64>>,
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
            map_u_um_bits: self
                .map_u_um
                .as_ref()
                .map(|u| u.iter().map(|&v| bits(v)).collect()),
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
        errmap_core::io::write_json(&dir.join(REDUCE_FILE), &file)
    }

    pub fn read(path: &Path) -> Result<PartReduce> {
        let text = errmap_core::io::read_text(path)?;
        let bad = |msg: String| {
            Diagnostic::input(
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
            map_u_um: file
                .map_u_um_bits
                .map(|u| u.iter().map(|v| parse(v)).collect::<Result<_>>())
                .transpose()?,
            hull_mm: file.hull_mm,
            surface_mm: file.surface_mm,
            marks: Marks {
                probes: points(&file.probes_mm_bits)?,
                rejected: points(&file.rejected_mm_bits)?,
                totals: None,
            },
        })
    }
}

/// Probe and rejected points (plane axes, mm) drawn on a map.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Marks {
    pub probes: Vec<(f64, f64)>,
    pub rejected: Vec<(f64, f64)>,
    /// The (kept, rejected) counts the legend gives when they differ from the marks drawn
    /// (a family map draws each distinct position once); `None`: the marks' own counts.
    pub totals: Option<(usize, usize)>,
}
