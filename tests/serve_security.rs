//! `errmap serve`'s security rules, each against the real server on a free loopback port with a real HTTP client: users file, login with its pre-session token, session cookies and expiry, logout, throttling, X-Forwarded-For, CSRF and roles, headers, the bind rule, bounded and bad requests, and the runs folder's confinement.

mod serve_support;

use serve_support::*;
use std::io::{Read, Write};
use std::time::Duration;

fn header(r: &reqwest::blocking::Response, name: &str) -> String {
    r.headers()
        .get(name)
        .map(|v| v.to_str().unwrap().to_string())
        .unwrap_or_default()
}

/// One raw HTTP/1.1 request (paths a URL library would normalise, bytes no client sends).
fn raw(url: &str, request: &[u8]) -> String {
    let addr = url.trim_start_matches("http://");
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    s.write_all(request).unwrap();
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

fn raw_get(url: &str, path: &str, cookie: &str) -> String {
    raw(
        url,
        format!("GET {path} HTTP/1.1\r\nHost: x\r\nCookie: {cookie}\r\nConnection: close\r\n\r\n")
            .as_bytes(),
    )
}

fn sql_count(db: &std::path::Path, sql: &str) -> i64 {
    let c = rusqlite::Connection::open(db).unwrap();
    c.query_row(sql, [], |r| r.get(0)).unwrap()
}

#[test]
fn users_file_holds_argon2id_hashes_written_for_its_owner_only() {
    let tmp = tempfile::tempdir().unwrap();
    let users = tmp.path().join("users.toml");
    let out = user_add(&users, "Ada", "operator", PASSWORD);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&users).unwrap();
    // The argon2 crate itself (not errmap) checks the stored PHC string.
    let table: toml::Table = toml::from_str(&text).unwrap();
    let entry = &table["user"].as_array().unwrap()[0];
    assert_eq!(
        entry["name"].as_str(),
        Some("ada"),
        "names are stored in lower case"
    );
    let phc = entry["password_hash"].as_str().unwrap();
    assert!(phc.starts_with("$argon2id$v=19$"), "{phc}");
    use argon2::password_hash::{phc::PasswordHash, PasswordVerifier};
    let parsed = PasswordHash::new(phc).unwrap();
    assert!(argon2::Argon2::default()
        .verify_password(PASSWORD.as_bytes(), &parsed)
        .is_ok());
    assert!(argon2::Argon2::default()
        .verify_password(b"wrong password", &parsed)
        .is_err());
    assert!(!text.contains(PASSWORD));
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&users).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600, "users file mode {mode:o}");
    }
    // Refusals: an existing name without --replace, a short password, a bad name.
    assert_eq!(
        user_add(&users, "ada", "viewer", PASSWORD).status.code(),
        Some(2)
    );
    assert_eq!(
        user_add(&users, "bob", "viewer", "short").status.code(),
        Some(2)
    );
    assert_eq!(
        user_add(&users, "b b", "viewer", PASSWORD).status.code(),
        Some(2)
    );
    assert_eq!(
        user_add(&users, "bob", "viewer", PASSWORD).status.code(),
        Some(0)
    );
    let list = errmap()
        .args(["serve", "user", "list", "--users"])
        .arg(&users)
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&list.stdout),
        "ada\toperator\nbob\tviewer\n"
    );
    let rm = errmap()
        .args(["serve", "user", "remove", "ADA", "--users"])
        .arg(&users)
        .output()
        .unwrap();
    assert!(rm.status.success());
    assert!(!std::fs::read_to_string(&users).unwrap().contains("ada"));
    let rm = errmap()
        .args(["serve", "user", "remove", "nobody", "--users"])
        .arg(&users)
        .output()
        .unwrap();
    assert_eq!(rm.status.code(), Some(2));
    // No temporary file is left beside it.
    let names: Vec<String> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names, ["users.toml"]);
}

#[test]
fn without_a_session_pages_redirect_to_login_and_the_api_answers_401() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    for page in [
        "/",
        "/live",
        "/history",
        "/runs/",
        "/runs/x/report.html",
        "/no/such/page",
    ] {
        let r = c.get(format!("{}{page}", server.url)).send().unwrap();
        assert_eq!(r.status(), 302, "{page}");
        assert_eq!(header(&r, "location"), "/login", "{page}");
    }
    for api in ["/api/live", "/api/state", "/api/nothing"] {
        let r = c.get(format!("{}{api}", server.url)).send().unwrap();
        assert_eq!(r.status(), 401, "{api}");
    }
    // A session id the client made up is no session (no fixation).
    let r = c
        .get(format!("{}/live", server.url))
        .header("cookie", "errmap_session=chosen-by-an-attacker")
        .send()
        .unwrap();
    assert_eq!(r.status(), 302);
    let r = c
        .post(format!("{}/live/command", server.url))
        .form(&[("command", "pause")])
        .send()
        .unwrap();
    assert_eq!(r.status(), 302);
    assert_eq!(sql_count(&site.db, "SELECT COUNT(*) FROM live_commands"), 0);
}

#[test]
fn login_needs_the_form_token_of_its_own_pre_session() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let url = &server.url;
    let (pre, token) = login_form(&c, url);
    let (other_pre, _) = login_form(&c, url);
    let form = [
        ("user", "op"),
        ("password", PASSWORD),
        ("csrf", token.as_str()),
    ];
    // No pre-session cookie, or another browser's: refused, right password or not.
    let r = c.post(format!("{url}/login")).form(&form).send().unwrap();
    assert_eq!(r.status(), 403);
    let r = c
        .post(format!("{url}/login"))
        .header("cookie", &other_pre)
        .form(&form)
        .send()
        .unwrap();
    assert_eq!(r.status(), 403);
    let r = c
        .post(format!("{url}/login"))
        .header("cookie", &pre)
        .form(&[("user", "op"), ("password", PASSWORD), ("csrf", "forged")])
        .send()
        .unwrap();
    assert_eq!(r.status(), 403);
    let r = c
        .post(format!("{url}/login"))
        .header("cookie", &pre)
        .form(&form)
        .send()
        .unwrap();
    assert_eq!(r.status(), 303);
    assert_eq!(header(&r, "location"), "/live");
}

#[test]
fn session_cookies_are_httponly_strict_and_new_at_each_login() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let url = &server.url;
    let r = post_login(&c, url, "op", PASSWORD);
    assert_eq!(r.status(), 303);
    let cookies = set_cookies(&r);
    let session = cookies
        .iter()
        .find(|c| c.starts_with("errmap_session="))
        .unwrap();
    let attrs: Vec<&str> = session.split(';').map(str::trim).skip(1).collect();
    assert_eq!(
        attrs,
        ["Path=/", "HttpOnly", "SameSite=Strict"],
        "{session}"
    );
    // The pre-session cookie goes.
    assert!(cookies
        .iter()
        .any(|c| c.starts_with("errmap_login=;") && c.contains("Max-Age=0")));
    let first = login(&c, url, "op");
    // Logging in again while carrying the first session: a new id, and the first one ends.
    let (pre, token) = login_form(&c, url);
    let r = c
        .post(format!("{url}/login"))
        .header("cookie", format!("{pre}; {}", first.cookie))
        .form(&[
            ("user", "op"),
            ("password", PASSWORD),
            ("csrf", token.as_str()),
        ])
        .send()
        .unwrap();
    assert_eq!(r.status(), 303);
    let second = cookie_value(&set_cookies(&r), "errmap_session").unwrap();
    assert_ne!(format!("errmap_session={second}"), first.cookie);
    assert!(second.len() >= 43, "256-bit ids");
    let old = c
        .get(format!("{url}/live"))
        .header("cookie", &first.cookie)
        .send()
        .unwrap();
    assert_eq!(old.status(), 302);
    let new = c
        .get(format!("{url}/live"))
        .header("cookie", format!("errmap_session={second}"))
        .send()
        .unwrap();
    assert_eq!(new.status(), 200);
}

#[test]
fn a_wrong_password_and_an_unknown_user_get_the_same_answer() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let message = |r: reqwest::blocking::Response| {
        assert_eq!(r.status(), 401);
        let b = body(r);
        let at = b.find("id=\"login-error\">").unwrap();
        b[at..at + b[at..].find("</p>").unwrap()].to_string()
    };
    let wrong = message(post_login(&c, &server.url, "op", "not the password"));
    let unknown = message(post_login(&c, &server.url, "nobody", "not the password"));
    assert_eq!(wrong, unknown);
    assert!(wrong.contains("wrong user name or password"), "{wrong}");
}

#[test]
fn logout_needs_its_token_and_ends_the_session() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let url = &server.url;
    let s = login(&c, url, "view");
    let r = c
        .post(format!("{url}/logout"))
        .header("cookie", &s.cookie)
        .form(&[("csrf", "wrong")])
        .send()
        .unwrap();
    assert_eq!(r.status(), 403);
    let still = c
        .get(format!("{url}/live"))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(still.status(), 200);
    let r = c
        .post(format!("{url}/logout"))
        .header("cookie", &s.cookie)
        .form(&[("csrf", s.csrf.as_str())])
        .send()
        .unwrap();
    assert_eq!(r.status(), 303);
    assert_eq!(header(&r, "location"), "/login");
    assert!(set_cookies(&r)
        .iter()
        .any(|c| c.starts_with("errmap_session=;") && c.contains("Max-Age=0")));
    let after = c
        .get(format!("{url}/live"))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(after.status(), 302);
    assert_eq!(
        sql_count(
            &site.db,
            "SELECT COUNT(*) FROM audit_log WHERE action = 'logout' AND user = 'view'"
        ),
        1
    );
}

#[test]
fn sessions_end_after_the_idle_timeout_and_the_absolute_lifetime() {
    let site = Site::new();
    let c = client();
    // Idle: unused for 2 s.
    let server = Server::start(&site, &["--idle-timeout", "2"]);
    let s = login(&c, &server.url, "view");
    std::thread::sleep(Duration::from_millis(3000));
    let r = c
        .get(format!("{}/live", server.url))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 302, "idle session still valid");
    drop(server);
    // Absolute: used every 0.5 s, still ended 3 s after its login.
    let server = Server::start(&site, &["--idle-timeout", "600", "--session-lifetime", "3"]);
    let s = login(&c, &server.url, "view");
    let start = std::time::Instant::now();
    let mut statuses = Vec::new();
    while start.elapsed() < Duration::from_millis(4500) {
        let r = c
            .get(format!("{}/live", server.url))
            .header("cookie", &s.cookie)
            .send()
            .unwrap();
        statuses.push((start.elapsed().as_millis(), r.status().as_u16()));
        std::thread::sleep(Duration::from_millis(500));
    }
    assert_eq!(statuses.first().unwrap().1, 200, "{statuses:?}");
    assert_eq!(statuses.last().unwrap().1, 302, "{statuses:?}");
}

#[test]
fn five_failed_logins_of_a_user_give_429_with_retry_after_even_for_the_right_password() {
    let site = Site::new();
    let mut server = Server::start(&site, &[]);
    let c = client();
    for _ in 0..5 {
        assert_eq!(
            post_login(&c, &server.url, "op", "wrong password").status(),
            401
        );
    }
    let r = post_login(&c, &server.url, "op", PASSWORD);
    assert_eq!(r.status(), 429);
    let retry: u64 = header(&r, "retry-after").parse().unwrap();
    assert!((1..=900).contains(&retry), "Retry-After {retry}");
    // Another user from the same address is blocked too (5 failures of this address).
    let r = post_login(&c, &server.url, "view", PASSWORD);
    assert_eq!(r.status(), 429);
    let log = server.log();
    assert!(log.contains("login throttled for \"op\""), "{log}");
    assert_eq!(
        sql_count(
            &site.db,
            "SELECT COUNT(*) FROM audit_log WHERE action = 'login_failed' AND user = 'op'"
        ),
        5
    );
    assert!(
        sql_count(
            &site.db,
            "SELECT COUNT(*) FROM audit_log WHERE action = 'login_throttled'"
        ) >= 2
    );
    assert_eq!(
        sql_count(
            &site.db,
            "SELECT COUNT(*) FROM audit_log WHERE action = 'login'"
        ),
        0
    );
}

#[test]
fn x_forwarded_for_counts_only_from_a_trusted_proxy() {
    let site = Site::new();
    let c = client();
    let fail_as = |url: &str, user: &str, xff: &str| {
        let (pre, token) = login_form(&c, url);
        c.post(format!("{url}/login"))
            .header("cookie", pre)
            .header("x-forwarded-for", xff)
            .form(&[
                ("user", user),
                ("password", "wrong password"),
                ("csrf", token.as_str()),
            ])
            .send()
            .unwrap()
            .status()
    };
    let login_as = |url: &str, xff: &str| {
        let (pre, token) = login_form(&c, url);
        c.post(format!("{url}/login"))
            .header("cookie", pre)
            .header("x-forwarded-for", xff)
            .form(&[
                ("user", "op"),
                ("password", PASSWORD),
                ("csrf", token.as_str()),
            ])
            .send()
            .unwrap()
            .status()
    };
    // Untrusted peer: its X-Forwarded-For is ignored, so five different "clients" are one.
    let server = Server::start(&site, &[]);
    for i in 0..5 {
        assert_eq!(
            fail_as(&server.url, &format!("u{i}"), &format!("10.0.0.{i}")),
            401
        );
    }
    assert_eq!(login_as(&server.url, "10.0.0.99"), 429);
    drop(server);
    // Behind the trusted proxy 127.0.0.1: the forwarded client is counted.
    let server = Server::start(&site, &["--trusted-proxy", "127.0.0.1"]);
    for i in 0..5 {
        assert_eq!(fail_as(&server.url, &format!("u{i}"), "203.0.113.7"), 401);
    }
    assert_eq!(login_as(&server.url, "203.0.113.7"), 429);
    // A client spoofing an address in front of the proxy's entry: the proxy's entry counts.
    assert_eq!(login_as(&server.url, "198.51.100.1, 203.0.113.7"), 429);
    // Garbage written in front of the proxy's entry does not make the proxy the client (which
    // would lock out everyone behind it): the proxy's entry still counts.
    assert_eq!(login_as(&server.url, "not-an-address, 203.0.113.7"), 429);
    assert_eq!(login_as(&server.url, "203.0.113.8"), 303);
    assert_eq!(
        sql_count(&site.db, "SELECT COUNT(*) FROM audit_log WHERE action = 'login_failed' AND address = '203.0.113.7'"),
        5
    );
}

#[test]
fn state_changes_need_the_csrf_token_and_the_operator_role() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let url = &server.url;
    let op = login(&c, url, "op");
    let view = login(&c, url, "view");
    let post = |s: &Login, form: &[(&str, &str)]| {
        c.post(format!("{url}/live/command"))
            .header("cookie", &s.cookie)
            .form(form)
            .send()
            .unwrap()
            .status()
    };
    assert_eq!(
        post(&view, &[("csrf", &view.csrf), ("command", "pause")]),
        403
    );
    assert_eq!(post(&op, &[("command", "pause")]), 403);
    assert_eq!(
        post(&op, &[("csrf", &view.csrf), ("command", "pause")]),
        403
    );
    assert_eq!(sql_count(&site.db, "SELECT COUNT(*) FROM live_commands"), 0);
    assert_eq!(post(&op, &[("csrf", &op.csrf), ("command", "launch")]), 400);
    assert_eq!(post(&op, &[("csrf", &op.csrf), ("command", "ack")]), 400);
    assert_eq!(post(&op, &[("csrf", &op.csrf), ("command", "pause")]), 303);
    assert_eq!(
        post(
            &op,
            &[("csrf", &op.csrf), ("command", "ack"), ("alarm_id", "7")]
        ),
        303
    );
    let conn = rusqlite::Connection::open(&site.db).unwrap();
    let rows: Vec<(String, String, Option<i64>, Option<String>)> = conn
        .prepare("SELECT user, command, alarm_id, handled_utc FROM live_commands ORDER BY id")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(
        rows,
        [
            ("op".into(), "pause".into(), None, None),
            ("op".into(), "ack".into(), Some(7), None)
        ]
    );
    assert_eq!(
        sql_count(
            &site.db,
            "SELECT COUNT(*) FROM audit_log WHERE action IN ('pause', 'ack') AND user = 'op'"
        ),
        2
    );
    assert_eq!(
        sql_count(
            &site.db,
            "SELECT COUNT(*) FROM audit_log WHERE action = 'refused'"
        ),
        3
    );
    // A GET changes nothing.
    let r = c
        .get(format!("{url}/live/command?command=pause"))
        .header("cookie", &op.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 405);
}

#[test]
fn every_response_carries_the_security_headers() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let s = login(&c, &server.url, "view");
    for (path, cookie) in [
        ("/login", ""),
        ("/live", s.cookie.as_str()),
        ("/history", s.cookie.as_str()),
        ("/static/app.css", ""),
        ("/static/live.js", ""),
        ("/api/state", ""),
        ("/nothing", s.cookie.as_str()),
    ] {
        let r = c
            .get(format!("{}{path}", server.url))
            .header("cookie", cookie)
            .send()
            .unwrap();
        let csp = header(&r, "content-security-policy");
        let directives: Vec<&str> = csp.split(';').map(str::trim).collect();
        for d in [
            "default-src 'none'",
            "script-src 'self'",
            "style-src 'self'",
            "frame-ancestors 'none'",
            "base-uri 'none'",
            "form-action 'self'",
        ] {
            assert!(directives.contains(&d), "{path}: {csp}");
        }
        assert!(!csp.contains("unsafe"), "{path}: {csp}");
        assert_eq!(header(&r, "x-content-type-options"), "nosniff", "{path}");
        assert_eq!(header(&r, "referrer-policy"), "no-referrer", "{path}");
        assert_eq!(header(&r, "x-frame-options"), "DENY", "{path}");
        assert_eq!(header(&r, "cache-control"), "no-store", "{path}");
        assert_eq!(
            header(&r, "strict-transport-security"),
            "",
            "no HSTS over plain HTTP"
        );
    }
    let r = c
        .get(format!("{}/static/live.js", server.url))
        .send()
        .unwrap();
    assert_eq!(header(&r, "content-type"), "text/javascript; charset=utf-8");
}

#[test]
fn a_non_loopback_address_needs_tls_or_insecure_http() {
    let site = Site::new();
    let (code, err) = refused(&site, &["--bind", "0.0.0.0:0"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--insecure-http") && err.contains("--tls-cert"),
        "{err}"
    );
    let mut server = Server::start(&site, &["--bind", "0.0.0.0:0", "--insecure-http"]);
    let log = server.log();
    assert!(log.contains("warning: serving plain HTTP"), "{log}");
    let port = server.url.rsplit(':').next().unwrap().to_string();
    let r = client()
        .get(format!("http://127.0.0.1:{port}/login"))
        .send()
        .unwrap();
    assert_eq!(r.status(), 200);
    // Half a TLS pair, a missing store or users file: refused before listening.
    let (code, err) = refused(&site, &["--bind", "127.0.0.1:0", "--tls-cert", "x.pem"]);
    assert_eq!(code, 2, "{err}");
    let tmp = tempfile::tempdir().unwrap();
    let out = errmap()
        .args(["serve", "--bind", "127.0.0.1:0", "--db"])
        .arg(tmp.path().join("none.sqlite"))
        .arg("--users")
        .arg(&site.users)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no store"));
    let out = errmap()
        .args(["serve", "--bind", "127.0.0.1:0", "--db"])
        .arg(&site.db)
        .arg("--users")
        .arg(tmp.path().join("none.toml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("serve user add"));
}

#[test]
fn bad_and_oversized_requests_get_4xx_and_the_server_keeps_serving() {
    let site = Site::new();
    let mut server = Server::start(&site, &["--runs", site.path().to_str().unwrap()]);
    let c = client();
    let url = server.url.clone();
    let s = login(&c, &url, "op");
    // Bodies are bounded (16 KiB).
    let big = "a".repeat(1 << 20);
    let r = c
        .post(format!("{url}/login"))
        .header("content-type", "application/x-www-form-urlencoded")
        .body(format!("user={big}"))
        .send()
        .unwrap();
    assert_eq!(r.status(), 413);
    // Forms that are not forms.
    for bad in ["user=%ZZ&password=x&csrf=y", "", "user=a", "\u{0}\u{1}"] {
        let r = c
            .post(format!("{url}/login"))
            .header("content-type", "application/x-www-form-urlencoded")
            .body(bad.to_string())
            .send()
            .unwrap();
        assert!(r.status().is_client_error(), "{bad:?}: {}", r.status());
    }
    let r = c
        .post(format!("{url}/live/command"))
        .header("cookie", &s.cookie)
        .header("content-type", "application/json")
        .body("{\"command\": \"pause\"}")
        .send()
        .unwrap();
    assert_eq!(r.status(), 403, "no form, no token");
    // A long password is refused quickly, not hashed.
    let long = "p".repeat(5000);
    assert_eq!(post_login(&c, &url, "op", &long).status(), 401);
    // Query ranges are bounded and checked.
    for q in [
        "from=yesterday",
        "from=2026-11-27T10:00&to=2026-11-27T09:00",
        "from=2026-01-01T00:00&to=2026-03-01T00:00",
        "from=%FF",
        &format!("from={}", "9".repeat(100)),
    ] {
        let r = c
            .get(format!("{url}/history?{q}"))
            .header("cookie", &s.cookie)
            .send()
            .unwrap();
        assert_eq!(r.status(), 400, "{q}");
    }
    let r = c
        .get(format!("{url}/history/campaign"))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 400);
    let r = c
        .get(format!("{url}/history/campaign?name={}", "x".repeat(300)))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 400);
    // Bytes no browser sends.
    let garbage = raw(&url, b"GARBAGE\r\n\r\n");
    assert!(garbage.starts_with("HTTP/1.1 400"), "{garbage}");
    let long_uri = raw_get(&url, &format!("/live?{}", "x".repeat(200_000)), &s.cookie);
    assert!(
        long_uri.starts_with("HTTP/1.1 4"),
        "{}",
        &long_uri[..long_uri.len().min(200)]
    );
    let bad_cookie = raw(
        &url,
        b"GET /live HTTP/1.1\r\nHost: x\r\nCookie: errmap_session=\xff\xfe\r\nConnection: close\r\n\r\n",
    );
    assert!(bad_cookie.starts_with("HTTP/1.1 302"), "{bad_cookie}");
    // Still serving, nothing panicked.
    assert_eq!(
        c.get(format!("{url}/live"))
            .header("cookie", &s.cookie)
            .send()
            .unwrap()
            .status(),
        200
    );
    let log = server.log();
    assert!(!log.contains("panicked"), "{log}");
}

#[test]
fn run_files_are_served_from_inside_the_runs_folder_only_with_their_types() {
    let site = Site::new();
    let runs = site.path().join("runs");
    let run = runs.join("plate-1");
    std::fs::create_dir_all(run.join("p01")).unwrap();
    let png: &[u8] = b"\x89PNG\r\n\x1a\n";
    std::fs::write(run.join("p01/map.png"), png).unwrap();
    std::fs::write(run.join("summary.json"), "{}").unwrap();
    std::fs::write(run.join("p01/map.csv"), "x_mm,y_mm,e_um\n").unwrap();
    std::fs::write(run.join("family.ngc"), "G1 X1\n").unwrap();
    std::fs::write(
        run.join("report.html"),
        "<!DOCTYPE html><style>p{}</style><p>r</p>",
    )
    .unwrap();
    std::fs::write(run.join(".errmap-x.tmp"), "half").unwrap();
    std::fs::write(site.path().join("secret.txt"), "outside").unwrap();
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(site.path().join("secret.txt"), run.join("leak.txt")).unwrap();
        std::os::unix::fs::symlink(site.path(), run.join("up")).unwrap();
    }
    let server = Server::start(&site, &["--runs", runs.to_str().unwrap()]);
    let c = client();
    let url = &server.url;
    let s = login(&c, url, "view");
    let get = |path: &str| {
        c.get(format!("{url}{path}"))
            .header("cookie", &s.cookie)
            .send()
            .unwrap()
    };
    for (path, ty) in [
        ("/runs/plate-1/report.html", "text/html; charset=utf-8"),
        ("/runs/plate-1/p01/map.png", "image/png"),
        ("/runs/plate-1/summary.json", "application/json"),
        ("/runs/plate-1/p01/map.csv", "text/csv; charset=utf-8"),
        ("/runs/plate-1/family.ngc", "text/plain; charset=utf-8"),
    ] {
        let r = get(path);
        assert_eq!(r.status(), 200, "{path}");
        assert_eq!(header(&r, "content-type"), ty, "{path}");
        assert_eq!(header(&r, "x-content-type-options"), "nosniff");
        let csp = header(&r, "content-security-policy");
        let d: Vec<&str> = csp.split(';').map(str::trim).collect();
        for want in [
            "default-src 'none'",
            "style-src 'unsafe-inline'",
            "img-src data:",
            "frame-ancestors 'none'",
        ] {
            assert!(d.contains(&want), "{path}: {csp}");
        }
        assert!(!csp.contains("script-src"), "{path}: {csp}");
    }
    assert_eq!(
        get("/runs/plate-1/p01/map.png").bytes().unwrap().as_ref(),
        png
    );
    let listing = body(get("/runs/plate-1/"));
    assert!(
        listing.contains("report.html") && listing.contains("p01/"),
        "{listing}"
    );
    assert!(
        !listing.contains("leak.txt") && !listing.contains(".errmap"),
        "{listing}"
    );
    let r = get("/runs/plate-1");
    assert_eq!(r.status(), 303);
    for path in [
        "/runs/plate-1/leak.txt",
        "/runs/plate-1/up/secret.txt",
        "/runs/plate-1/.errmap-x.tmp",
        "/runs/nothing",
    ] {
        assert_eq!(get(path).status(), 404, "{path}");
    }
    // Paths a URL library would normalise: sent raw.
    for path in [
        "/runs/../secret.txt",
        "/runs/plate-1/../../secret.txt",
        "/runs/%2e%2e/secret.txt",
        "/runs/plate-1/%2E%2E/%2E%2E/secret.txt",
        "/runs/..%2Fsecret.txt",
        "/runs/%2Fetc%2Fpasswd",
        "/runs/plate-1/report.html%00",
        "/runs/plate-1%5C..%5C..%5Csecret.txt",
    ] {
        let r = raw_get(url, path, &s.cookie);
        assert!(
            !r.contains("outside") && !r.contains("root:"),
            "{path}: {r}"
        );
        assert!(
            r.starts_with("HTTP/1.1 404") || r.starts_with("HTTP/1.1 400"),
            "{path}: {r}"
        );
    }
}

#[test]
fn removing_a_user_ends_their_sessions_on_the_running_server() {
    let site = Site::new();
    let server = Server::start(&site, &[]);
    let c = client();
    let view = login(&c, &server.url, "view");
    let op = login(&c, &server.url, "op");
    let rm = errmap()
        .args(["serve", "user", "remove", "view", "--users"])
        .arg(&site.users)
        .output()
        .unwrap();
    assert!(rm.status.success());
    // The server re-reads the file within a second of the change.
    std::thread::sleep(Duration::from_millis(2500));
    let gone = c
        .get(format!("{}/live", server.url))
        .header("cookie", &view.cookie)
        .send()
        .unwrap();
    assert_eq!(gone.status(), 302);
    let still = c
        .get(format!("{}/live", server.url))
        .header("cookie", &op.cookie)
        .send()
        .unwrap();
    assert_eq!(still.status(), 200);
    assert_eq!(post_login(&c, &server.url, "view", PASSWORD).status(), 401);
}
