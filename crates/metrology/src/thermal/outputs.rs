//! The CSV files of the thermal commands: difference.csv and lines.csv (`thermal difference`)
//! and evaluate.csv (`thermal evaluate`), each written atomically.

use super::difference::Difference;
use super::evaluate::EvaluationReport;
use errmap_core::error::Result;
use errmap_core::io::write_atomic;
use std::path::Path;

/// Every reading's error, cold error and thermal error:
/// `time_s,direction,target_mm,e_um,es_um,et_um`.
pub fn write_difference_csv(path: &Path, d: &Difference) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "time_s,direction,target_mm,e_um,es_um,et_um")?;
        for r in &d.rows {
            writeln!(
                w,
                "{},{},{},{:.4},{:.4},{:.4}",
                r.time_s,
                r.direction.symbol(),
                r.target_mm,
                r.e_um,
                r.es_um,
                r.et_um
            )?;
        }
        Ok(())
    })
}

/// The error line of each time and direction with the mean temperature of each of `sensors`:
/// `time_s,direction,slope_um_per_m,offset_um,rms_um,<sensor>_c…`.
pub fn write_lines_csv(path: &Path, d: &Difference, sensors: &[String]) -> Result<()> {
    write_atomic(path, |w| {
        write!(w, "time_s,direction,slope_um_per_m,offset_um,rms_um")?;
        for s in sensors {
            write!(w, ",{s}_c")?;
        }
        writeln!(w)?;
        for l in &d.lines {
            write!(
                w,
                "{},{},{:.4},{:.4},{:.4}",
                l.time_s,
                l.direction.symbol(),
                l.slope_um_per_m,
                l.offset_um,
                l.rms_um
            )?;
            for s in sensors {
                write!(
                    w,
                    ",{:.3}",
                    l.temperatures_c.get(s).copied().unwrap_or(f64::NAN)
                )?;
            }
            writeln!(w)?;
        }
        Ok(())
    })
}

/// The figures of each measurement before and after compensation (empty where a figure is
/// not defined by the standard).
pub fn write_evaluate_csv(path: &Path, report: &EvaluationReport) -> Result<()> {
    let fmt = |v: Option<f64>| v.map(|v| format!("{v:.4}")).unwrap_or_default();
    write_atomic(path, |w| {
        writeln!(
            w,
            "campaign,time_s,e_before_um,e_after_um,a_before_um,a_after_um,r_before_um,r_after_um,b_before_um,b_after_um,rms_before_um,rms_after_um"
        )?;
        for t in &report.times {
            writeln!(
                w,
                "{},{},{},{},{},{},{},{},{},{},{:.4},{:.4}",
                t.campaign,
                t.time_s,
                fmt(t.before.E),
                fmt(t.after.E),
                fmt(t.before.A),
                fmt(t.after.A),
                fmt(t.before.R),
                fmt(t.after.R),
                fmt(t.before.B),
                fmt(t.after.B),
                t.rms_before_um,
                t.rms_after_um
            )?;
        }
        Ok(())
    })
}
