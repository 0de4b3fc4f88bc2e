//! `report.html`: one page that opens offline — every image is embedded as a `data:` URI, no script, no
//! external style sheet.

use super::metrics::SurfaceMetrics;
use super::Metrics;
use crate::base::plot::escape_markup as esc;

/// A picture with a caption.
pub struct Figure {
    /// Heading.
    pub title: String,
    /// What it shows.
    pub caption: String,
    /// The drawing as an SVG element ([`crate::base::plot::Canvas::to_svg`]): text as text.
    pub svg: String,
    /// The drawing, kept for [`Figure::png`] (a few figures are also written as `.png` files) and for its
    /// label defects ([`crate::base::plot::Canvas::label_defects`]), which the page lists under the figure
    /// with the class `label-defect`.
    pub canvas: crate::base::plot::Canvas,
}

impl Figure {
    /// A figure from a drawn canvas, its SVG written here.
    pub fn new(title: impl Into<String>, caption: impl Into<String>, canvas: &crate::base::plot::Canvas) -> Self {
        Self {
            title: title.into(),
            caption: caption.into(),
            svg: canvas.to_svg(),
            canvas: canvas.clone(),
        }
    }

    /// The drawing as PNG bytes (a job's `.png` artifacts), text drawn in a bitmap font.
    pub fn png(&self) -> Vec<u8> {
        self.canvas.to_png()
    }
}

/// What the page's verdict and metrics come from.
pub enum Verdict<'a> {
    /// One target.
    Single(&'a Metrics),
    /// A spatially varying target: one set of metrics per region.
    Regions(&'a super::RegionsMetrics),
}

/// Everything the page shows.
pub struct Report<'a> {
    /// Job name.
    pub title: String,
    /// The metrics.
    pub verdict: Verdict<'a>,
    /// Figures in order.
    pub figures: Vec<Figure>,
    /// Job parameters as (key, value).
    pub parameters: Vec<(String, String)>,
    /// The G-code summary as (key, value).
    pub program: Vec<(String, String)>,
    /// Artifacts written, as (file, what).
    pub artifacts: Vec<(String, String)>,
}

/// Prose for the page: escaped, a `quoted` name (a key, a file, a tool, a spec) set as code rather than
/// shown with its backticks; an unpaired backtick is dropped.
pub(crate) fn rich(s: &str) -> String {
    let parts: Vec<&str> = s.split('`').collect();
    let paired = parts.len() % 2 == 1;
    let mut out = String::with_capacity(s.len() + 16);
    for (k, part) in parts.iter().enumerate() {
        let code = k % 2 == 1 && (paired || k + 1 < parts.len());
        if code {
            out.push_str(&format!("<code>{}</code>", esc(part)));
        } else {
            out.push_str(&esc(part));
        }
    }
    out
}

fn kv_table(rows: &[(String, String)]) -> String {
    let mut s = String::from("<table class=\"kv\">");
    for (k, v) in rows {
        s.push_str(&format!("<tr><th>{}</th><td>{}</td></tr>", rich(k), rich(v)));
    }
    s.push_str("</table>");
    s
}

/// A metric's value: four decimals for every metric, so that one column reads at one precision (a
/// relative albedo error of 7.6e-6 shows as 0.0000 beside 0.0032, not in another notation).
fn fmt(v: f64) -> String {
    if v.abs() < 1e5 {
        let s = format!("{v:.4}");
        // "-0.0000" is a sign without a value
        if s.trim_start_matches('-').bytes().all(|b| b == b'0' || b == b'.') {
            s.trim_start_matches('-').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.3e}")
    }
}

fn metrics_table(design: &SurfaceMetrics, milled: &SurfaceMetrics, ideal: Option<&SurfaceMetrics>) -> String {
    let mut columns = vec![("design tile", design), ("milled (simulated)", milled)];
    if let Some(i) = ideal {
        columns.push(("milled on a perfect machine", i));
    }
    checks_table(&columns)
}

/// The verdict's checks of several measured surfaces, one column each, with the tolerances of the first.
pub(crate) fn checks_table(columns: &[(&str, &SurfaceMetrics)]) -> String {
    let mut s = String::from("<table class=\"metrics\"><tr><th>metric</th><th>tolerance</th>");
    for (name, _) in columns {
        s.push_str(&format!("<th>{}</th>", rich(name)));
    }
    s.push_str("</tr>");
    let cell = |c: &super::metrics::Check| {
        if !c.is_checked() {
            return format!("<td class=\"unchecked\">{} (not checked)</td>", fmt(c.value));
        }
        format!(
            "<td class=\"{}\">{} {}</td>",
            if c.pass { "pass" } else { "fail" },
            fmt(c.value),
            if c.pass { "✓" } else { "✗" }
        )
    };
    let Some((_, first)) = columns.first() else {
        return String::new();
    };
    for (k, d) in first.checks.iter().enumerate() {
        s.push_str(&format!(
            "<tr><td>{}</td><td>{}</td>",
            rich(&d.name),
            rich(&d.tolerance)
        ));
        for (_, m) in columns {
            s.push_str(&m.checks.get(k).map(cell).unwrap_or_default());
        }
        s.push_str("</tr>");
    }
    s.push_str("</table>");
    s
}

/// The page around `body`: the head with the report's style, the heading `{kind} — {title}`, and the
/// footer. One page that opens offline.
pub(crate) fn page(kind: &str, title: &str, body: &str) -> String {
    let mut h = String::with_capacity(body.len() + 4096);
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">");
    h.push_str(&format!(
        "<title>{} — {}</title>",
        esc(kind),
        esc(&title.replace('`', ""))
    ));
    h.push_str(STYLE);
    h.push_str(&format!("<h1>{} — {}</h1>", esc(kind), rich(title)));
    h.push_str(body);
    h.push_str("<p><small>Generated by brdfmill ");
    h.push_str(env!("CARGO_PKG_VERSION"));
    h.push_str(". The page is self-contained: it needs no network.</small></p></body></html>\n");
    h
}

/// A figure with its heading and caption, and any defect of its labels.
pub(crate) fn figure_html(f: &Figure) -> String {
    let mut h = format!(
        "<h2>{}</h2><figure>{}<figcaption>{}</figcaption></figure>",
        rich(&f.title),
        f.svg,
        rich(&f.caption)
    );
    for d in &f.canvas.label_defects {
        h.push_str(&format!("<p class=\"label-defect\">Figure defect: {}</p>", esc(d)));
    }
    h
}

/// A table of (key, value) rows.
pub(crate) fn key_values(rows: &[(String, String)]) -> String {
    kv_table(rows)
}

const STYLE: &str = "<style>body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}\
             h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}\
             table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}\
             td.pass{background:#e6f4ea}td.fail{background:#fde8e8}.verdict{font-size:1.2em;padding:.6em 1em;border-radius:6px}\
             .ok{background:#e6f4ea}.no{background:#fde8e8}figure{margin:1em 0}figure svg{max-width:100%;height:auto;border:1px solid #ddd}\
             figcaption{color:#555;font-size:.9em}td.unchecked{color:#666;background:#f3f3f3}code{font-size:.92em;background:#f3f3f3;padding:0 .2em;border-radius:3px}table.kv th{background:#f6f6f6;font-weight:normal}</style></head><body>";

impl Report<'_> {
    /// The HTML text.
    pub fn to_html(&self) -> String {
        let mut h = String::with_capacity(1 << 20);
        match self.verdict {
            Verdict::Single(m) => single_verdict(&mut h, m),
            Verdict::Regions(m) => regions_verdict(&mut h, m),
        }
        h.push_str("<h2>To mill this</h2>");
        h.push_str(&kv_table(&self.program));
        match self.verdict {
            Verdict::Single(m) => single_metrics(&mut h, m),
            Verdict::Regions(m) => regions_metrics(&mut h, m),
        }
        for f in &self.figures {
            h.push_str(&figure_html(f));
        }
        h.push_str("<h2>Job parameters</h2>");
        h.push_str(&kv_table(&self.parameters));
        h.push_str("<h2>Artifacts</h2>");
        h.push_str(&kv_table(&self.artifacts));
        page("brdfmill report", &self.title, &h)
    }
}

fn failed(checks: &[super::metrics::Check]) -> Vec<String> {
    checks
        .iter()
        .filter(|c| !c.pass)
        .map(|c| format!("{} = {} (needs {})", c.name, fmt(c.value), c.tolerance))
        .collect()
}

fn notes(h: &mut String, notes: &[String]) {
    if !notes.is_empty() {
        h.push_str("<h2>Why</h2><ul>");
        for n in notes {
            h.push_str(&format!("<li>{}</li>", rich(n)));
        }
        h.push_str("</ul>");
    }
}

/// Verdict and reasons of a single target.
fn single_verdict(h: &mut String, m: &Metrics) {
    h.push_str(&format!(
        "<p class=\"verdict {}\">{}</p>",
        if m.pass { "ok" } else { "no" },
        rich(&if m.pass {
            "The simulated milled surface meets every tolerance against the target.".to_string()
        } else {
            format!(
                "The simulated milled surface falls short: {}.",
                failed(&m.milled.checks).join("; ")
            )
        })
    ));
    notes(h, &m.notes);
}

/// Metrics of a single target, and what the machine does to them.
fn single_metrics(h: &mut String, m: &Metrics) {
    h.push_str(&format!("<h2>Metrics</h2><p>Reference: {}.</p>", rich(&m.reference)));
    let ideal = m.milled_ideal.as_ref().filter(|_| m.accuracy.is_some());
    if let Some(a) = &m.accuracy {
        h.push_str(&format!(
            "<p>The milled column is the cut on the declared machine ({}); the last column is the same program on a perfect machine.</p>",
            rich(&a.describe())
        ));
    }
    h.push_str(&metrics_table(&m.design, &m.milled, ideal));
    appearance(h, m);
    machine_effects(h, m);
}

/// What a glossmeter would read off the target and the milled part.
fn appearance(h: &mut String, m: &Metrics) {
    let Some(a) = &m.appearance else {
        return;
    };
    h.push_str(&format!(
        "<h3>Appearance in a lab's units</h3><p>What a glossmeter would read, from each BRDF (not checked against a tolerance): {}.</p>\
         <table class=\"metrics\"><tr><th>surface</th><th>gloss 20°</th><th>gloss 60°</th><th>gloss 85°</th><th>haze (30°, 2°)</th><th>DOI (30°)</th><th>haze index G60 − G20</th></tr>",
        rich(&a.method)
    ));
    for (name, x) in [("target", &a.target), ("milled (simulated)", &a.milled)] {
        h.push_str(&format!(
            "<tr><td>{name}</td><td>{:.1} GU</td><td>{:.1} GU</td><td>{:.1} GU</td><td>{:.2}</td><td>{:.1}</td><td>{:.1} GU</td></tr>",
            x.gloss_gu[0], x.gloss_gu[1], x.gloss_gu[2], x.haze, x.doi, x.haze_index_gu
        ));
    }
    h.push_str("</table>");
}

/// Which machine error moved what: the cut with each error alone.
fn machine_effects(h: &mut String, m: &Metrics) {
    let (Some(ideal), false) = (&m.milled_ideal, m.machine_effects.is_empty()) else {
        return;
    };
    h.push_str(
        "<h2>What the machine does to the cut</h2><p>The program cut on a perfect machine, with one of the machine's errors alone, with all but one, and with all of them, each measured as the milled surface is: an error's effect is its row against the perfect machine's, or the verdict's row against the row without it.</p>\
         <table class=\"metrics\"><tr><th>cut</th><th>variance ratio x</th><th>variance ratio y</th><th>NDF L1</th><th>NDF correlation</th></tr>",
    );
    let row = |h: &mut String, name: &str, c: [f64; 2], l1: f64, corr: f64| {
        h.push_str(&format!(
            "<tr><td>{}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td></tr>",
            rich(name),
            c[0],
            c[1],
            l1,
            corr
        ));
    };
    row(h, "perfect machine", ideal.cov_ratio, ideal.ndf_l1, ideal.ndf_corr);
    for e in &m.machine_effects {
        let name = if e.alone {
            format!("{} only ({})", e.error, e.what)
        } else {
            format!("all but {}", e.error)
        };
        row(h, &name, e.cov_ratio, e.ndf_l1, e.ndf_corr);
    }
    row(
        h,
        "all of them (the verdict's)",
        m.milled.cov_ratio,
        m.milled.ndf_l1,
        m.milled.ndf_corr,
    );
    h.push_str("</table>");
}

/// Verdict and reasons of a spatially varying target.
fn regions_verdict(h: &mut String, m: &super::RegionsMetrics) {
    let short: Vec<String> = m
        .regions
        .iter()
        .filter(|r| !r.pass)
        .map(|r| format!("region `{}`: {}", r.name, failed(&r.milled.checks).join("; ")))
        .collect();
    h.push_str(&format!(
        "<p class=\"verdict {}\">{}</p>",
        if m.pass { "ok" } else { "no" },
        rich(&if m.pass {
            format!(
                "Every region of the simulated milled part ({}) meets every tolerance against its own target.",
                m.regions
                    .iter()
                    .map(|r| format!("`{}`", r.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            format!("The simulated milled part falls short: {}.", short.join("; "))
        })
    ));
    notes(h, &m.notes);
}

/// The regions and each one's metrics.
fn regions_metrics(h: &mut String, m: &super::RegionsMetrics) {
    h.push_str("<h2>Regions</h2><table class=\"metrics\"><tr><th>region</th><th>colour</th><th>target</th><th>share</th><th>border</th><th>measured</th></tr>");
    for r in &m.regions {
        h.push_str(&format!(
            "<tr><td>{}</td><td><span style=\"display:inline-block;width:1em;height:1em;border:1px solid #888;background:{}\"></span> {}</td><td>{}</td><td>{:.0}%</td><td>{:.2} mm</td><td>{:.1} mm² (at least {:.2} mm from other regions)</td></tr>",
            esc(&r.name),
            esc(&r.color),
            esc(&r.color),
            esc(&r.target),
            r.area_fraction * 100.0,
            r.border_mm,
            r.measured_mm2,
            r.excluded_mm
        ));
    }
    h.push_str("</table>");
    for r in &m.regions {
        h.push_str(&format!(
            "<h2>Metrics: region <code>{}</code></h2><p>Reference: the observed half-angle distribution of <code>{}</code>; the design is its own tile's facets convolved with the base lobe, the milled figures come from the region's cells away from its border.</p>",
            esc(&r.name),
            esc(&r.target)
        ));
        h.push_str(&metrics_table(&r.design, &r.milled, None));
    }
}
