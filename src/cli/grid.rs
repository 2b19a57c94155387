//! CLI of `errmap grid`: interpolate probe points onto a grid without a network.

use super::Globals;
use errmap::geom::Axis;
use errmap::interp::{resample, Grid, Method, Surface};
use errmap::io::write_atomic;
use errmap::probe::{parse_domain, read_probes, ProbeSpec};
use errmap::{Error, Location, Result};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct GridArgs {
    /// The probe file (CSV: x_mm,y_mm,z_mm, optional nx_mm,ny_mm,nz_mm and id).
    pub probes: PathBuf,
    /// Interpolation method.
    #[arg(long, value_enum, default_value_t = Method::NaturalNeighbour)]
    pub method: Method,
    /// Grid step in mm.
    #[arg(long, value_name = "MM")]
    pub step: f64,
    /// Grid domain UMIN,VMIN,UMAX,VMAX in mm along the plane axes (x,y for normal z; y,z for x;
    /// z,x for y). Default: the probes' bounding box. Probes outside it are an error.
    #[arg(long, value_name = "UMIN,VMIN,UMAX,VMAX", allow_hyphen_values = true)]
    pub domain: Option<String>,
    /// Error direction: the axis E is measured along (x, y or z).
    #[arg(long, default_value = "z", value_parser = parse_axis)]
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
}

fn parse_axis(text: &str) -> std::result::Result<Axis, String> {
    Axis::parse(text).ok_or_else(|| format!("'{text}' is not an axis: use x, y or z"))
}

/// Round to a multiple of 1/`scale` for output, without a negative zero.
fn rounded(x: f64, scale: f64) -> f64 {
    let r = (x * scale).round() / scale;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

pub fn run(args: GridArgs, _globals: Globals) -> Result<i32> {
    let domain = args.domain.as_deref().map(parse_domain).transpose()?;
    errmap::probe::validate_max_deviation(args.max_deviation_mm, "--max-deviation-mm")?;
    let spec = ProbeSpec {
        normal: args.normal,
        nominal_plane_mm: args.nominal_plane,
        domain,
        max_deviation_mm: args.max_deviation_mm,
    };
    let set = read_probes(&args.probes, &spec)?;
    let domain = match domain.or_else(|| set.bounding_box()) {
        Some(d) => d,
        None => {
            return Err(Error::Internal(
                "a validated probe set has no points".into(),
            ))
        }
    };
    let grid = Grid::covering(&domain, args.step)?;
    let surface = Surface::new(&set.uve()).map_err(|e| {
        Error::input(
            Location::file(&args.probes),
            e.to_string(),
            "the probes must span an area in the map plane",
        )
    })?;
    let values = resample(&surface, args.method, &grid);
    let (ua, va) = args.normal.plane_axes();
    let mut inside = 0usize;
    write_atomic(&args.output, |w| {
        writeln!(w, "{}_mm,{}_mm,e_um", ua.name(), va.name())?;
        for j in 0..grid.nv {
            for i in 0..grid.nu {
                if let Some(e) = values[j * grid.nu + i] {
                    let (u, v) = grid.node(i, j);
                    // Nodes to 1 nm (no 0.30000000000000004), E to 1e-6 µm.
                    writeln!(
                        w,
                        "{},{},{}",
                        rounded(u, 1e6),
                        rounded(v, 1e6),
                        rounded(e, 1e6)
                    )?;
                    inside += 1;
                }
            }
        }
        Ok(())
    })?;
    info!(
        "errmap grid: {} probe points → {} of {} nodes ({} × {}, step {} mm) inside their hull, {} → {}",
        set.points.len(),
        inside,
        grid.len(),
        grid.nu,
        grid.nv,
        grid.step_mm,
        args.method,
        args.output.display()
    );
    Ok(0)
}
