//! CLI of `errmap grid`: interpolate probe points onto a grid without a network.

use super::exit::Result;
use super::Globals;
use errmap::geom::Axis;
use errmap::interp::Method;
use errmap::map::grid_file::{grid_probes, GridRequest};
use errmap::probe::parse_domain;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct GridArgs {
    /// The probe file (CSV: x_mm,y_mm,z_mm, optional nx_mm,ny_mm,nz_mm and id; a CSV export
    /// with --columns; DMIS .dmi/.dms/.dmis; point cloud .xyz/.ply).
    pub probes: PathBuf,
    /// Interpolation method.
    #[arg(long, value_parser = super::choices::Method::parser(), default_value = "natural-neighbour")]
    pub method: Method,
    /// Grid step in mm.
    #[arg(long, value_name = "MM")]
    pub step: f64,
    /// Grid domain UMIN,VMIN,UMAX,VMAX in mm along the plane axes (x,y for normal z; y,z for x;
    /// z,x for y). Default: the probes' bounding box. Probes outside it are an error.
    #[arg(long, value_name = "UMIN,VMIN,UMAX,VMAX", allow_hyphen_values = true)]
    pub domain: Option<String>,
    /// Error direction: the axis E is measured along (x, y or z).
    #[arg(long, default_value = "z", value_parser = Axis::parse_arg)]
    pub normal: Axis,
    /// Nominal coordinate of the surface along the normal, in mm, for files without
    /// nx_mm,ny_mm,nz_mm columns (the columns win when present).
    #[arg(long, value_name = "MM", allow_hyphen_values = true)]
    pub nominal_plane: Option<f64>,
    /// Output grid CSV (u,v,e_um with the plane axes' names; nodes outside the probes' convex
    /// hull are left out).
    #[arg(short, long, value_name = "GRID.csv")]
    pub output: PathBuf,
    /// Plausibility bound, mm: a probe deviation beyond it is an error naming the likely unit
    /// slip (µm or inches written as mm).
    #[arg(long, value_name = "MM", default_value_t = errmap::probe::DEFAULT_MAX_DEVIATION_MM)]
    pub max_deviation_mm: f64,
    /// Read an instrument's CSV export: FIELD=COLUMN[unit],… with fields x,y,z (required),
    /// nx,ny,nz, i,j,k (the point's surface normal), id; COLUMN a header name or 1-based number,
    /// unit mm, um, m or in (e.g. x=X,y=Y,z=Z[um],i=I,j=J,k=K,id=POINT). Unmapped columns are
    /// ignored; the header is the first line naming every mapped column.
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// 1-based line of the CSV header (lines before it are skipped and counted).
    #[arg(long, value_name = "N")]
    pub header_line: Option<u64>,
}

pub fn run(args: GridArgs, _globals: Globals) -> Result<i32> {
    let domain = args.domain.as_deref().map(parse_domain).transpose()?;
    let req = GridRequest {
        probes: args.probes,
        method: args.method,
        step_mm: args.step,
        domain,
        normal: args.normal,
        nominal_plane_mm: args.nominal_plane,
        max_deviation_mm: args.max_deviation_mm,
        columns: args.columns,
        header_line: args.header_line,
    };
    let done = grid_probes(&req, &args.output)?;
    let grid = done.grid;
    let mut skipped = String::new();
    if done.preamble_lines > 0 {
        skipped.push_str(&format!(
            " ({} line(s) before the header skipped)",
            done.preamble_lines
        ));
    }
    if done.skipped_features > 0 {
        skipped.push_str(&format!(
            " ({} DMIS feature(s) other than points skipped)",
            done.skipped_features
        ));
    }
    info!(
        "errmap grid: {} probe points{skipped} → {} of {} nodes ({} × {}, step {} mm) inside their hull, {} → {}",
        done.points,
        done.inside,
        grid.len(),
        grid.nu,
        grid.nv,
        grid.step_mm,
        args.method,
        args.output.display()
    );
    Ok(0)
}
