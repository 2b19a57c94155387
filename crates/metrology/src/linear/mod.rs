//! Linear axes measured by laser interferometer: run files, positioning evaluation by standard, air and material correction, error budget, pitch-error fit, compensation tables.

mod air;
mod analysis;
mod budget;
mod chart;
mod columns;
mod correct;
mod eval;
mod pitch;
mod report_json;
mod runs;
mod table;
pub mod text;

pub use crate::error::LinearError;
pub use air::{
    refractive_index, saturation_vapour_pressure_pa, sensitivities, vapour_pressure_pa,
    AirConditions, AirFormula, DEFAULT_CO2_PPM, HENE_WAVELENGTH_NM,
};
pub use analysis::{
    analyze, plan_table, Analysis, AnalyzeRequest, Corrections, RunSource, TablePlan,
};
pub use budget::{
    compute_budget, read_budget_setup, AbbeSetup, AirSetup, AlignmentSetup, Budget, BudgetSetup,
    BudgetTerm, ThermalSetup,
};
pub use chart::{save_chart, ChartInput};
pub use columns::ColumnMap;
pub use correct::{correct_air, normalise_material, AirCorrection, REFERENCE_TEMP_C};
pub use eval::{
    evaluate, mean, std_dev, target_symbols, AxisFigures, Evaluation, Figure, Standard,
    TargetFigures,
};
pub use pitch::{fit_pitch, PitchFit};
pub use report_json::{targets_json, AfterJson, AirIndexJson, AnalyzeJson, TargetJson};
pub use runs::{
    parse_runs, read_runs, read_runs_mapped, Direction, Env, RunFile, RunRow, Sample, RUN_COLUMNS,
    TARGET_TOLERANCE_MM,
};
pub use table::{
    detect_format, read_table, render_table, sinumerik_cec_path, CompTable, TableFormat,
    TableOptions, FANUC_MAX_POINTS, LINUXCNC_MAX_LINES,
};
