//! The heatmaps of a part's and of the family's maps: E (diverging) and u(E) (sequential), with the probe and rejected points, the measured hull and the extrapolated nodes lightened.

use crate::part_record::Marks;
use errmap_core::error::Result;
use errmap_core::geom::Axis;
use errmap_maps::map::ErrorMap;
use errmap_report::heatmap::{self, Heatmap, Scale};
use std::path::Path;

/// Draw a map's heatmap with its probe and rejected points, the measured hull and the nodes
/// outside it (`extrapolated`) lightened.
#[allow(clippy::too_many_arguments)]
pub(crate) fn draw_shaded(
    path: &Path,
    title: &str,
    map: &ErrorMap,
    marks: &Marks,
    hull: &[[f64; 2]],
    scale: Scale,
    (ua, va): (Axis, Axis),
    label: &str,
    extrapolated: &[bool],
) -> Result<()> {
    let values: Vec<Option<f64>> = map.values.iter().map(|&v| Some(v)).collect();
    let counts = marks
        .totals
        .unwrap_or((marks.probes.len(), marks.rejected.len()));
    heatmap::save_heatmap_counted(
        path,
        &Heatmap {
            title: title.into(),
            u_name: ua.name(),
            v_name: va.name(),
            value_label: label,
            u0_mm: map.grid.u0_mm,
            v0_mm: map.grid.v0_mm,
            step_mm: map.grid.step_mm,
            nu: map.grid.nu,
            nv: map.grid.nv,
            values: &values,
            probes: &marks.probes,
            rejected: &marks.rejected,
            hull,
            scale,
            extrapolated,
        },
        counts,
    )?;
    Ok(())
}

/// The heatmap of a map's u(E) (`uncertainty.png`; viridis from 0), or of zeros with a title
/// saying it is unknown when the points could not be kriged.
#[allow(clippy::too_many_arguments)]
pub(crate) fn draw_uncertainty(
    path: &Path,
    label: &str,
    map: &ErrorMap,
    u_um: Option<&[f64]>,
    figures: Option<(f64, f64)>,
    marks: &Marks,
    hull: &[[f64; 2]],
    axes: (Axis, Axis),
    extrapolated: &[bool],
) -> Result<()> {
    let (values, title) = match (u_um, figures) {
        (Some(u), Some((median, max))) => (
            u.to_vec(),
            format!("{label} — u(E): median {median:.2} µm, max {max:.2} µm (measured area)"),
        ),
        _ => (
            vec![0.0; map.values.len()],
            format!("{label} — u(E) unknown (the points could not be kriged)"),
        ),
    };
    let u_map = ErrorMap {
        grid: map.grid,
        normal: map.normal,
        values,
    };
    draw_shaded(
        path,
        &title,
        &u_map,
        marks,
        hull,
        Scale::Sequential,
        axes,
        "u(E) (µm)",
        extrapolated,
    )
}
