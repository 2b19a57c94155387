//! Stage 6, summary: the run's parts, family and toolpaths gathered into its [`BatchSummary`], in the plan's part order.

use crate::plan::Plan;
use crate::summary::{BatchSummary, FamilySummary, PartSummary, ToolpathSummary};
use errmap_core::geom::Domain;
use errmap_maps::nn::Trainer;

pub(crate) fn finish(
    plan: &Plan,
    trainer: &dyn Trainer,
    domain: Option<Domain>,
    mut parts: Vec<PartSummary>,
    family_map: Option<FamilySummary>,
    toolpaths: Vec<ToolpathSummary>,
) -> BatchSummary {
    // Stable order: the plan's part order.
    let order = |p: &PartSummary| {
        plan.parts
            .iter()
            .position(|q| q.name == p.part)
            .unwrap_or(usize::MAX)
    };
    parts.sort_by_key(order);
    BatchSummary {
        family: plan.settings.family.clone(),
        job: plan.job.clone(),
        backend: trainer.name(),
        normal: plan.settings.normal,
        shard: plan.shard,
        domain_mm: domain.map(|d| [d.u_min_mm, d.v_min_mm, d.u_max_mm, d.v_max_mm]),
        grid_step_mm: plan.settings.grid_step_mm,
        failed_parts: parts.iter().filter(|p| !p.ok).count(),
        parts,
        family_map,
        toolpaths,
        timing: None,
    }
}
