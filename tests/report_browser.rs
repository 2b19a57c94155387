//! report.html in a real browser: the sample job's report opened by headless Chromium over the DevTools protocol (every image decoded, no console error, no request outside the file, the figures equal summary.json, printed to PDF), and `errmap report`'s refusals.
//!
//! The browser is driven as tests/devtools says; without one the browser tests are skipped
//! (and say so), unless `ERRMAP_REQUIRE_BROWSER=1`, as in CI, which makes them fail.

mod common;
mod devtools;

use base64::Engine as _;
use devtools::{browser_or_skip, DevTools};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

/// The sample job run once for the whole file: (its folder, the repository root).
fn sample_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let tmp = tempfile::tempdir().unwrap().keep();
        let out = tmp.join("run");
        common::ok(
            root,
            &[
                "batch",
                "data/web-plate/job.toml",
                "--out",
                out.to_str().unwrap(),
                "-q",
            ],
        );
        out
    })
}

fn file_url(path: &Path) -> String {
    let abs = path.canonicalize().unwrap();
    let mut url = String::from("file://");
    for b in abs.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            url.push(b as char);
        } else {
            url.push_str(&format!("%{b:02X}"));
        }
    }
    url
}

/// What the page says about itself, read in the page by DevTools (the page has no script).
const PROBE: &str = r#"JSON.stringify({
  images: Array.from(document.images).map(i => ({alt: i.alt, complete: i.complete, width: i.naturalWidth})),
  svgs: document.querySelectorAll('svg polygon').length,
  sections: Array.from(document.querySelectorAll('section')).map(s => ({id: s.id, text: s.innerText.length})),
  figures: Array.from(document.querySelectorAll('[data-figure]')).map(e => [e.dataset.figure, e.dataset.value === undefined ? null : Number(e.dataset.value)]),
  scripts: document.scripts.length
})"#;

#[test]
fn the_sample_report_opens_in_chromium_complete_and_equal_to_the_summary() {
    let Some(chrome) = browser_or_skip("report_browser") else {
        return;
    };
    let run = sample_run();
    let report = run.join("report.html");
    let url = file_url(&report);
    let mut dt = DevTools::start(&chrome);
    let target = dt.call(None, "Target.createTarget", json!({"url": "about:blank"}));
    let attached = dt.call(
        None,
        "Target.attachToTarget",
        json!({"targetId": target["targetId"], "flatten": true}),
    );
    let session = attached["sessionId"].as_str().unwrap().to_string();
    let s = Some(session.as_str());
    for domain in [
        "Page.enable",
        "Runtime.enable",
        "Log.enable",
        "Network.enable",
    ] {
        dt.call(s, domain, json!({}));
    }
    dt.call(s, "Page.navigate", json!({"url": url}));
    dt.wait_for("Page.loadEventFired");
    let probe = dt.call(
        s,
        "Runtime.evaluate",
        json!({"expression": PROBE, "returnByValue": true}),
    );
    let page: Value = serde_json::from_str(probe["result"]["value"].as_str().unwrap()).unwrap();
    // The table of parts sorts without a script: following a column heading's link shows the
    // variant sorted by that column, largest first; the part heading's shows the file order.
    let shown = |dt: &mut DevTools, hash: &str| -> Vec<String> {
        let expr = format!(
            "location.hash = '{hash}'; JSON.stringify(Array.from(document.querySelectorAll('table.parts'))\
             .filter(t => t.offsetParent !== null)\
             .map(t => Array.from(t.tBodies[0].rows).map(r => r.cells[0].innerText)))"
        );
        let r = dt.call(
            s,
            "Runtime.evaluate",
            json!({"expression": expr, "returnByValue": true}),
        );
        let tables: Vec<Vec<String>> =
            serde_json::from_str(r["result"]["value"].as_str().unwrap()).unwrap();
        assert_eq!(
            tables.len(),
            1,
            "one table of parts visible at {hash}: {tables:?}"
        );
        tables.into_iter().next().unwrap()
    };
    let by_rms = shown(&mut dt, "#parts-by-rms");
    let by_name = shown(&mut dt, "#parts");
    let pdf = dt.call(s, "Page.printToPDF", json!({"printBackground": true}));
    dt.drain(Duration::from_millis(500));

    // Every image decoded: the family's mean, std and u(E) maps, and a map and a u(E) map per part.
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap();
    let parts = summary["parts"].as_array().unwrap();
    let images = page["images"].as_array().unwrap();
    assert_eq!(images.len(), 3 + 2 * parts.len(), "{page}");
    for img in images {
        assert!(
            img["complete"] == true && img["width"].as_u64().unwrap() > 0,
            "image not decoded: {img}"
        );
    }
    assert_eq!(page["svgs"], 1, "the family hull is drawn");
    assert_eq!(page["scripts"], 0);
    // Every section present and filled.
    let ids: Vec<&str> = page["sections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap())
        .collect();
    let mut want = vec![
        "job".to_string(),
        "family".into(),
        "toolpaths".into(),
        "parts".into(),
    ];
    want.extend(
        parts
            .iter()
            .map(|p| format!("part-{}", p["part"].as_str().unwrap())),
    );
    assert_eq!(ids, want);
    for sec in page["sections"].as_array().unwrap() {
        assert!(sec["text"].as_u64().unwrap() > 100, "empty section {sec}");
    }
    // The sorted orders, checked against summary.json's figures.
    let names: Vec<String> = parts
        .iter()
        .map(|p| p["part"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(by_name, names);
    let mut want_rms = names.clone();
    let rms = |n: &String| {
        parts.iter().find(|p| p["part"] == n.as_str()).unwrap()["rms_um"]
            .as_f64()
            .unwrap()
    };
    want_rms.sort_by(|a, b| rms(b).partial_cmp(&rms(a)).unwrap());
    assert_eq!(by_rms, want_rms);
    // No console error, no exception, no failed or blocked load.
    for e in &dt.events {
        let m = e["method"].as_str().unwrap_or("");
        let p = &e["params"];
        let bad = match m {
            "Runtime.consoleAPICalled" => matches!(p["type"].as_str(), Some("error" | "assert")),
            "Runtime.exceptionThrown" => true,
            "Log.entryAdded" => p["entry"]["level"] == "error",
            "Network.loadingFailed" => true,
            _ => false,
        };
        assert!(!bad, "browser reported: {e}");
    }
    // No request but the file itself and its data: images.
    let requests: Vec<&str> = dt
        .events
        .iter()
        .filter(|e| e["method"] == "Network.requestWillBeSent")
        .filter_map(|e| e["params"]["request"]["url"].as_str())
        .collect();
    assert!(requests.contains(&url.as_str()), "{requests:?}");
    for r in &requests {
        assert!(
            *r == url || r.starts_with("data:"),
            "request outside the file: {r}"
        );
    }
    // The figures in the page equal summary.json's, exactly.
    let figures: std::collections::BTreeMap<String, Value> = page["figures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f[0].as_str().unwrap().to_string(), f[1].clone()))
        .collect();
    let mut checked = 0;
    for p in parts {
        let name = p["part"].as_str().unwrap();
        for key in [
            "points",
            "rejected",
            "sigma_um",
            "holdout_points",
            "holdout_rmse_um",
            "kriging_holdout_rmse_um",
            "holdout_e_rms_um",
            "benefit_share",
            "rms_um",
            "pv_um",
        ] {
            let shown = &figures[&format!("{name}.{key}")];
            assert_eq!(shown.as_f64(), p[key].as_f64(), "{name}.{key}");
            checked += 1;
        }
    }
    let fam = &summary["family_map"];
    for key in ["mean_rms_um", "mean_pv_um", "std_max_um", "parts"] {
        assert_eq!(
            figures[&format!("family.{key}")].as_f64(),
            fam[key].as_f64(),
            "family.{key}"
        );
        checked += 1;
    }
    assert_eq!(checked, parts.len() * 10 + 4);
    // Printed to PDF.
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(pdf["data"].as_str().unwrap())
        .unwrap();
    assert!(
        bytes.len() > 10_000 && bytes.starts_with(b"%PDF"),
        "{} bytes",
        bytes.len()
    );
}

#[test]
fn report_rewrites_the_same_bytes_and_prints_a_pdf() {
    let run = sample_run();
    let tmp = tempfile::tempdir().unwrap();
    let again = tmp.path().join("again.html");
    let r = common::errmap(
        tmp.path(),
        &[
            "report",
            run.to_str().unwrap(),
            "-o",
            again.to_str().unwrap(),
        ],
    );
    r.expect_code(0);
    // The same run gives the same bytes (the date is the run's, from run.json).
    assert!(
        std::fs::read(&again).unwrap() == std::fs::read(run.join("report.html")).unwrap(),
        "errmap report differs from the batch's report.html"
    );
    let Some(chrome) = browser_or_skip("report --pdf") else {
        return;
    };
    let pdf = tmp.path().join("r.pdf");
    let r = common::errmap_with(
        tmp.path(),
        &[
            "report",
            run.to_str().unwrap(),
            "-o",
            again.to_str().unwrap(),
            "--pdf",
            pdf.to_str().unwrap(),
        ],
        |c| {
            c.env("ERRMAP_CHROMIUM", &chrome);
        },
    );
    r.expect_code(0);
    let bytes = std::fs::read(&pdf).unwrap();
    assert!(
        bytes.len() > 10_000 && bytes.starts_with(b"%PDF"),
        "{}",
        r.report()
    );
}

#[test]
fn report_refuses_an_input_as_output_and_a_missing_browser() {
    let run = sample_run();
    let summary = run.join("summary.json");
    let before = std::fs::read(&summary).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let r = common::errmap(
        tmp.path(),
        &[
            "report",
            run.to_str().unwrap(),
            "-o",
            summary.to_str().unwrap(),
        ],
    );
    r.expect_code(2);
    assert!(r.stderr.contains("input"), "{}", r.report());
    assert_eq!(std::fs::read(&summary).unwrap(), before);
    // A PNG the report embeds is an input too.
    let png = run.join("p01").join("map.png");
    let r = common::errmap(
        tmp.path(),
        &["report", run.to_str().unwrap(), "-o", png.to_str().unwrap()],
    );
    r.expect_code(2);
    assert!(
        r.stderr.contains("map.png") && r.stderr.contains("input"),
        "{}",
        r.report()
    );
    // --pdf with no browser anywhere: exit 2 naming what to install.
    let empty = tmp.path().join("empty-path");
    std::fs::create_dir(&empty).unwrap();
    let out = tmp.path().join("r.html");
    let r = common::errmap_with(
        tmp.path(),
        &[
            "report",
            run.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--pdf",
            tmp.path().join("r.pdf").to_str().unwrap(),
        ],
        |c| {
            c.env("PATH", &empty).env_remove("ERRMAP_CHROMIUM");
        },
    );
    r.expect_code(2);
    assert!(
        r.stderr.contains("apt-get install chromium"),
        "{}",
        r.report()
    );
    assert!(!tmp.path().join("r.pdf").exists());
    // A folder that holds neither a run nor a result.
    let r = common::errmap(tmp.path(), &["report", empty.to_str().unwrap()]);
    r.expect_code(2);
    assert!(r.stderr.contains("holds no errmap run"), "{}", r.report());
}

#[test]
fn analyses_write_results_that_report_renders_in_each_standards_symbols() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("axes");
    std::fs::create_dir(&dir).unwrap();
    let chart = dir.join("x.png");
    let runs = root.join("data/linear/runs.csv");
    let r = common::ok(
        tmp.path(),
        &[
            "linear",
            "analyze",
            runs.to_str().unwrap(),
            "--standard",
            "vdi3441",
            "--chart",
            chart.to_str().unwrap(),
            "--json",
        ],
    );
    let printed = common::json(&r);
    let result: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("x.json")).unwrap()).unwrap();
    assert_eq!(result["format"], "errmap-result/1");
    assert_eq!(result["charts"], json!(["x.png"]));
    assert_eq!(
        result["result"], printed,
        "the result is what --json prints"
    );
    assert_eq!(printed["target_symbols"][4], "U_j");
    let centres = root.join("data/rotary/centres.csv");
    common::ok(
        tmp.path(),
        &[
            "rotary",
            "analyze",
            centres.to_str().unwrap(),
            "--chart",
            dir.join("c.png").to_str().unwrap(),
        ],
    );
    common::ok(tmp.path(), &["report", dir.to_str().unwrap(), "-q"]);
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert_eq!(html.matches("<section id=").count(), 2);
    assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 2);
    // VDI/DGQ 3441's own symbols, not ISO's, with each value as --json gave it.
    for f in printed["figures"].as_array().unwrap() {
        let sym = f["symbol"].as_str().unwrap();
        let v = f["value"].as_f64().unwrap();
        let attr = format!("data-figure=\"x.{sym}\" data-value=\"");
        let at = html.find(&attr).unwrap_or_else(|| panic!("{sym} missing"));
        let rest = &html[at + attr.len()..];
        let shown: f64 = rest[..rest.find('"').unwrap()].parse().unwrap();
        assert_eq!(shown, v, "{sym}");
    }
    assert!(html.contains("<th>Ps_j</th>") && html.contains("<th>U_j</th>"));
    assert!(!html.contains("<th>R_i</th>") && !html.contains(">B̄<"));
}
