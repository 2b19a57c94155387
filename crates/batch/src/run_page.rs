//! The report of a batch run (`report.html`): job metadata, the family (mean, spread, hull), each part (heatmap, figures, hold-out accuracy, rejected points) and the compensated toolpaths, read from the run's own files.
//!
//! Everything shown comes from the run folder (`run.json`, `summary.json`, the part and family
//! files), so the same run always gives the same bytes; the date is the run's, from `run.json`.

use super::manifest::RunManifest;
use super::summary::{BatchSummary, PartSummary};
use errmap_core::error::{Diagnostic, Location, Result};
use errmap_report::html::{self, figure_cell, json_text, num, para, png_figure, table, Cell, Page};
use std::path::Path;

/// File name of the report in a run's folder, and of each part's page in its folder when the
/// family has more than [`INLINE_PARTS`] parts.
pub const REPORT_FILE: &str = "report.html";

/// Up to this many parts, each part's figures and pictures are sections of `report.html`;
/// beyond, each part has its own page (`<part>/report.html`) linked from the table of parts,
/// so the report of a large family stays one overview of a few MB, not a thousand pictures.
pub const INLINE_PARTS: usize = 50;

/// What a run report is built from.
pub struct RunInput<'a> {
    /// The run's folder (or its staging folder while the batch writes it).
    pub dir: &'a Path,
    /// The run's `run.json`: job, inputs, backend, date and metadata.
    pub manifest: &'a RunManifest,
    /// The run's `summary.json`: the family, every part's figures and the toolpaths.
    pub summary: &'a BatchSummary,
}

/// Render the report of a run.
pub fn render_run(input: &RunInput) -> Result<String> {
    let page = RunPage::new(input)?;
    let mut bytes = Vec::new();
    page.write(input, &mut bytes)
        .map_err(|e| Diagnostic::Internal(format!("the report in memory: {e}")))?;
    String::from_utf8(bytes)
        .map_err(|e| Diagnostic::Internal(format!("the report is not UTF-8: {e}")))
}

/// Where the table of parts goes in the rendered page: text no section can hold (part names
/// are file names, which hold no NUL).
const PARTS_SLOT: &str = "\u{0}errmap-table-of-parts\u{0}";

/// A run's report ready to be written: the page before and after its table of parts, which
/// is written row by row, so a family of any size needs memory for its rows' figures only.
pub struct RunPage {
    /// The rendered page with [`PARTS_SLOT`] where the table goes.
    html: String,
    /// Where the slot starts in `html`.
    slot: usize,
    inline: bool,
}

impl RunPage {
    /// Everything of the page but the table of parts (job, family, toolpaths and, up to
    /// [`INLINE_PARTS`] parts, each part's section).
    pub fn new(input: &RunInput) -> Result<RunPage> {
        let s = input.summary;
        let mut page = Page {
            title: format!("errmap report — {}", s.family),
            lead: format!(
                "Part family {}: {} part(s), {} failed. Lengths in mm, errors in µm.",
                s.family,
                s.parts.len(),
                s.failed_parts
            ),
            sections: Vec::new(),
        };
        page.section("job", "Job", job_section(input));
        if let Some(f) = &s.family_map {
            page.section("family", "Family", family_section(input, f)?);
        }
        if !s.toolpaths.is_empty() {
            page.section("toolpaths", "Compensated toolpaths", toolpath_section(s));
        }
        let inline = s.parts.len() <= INLINE_PARTS;
        page.section("parts", "Parts", PARTS_SLOT.to_string());
        if inline {
            for p in &s.parts {
                page.section(
                    &format!("part-{}", p.part),
                    &format!("Part {}", p.part),
                    part_section(input, p)?,
                );
            }
        }
        let html = page.render();
        let slot = html
            .find(PARTS_SLOT)
            .ok_or_else(|| Diagnostic::Internal("the report lost its table of parts".into()))?;
        Ok(RunPage { html, slot, inline })
    }

    /// Write the page to `w`, the table of parts row by row.
    pub fn write(&self, input: &RunInput, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        w.write_all(&self.html.as_bytes()[..self.slot])?;
        parts_table(input, self.inline, w)?;
        w.write_all(&self.html.as_bytes()[self.slot + PARTS_SLOT.len()..])
    }
}

/// Whether a run of `parts` parts has a page per part (`<part>/report.html`).
pub fn has_part_pages(parts: usize) -> bool {
    parts > INLINE_PARTS
}

/// The page of one part (`<part>/report.html` of a large family): its figures, pictures and
/// rejected points, and the way back to the family's report.
pub fn render_part(input: &RunInput, p: &PartSummary) -> Result<String> {
    let back = format!(
        "<p><a href=\"../{REPORT_FILE}#parts\">← all parts of {}</a></p>\n",
        html::escape(&input.summary.family)
    );
    let mut page = Page {
        title: format!("errmap report — {} part {}", input.summary.family, p.part),
        lead: format!(
            "Part {} of family {}. Lengths in mm, errors in µm.",
            p.part, input.summary.family
        ),
        sections: Vec::new(),
    };
    page.section(
        &format!("part-{}", p.part),
        &format!("Part {}", p.part),
        back + &part_section(input, p)?,
    );
    Ok(page.render())
}

/// The columns of the table of parts: heading, anchor of the variant sorted by it, and the
/// figure (`None` sorts last).
type Column = (&'static str, &'static str, fn(&PartSummary) -> Option<f64>);

const SORT_COLUMNS: [Column; 7] = [
    ("points", "points", |p| Some(p.points as f64)),
    ("rejected", "rejected", |p| Some(p.rejected as f64)),
    ("hold-out RMSE (delivered), µm", "holdout", |p| {
        p.delivered_holdout_rmse_um
    }),
    ("benefit share", "benefit", |p| p.benefit_share),
    ("map RMS, µm", "rms", |p| p.rms_um),
    ("map PV, µm", "pv", |p| p.pv_um),
    ("u(E) max, µm", "umax", |p| p.u_max_um),
];

/// Where a part's details are: its section of this page, or its own page.
fn part_href(part: &str, inline: bool) -> String {
    if inline {
        format!("#{}", html::anchor(&format!("part-{part}")))
    } else {
        // Part names are safe folder names; a few characters still mean something in a URL.
        let path: String = part
            .chars()
            .map(|c| match c {
                '%' => "%25".to_string(),
                ' ' => "%20".to_string(),
                '#' => "%23".to_string(),
                '?' => "%3F".to_string(),
                c => c.to_string(),
            })
            .collect();
        format!("{path}/{REPORT_FILE}")
    }
}

/// One table of every part in `order`, its headings linking to the variants sorted by them,
/// written row by row.
fn parts_variant(
    s: &BatchSummary,
    order: &[usize],
    inline: bool,
    w: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    let mut t =
        String::from("<table class=\"parts\">\n<thead><tr><th><a href=\"#parts\">part</a></th>");
    for (title, id, _) in SORT_COLUMNS {
        t.push_str(&format!(
            "<th><a href=\"#parts-by-{id}\">{}</a></th>",
            html::escape(title)
        ));
    }
    t.push_str("<th>status</th></tr></thead>\n<tbody>\n");
    w.write_all(t.as_bytes())?;
    for &k in order {
        let p = &s.parts[k];
        let mut t = format!(
            "<tr><td><a href=\"{}\">{}</a></td>",
            html::escape(&part_href(&p.part, inline)),
            html::escape(&p.part)
        );
        for (i, (_, _, value)) in SORT_COLUMNS.iter().enumerate() {
            let digits = if i < 2 { 0 } else { 3 };
            let v = if p.ok { value(p) } else { None };
            t.push_str(&format!("<td class=\"num\">{}</td>", num(v, digits)));
        }
        let status = if p.ok { "mapped" } else { "FAILED" };
        t.push_str(&format!("<td>{status}</td></tr>\n"));
        w.write_all(t.as_bytes())?;
    }
    w.write_all(b"</tbody></table>\n")
}

/// The table of parts, sortable without a script (the report's policy allows none): one
/// variant per column, pre-sorted (largest first, failed parts last), shown when its heading's
/// link makes it the page's target; by name otherwise.
fn parts_table(input: &RunInput, inline: bool, w: &mut dyn std::io::Write) -> std::io::Result<()> {
    let s = input.summary;
    w.write_all(
        b"<style>.parts-sorted{display:none}.parts-sorted:target{display:block}\
.parts-sorted:target~.parts-default{display:none}table.parts td a{text-decoration:none}</style>\n",
    )?;
    w.write_all(
        para(
            "note",
            &format!(
                "{} part(s), {} failed. Click a column's heading to sort by it (largest first), \
the part heading for the order of the probe files; a part's name opens its {}.",
                s.parts.len(),
                s.failed_parts,
                if inline { "section below" } else { "own page" }
            ),
        )
        .as_bytes(),
    )?;
    for (title, id, value) in SORT_COLUMNS {
        let mut order: Vec<usize> = (0..s.parts.len()).collect();
        let key = |k: &usize| s.parts[*k].ok.then(|| value(&s.parts[*k])).flatten();
        // Largest first, unknown last, ties in batch order (a stable sort).
        order.sort_by(|a, b| match (key(a), key(b)) {
            (Some(x), Some(y)) => y.total_cmp(&x),
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (None, None) => std::cmp::Ordering::Equal,
        });
        w.write_all(
            format!(
                "<div id=\"parts-by-{id}\" class=\"parts-sorted\">\n<p class=\"note\">sorted by {}</p>\n",
                html::escape(title)
            )
            .as_bytes(),
        )?;
        parts_variant(s, &order, inline, w)?;
        w.write_all(b"</div>\n")?;
    }
    let order: Vec<usize> = (0..s.parts.len()).collect();
    w.write_all(b"<div class=\"parts-default\">\n")?;
    parts_variant(s, &order, inline, w)?;
    w.write_all(b"</div>\n")
}

fn kv(key: &str, value: impl Into<String>) -> Vec<Cell> {
    vec![Cell::text(key), Cell::text(value)]
}

fn job_section(input: &RunInput) -> String {
    let m = input.manifest;
    let s = input.summary;
    let mut rows = vec![
        kv("errmap version", &m.errmap_version),
        kv("run", &m.kind),
        kv(
            "job file",
            m.job
                .as_ref()
                .map_or("-".to_string(), |j| j.display().to_string()),
        ),
        vec![
            Cell::text("job hash (SHA-256)"),
            Cell::Raw(format!("<code>{}</code>", html::escape(&m.job_hash))),
        ],
        kv(
            "date (UTC, of the run)",
            m.created_utc
                .clone()
                .unwrap_or_else(|| "not recorded".into()),
        ),
        kv("backend", &m.backend),
        kv("error direction (normal)", format!("{:?}", s.normal)),
        kv("units", "coordinates mm, errors µm"),
        kv("map grid step", format!("{} mm", s.grid_step_mm)),
    ];
    if let Some(d) = s.domain_mm {
        rows.push(kv(
            "map domain [u_min, v_min, u_max, v_max]",
            format!("[{}, {}, {}, {}] mm", d[0], d[1], d[2], d[3]),
        ));
    }
    if let Some([i, n]) = m.shard {
        rows.push(kv("shard", format!("{i} of {n} (0-based)")));
    }
    let mut body = table(&["", ""], &rows);
    if !m.metadata.is_empty() {
        body.push_str("<h3>Machine and set-up (job [metadata])</h3>\n");
        let rows: Vec<Vec<Cell>> = m
            .metadata
            .iter()
            .map(|(k, v)| {
                let text = match v {
                    serde_json::Value::String(t) => t.clone(),
                    other => other.to_string(),
                };
                kv(k, text)
            })
            .collect();
        body.push_str(&table(&["key", "value"], &rows));
    }
    body.push_str("<h3>Inputs</h3>\n");
    let rows: Vec<Vec<Cell>> = m
        .inputs
        .iter()
        .map(|(f, h)| {
            vec![
                Cell::text(f.display().to_string()),
                Cell::Raw(format!("<code>{}</code>", html::escape(h))),
            ]
        })
        .collect();
    body.push_str(&table(&["file", "SHA-256"], &rows));
    body
}

/// A PNG of the run as a figure, or a note when it is missing.
fn picture(dir: &Path, rel: &str, caption: &str) -> Result<String> {
    let path = dir.join(rel);
    if !path.is_file() {
        return Ok(para("note", &format!("{rel}: not written")));
    }
    errmap_core::io::safety::protect(&path);
    let bytes = std::fs::read(&path).map_err(|e| Diagnostic::read(&path, e))?;
    Ok(png_figure(&bytes, rel, caption))
}

fn family_section(input: &RunInput, f: &super::summary::FamilySummary) -> Result<String> {
    let rows = vec![
        vec![
            Cell::text("parts in the family"),
            figure_cell("family.parts", Some(f.parts as f64), 0),
            Cell::text("parts whose maps were averaged"),
        ],
        vec![
            Cell::text("mean map RMS, µm"),
            figure_cell("family.mean_rms_um", Some(f.mean_rms_um), 2),
            Cell::text("RMS about 0 of the mean map over the grid nodes in the measured domain"),
        ],
        vec![
            Cell::text("mean map PV, µm"),
            figure_cell("family.mean_pv_um", Some(f.mean_pv_um), 2),
            Cell::text("peak-to-valley of the mean map over the same nodes"),
        ],
        vec![
            Cell::text("largest part-to-part spread, µm"),
            figure_cell("family.std_max_um", Some(f.std_max_um), 2),
            Cell::text("largest standard deviation of the parts' maps at one grid node"),
        ],
        vec![
            Cell::text("benefit share"),
            figure_cell("family.benefit_share", None, 3),
            Cell::text("unknown: the family map has no held-out points to judge it by"),
        ],
        vec![
            Cell::text("u(E) median, µm"),
            figure_cell("family.u_median_um", f.u_median_um, 3),
            Cell::text("median over the measured domain of √(std² + Σ u_i² / N²): the next part's spread and the parts' maps' own uncertainty"),
        ],
        vec![
            Cell::text("u(E) max, µm"),
            figure_cell("family.u_max_um", f.u_max_um, 3),
            Cell::text("the largest of the same"),
        ],
    ];
    let mut body = table(&["figure", "value", "definition"], &rows);
    body.push_str(&picture(
        input.dir,
        "family/mean.png",
        "Mean error map of the family (µm)",
    )?);
    body.push_str(&picture(
        input.dir,
        "family/std.png",
        "Part-to-part spread: standard deviation of the parts' maps at each node (µm)",
    )?);
    if input.dir.join("family/uncertainty.png").is_file() {
        body.push_str(&picture(
            input.dir,
            "family/uncertainty.png",
            "Standard uncertainty u(E) of the family map (µm)",
        )?);
    }
    body.push_str("<h3>Measured domain (convex hull of the probes)</h3>\n");
    body.push_str(&hull_block(input.dir, input.summary.domain_mm)?);
    Ok(body)
}

/// The family's measured hull (from `family/model.json`) as an inline SVG in the map domain,
/// with its vertices.
fn hull_block(dir: &Path, domain: Option<[f64; 4]>) -> Result<String> {
    let path = dir.join("family/model.json");
    if !path.is_file() {
        return Ok(para("note", "family/model.json: not written"));
    }
    let text = errmap_core::io::read_text(&path)?;
    let doc: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        Diagnostic::input(
            Location::file(&path),
            format!("not an errmap model: {e}"),
            "rerun the batch",
        )
    })?;
    let hull: Vec<[f64; 2]> = doc
        .get("hull_mm")
        .and_then(|h| serde_json::from_value(h.clone()).ok())
        .unwrap_or_default();
    if hull.is_empty() {
        return Ok(para("note", "no hull recorded"));
    }
    let [u0, v0, u1, v1] = domain.unwrap_or_else(|| {
        let (mut a, mut b, mut c, mut d) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for [u, v] in &hull {
            (a, b, c, d) = (a.min(*u), b.min(*v), c.max(*u), d.max(*v));
        }
        [a, b, c, d]
    });
    let (w, h) = ((u1 - u0).max(1e-9), (v1 - v0).max(1e-9));
    let scale = 600.0 / w.max(h);
    let (pw, ph) = (w * scale, h * scale);
    // SVG's y grows downwards; the map's v grows upwards.
    let pt = |[u, v]: [f64; 2]| format!("{:.2},{:.2}", (u - u0) * scale, (v1 - v) * scale);
    let points: Vec<String> = hull.iter().map(|p| pt(*p)).collect();
    let mut s = format!(
        "<figure><svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{pw:.0}\" height=\"{ph:.0}\" viewBox=\"-4 -4 {:.2} {:.2}\" role=\"img\">\
<rect x=\"0\" y=\"0\" width=\"{pw:.2}\" height=\"{ph:.2}\" fill=\"none\" stroke=\"#888\" stroke-dasharray=\"6 4\"/>\
<polygon points=\"{}\" fill=\"#cfe3f5\" fill-opacity=\"0.6\" stroke=\"#1f4e79\" stroke-width=\"2\"/></svg>\
<figcaption>Solid: the convex hull of the probes, where the maps interpolate; dashed: the map domain \
[{u0}, {v0}] – [{u1}, {v1}] mm (outside the hull the maps extrapolate).</figcaption></figure>\n",
        pw + 8.0,
        ph + 8.0,
        points.join(" ")
    );
    let rows: Vec<Vec<Cell>> = hull
        .iter()
        .map(|[u, v]| vec![Cell::Num(format!("{u}")), Cell::Num(format!("{v}"))])
        .collect();
    s.push_str(&table(&["u, mm", "v, mm"], &rows));
    Ok(s)
}

fn toolpath_section(s: &BatchSummary) -> String {
    let mut body = String::new();
    for t in &s.toolpaths {
        let name = last_components(&t.output, 2);
        body.push_str(&format!(
            "<h3>{} → {}</h3>\n",
            html::escape(&t.input.display().to_string()),
            html::escape(&name)
        ));
        body.push_str(&para("", &format!("compensated with the {} map", t.map)));
        if let Some(e) = &t.error {
            body.push_str(&para("failed", &format!("FAILED: {e}")));
        }
        if let Some(serde_json::Value::Object(r)) = &t.report {
            let rows: Vec<Vec<Cell>> = r
                .iter()
                .map(|(k, v)| vec![Cell::text(k), Cell::Num(json_text(v))])
                .collect();
            body.push_str(&table(&["compensation report", "value"], &rows));
        }
    }
    body
}

/// The last `n` components of a path, joined with `/` (a run's own file, wherever it lies).
fn last_components(p: &Path, n: usize) -> String {
    let parts: Vec<String> = p
        .components()
        .map(|c| c.as_os_str().to_string_lossy().to_string())
        .collect();
    parts[parts.len().saturating_sub(n)..].join("/")
}

/// The part's folder relative to the run: where the manifest lists its `summary.json`
/// (`shard-I-of-N/<part>/` in a merged run), else `<part>/`.
fn part_folder(m: &RunManifest, part: &str) -> String {
    let tail = format!("{part}/summary.json");
    m.parts
        .iter()
        .filter(|r| r.part == part)
        .flat_map(|r| r.outputs.keys())
        .find(|k| k.as_str() == tail || k.ends_with(&format!("/{tail}")))
        .map_or(format!("{part}/"), |k| {
            k[..k.len() - "summary.json".len()].to_string()
        })
}

fn part_section(input: &RunInput, p: &PartSummary) -> Result<String> {
    let mut body = para("", &format!("probe file {}", p.probe_file.display()));
    if !p.ok {
        let why = p
            .error
            .as_ref()
            .map_or("unknown error".to_string(), |e| e.to_string());
        body.push_str(&para("failed", &format!("FAILED: {why}")));
        return Ok(body);
    }
    let key = |k: &str| format!("{}.{k}", p.part);
    let f = |k: &str, label: &str, v: Option<f64>, d: usize, def: &str| {
        vec![
            Cell::text(label),
            figure_cell(&key(k), v, d),
            Cell::text(def),
        ]
    };
    let mut rows = vec![
        f("points", "probe points", Some(p.points as f64), 0, "points after averaging repeats"),
        f("repeats_averaged", "repeats averaged", Some(p.repeats_averaged as f64), 0, "rows that repeated another row's nominal point, averaged into it"),
        f("rejected", "rejected points", Some(p.rejected as f64), 0, "gross errors: leave-one-out residual beyond k·σ (listed below)"),
        f("sigma_um", "σ, µm", p.sigma_um, 3, "robust standard deviation (from the MAD) of the clean points' leave-one-out residuals"),
        f("holdout_points", "hold-out points", Some(p.holdout_points as f64), 0, "clean points held out of the first fit"),
        f("holdout_rmse_um", "hold-out RMSE (network), µm", p.holdout_rmse_um, 3, "RMS of held-out probe value − network fitted without them: the accuracy of the map"),
        f("kriging_holdout_rmse_um", "hold-out RMSE (kriging), µm", p.kriging_holdout_rmse_um, 3, "the same for the kriging baseline (Matérn 5/2 + nugget, maximum likelihood) on the same points"),
        f("holdout_e_rms_um", "hold-out E RMS, µm", p.holdout_e_rms_um, 3, "RMS about 0 of E at the held-out points: what compensation there has to remove"),
        f("delivered_holdout_rmse_um", "hold-out RMSE (delivered, nested), µm", p.delivered_holdout_rmse_um, 3, "each held-out point judged by the kind (network or kriging) the other held-out points chose: the honest accuracy of the map delivered"),
        f("benefit_share", "benefit share", p.benefit_share, 3, "1 − (delivered map's hold-out RMSE) / (hold-out E RMS): the share of E the map removes; below 0.10 compensate refuses the map"),
        f("u_median_um", "u(E) median, µm", p.u_median_um, 3, "median standard uncertainty of the map over the grid nodes in the measured domain (map.csv's u_um)"),
        f("u_max_um", "u(E) max, µm", p.u_max_um, 3, "largest u(E) there; |E_true − E_map| ≤ 2u at about 95 % of the nodes"),
        f("u_factor", "u calibration factor", p.u_factor, 3, "c in u = c·max(σ_K, |E_map − E_K|), fitted on 10 cross-validation folds of the probe points"),
        f("noise_um", "probe noise s, µm", p.noise_um, 3, "the noise the kriging's nugget stands for: left-out points lie within 2·√(u² + s²) of the map"),
        f("rms_um", "map RMS, µm", p.rms_um, 2, "RMS about 0 of the map over the grid nodes in the measured domain (the probes' hull)"),
        f("pv_um", "map PV, µm", p.pv_um, 2, "peak-to-valley of the map over the same nodes"),
    ];
    if p.extrapolated_fraction.is_some() {
        rows.push(f(
            "extrapolated_fraction",
            "extrapolated share of nodes",
            p.extrapolated_fraction,
            3,
            "grid nodes outside the measured domain, where the map extrapolates",
        ));
        rows.push(f(
            "rms_extrapolated_um",
            "RMS of extrapolated nodes, µm",
            p.rms_extrapolated_um,
            2,
            "not an accuracy figure",
        ));
        rows.push(f(
            "pv_extrapolated_um",
            "PV of extrapolated nodes, µm",
            p.pv_extrapolated_um,
            2,
            "not an accuracy figure",
        ));
    }
    body.push_str(&table(&["figure", "value", "definition"], &rows));
    if let Some(b) = &p.better_fit {
        body.push_str(&para("note", &format!("lower hold-out RMSE: {b}")));
    }
    let folder = part_folder(input.manifest, &p.part);
    body.push_str(&picture(
        input.dir,
        &format!("{folder}map.png"),
        &format!("Error map of part {} (µm)", p.part),
    )?);
    if input.dir.join(format!("{folder}uncertainty.png")).is_file() {
        body.push_str(&picture(
            input.dir,
            &format!("{folder}uncertainty.png"),
            &format!(
                "Standard uncertainty u(E) of the map of part {} (µm)",
                p.part
            ),
        )?);
    }
    body.push_str("<h3>Rejected points</h3>\n");
    body.push_str(&rejected_block(input, p, &folder)?);
    Ok(body)
}

fn rejected_block(input: &RunInput, p: &PartSummary, folder: &str) -> Result<String> {
    let path = input.dir.join(format!("{folder}rejected.csv"));
    if !path.is_file() {
        return Ok(para("note", "rejected.csv: not written"));
    }
    let t = errmap_core::io::CsvTable::read(&path)?;
    let cols = ["x_mm", "y_mm", "z_mm", "residual_um"]
        .map(|c| t.require(c))
        .into_iter()
        .collect::<Result<Vec<usize>>>()?;
    let limit = match (input.manifest.k_sigma, p.sigma_um) {
        (Some(k), Some(s)) => Some((k, s)),
        _ => None,
    };
    let mut rows = Vec::new();
    for row in &t.rows {
        let r = t.f64(row, cols[3])?;
        let reason = match limit {
            Some((k, s)) => format!(
                "leave-one-out residual {r:.2} µm: |r| > k·σ = {k}·{s:.3} = {:.3} µm",
                k * s
            ),
            None => format!("leave-one-out residual {r:.2} µm beyond k·σ"),
        };
        let mut cells: Vec<Cell> = cols[..3]
            .iter()
            .map(|&c| Cell::Num(t.text(row, c).to_string()))
            .collect();
        cells.push(Cell::Num(num(Some(r), 3)));
        cells.push(Cell::text(reason));
        rows.push(cells);
    }
    Ok(table(
        &["x, mm", "y, mm", "z, mm", "residual, µm", "reason"],
        &rows,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// A run folder with one mapped part whose name needs escaping, one failed part, the
    /// family and a toolpath.
    fn fake_run(dir: &Path) -> (RunManifest, BatchSummary) {
        let part = "p<1>&";
        std::fs::create_dir_all(dir.join(part)).unwrap();
        std::fs::create_dir_all(dir.join("family")).unwrap();
        for f in [
            format!("{part}/map.png"),
            "family/mean.png".into(),
            "family/std.png".into(),
        ] {
            std::fs::write(dir.join(f), b"\x89PNG fake").unwrap();
        }
        std::fs::write(
            dir.join(part).join("rejected.csv"),
            "x_mm,y_mm,z_mm,residual_um\n125,70.5,5.05,39.5\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("family/model.json"),
            r#"{"hull_mm": [[25.0, 25.0], [575.0, 25.0], [575.0, 275.0]]}"#,
        )
        .unwrap();
        let summary: BatchSummary = serde_json::from_value(json!({
            "family": "web<plate>", "job": "job.toml", "backend": "cpu", "normal": "z",
            "shard": null, "domain_mm": [10.0, 10.0, 590.0, 290.0], "grid_step_mm": 5.0,
            "parts": [
                {"part": part, "probe_file": "probes/p<1>&.csv", "ok": true, "points": 144,
                 "repeats_averaged": 2, "rejected": 1, "sigma_um": 1.25, "holdout_points": 14,
                 "holdout_rmse_um": 1.19, "kriging_holdout_rmse_um": 1.2, "better_fit": "network",
                 "holdout_e_rms_um": 14.2, "benefit_share": 0.916,
                 "rms_um": 16.6, "pv_um": 30.7, "output_dir": null, "error": null},
                {"part": "bad", "probe_file": "probes/bad.csv", "ok": false, "points": 0,
                 "repeats_averaged": 0, "rejected": 0, "sigma_um": null, "holdout_points": 0,
                 "holdout_rmse_um": null, "rms_um": null, "pv_um": null, "output_dir": null,
                 "error": {"kind": "input", "message": "no <points>", "file": null, "line": null,
                           "column": null, "hint": null}}
            ],
            "failed_parts": 1,
            "family_map": {"parts": 1, "output_dir": "family", "mean_rms_um": 17.5,
                           "mean_pv_um": 31.0, "std_max_um": 2.5},
            "toolpaths": [{"input": "finish.ngc", "output": "/x/family/finish-compensated.ngc",
                           "map": "family", "report": {"moves_changed": 34}, "error": null}]
        }))
        .unwrap();
        let manifest: RunManifest = serde_json::from_value(json!({
            "format": "errmap-run/1", "errmap_version": "0.1.0", "kind": "batch",
            "job": "job.toml", "job_hash": "abc", "shard": null, "backend": "cpu",
            "inputs": {"probes/p<1>&.csv": "1234"},
            "parts": [{"part": part, "probe_file": "probes/p<1>&.csv", "input_sha256": "1234",
                       "ok": true, "reused": false,
                       "outputs": {"p<1>&/summary.json": "00", "p<1>&/map.png": "01"}}],
            "files": {}, "shards": {}, "created_utc": "2026-11-23T16:11:05Z",
            "metadata": {"machine": "DMU <50>", "spindle_temp_c": 21.5}, "k_sigma": 3.0
        }))
        .unwrap();
        (manifest, summary)
    }

    #[test]
    fn every_section_is_present_and_every_text_escaped() {
        let tmp = tempfile::tempdir().unwrap();
        let (manifest, summary) = fake_run(tmp.path());
        let html = render_run(&RunInput {
            dir: tmp.path(),
            manifest: &manifest,
            summary: &summary,
        })
        .unwrap();
        for id in ["job", "family", "toolpaths", "part-p-1--", "part-bad"] {
            assert!(html.contains(&format!("<section id=\"{id}\">")), "{id}");
        }
        // Job metadata: date from run.json, metadata, inputs, escaped.
        assert!(html.contains("2026-11-23T16:11:05Z"));
        assert!(html.contains("DMU &lt;50&gt;") && html.contains("21.5"));
        assert!(html.contains("probes/p&lt;1&gt;&amp;.csv"));
        assert!(!html.contains("<1>") && !html.contains("<plate>") && !html.contains("<points>"));
        // Three pictures (the fake PNG bytes, base64) and the hull drawn.
        assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 3);
        assert!(html.contains("<polygon points=\""));
        // Figures with exact values; the rejected point with its reason (k·σ = 3·1.25).
        assert!(
            html.contains("data-figure=\"p&lt;1&gt;&amp;.holdout_rmse_um\" data-value=\"1.19\"")
        );
        assert!(html.contains("data-figure=\"family.std_max_um\" data-value=\"2.5\""));
        // The benefit: the part's share as given; the family's stated unknown, not invented.
        assert!(html.contains("data-figure=\"p&lt;1&gt;&amp;.benefit_share\" data-value=\"0.916\""));
        assert!(!html.contains("data-figure=\"family.benefit_share\" data-value"));
        assert!(html.contains("unknown: the family map has no held-out points"));
        assert!(html.contains("|r| &gt; k·σ = 3·1.250 = 3.750 µm"), "{html}");
        assert!(html.contains("moves_changed") && html.contains("family/finish-compensated.ngc"));
        assert!(html.contains("FAILED: no &lt;points&gt;"));
        // No network: nothing but data: URIs and in-page anchors.
        assert!(!html.contains("http://") || html.matches("http://").count() == 1);
        assert!(!html.contains("https://") && !html.contains("<script"));
    }

    #[test]
    fn a_family_of_1000_parts_gets_an_overview_and_a_page_per_part() {
        // 1000 synthetic summary rows: part k has map RMS k/10 µm, every 100th failed.
        let tmp = tempfile::tempdir().unwrap();
        let (manifest, mut summary) = fake_run(tmp.path());
        let template = summary.parts[0].clone();
        let failed = summary.parts[1].clone();
        summary.parts = (0..1000)
            .map(|k| {
                let mut p = if k % 100 == 99 {
                    failed.clone()
                } else {
                    template.clone()
                };
                p.part = format!("p{k:04}");
                if p.ok {
                    p.rms_um = Some(k as f64 / 10.0);
                }
                p
            })
            .collect();
        summary.failed_parts = 10;
        let input = RunInput {
            dir: tmp.path(),
            manifest: &manifest,
            summary: &summary,
        };
        let html = render_run(&input).unwrap();
        // No part's pictures or sections on the overview: the family's two pictures only.
        assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 2);
        assert!(!html.contains("<section id=\"part-"));
        assert!(html.len() < 4_000_000, "{} bytes", html.len());
        // Eight tables of every part (seven sorted, one by name), each row a link to its page.
        assert_eq!(html.matches("<table class=\"parts\">").count(), 8);
        assert_eq!(html.matches("<tr><td><a href=\"p").count(), 8000);
        assert_eq!(html.matches("href=\"p0042/report.html\"").count(), 8);
        // Sorted by RMS: largest first (p0998, as p0999 failed), failed parts last.
        let by_rms = &html[html.find("id=\"parts-by-rms\"").unwrap()..];
        let by_rms = &by_rms[..by_rms.find("</div>").unwrap()];
        let rows: Vec<&str> = by_rms
            .split("<tr><td><a href=\"")
            .skip(1)
            .map(|r| &r[..5])
            .collect();
        assert_eq!(rows[..3], ["p0998", "p0997", "p0996"]);
        assert_eq!(rows[989], "p0000");
        assert_eq!(
            rows[990..],
            [
                "p0099", "p0199", "p0299", "p0399", "p0499", "p0599", "p0699", "p0799", "p0899",
                "p0999"
            ]
        );
        // The default (by name) variant comes last, so a sorted one hides it when targeted.
        let default_at = html.find("class=\"parts-default\"").unwrap();
        assert!(html.rfind("class=\"parts-sorted\"").unwrap() < default_at);
        // A part's own page: its figures and the way back.
        let page = render_part(&input, &summary.parts[42]).unwrap();
        assert!(page.contains("href=\"../report.html#parts\""));
        assert!(page.contains("data-figure=\"p0042.rms_um\" data-value=\"4.2\""));
        assert!(!page.contains("<script"));
        // Up to INLINE_PARTS parts the sections stay on the one page, linked by anchor.
        summary.parts.truncate(INLINE_PARTS);
        let input = RunInput {
            dir: tmp.path(),
            manifest: &manifest,
            summary: &summary,
        };
        let html = render_run(&input).unwrap();
        assert_eq!(html.matches("<section id=\"part-").count(), INLINE_PARTS);
        assert!(html.contains("href=\"#part-p0042\""));
    }
}
