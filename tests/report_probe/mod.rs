//! The report as a real browser renders it (issue 38), shared by the tests that run a job: headless
//! Chromium's screenshot and DOM of `report.html`.

use std::path::Path;
use std::process::Command;

/// Chromium's command. The test that needs it is `#[ignore]`d, so that plain `cargo test` reports it as
/// ignored rather than passing it; run with `cargo test -- --ignored` (as `.ci/run` does after installing
/// it) it fails when no browser is installed.
pub fn chromium() -> &'static str {
    ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|c| {
            Command::new(c)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .expect("chromium is required by this test but not installed (apt-get install chromium)")
}

/// Pixels that only the report's images contain: viridis' dark purple end and the rendered spheres' greys
/// are not used by the page's text, tables or backgrounds.
fn image_pixels(png_bytes: &[u8]) -> usize {
    let dec = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    buf[..info.buffer_size()]
        .chunks(ch)
        .filter(|p| {
            let (r, g, b) = (p[0] as i32, p[1] as i32, p[2] as i32);
            // viridis dark purple (68, 1, 84) ± a little
            (r - 68).abs() < 20 && g < 40 && (b - 84).abs() < 25
        })
        .count()
}

/// Chromium's headless run on the report with `mode` (`--screenshot=PATH` or `--dump-dom`).
fn chromium_on(report: &Path, mode: &str) -> std::process::Output {
    let profile = tempfile::tempdir().unwrap();
    Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--window-size=1280,12000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(mode)
        .arg(format!("file://{}", report.display()))
        .output()
        .unwrap()
}

/// The report rendered by a real browser: its figures show, their labels are text set in a real font and,
/// measured with that font, lie inside their figures; the page reads top-down (`verdict`, then "To mill
/// this", then the evidence) with no Markdown backtick or Rust name in its visible text, and it carries no
/// figure defect.
pub fn check(report: &Path, verdict: &str) {
    let out = tempfile::tempdir().unwrap();
    let shot = out.path().join("shot.png");
    let r = chromium_on(report, &format!("--screenshot={}", shot.display()));
    assert!(shot.exists(), "no screenshot: {}", String::from_utf8_lossy(&r.stderr));
    let n = image_pixels(&std::fs::read(&shot).unwrap());
    println!("{n} image pixels in the screenshot");
    assert!(
        n > 5_000,
        "the rendered page shows only {n} image pixels: images did not render"
    );
    // The page as Chromium built it, with a probe added to a copy: every figure label's box, measured by
    // the browser in the font it chose, against its figure's box.
    let html = std::fs::read_to_string(report).unwrap();
    let probe = out.path().join("probe.html");
    std::fs::write(&probe, html.replace("</body>", LABEL_PROBE)).unwrap();
    let dom = chromium_on(&probe, "--dump-dom");
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert!(
        dom.contains("<figure><svg"),
        "Chromium built no page: {}",
        &dom[..dom.len().min(300)]
    );
    let probed = dom
        .split("data-labels=\"")
        .nth(1)
        .and_then(|t| t.split('"').next())
        .expect("the probe ran");
    let (count, outside) = probed.split_once(';').unwrap();
    let count: usize = count.parse().unwrap();
    println!("{count} figure labels measured in Chromium");
    assert!(count > 100, "only {count} labels: the figures' text is not text");
    assert!(outside.is_empty(), "labels outside their figures: {outside}");
    let defects: Vec<&str> = dom.lines().filter(|l| l.contains("label-defect")).collect();
    assert!(defects.is_empty(), "figure defects in the report: {defects:?}");
    // what a reader sees: the text outside tags, style and figures' embedded images
    let body = &dom[dom.find("<body").unwrap()..];
    let mut text = String::new();
    let mut in_tag = false;
    for c in body.chars() {
        match c {
            '<' => in_tag = true,
            '>' => {
                in_tag = false;
                text.push(' ');
            }
            c if !in_tag => text.push(c),
            _ => {}
        }
    }
    assert!(
        !text.contains('`'),
        "a Markdown backtick in the page: {}",
        around(&text, "`")
    );
    for rust in ["Tolerance)", "Aluminium", "Zigzag", "OneWay", "Some(", "Grbl", "/../"] {
        assert!(!text.contains(rust), "a Rust name in the page: {}", around(&text, rust));
    }
    let at = |s: &str| text.find(s).unwrap_or_else(|| panic!("{s} not in the page"));
    assert!(at(verdict) < at("To mill this"), "the verdict first");
    assert!(at("To mill this") < at("Metrics"), "what to do before the evidence");
    let first_figure = dom.find("<figure>").unwrap();
    assert!(
        dom.find("To mill this").unwrap() < first_figure,
        "the setup sheet before the first figure"
    );
}

/// Added before `</body>` of a copy of the report: counts the figures' text elements and lists those whose
/// box (as the browser lays it out) leaves their figure's view box, into `data-labels` on the body.
const LABEL_PROBE: &str = "<script>(function(){let n=0,bad=[];\
document.querySelectorAll('figure svg').forEach(function(s,i){var v=s.viewBox.baseVal;\
s.querySelectorAll('text').forEach(function(t){n++;var b=t.getBBox();\
if(b.x<-0.5||b.y<-0.5||b.x+b.width>v.width+0.5||b.y+b.height>v.height+0.5){bad.push('figure '+i+': '+t.textContent.replace(/[\"<>;]/g,' ')+' at '+Math.round(b.x)+'..'+Math.round(b.x+b.width)+' of '+v.width);}});});\
document.body.setAttribute('data-labels',n+';'+bad.join(' | '));})();</script></body>";

/// Forty characters either side of the first `s` in `text`.
fn around(text: &str, s: &str) -> String {
    let k = text.find(s).unwrap_or(0);
    let before: String = text[..k]
        .chars()
        .rev()
        .take(40)
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    let after: String = text[k..].chars().take(40).collect();
    before + &after
}
