//! Line charts as inline SVG for the monitor's pages: axes with rounded ticks, one polyline per series, a legend; colours and lines as SVG attributes only (no `style`), so the pages' strict CSP holds.

use std::fmt::Write as _;

/// One line of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// The line's name in the legend (e.g. a sensor or an axis), escaped when drawn.
    pub name: String,
    /// (x, y) in the chart's units; non-finite points break the line.
    pub points: Vec<(f64, f64)>,
}

/// A chart's width, px (the SVG's view box).
pub const WIDTH: f64 = 760.0;
/// A chart's height, px.
pub const HEIGHT: f64 = 300.0;
/// Margin left of the plot area (the y tick labels), px.
pub const LEFT: f64 = 64.0;
/// Margin right of the plot area (the legend), px.
pub const RIGHT: f64 = 150.0;
/// Margin above the plot area (the title), px.
pub const TOP: f64 = 28.0;
/// Margin below the plot area (the x tick labels and the axis label), px.
pub const BOTTOM: f64 = 44.0;

/// Colour-blind-safe line colours (Okabe–Ito).
const COLOURS: [&str; 8] = [
    "#0072b2", "#e69f00", "#009e73", "#cc79a7", "#56b4e9", "#d55e00", "#f0e442", "#000000",
];

/// Text for SVG and HTML: `& < > " '` escaped.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if c.is_control() && c != '\n' && c != '\t' => out.push('\u{fffd}'),
            c => out.push(c),
        }
    }
    out
}

/// Tick positions of a range: steps of 1, 2 or 5 × 10ⁿ, about `target` of them, covering
/// [lo, hi]; returns (first tick ≤ lo, last tick ≥ hi, step).
pub fn nice_range(lo: f64, hi: f64, target: usize) -> (f64, f64, f64) {
    let (lo, hi) = if hi > lo {
        (lo, hi)
    } else {
        // One value: a unit around it.
        let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.05 };
        (lo - pad, hi + pad)
    };
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    ((lo / step).floor() * step, (hi / step).ceil() * step, step)
}

fn label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

/// A line chart; `x_label` and `y_label` name quantity and unit. With no finite point, a
/// chart frame saying so.
pub fn line_chart(title: &str, x_label: &str, y_label: &str, series: &[Series]) -> String {
    let finite = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut any = false;
    for &(x, y) in finite {
        any = true;
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let mut svg = String::new();
    let _ = write!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" class="chart" viewBox="0 0 {WIDTH} {HEIGHT}" width="{WIDTH}" height="{HEIGHT}" role="img" aria-label="{t}"><title>{t}</title>"#,
        t = escape(title)
    );
    let _ = write!(
        svg,
        r##"<text x="{LEFT}" y="18" font-size="14" font-family="sans-serif" fill="#222">{}</text>"##,
        escape(title)
    );
    let pw = WIDTH - LEFT - RIGHT;
    let ph = HEIGHT - TOP - BOTTOM;
    let _ = write!(
        svg,
        r##"<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="#888"/>"##
    );
    if !any {
        let _ = write!(
            svg,
            r##"<text x="{}" y="{}" font-size="13" font-family="sans-serif" fill="#555" text-anchor="middle">no data in this range</text></svg>"##,
            LEFT + pw / 2.0,
            TOP + ph / 2.0
        );
        return svg;
    }
    let (xa, xb, xs) = nice_range(x0, x1, 6);
    let (ya, yb, ys) = nice_range(y0, y1, 5);
    let px = |x: f64| LEFT + (x - xa) / (xb - xa) * pw;
    let py = |y: f64| TOP + ph - (y - ya) / (yb - ya) * ph;
    let mut t = xa;
    while t <= xb + xs * 1e-9 {
        let _ = write!(
            svg,
            r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{b}" stroke="#ddd"/><text x="{x:.1}" y="{ty}" font-size="11" font-family="sans-serif" fill="#333" text-anchor="middle">{l}</text>"##,
            x = px(t),
            b = TOP + ph,
            ty = TOP + ph + 14.0,
            l = label(t, xs)
        );
        t += xs;
    }
    let mut t = ya;
    while t <= yb + ys * 1e-9 {
        let _ = write!(
            svg,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{r}" y2="{y:.1}" stroke="#ddd"/><text x="{lx}" y="{ly:.1}" font-size="11" font-family="sans-serif" fill="#333" text-anchor="end">{l}</text>"##,
            y = py(t),
            r = LEFT + pw,
            lx = LEFT - 6.0,
            ly = py(t) + 4.0,
            l = label(t, ys)
        );
        t += ys;
    }
    let _ = write!(
        svg,
        r##"<text x="{}" y="{}" font-size="12" font-family="sans-serif" fill="#222" text-anchor="middle">{}</text>"##,
        LEFT + pw / 2.0,
        HEIGHT - 8.0,
        escape(x_label)
    );
    let _ = write!(
        svg,
        r##"<text x="14" y="{}" font-size="12" font-family="sans-serif" fill="#222" text-anchor="middle" transform="rotate(-90 14 {})">{}</text>"##,
        TOP + ph / 2.0,
        TOP + ph / 2.0,
        escape(y_label)
    );
    for (i, s) in series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        // Runs of finite points, each one polyline.
        let mut run = String::new();
        let flush = |run: &mut String, svg: &mut String| {
            if !run.is_empty() {
                let _ = write!(
                    svg,
                    r#"<polyline data-series="{}" fill="none" stroke="{colour}" stroke-width="1.5" points="{}"/>"#,
                    escape(&s.name),
                    run.trim_end()
                );
                run.clear();
            }
        };
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                let _ = write!(run, "{:.2},{:.2} ", px(x), py(y));
            } else {
                flush(&mut run, &mut svg);
            }
        }
        flush(&mut run, &mut svg);
        let ly = TOP + 10.0 + 18.0 * i as f64;
        let lx = LEFT + pw + 12.0;
        let _ = write!(
            svg,
            r##"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="3"/><text x="{}" y="{}" font-size="12" font-family="sans-serif" fill="#222">{}</text>"##,
            lx + 18.0,
            lx + 24.0,
            ly + 4.0,
            escape(&s.name)
        );
    }
    svg.push_str("</svg>");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_rounded_and_cover_the_data() {
        assert_eq!(nice_range(0.0, 10.0, 5), (0.0, 10.0, 2.0));
        assert_eq!(nice_range(0.3, 9.2, 5), (0.0, 10.0, 2.0));
        let (a, b, s) = nice_range(20.1, 21.3, 5);
        // 1.2 °C over 5 ticks: 0.24 rounds up to 0.5; 20.0 … 21.5.
        assert!(
            (s - 0.5).abs() < 1e-12 && a == 20.0 && b == 21.5,
            "{a} {b} {s}"
        );
        // One value: a band of ±5 % around it.
        let (a, b, _) = nice_range(5.0, 5.0, 5);
        assert!(a <= 4.75 && b >= 5.25 && b - a < 1.0, "{a} {b}");
    }

    #[test]
    fn points_land_where_the_axes_put_them() {
        // x 0…10 and y 0…100 are already on ticks (steps 2 and 20): the plot box maps them
        // linearly. By hand: x = 5 → 64 + 0.5 · 546 = 337; y = 25 → 28 + 228 − 0.25 · 228 = 199.
        let s = Series {
            name: "T1 <nut>".into(),
            points: vec![
                (0.0, 0.0),
                (5.0, 25.0),
                (10.0, 100.0),
                (f64::NAN, 1.0),
                (10.0, 0.0),
            ],
        };
        let svg = line_chart("t", "time (s)", "°C", &[s]);
        assert!(
            svg.contains(r#"points="64.00,256.00 337.00,199.00 610.00,28.00""#),
            "{svg}"
        );
        // The NaN broke the line: a second polyline with the last point.
        assert!(svg.contains(r#"points="610.00,256.00""#));
        assert!(svg.contains("T1 &lt;nut&gt;") && !svg.contains("<nut>"));
        assert!(!svg.contains("style="));
        assert!(line_chart("e", "x", "y", &[]).contains("no data"));
    }
}
