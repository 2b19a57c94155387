//! The family's statistics built one part at a time, so a family of any size needs memory for one part and the running sums: the node-wise mean of the training sets, the sums of the maps and of u(E)², the measured domain and the marks drawn on the family maps.
//!
//! Every sum adds the parts in batch order starting from −0.0, as `Iterator::sum` does, so
//! the figures are bit for bit those of a sum over all parts held at once. The spread (std)
//! needs the mean first: [`FamilyMaps::std_map`] takes the parts' maps a second time.

use super::part_record::Marks;
use errmap_core::geom::{convex_hull, Axis};
use errmap_maps::interp::Grid;
use errmap_maps::map::ErrorMap;
use std::collections::HashMap;

/// The running node-wise mean of the parts' training-grid values: a node counts where every
/// part has a value.
#[derive(Debug, Clone)]
pub(crate) struct FamilyNodes {
    sum: Vec<f64>,
    present: Vec<bool>,
    count: usize,
}

impl FamilyNodes {
    /// No part yet, on a training grid of `len` nodes.
    pub fn new(len: usize) -> FamilyNodes {
        FamilyNodes {
            sum: vec![-0.0; len],
            present: vec![true; len],
            count: 0,
        }
    }

    /// Add the next part's node values (batch order); a part of another length is ignored.
    pub fn add(&mut self, nodes: &[Option<f64>]) {
        if nodes.len() != self.sum.len() {
            return;
        }
        for ((s, ok), v) in self.sum.iter_mut().zip(&mut self.present).zip(nodes) {
            match v {
                Some(v) => *s += v,
                None => *ok = false,
            }
        }
        self.count += 1;
    }

    /// The mean at every node every part has; `None` without parts or with fewer than 3 such
    /// nodes (no family network).
    pub fn mean(&self) -> Option<Vec<Option<f64>>> {
        if self.count == 0 {
            return None;
        }
        let n = self.count as f64;
        let mean: Vec<Option<f64>> = self
            .sum
            .iter()
            .zip(&self.present)
            .map(|(s, &ok)| ok.then_some(s / n))
            .collect();
        (mean.iter().flatten().count() >= 3).then_some(mean)
    }
}

/// How often at most one position is drawn on a family map: a mark's anti-aliased rim is
/// blended again at each drawing, and after this many it no longer changes a pixel.
pub(crate) const MAX_DRAWS_PER_MARK: usize = 64;

/// Marks drawn on the family maps: each distinct position (in the order first seen) with how
/// many parts have it, and how many points every part has.
#[derive(Debug, Clone, Default)]
pub(crate) struct DistinctMarks {
    probes: Vec<((f64, f64), usize)>,
    rejected: Vec<((f64, f64), usize)>,
    seen_probes: HashMap<(u64, u64), usize>,
    seen_rejected: HashMap<(u64, u64), usize>,
    probes_total: usize,
    rejected_total: usize,
}

/// Count `points` into the distinct positions `list` (indexed by `seen`).
fn count_into(
    list: &mut Vec<((f64, f64), usize)>,
    seen: &mut HashMap<(u64, u64), usize>,
    points: &[(f64, f64)],
) {
    for &(u, v) in points {
        let k = *seen.entry((u.to_bits(), v.to_bits())).or_insert_with(|| {
            list.push(((u, v), 0));
            list.len() - 1
        });
        list[k].1 += 1;
    }
}

/// Each position as often as it was seen, up to [`MAX_DRAWS_PER_MARK`].
fn expanded(list: &[((f64, f64), usize)]) -> Vec<(f64, f64)> {
    list.iter()
        .flat_map(|&(p, n)| std::iter::repeat_n(p, n.min(MAX_DRAWS_PER_MARK)))
        .collect()
}

impl DistinctMarks {
    /// Add a part's kept and rejected points.
    pub fn add(&mut self, part: &Marks) {
        count_into(&mut self.probes, &mut self.seen_probes, &part.probes);
        count_into(&mut self.rejected, &mut self.seen_rejected, &part.rejected);
        self.probes_total += part.probes.len();
        self.rejected_total += part.rejected.len();
    }

    /// The marks to draw: each position as often as parts have it (at most
    /// [`MAX_DRAWS_PER_MARK`] times), with every part's counts for the legend. Marks that do not
    /// overlap give the same picture as every part's marks drawn in turn.
    pub fn to_marks(&self) -> Marks {
        Marks {
            probes: expanded(&self.probes),
            rejected: expanded(&self.rejected),
            totals: Some(self.totals()),
        }
    }

    /// Every part's (kept, rejected) points, counted for the legend.
    pub fn totals(&self) -> (usize, usize) {
        (self.probes_total, self.rejected_total)
    }
}

/// The delivered maps' running sums: E (for the mean), u(E)² (for the family's u), the
/// measured domain (hull and surface span of every part) and the marks.
#[derive(Debug, Clone)]
pub(crate) struct FamilyMaps {
    grid: Grid,
    normal: Axis,
    sum_e: Vec<f64>,
    /// `None` once a part has no u(E).
    sum_u2: Option<Vec<f64>>,
    count: usize,
    /// `None` once a part has no hull or surface span (the family model then has none).
    hull: Option<Vec<[f64; 2]>>,
    surface: Option<[f64; 2]>,
    domains_known: bool,
    marks: DistinctMarks,
}

impl FamilyMaps {
    /// No map yet, on the map grid `grid`.
    pub fn new(grid: Grid, normal: Axis) -> FamilyMaps {
        FamilyMaps {
            grid,
            normal,
            sum_e: vec![-0.0; grid.len()],
            sum_u2: Some(vec![-0.0; grid.len()]),
            count: 0,
            hull: None,
            surface: None,
            domains_known: true,
            marks: DistinctMarks::default(),
        }
    }

    /// Add the next delivered part (batch order): its map, u(E), measured domain and marks.
    pub fn add(
        &mut self,
        e_um: &[f64],
        u_um: Option<&[f64]>,
        domain: (Option<&Vec<[f64; 2]>>, Option<[f64; 2]>),
        marks: &Marks,
    ) {
        for (s, e) in self.sum_e.iter_mut().zip(e_um) {
            *s += e;
        }
        self.sum_u2 = match (self.sum_u2.take(), u_um) {
            (Some(mut sum), Some(u)) if u.len() == sum.len() => {
                for (s, u) in sum.iter_mut().zip(u) {
                    *s += u * u;
                }
                Some(sum)
            }
            _ => None,
        };
        match domain {
            (Some(h), Some(s)) if self.domains_known => {
                let mut all = self.hull.take().unwrap_or_default();
                all.extend_from_slice(h);
                self.hull = Some(convex_hull(&all));
                self.surface = Some(match self.surface {
                    None => s,
                    Some(a) => [a[0].min(s[0]), a[1].max(s[1])],
                });
            }
            _ => {
                self.domains_known = false;
                self.hull = None;
                self.surface = None;
            }
        }
        self.marks.add(marks);
        self.count += 1;
    }

    /// How many maps were added.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The mean map; `None` before the first part.
    pub fn mean(&self) -> Option<ErrorMap> {
        let n = self.count as f64;
        (self.count > 0).then(|| ErrorMap {
            grid: self.grid,
            normal: self.normal,
            values: self.sum_e.iter().map(|s| s / n).collect(),
        })
    }

    /// The spread about `mean` of the maps, given again in the same order: √(Σ (e − μ)² / N).
    pub fn std_map(
        &self,
        mean: &ErrorMap,
        maps: impl Iterator<Item = errmap_core::Result<Vec<f64>>>,
    ) -> errmap_core::Result<ErrorMap> {
        let mut sum = vec![-0.0; mean.values.len()];
        for map in maps {
            for ((s, e), mu) in sum.iter_mut().zip(map?).zip(&mean.values) {
                *s += (e - mu).powi(2);
            }
        }
        let n = self.count as f64;
        Ok(ErrorMap {
            grid: self.grid,
            normal: self.normal,
            values: sum.iter().map(|s| (s / n).sqrt()).collect(),
        })
    }

    /// Σ u_i² per node, when every part had u(E).
    pub fn u_squared_sum(&self) -> Option<&[f64]> {
        self.sum_u2.as_deref().filter(|_| self.count > 0)
    }

    /// The family's measured domain (hull, surface span), when every part had one.
    pub fn domain(&self) -> Option<(Vec<[f64; 2]>, [f64; 2])> {
        match (
            &self.hull,
            self.surface,
            self.domains_known && self.count > 0,
        ) {
            (Some(h), Some(s), true) => Some((h.clone(), s)),
            _ => None,
        }
    }

    /// The marks to draw on the family maps, with every part's counts.
    pub fn marks(&self) -> &DistinctMarks {
        &self.marks
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_sums_equal_the_sums_over_all_parts() {
        // Three maps of two nodes; mean and std by hand: node 0 values 1, 2, 6 → mean 3,
        // variance (4 + 1 + 9)/3 = 14/3; node 1 values 0, 0, 3 → mean 1, variance (1+1+4)/3 = 2.
        let grid = Grid {
            u0_mm: 0.0,
            v0_mm: 0.0,
            step_mm: 1.0,
            nu: 2,
            nv: 1,
        };
        let maps = [vec![1.0, 0.0], vec![2.0, 0.0], vec![6.0, 3.0]];
        let mut f = FamilyMaps::new(grid, Axis::Z);
        let marks = Marks {
            probes: vec![(1.0, 2.0), (3.0, 4.0)],
            rejected: vec![(1.0, 2.0)],
            totals: None,
        };
        for (k, m) in maps.iter().enumerate() {
            let hull = vec![[k as f64, 0.0], [k as f64 + 1.0, 0.0], [k as f64, 1.0]];
            f.add(
                m,
                Some(&[1.0, 2.0]),
                (Some(&hull), Some([0.0, k as f64])),
                &marks,
            );
        }
        let mean = f.mean().unwrap();
        assert_eq!(mean.values, vec![3.0, 1.0]);
        let std = f
            .std_map(&mean, maps.iter().map(|m| Ok(m.clone())))
            .unwrap();
        assert_eq!(std.values, vec![(14.0f64 / 3.0).sqrt(), 2.0f64.sqrt()]);
        assert_eq!(f.u_squared_sum().unwrap(), &[3.0, 12.0]);
        let (hull, surface) = f.domain().unwrap();
        assert_eq!(hull, vec![[0.0, 0.0], [3.0, 0.0], [2.0, 1.0], [0.0, 1.0]]);
        assert_eq!(surface, [0.0, 2.0]);
        // Each position drawn as often as parts have it, every point counted.
        assert_eq!(
            f.marks().to_marks().probes,
            vec![
                (1.0, 2.0),
                (1.0, 2.0),
                (1.0, 2.0),
                (3.0, 4.0),
                (3.0, 4.0),
                (3.0, 4.0)
            ]
        );
        assert_eq!(f.marks().totals(), (6, 3));
        // A part without u(E) or a hull takes them from the family.
        f.add(&[0.0, 0.0], None, (None, None), &Marks::default());
        assert!(f.u_squared_sum().is_none() && f.domain().is_none());
    }

    #[test]
    fn the_node_mean_needs_every_part_and_three_nodes() {
        let mut n = FamilyNodes::new(4);
        assert!(n.mean().is_none());
        n.add(&[Some(1.0), None, Some(3.0), Some(1.0)]);
        n.add(&[Some(2.0), Some(5.0), Some(4.0), Some(2.0)]);
        assert_eq!(
            n.mean().unwrap(),
            vec![Some(1.5), None, Some(3.5), Some(1.5)]
        );
        n.add(&[None, Some(1.0), Some(1.0), Some(1.0)]);
        assert!(n.mean().is_none(), "two nodes left");
    }
}
