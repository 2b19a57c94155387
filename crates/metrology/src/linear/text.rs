//! The text reports of the linear-axis commands: what `errmap linear analyze` and `errmap linear budget` print.

use super::budget::Budget;
use super::eval::{target_symbols, Evaluation, Standard};
use std::fmt::Write;

/// `writeln!` into a String, which cannot fail.
macro_rules! put {
    ($out:expr, $($arg:tt)*) => {
        let _ = writeln!($out, $($arg)*);
    };
}

fn fmt_opt(v: Option<f64>) -> String {
    format!("{:>9}", errmap_core::numeric::format::opt(v, 3, "n/a"))
}

/// The text `errmap linear analyze` prints for one evaluation: per-target figures in the
/// standard's own symbols, then the axis figures with their definitions.
pub fn evaluation_report(title: &str, ev: &Evaluation) -> String {
    let mut out = String::new();
    put!(out, "{title} — {} (k = {}), µm", ev.standard, ev.k);
    // Per-target columns in the standard's own symbols; a figure it does not define is left out.
    let symbols = target_symbols(ev.standard);
    let mut head = format!("{:>10}", "target_mm");
    for s in symbols.iter().filter(|s| !s.is_empty()) {
        head.push_str(&format!(" {s:>9}"));
    }
    put!(out, "{head}");
    for t in &ev.targets {
        let reversal = match ev.standard {
            // VDI/DGQ 3441's reversal span U_j is a span: |x̄_j↑ − x̄_j↓|.
            Standard::Vdi3441 => t.reversal.map(f64::abs),
            _ => t.reversal,
        };
        let values = [
            t.mean_up,
            t.mean_down,
            t.s_up,
            t.s_down,
            reversal,
            t.repeatability_up,
            t.repeatability_down,
            t.repeatability,
        ];
        let mut line = format!("{:>10.3}", t.target);
        for (s, v) in symbols.iter().zip(values) {
            if !s.is_empty() {
                line.push(' ');
                line.push_str(&fmt_opt(v));
            }
        }
        put!(out, "{line}");
    }
    // Columns on screen: combining marks (the bar of B̄, P̄s, Ū) take none.
    let columns = |s: &str| {
        s.chars()
            .filter(|c| !('\u{300}'..='\u{36f}').contains(c))
            .count()
    };
    let width = ev
        .figures()
        .iter()
        .map(|f| columns(f.symbol))
        .max()
        .unwrap_or(1);
    for (i, f) in ev.figures().iter().enumerate() {
        let pad = width - columns(f.symbol);
        put!(
            out,
            "{} {}{} = {}  {}: {}",
            if i == 0 { "axis:" } else { "     " },
            f.symbol,
            " ".repeat(pad),
            fmt_opt(f.value).trim(),
            f.name,
            f.definition
        );
    }
    if let Some(d) = ev.unidirectional {
        put!(
            out,
            "      unidirectional test (direction {} only): bidirectional figures are n/a",
            d.symbol()
        );
    }
    out
}

/// The text `errmap linear budget` prints: each term with its formula, then the RSS total.
pub fn budget_report(b: &Budget) -> String {
    let mut out = String::new();
    put!(out, "error budget over {} mm (µm):", b.length_mm);
    for t in &b.terms {
        put!(out, "  {:<22} {:10.4}   {}", t.name, t.value_um, t.formula);
    }
    put!(out, "  {:<22} {:10.4}   √(Σ δ²)", "total (RSS)", b.total_um);
    out
}
