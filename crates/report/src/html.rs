//! A self-contained HTML page: escaping, tables, figures marked with `data-` attributes, PNGs as `data:` URIs, inline CSS with print rules and a strict Content-Security-Policy.
//!
//! Nothing here loads from the network: the only policy the page allows is inline style and
//! `data:` images, so a report opened offline (or mailed) shows exactly what it holds.

use base64::Engine as _;

/// The page's Content-Security-Policy: no script, no request, images only from `data:`.
pub const CSP: &str = "default-src 'none'; img-src data:; style-src 'unsafe-inline'";

/// Screen and print rules: one section per printed page, tables and figures unbroken.
const CSS: &str = "
body{font-family:'DejaVu Sans',Arial,Helvetica,sans-serif;color:#111;margin:2em auto;max-width:60em;padding:0 1em;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{font-size:1.3em;border-bottom:2px solid #333;padding-bottom:.2em;margin-top:2em}
h3,h4,h5{font-size:1.05em;margin-top:1.4em}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
th,td{border:1px solid #999;padding:.2em .5em;text-align:left;vertical-align:top}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
th{background:#eee}
code,pre{font-family:'DejaVu Sans Mono',monospace;font-size:.85em}
pre{background:#f6f6f6;border:1px solid #ccc;padding:.5em;overflow-x:auto;white-space:pre-wrap}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #ccc}
figcaption{font-size:.85em;color:#444}
.note{color:#444;font-size:.9em}
.failed{color:#a00;font-weight:bold}
nav ul{columns:2}
@media print{body{margin:0;max-width:none}section{break-before:page}section:first-of-type{break-before:auto}
nav{display:none}table,figure,pre{break-inside:avoid}a{color:inherit;text-decoration:none}}
";

/// Escape text for HTML element content and double-quoted attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// A number for a table cell: `digits` decimals, `n/a` for none or a non-finite value.
pub fn num(value: Option<f64>, digits: usize) -> String {
    match value {
        Some(v) if v.is_finite() => format!("{v:.digits$}"),
        _ => "n/a".to_string(),
    }
}

/// One table cell: escaped text, or a number (right-aligned).
#[derive(Debug, Clone)]
pub enum Cell {
    /// Text, escaped when rendered, left-aligned.
    Text(String),
    /// A number already formatted (as by [`num`]), escaped, right-aligned in tabular figures.
    Num(String),
    /// Already-escaped HTML (a `<code>` span, a figure with its `data-` attributes).
    Raw(String),
}

impl Cell {
    /// A text cell.
    pub fn text(t: impl Into<String>) -> Cell {
        Cell::Text(t.into())
    }

    fn render(&self) -> String {
        match self {
            Cell::Text(t) => format!("<td>{}</td>", escape(t)),
            Cell::Num(t) => format!("<td class=\"num\">{}</td>", escape(t)),
            Cell::Raw(h) => format!("<td>{h}</td>"),
        }
    }
}

/// A table with a header row; empty tables render as a note.
pub fn table(headers: &[&str], rows: &[Vec<Cell>]) -> String {
    if rows.is_empty() {
        return "<p class=\"note\">none</p>\n".to_string();
    }
    let mut s = String::from("<table>\n");
    if headers.iter().any(|h| !h.is_empty()) {
        s.push_str("<thead><tr>");
        for h in headers {
            s.push_str(&format!("<th>{}</th>", escape(h)));
        }
        s.push_str("</tr></thead>\n");
    }
    s.push_str("<tbody>\n");
    for row in rows {
        s.push_str("<tr>");
        for c in row {
            s.push_str(&c.render());
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table>\n");
    s
}

/// A figure's value as a cell carrying its exact value for machines:
/// `<span data-figure="KEY" data-value="…">shown</span>` (`data-value` is absent for none).
pub fn figure_cell(key: &str, value: Option<f64>, digits: usize) -> Cell {
    let exact = match value {
        Some(v) if v.is_finite() => format!(" data-value=\"{}\"", v),
        _ => String::new(),
    };
    Cell::Raw(format!(
        "<span class=\"num\" data-figure=\"{}\"{exact}>{}</span>",
        escape(key),
        escape(&num(value, digits))
    ))
}

/// A PNG as an `<img>` with a `data:` URI, in a figure with a caption.
pub fn png_figure(png: &[u8], alt: &str, caption: &str) -> String {
    let b64 = base64::engine::general_purpose::STANDARD.encode(png);
    format!(
        "<figure><img src=\"data:image/png;base64,{b64}\" alt=\"{}\"><figcaption>{}</figcaption></figure>\n",
        escape(alt),
        escape(caption)
    )
}

/// Preformatted text (a controller table, a report).
pub fn pre(text: &str) -> String {
    format!("<pre>{}</pre>\n", escape(text))
}

/// A paragraph of escaped text with a CSS class (`note`, `failed`, or empty).
pub fn para(class: &str, text: &str) -> String {
    if class.is_empty() {
        format!("<p>{}</p>\n", escape(text))
    } else {
        format!("<p class=\"{class}\">{}</p>\n", escape(text))
    }
}

/// One section of the page: an anchor, a heading, and its HTML body.
#[derive(Debug, Clone)]
pub struct Section {
    /// Anchor id (made safe here).
    pub id: String,
    /// Heading of the section and its entry in the contents list (escaped when rendered).
    pub title: String,
    /// The section's content as HTML, inserted as it stands (build it from this module's
    /// escaping helpers).
    pub body: String,
}

/// The whole page: title, a lead paragraph, sections. Rendered byte-for-byte the same for the
/// same content.
#[derive(Debug, Clone, Default)]
pub struct Page {
    /// The document's `<title>` and top heading (escaped when rendered).
    pub title: String,
    /// A note paragraph under the heading (escaped); empty for none.
    pub lead: String,
    /// The sections in page order, each listed in the contents.
    pub sections: Vec<Section>,
}

/// An anchor id from any text: letters, digits, `-` and `_` kept, the rest `-`.
pub fn anchor(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

impl Page {
    /// Append a section; `id` is turned into a safe anchor ([`anchor`]).
    pub fn section(&mut self, id: &str, title: &str, body: String) {
        self.sections.push(Section {
            id: anchor(id),
            title: title.to_string(),
            body,
        });
    }

    /// The HTML document: CSP and charset first, inline CSS, a contents list, the sections.
    pub fn render(&self) -> String {
        let mut s = String::new();
        s.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
        s.push_str(&format!(
            "<meta http-equiv=\"Content-Security-Policy\" content=\"{CSP}\">\n"
        ));
        s.push_str("<meta name=\"generator\" content=\"errmap\">\n");
        s.push_str(&format!("<title>{}</title>\n", escape(&self.title)));
        s.push_str(&format!("<style>{CSS}</style>\n</head>\n<body>\n"));
        s.push_str(&format!("<h1>{}</h1>\n", escape(&self.title)));
        if !self.lead.is_empty() {
            s.push_str(&para("note", &self.lead));
        }
        s.push_str("<nav><ul>\n");
        for sec in &self.sections {
            s.push_str(&format!(
                "<li><a href=\"#{}\">{}</a></li>\n",
                sec.id,
                escape(&sec.title)
            ));
        }
        s.push_str("</ul></nav>\n");
        for sec in &self.sections {
            s.push_str(&format!(
                "<section id=\"{}\">\n<h2>{}</h2>\n{}</section>\n",
                sec.id,
                escape(&sec.title),
                sec.body
            ));
        }
        s.push_str("</body>\n</html>\n");
        s
    }
}

/// A JSON value as table text: strings bare, numbers and arrays as JSON.
pub fn json_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::String(t) => t.clone(),
        serde_json::Value::Null => "-".into(),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_escaped_everywhere_it_lands() {
        assert_eq!(
            escape(r#"<b>"a" & 'b'</b>"#),
            "&lt;b&gt;&quot;a&quot; &amp; &#39;b&#39;&lt;/b&gt;"
        );
        let mut page = Page {
            title: "<script>x</script>".into(),
            lead: "a&b".into(),
            sections: Vec::new(),
        };
        page.section(
            "p\"1",
            "<img src=x onerror=alert(1)>",
            table(
                &["<h>"],
                &[vec![Cell::text("<td>"), Cell::Num("1<2".into())]],
            ),
        );
        let html = page.render();
        assert!(!html.contains("<script>"), "{html}");
        assert!(!html.contains("<img src=x"), "{html}");
        assert!(!html.contains("<td><td>"), "{html}");
        assert!(html.contains("&lt;script&gt;x&lt;/script&gt;"));
        assert!(html.contains("id=\"p-1\""), "{html}");
        assert!(html.contains("<td class=\"num\">1&lt;2</td>"));
        assert!(html.contains(&format!("content=\"{CSP}\"")));
    }

    #[test]
    fn figures_carry_their_exact_value_and_pngs_are_base64() {
        let c = figure_cell("p01.holdout_rmse_um", Some(1.194134220034155), 2);
        let Cell::Raw(h) = c else { panic!() };
        assert!(h.contains("data-figure=\"p01.holdout_rmse_um\""), "{h}");
        assert!(h.contains("data-value=\"1.194134220034155\""), "{h}");
        assert!(h.contains(">1.19<"), "{h}");
        let Cell::Raw(h) = figure_cell("x", None, 2) else {
            panic!()
        };
        assert!(!h.contains("data-value") && h.contains("n/a"), "{h}");
        // RFC 4648 test vector: "foobar" → "Zm9vYmFy".
        let f = png_figure(b"foobar", "a\"b", "c");
        assert!(f.contains("src=\"data:image/png;base64,Zm9vYmFy\""), "{f}");
        assert!(f.contains("alt=\"a&quot;b\""), "{f}");
    }
}
