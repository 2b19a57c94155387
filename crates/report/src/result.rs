//! Analysis results beside their charts (`<chart>.json`, format `errmap-result/1`) and their report sections: linear axes by their standard's own symbols, thermal, rotary and circular figures and tables.
//!
//! `linear analyze --chart`, `thermal difference`, `thermal evaluate`, `rotary analyze --chart`
//! and `circular -o` write one such file beside their chart, so that `errmap report FOLDER`
//! can build a report from what the analysis wrote (docs/report.md).

use super::html::json_text;
use super::html::{self, figure_cell, num, para, png_figure, pre, table, Cell, Page};
use crate::ReportError;
use errmap_core::error::{Error, Location, Result};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// `format` of a result file.
pub const RESULT_FORMAT: &str = "errmap-result/1";

/// One analysis result, written beside its chart(s).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AnalysisResult {
    /// The file format, [`RESULT_FORMAT`].
    pub format: String,
    /// `linear-analysis`, `thermal-difference`, `thermal-evaluate`, `rotary-analysis`, `circular`.
    pub kind: String,
    /// Heading of the result's report section, e.g. "Rotary axis B".
    pub title: String,
    /// Version of the errmap that wrote the file.
    pub errmap_version: String,
    /// When the analysis ran, UTC (`SOURCE_DATE_EPOCH` when set).
    pub created_utc: String,
    /// Input files as given, with their SHA-256.
    pub inputs: BTreeMap<PathBuf, String>,
    /// Charts, relative to the result file's folder.
    pub charts: Vec<String>,
    /// A controller table the analysis read (`linear analyze --apply-table`): name and text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<(String, String)>,
    /// The analysis's JSON document (what `--json` prints).
    pub result: Value,
}

/// A path as seen from `dir`: the file name when it lies there, else the path as given.
fn relative_to(dir: &Path, p: &Path) -> String {
    match (p.parent(), p.file_name()) {
        (Some(parent), Some(name))
            if parent == dir || (parent.as_os_str().is_empty() && dir == Path::new(".")) =>
        {
            name.to_string_lossy().to_string()
        }
        _ => p.display().to_string(),
    }
}

/// The folder of a file (`.` for a bare name).
fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// The result file that goes with a chart: `x.png` → `x.json`.
pub fn beside(chart: &Path) -> PathBuf {
    chart.with_extension("json")
}

/// What [`write_result`] records.
pub struct ResultSpec<'a> {
    /// The analysis kind ([`AnalysisResult::kind`]), e.g. `rotary-analysis`.
    pub kind: &'a str,
    /// Heading of the result's report section.
    pub title: String,
    /// Input files, recorded with their SHA-256.
    pub inputs: &'a [&'a Path],
    /// Charts written beside the result; recorded relative to its folder.
    pub charts: &'a [&'a Path],
    /// A controller table the analysis read, copied into the result; `None` for none.
    pub table: Option<&'a Path>,
}

/// Write a result file (atomically; never over an input).
pub fn write_result(path: &Path, spec: &ResultSpec, result: &impl Serialize) -> Result<()> {
    if spec.charts.contains(&path) {
        return Err(Error::usage(
            format!("the result {} would replace the chart", path.display()),
            "name the chart NAME.png; its result is NAME.json",
        ));
    }
    let dir = folder_of(path);
    let mut inputs = BTreeMap::new();
    for f in spec.inputs {
        inputs.insert(f.to_path_buf(), errmap_core::io::stamp::sha256_file(f)?);
    }
    let table = match spec.table {
        Some(t) => Some((t.display().to_string(), errmap_core::io::read_text(t)?)),
        None => None,
    };
    let doc = AnalysisResult {
        format: RESULT_FORMAT.into(),
        kind: spec.kind.into(),
        title: spec.title.clone(),
        errmap_version: env!("CARGO_PKG_VERSION").into(),
        created_utc: errmap_core::io::stamp::utc_now(),
        inputs,
        charts: spec.charts.iter().map(|c| relative_to(&dir, c)).collect(),
        table,
        result: serde_json::to_value(result)
            .map_err(|e| Error::Internal(format!("JSON of the result: {e}")))?,
    };
    errmap_core::io::write_json(path, &doc)
}

/// Read a result file; `None` when the file is JSON of another kind.
pub fn read_result(path: &Path) -> Result<Option<AnalysisResult>, ReportError> {
    let text = errmap_core::io::read_text(path)?;
    let Ok(v) = serde_json::from_str::<Value>(&text) else {
        return Ok(None);
    };
    if v.get("format").and_then(Value::as_str) != Some(RESULT_FORMAT) {
        return Ok(None);
    }
    serde_json::from_value(v)
        .map(Some)
        .map_err(|e| {
            Error::input(
                Location::file(path),
                format!("not an errmap result: {e}"),
                "rerun the analysis that wrote it",
            )
        })
        .map_err(Into::into)
}

/// Every result file in `dir` (by name), read.
pub fn results_in(dir: &Path) -> Result<Vec<(PathBuf, AnalysisResult)>, ReportError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::read(dir, e))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json") && p.is_file())
        .collect();
    files.sort();
    let mut out = Vec::new();
    for f in files {
        if let Some(r) = read_result(&f)? {
            out.push((f, r));
        }
    }
    Ok(out)
}

/// The report of analysis results (one section each, in file-name order).
pub fn render_results(results: &[(PathBuf, AnalysisResult)]) -> Result<String, ReportError> {
    let mut page = Page {
        title: "errmap report — analyses".into(),
        lead: String::new(),
        sections: Vec::new(),
    };
    for (path, r) in results {
        let stem = path
            .file_stem()
            .map_or("result".to_string(), |s| s.to_string_lossy().to_string());
        page.section(&stem, &r.title, result_section(path, r)?);
    }
    if let [(_, only)] = results {
        page.title = format!("errmap report — {}", only.title);
    }
    Ok(page.render())
}

fn result_section(path: &Path, r: &AnalysisResult) -> Result<String> {
    let mut body = String::new();
    let mut rows = vec![
        vec![Cell::text("errmap version"), Cell::text(&r.errmap_version)],
        vec![Cell::text("date (UTC)"), Cell::text(&r.created_utc)],
        vec![Cell::text("analysis"), Cell::text(&r.kind)],
    ];
    for (f, h) in &r.inputs {
        rows.push(vec![
            Cell::text(format!("input {}", f.display())),
            Cell::Raw(format!("<code>{}</code>", html::escape(h))),
        ]);
    }
    body.push_str(&table(&["", ""], &rows));
    let dir = folder_of(path);
    for c in &r.charts {
        let png = dir.join(c);
        if png.is_file() {
            errmap_core::io::safety::protect(&png);
            let bytes = std::fs::read(&png).map_err(|e| Error::read(&png, e))?;
            body.push_str(&png_figure(&bytes, c, c));
        } else {
            body.push_str(&para("note", &format!("chart {c}: not found")));
        }
    }
    let key = path
        .file_stem()
        .map_or("result".to_string(), |s| s.to_string_lossy().to_string());
    if r.kind == "linear-analysis" {
        body.push_str(&linear_block(&key, &r.result));
    } else {
        body.push_str(&generic_block(&key, &r.result));
    }
    if let Some((name, text)) = &r.table {
        body.push_str(&format!(
            "<h3>Compensation table {}</h3>\n",
            html::escape(name)
        ));
        body.push_str(&pre(text));
    }
    Ok(body)
}

/// Per-target values in the order of `linear::target_symbols`.
const TARGET_KEYS: [&str; 8] = [
    "mean_up",
    "mean_down",
    "s_up",
    "s_down",
    "reversal",
    "repeatability_up",
    "repeatability_down",
    "repeatability",
];

/// A linear axis: the figures in the standard's own symbols with their definitions, the
/// per-target table under the standard's headings, the pitch fit and the figures after a table.
fn linear_block(key: &str, doc: &Value) -> String {
    let standard = doc.get("standard").and_then(Value::as_str).unwrap_or("");
    let unit = doc.get("unit").and_then(Value::as_str).unwrap_or("um");
    let unit = if unit == "um" { "µm" } else { unit };
    let mut s = para("", &format!("standard {standard}; values in {unit}"));
    s.push_str(&figures_table(key, doc.get("figures")));
    let symbols: Vec<String> = doc
        .get("target_symbols")
        .and_then(|v| serde_json::from_value(v.clone()).ok())
        .unwrap_or_else(|| TARGET_KEYS.iter().map(|k| k.to_string()).collect());
    s.push_str(&targets_table(standard, &symbols, doc.get("targets")));
    if let Some(Value::Object(fit)) = doc.get("pitch_fit") {
        s.push_str("<h3>Pitch-error fit e(x) = a + k·x + d·sin(2πx/P + φ)</h3>\n");
        let rows: Vec<Vec<Cell>> = fit
            .iter()
            .map(|(k, v)| vec![Cell::text(k), Cell::Num(json_text(v))])
            .collect();
        s.push_str(&table(&["term", "value"], &rows));
    }
    if let Some(after) = doc.get("after") {
        let name = after.get("table").and_then(Value::as_str).unwrap_or("");
        s.push_str(&format!("<h3>After applying {}</h3>\n", html::escape(name)));
        s.push_str(&figures_table(
            &format!("{key}.after"),
            after.get("figures"),
        ));
        s.push_str(&targets_table(standard, &symbols, after.get("targets")));
    }
    if let Some(Value::Array(notes)) = doc.get("corrections") {
        for n in notes.iter().filter_map(Value::as_str) {
            s.push_str(&para("note", n));
        }
    }
    s
}

fn figures_table(key: &str, figures: Option<&Value>) -> String {
    let Some(Value::Array(figs)) = figures else {
        return String::new();
    };
    let rows: Vec<Vec<Cell>> = figs
        .iter()
        .map(|f| {
            let sym = f.get("symbol").and_then(Value::as_str).unwrap_or("");
            vec![
                Cell::text(sym),
                figure_cell(
                    &format!("{key}.{sym}"),
                    f.get("value").and_then(Value::as_f64),
                    3,
                ),
                Cell::text(f.get("name").and_then(Value::as_str).unwrap_or("")),
                Cell::text(f.get("definition").and_then(Value::as_str).unwrap_or("")),
            ]
        })
        .collect();
    table(&["symbol", "value", "name", "definition"], &rows)
}

fn targets_table(standard: &str, symbols: &[String], targets: Option<&Value>) -> String {
    let Some(Value::Array(ts)) = targets else {
        return String::new();
    };
    let mut headers = vec!["target, mm"];
    let shown: Vec<usize> = (0..symbols.len().min(8))
        .filter(|&i| !symbols[i].is_empty())
        .collect();
    headers.extend(shown.iter().map(|&i| symbols[i].as_str()));
    let rows: Vec<Vec<Cell>> = ts
        .iter()
        .map(|t| {
            let mut row = vec![Cell::Num(num(
                t.get("target_mm").and_then(Value::as_f64),
                3,
            ))];
            for &i in &shown {
                let mut v = t.get(TARGET_KEYS[i]).and_then(Value::as_f64);
                // VDI/DGQ 3441's reversal span U_j is a span: |x̄_j↑ − x̄_j↓|.
                if standard == "vdi3441" && TARGET_KEYS[i] == "reversal" {
                    v = v.map(f64::abs);
                }
                row.push(Cell::Num(num(v, 3)));
            }
            row
        })
        .collect();
    table(&headers, &rows)
}

/// Any other analysis: its scalar figures, then each nested object as its own table (two
/// levels deep) and each list of records as a table.
fn generic_block(key: &str, doc: &Value) -> String {
    match doc {
        Value::Object(map) => object_block(key, map, 3),
        other => pre(&other.to_string()),
    }
}

fn object_block(key: &str, map: &serde_json::Map<String, Value>, level: usize) -> String {
    let mut s = String::new();
    let scalars: Vec<Vec<Cell>> = map
        .iter()
        .filter(|(_, v)| !v.is_object() && !v.is_array())
        .map(|(k, v)| scalar_row(&format!("{key}.{k}"), k, v))
        .collect();
    if !scalars.is_empty() {
        s.push_str(&table(&["figure", "value"], &scalars));
    }
    let heading = |k: &str| format!("<h{level}>{}</h{level}>\n", html::escape(k));
    for (k, v) in map {
        match v {
            Value::Object(inner) if level < 5 => {
                s.push_str(&heading(k));
                s.push_str(&object_block(&format!("{key}.{k}"), inner, level + 1));
            }
            Value::Object(_) => s.push_str(&para("", &format!("{k}: {v}"))),
            Value::Array(items) if items.iter().all(Value::is_object) && !items.is_empty() => {
                s.push_str(&heading(k));
                s.push_str(&records_table(items));
            }
            Value::Array(items) if !items.is_empty() => {
                let text: Vec<String> = items.iter().map(json_text).collect();
                s.push_str(&para("", &format!("{k}: {}", text.join(", "))));
            }
            _ => {}
        }
    }
    s
}

fn scalar_row(figure_key: &str, label: &str, v: &Value) -> Vec<Cell> {
    match v.as_f64() {
        Some(x) if v.is_number() => vec![Cell::text(label), figure_cell(figure_key, Some(x), 4)],
        _ => vec![Cell::text(label), Cell::text(json_text(v))],
    }
}

/// Records as a table: the columns are the keys of the first record, nested values as JSON.
fn records_table(items: &[Value]) -> String {
    const MAX_ROWS: usize = 500;
    let Some(Value::Object(first)) = items.first() else {
        return String::new();
    };
    let cols: Vec<&str> = first.keys().map(String::as_str).collect();
    let rows: Vec<Vec<Cell>> = items
        .iter()
        .take(MAX_ROWS)
        .map(|it| {
            cols.iter()
                .map(|c| match it.get(*c) {
                    Some(v) if v.is_number() => Cell::Num(num(v.as_f64(), 4)),
                    Some(v) => Cell::text(json_text(v)),
                    None => Cell::text("-"),
                })
                .collect()
        })
        .collect();
    let mut s = table(&cols, &rows);
    if items.len() > MAX_ROWS {
        s.push_str(&para(
            "note",
            &format!("first {MAX_ROWS} of {} rows shown", items.len()),
        ));
    }
    s
}
