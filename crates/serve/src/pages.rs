//! The monitor's HTML pages: login, live, history, a campaign, a runs folder. Every value is escaped; no inline script or style (the style sheet and the live page's script are files of this server).

use super::svg::escape;
use super::users::Role;
use std::fmt::Write as _;

/// Who is looking, for the page header and the operator's forms.
pub struct Viewer<'a> {
    /// The logged-in user's name, shown in the header (escaped).
    pub user: &'a str,
    /// The user's role now: the operator's forms are drawn only for [`Role::Operator`] (the
    /// server checks the role again when a command arrives).
    pub role: Role,
    /// The session's CSRF token, put in every form that changes state.
    pub csrf: &'a str,
}

fn head(title: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{} — errmap</title><link rel=\"stylesheet\" href=\"/static/app.css\"></head>",
        escape(title)
    )
}

/// A page with the navigation header.
pub fn page(title: &str, here: &str, who: &Viewer, main_id: &str, body: &str) -> String {
    let mut s = head(title);
    s.push_str("<body><header><strong>errmap</strong>");
    for (href, name) in [
        ("/live", "Live"),
        ("/history", "History"),
        ("/runs/", "Runs"),
    ] {
        let class = if href.trim_end_matches('/') == here {
            " class=\"here\""
        } else {
            ""
        };
        let _ = write!(s, "<a href=\"{href}\"{class}>{name}</a>");
    }
    let _ = write!(
        s,
        "<span class=\"who\">{} ({}) <form method=\"post\" action=\"/logout\"><input type=\"hidden\" name=\"csrf\" value=\"{}\"><button type=\"submit\">Log out</button></form></span></header>",
        escape(who.user),
        who.role.as_str(),
        escape(who.csrf)
    );
    let _ = write!(
        s,
        "<main id=\"{main_id}\"><h1>{}</h1>{body}</main></body></html>",
        escape(title)
    );
    s
}

/// The login form; `message` after a failed attempt.
pub fn login(form_token: &str, message: Option<&str>) -> String {
    let mut s = head("Log in");
    s.push_str("<body><main><form class=\"login\" method=\"post\" action=\"/login\"><h1>errmap monitor</h1>");
    if let Some(m) = message {
        let _ = write!(s, "<p class=\"error\" id=\"login-error\">{}</p>", escape(m));
    }
    let _ = write!(
        s,
        "<input type=\"hidden\" name=\"csrf\" value=\"{}\"><label>User <input name=\"user\" autocomplete=\"username\" required maxlength=\"64\"></label><label>Password <input name=\"password\" type=\"password\" autocomplete=\"current-password\" required maxlength=\"1024\"></label><button type=\"submit\">Log in</button></form></main></body></html>",
        escape(form_token)
    );
    s
}

/// A page for an error status with a short reason.
pub fn error(title: &str, text: &str) -> String {
    format!(
        "{}<body><main><h1>{}</h1><p>{}</p><p><a href=\"/live\">Back</a></p></main></body></html>\n",
        head(title),
        escape(title),
        escape(text)
    )
}

/// The live page: the skeleton the live script fills from /api/live.
pub fn live(who: &Viewer) -> String {
    let mut b = String::new();
    b.push_str("<p class=\"problem\" id=\"problem\" hidden></p><noscript><p class=\"problem\">This page shows the live state with a script of this server; without it, read <a href=\"/api/state\">/api/state</a>.</p></noscript>");
    if who.role == Role::Operator {
        let _ = write!(
            b,
            "<form id=\"controls\" method=\"post\" action=\"/live/command\"><input type=\"hidden\" name=\"csrf\" value=\"{}\"><button type=\"submit\" name=\"command\" value=\"pause\">Pause (hold values)</button> <button type=\"submit\" name=\"command\" value=\"resume\">Resume</button></form>",
            escape(who.csrf)
        );
    }
    b.push_str("<dl><dt>connection</dt><dd id=\"connection\">connecting…</dd><dt>mode</dt><dd id=\"mode\">waiting for the live state…</dd><dt>cycle</dt><dd id=\"cycle\">—</dd><dt>written</dt><dd id=\"written\">—</dd><dt>period</dt><dd id=\"period\">—</dd><dt>dry run</dt><dd id=\"dry-run\">—</dd><dt>coolant</dt><dd id=\"coolant\">—</dd></dl>");
    let table = |id: &str, title: &str, cols: &[&str]| {
        let mut t = format!("<h2>{title}</h2><table id=\"{id}\"><thead><tr>");
        for c in cols {
            let _ = write!(t, "<th>{c}</th>");
        }
        t.push_str("</tr></thead><tbody></tbody></table>");
        t
    };
    b.push_str(&table(
        "sensors",
        "Temperatures",
        &["sensor", "°C", "state", "source", "age (ms)", "problem"],
    ));
    b.push_str(&table(
        "axes",
        "Compensation",
        &[
            "axis",
            "position (mm)",
            "direction",
            "computed (µm)",
            "written (µm)",
            "limit (µm)",
            "rate limit (µm/s)",
            "target",
            "held",
        ],
    ));
    b.push_str(&table(
        "sources",
        "Sources",
        &["source", "kind", "health", "last good (UTC)", "problem"],
    ));
    b.push_str(&table(
        "alarms",
        "Alarms",
        &["id", "raised (UTC)", "source", "message", "state", ""],
    ));
    b.push_str("<script src=\"/static/live.js\"></script>");
    page("Live", "/live", who, "live", &b)
}

/// A table of rows of text cells.
pub fn table(id: &str, header: &[&str], rows: &[Vec<String>]) -> String {
    let mut t = format!("<table id=\"{id}\"><thead><tr>");
    for h in header {
        let _ = write!(t, "<th>{}</th>", escape(h));
    }
    t.push_str("</tr></thead><tbody>");
    for r in rows {
        t.push_str("<tr>");
        for c in r {
            let _ = write!(t, "<td>{}</td>", escape(c));
        }
        t.push_str("</tr>");
    }
    t.push_str("</tbody></table>");
    t
}

/// Percent-encode a path segment or query value (everything but unreserved characters).
pub fn url_encode(text: &str) -> String {
    let mut out = String::new();
    for b in text.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// A runs folder's listing: `rel` is its path under the runs root ("" for the root).
pub fn runs_listing(who: &Viewer, rel: &str, entries: &[(String, bool)]) -> String {
    let base: String = rel
        .split('/')
        .filter(|p| !p.is_empty())
        .map(|p| format!("{}/", url_encode(p)))
        .collect();
    let mut b = String::new();
    if !rel.is_empty() {
        b.push_str("<p><a href=\"../\">up</a></p>");
    }
    if entries.is_empty() {
        b.push_str("<p>This folder is empty.</p>");
    }
    b.push_str("<ul id=\"entries\">");
    for (name, is_dir) in entries {
        let slash = if *is_dir { "/" } else { "" };
        let _ = write!(
            b,
            "<li><a href=\"/runs/{base}{}{slash}\">{}{slash}</a></li>",
            url_encode(name),
            escape(name)
        );
    }
    b.push_str("</ul>");
    let title = if rel.is_empty() {
        "Runs".to_string()
    } else {
        format!("Runs: {rel}")
    };
    page(&title, "/runs", who, "runs", &b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_escaped_and_pages_have_no_inline_script_or_style() {
        let who = Viewer {
            user: "<b>x</b>",
            role: Role::Operator,
            csrf: "t\"k",
        };
        let p = live(&who);
        assert!(p.contains("&lt;b&gt;x&lt;/b&gt;") && p.contains("t&quot;k"));
        assert!(!p.contains("style=") && !p.contains("<style"));
        assert_eq!(p.matches("<script").count(), 1);
        assert!(p.contains("<script src=\"/static/live.js\"></script>"));
        let l = login("tok", Some("<wrong>"));
        assert!(l.contains("&lt;wrong&gt;") && !l.contains("<script"));
        let viewer = Viewer {
            user: "v",
            role: Role::Viewer,
            csrf: "c",
        };
        assert!(!live(&viewer).contains("id=\"controls\""));
        assert_eq!(url_encode("a b/ü"), "a%20b%2F%C3%BC");
    }
}
