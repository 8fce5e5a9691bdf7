//! The playground page in a real browser (headless Chromium through chromedriver): a vectorize
//! job of a committed image draws live and ends with a download of exactly `result.svg`; a bad
//! upload shows the API's message; a text job's canvas, colours and 3 variations go from the
//! form to the job, one variation is picked among thumbnails and exported as SVG, PDF and PNG; on a server with an API key the page asks for it, and with
//! the key typed in, runs the same job. Screenshots go to `target/tmp/playground/` (and to
//! `$VF_PAGE_SCREENSHOTS` when set, e.g. `docs/img`). `.ci/run` installs chromium and
//! chromium-driver when it can; without them the test prints SKIP (and
//! fails where `.ci/run` sets `VF_REQUIRE_ALL`).

mod common;

use common::server::TestServer;
use common::webdriver::{Browser, installed};
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use vectorfusion::worker::test_executor::TestExecutor;

const IMAGE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/clip-tiny/images/gradient_48x40.png"
);

fn save(b: &Browser, name: &str) {
    let Ok(png) = b.screenshot() else { return };
    let mut dirs = vec![PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("playground")];
    if let Some(d) = std::env::var_os("VF_PAGE_SCREENSHOTS") {
        dirs.push(PathBuf::from(d));
    }
    for d in dirs {
        let _ = std::fs::create_dir_all(&d);
        let _ = std::fs::write(d.join(name), &png);
    }
}

/// The page on a server with `api_key` (when given) drives a vectorize job of [`IMAGE`] to its
/// end; `checks` runs after that, with the browser and the base URL.
fn with_page(api_key: Option<&str>, checks: impl FnOnce(&Browser, &str) -> Result<(), String>) {
    let Some((driver, chromium)) = installed() else {
        common::skip(
            "playground page",
            "chromium / chromedriver not installed (apt-get install chromium chromium-driver)",
        );
        return;
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let key = api_key.map(str::to_string);
    let srv = rt.block_on(TestServer::start(Arc::new(TestExecutor::new(20)), |c| {
        c.queue.workers = 1;
        if let Some(k) = key {
            c.server.api_key = k;
        }
    }));
    let base = format!("http://{}", srv.addr);
    let b = Browser::start(&driver, &chromium);
    let wait = Duration::from_secs(30);
    let run = || -> Result<(), String> {
        b.goto(&format!("{base}/"));
        if let Some(k) = api_key {
            // The page's first call (the job list) gets 401: it asks for the key.
            b.wait_for(
                "const f = document.getElementById('key-form'); return f && !f.hidden;",
                wait,
            )?;
            b.type_into(&b.find("#api-key", wait)?, k)?;
        }
        let file = b.find("#file", wait)?;
        b.type_into(&file, IMAGE)?;
        // Few steps, so the job takes about a second.
        b.eval(
            "const s = document.getElementById('steps'); if (s) { s.value = '40'; } \
             const p = document.getElementById('paths'); p.value = '4';",
            json!([]),
        )?;
        b.click(&b.find("#submit", wait)?)?;
        // Snapshots draw live, then the result appears.
        b.wait_for(
            "const i = document.getElementById('snapshot'); return i && i.src.startsWith('blob:');",
            wait,
        )?;
        if api_key.is_none() {
            save(&b, "playground-running.png");
        }
        b.wait_for(
            "const i = document.getElementById('result'); return i && i.src.startsWith('blob:') && i.offsetParent !== null;",
            wait,
        )?;
        b.wait_for(
            "const a = document.getElementById('download-svg'); return a && a.href.startsWith('blob:');",
            wait,
        )?;
        checks(&b, &base)
    };
    let result = run();
    if let Err(e) = &result {
        save(&b, "playground-failure.png");
        panic!("{e} (screenshot: target/tmp/playground/playground-failure.png)");
    }
    drop(b);
    rt.block_on(srv.stop());
}

/// The `GET` body of `url`, with `key` as a bearer token when given.
fn fetch(url: &str, key: Option<&str>) -> Result<String, String> {
    let mut req = ureq::get(url);
    if let Some(k) = key {
        req = req.set("Authorization", &format!("Bearer {k}"));
    }
    req.call()
        .map_err(|e| e.to_string())?
        .into_string()
        .map_err(|e| e.to_string())
}

/// The text of the page's SVG download link.
fn downloaded_svg(b: &Browser) -> Result<serde_json::Value, String> {
    b.eval_async(
        "const done = arguments[arguments.length - 1]; \
         fetch(document.getElementById('download-svg').href).then(r => r.text()).then(done, e => done('ERR ' + e));",
        json!([]),
    )
}

/// The newest job's `result.svg`, as the API serves it.
fn served_svg(base: &str, key: Option<&str>) -> Result<String, String> {
    let list: serde_json::Value =
        serde_json::from_str(&fetch(&format!("{base}/jobs"), key)?).map_err(|e| e.to_string())?;
    let id = list["jobs"][0]["id"].as_str().ok_or("no job listed")?;
    fetch(&format!("{base}/jobs/{id}/result.svg"), key)
}

/// The canvas select and the negative-prompt field: hidden for an image, sent with a caption.
fn canvas_controls_reach_a_text_job(b: &Browser, base: &str) -> Result<(), String> {
    let wait = Duration::from_secs(30);
    let shown = "return !document.getElementById('text-fields').hidden;";
    if b.eval(shown, json!([]))? != json!(false) {
        return Err("the canvas controls show for an image job".into());
    }
    b.click(&b.find("#file-clear", wait)?)?;
    b.wait_for(shown, wait)?;
    b.eval(
        "document.getElementById('caption').value = 'a lighthouse'; \
         document.getElementById('aspect').value = '16:9'; \
         document.getElementById('negative-prompt').value = 'blurry';",
        json!([]),
    )?;
    b.click(&b.find("#submit", wait)?)?;
    for _ in 0..100 {
        let list: serde_json::Value = serde_json::from_str(&fetch(&format!("{base}/jobs"), None)?)
            .map_err(|e| e.to_string())?;
        let p = &list["jobs"][0]["params"];
        if list["jobs"][0]["kind"] == "text" {
            return if p["aspect"] == "16:9" && p["negative_prompt"] == "blurry" {
                Ok(())
            } else {
                Err(format!("the text job's params: {p}"))
            };
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Err("the text job was not submitted".into())
}

/// The newest job of `kind` in the list, once there is one (polled for 10 s).
fn newest_job(base: &str, kind: &str, after: Option<&str>) -> Result<serde_json::Value, String> {
    for _ in 0..100 {
        let list: serde_json::Value = serde_json::from_str(&fetch(&format!("{base}/jobs"), None)?)
            .map_err(|e| e.to_string())?;
        let job = &list["jobs"][0];
        if job["kind"] == kind && job["id"].as_str() != after {
            return Ok(job.clone());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Err(format!("no new {kind} job was submitted"))
}

/// The bytes of the page's download link `id` (a blob: URL): `[length, first 4 bytes as text,
/// PNG width, PNG height]`.
fn downloaded_head(b: &Browser, id: &str) -> Result<serde_json::Value, String> {
    b.eval_async(
        "const done = arguments[arguments.length - 1]; \
         fetch(document.getElementById(arguments[0]).href).then(r => r.arrayBuffer()).then(buf => { \
           const d = new DataView(buf); \
           done([buf.byteLength, String.fromCharCode(...new Uint8Array(buf.slice(0, 4))), \
                 buf.byteLength > 24 ? d.getUint32(16) : 0, buf.byteLength > 24 ? d.getUint32(20) : 0]); \
         }, e => done('ERR ' + e));",
        json!([id]),
    )
}

/// Colours, background, grouping and 3 variations from the form: a bad palette is refused on
/// the page (naming the field), a good one reaches the job's params; the finished job shows 3
/// thumbnails, picking the third shows it, and its SVG, PDF and PNG (at the chosen size)
/// download links hold variation 3's files.
fn variations_and_colours_reach_the_job(b: &Browser, base: &str) -> Result<(), String> {
    let wait = Duration::from_secs(30);
    let before = newest_job(base, "text", None)?;
    let before_id = before["id"].as_str();
    b.eval(
        "const set = (id, v) => { document.getElementById(id).value = v; }; \
         set('variations', '3'); set('colors', '4'); set('palette', '#e63946, #1d3557 red'); \
         set('background', 'color'); document.getElementById('background').dispatchEvent(new Event('change')); \
         set('background-color', '#ffeecc'); set('group', 'color');",
        json!([]),
    )?;
    b.click(&b.find("#submit", wait)?)?;
    let msg = b.wait_for(
        "const e = document.getElementById('error'); return e && e.textContent.trim();",
        wait,
    )?;
    if !msg
        .as_str()
        .unwrap_or("")
        .starts_with("palette: red is not a colour")
    {
        return Err(format!("a bad palette shows {msg}"));
    }
    b.eval(
        "document.getElementById('palette').value = '#e63946, #1d3557 #FFF';",
        json!([]),
    )?;
    b.click(&b.find("#submit", wait)?)?;
    let job = newest_job(base, "text", before_id)?;
    let p = &job["params"];
    let want = json!({"variations": 3, "colors": 4, "palette": ["#e63946", "#1d3557", "#ffffff"],
        "background": "#ffeecc", "group": "color"});
    for (k, v) in want.as_object().ok_or("want")? {
        if &p[k] != v {
            return Err(format!("params.{k} is {} (want {v}): {p}", p[k]));
        }
    }
    let id = job["id"].as_str().ok_or("id")?;
    b.wait_for(
        "return [...document.querySelectorAll('#variation-list img')].filter(i => i.src.startsWith('blob:')).length === 3;",
        Duration::from_secs(60),
    )?;
    b.click(&b.find("#variation-list button[data-i='3']", wait)?)?;
    b.wait_for(
        "return document.getElementById('result-paths').textContent.startsWith('Variation 3 of 3') \
         && document.getElementById('download-pdf').href.startsWith('blob:') \
         && document.getElementById('download-png').href.startsWith('blob:');",
        wait,
    )?;
    let svg = b.eval_async(
        "const done = arguments[arguments.length - 1]; \
         fetch(document.getElementById('download-svg').href).then(r => r.text()).then(done, e => done('ERR ' + e));",
        json!([]),
    )?;
    let served = fetch(&format!("{base}/jobs/{id}/result/3.svg"), None)?;
    let first = fetch(&format!("{base}/jobs/{id}/result/1.svg"), None)?;
    if svg.as_str() != Some(served.as_str()) || served == first {
        return Err(format!("the picked SVG is not variation 3's: {svg:.200}"));
    }
    let pdf = downloaded_head(b, "download-pdf")?;
    if pdf[1] != "%PDF" {
        return Err(format!("the PDF link holds {pdf}"));
    }
    b.eval(
        "const s = document.getElementById('png-size'); s.value = '512'; s.dispatchEvent(new Event('change'));",
        json!([]),
    )?;
    b.wait_for(
        "const a = document.getElementById('download-png'); return a.href.startsWith('blob:') && a.download.endsWith('-3-512px.png');",
        wait,
    )?;
    let png = downloaded_head(b, "download-png")?;
    if png[1] != "\u{89}PNG" || png[2].as_u64().max(png[3].as_u64()) != Some(512) {
        return Err(format!("the PNG link holds {png}"));
    }
    b.eval(
        "document.getElementById('variation-picker').scrollIntoView({block: 'center'});",
        json!([]),
    )?;
    save(b, "playground-variations.png");
    Ok(())
}

#[test]
fn playground_page_runs_a_job_in_a_real_browser() {
    with_page(None, |b, base| {
        let wait = Duration::from_secs(30);
        save(b, "playground-done.png");
        // The download link holds exactly the bytes of GET /jobs/{id}/result.svg.
        let downloaded = downloaded_svg(b)?;
        let served = served_svg(base, None)?;
        if downloaded.as_str() != Some(served.as_str()) {
            return Err(format!(
                "download differs from result.svg: {downloaded:.200} vs {served:.200}"
            ));
        }
        canvas_controls_reach_a_text_job(b, base)?;
        variations_and_colours_reach_the_job(b, base)?;
        // A bad upload shows the API's message.
        let bad = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("not-an-image.png");
        std::fs::write(&bad, b"this is not a PNG").map_err(|e| e.to_string())?;
        b.type_into(&b.find("#file", wait)?, bad.to_str().ok_or("path")?)?;
        b.click(&b.find("#submit", wait)?)?;
        let msg = b.wait_for(
            "const e = document.getElementById('error'); return e && e.textContent.trim();",
            wait,
        )?;
        let msg = msg.as_str().unwrap_or("");
        if !msg.contains("image") {
            return Err(format!("error region says {msg:?}"));
        }
        b.eval(
            "document.getElementById('error').scrollIntoView({block: 'center'});",
            json!([]),
        )?;
        save(b, "playground-error.png");
        Ok(())
    });
}

#[test]
fn playground_page_asks_for_the_api_key_and_sends_it() {
    const KEY: &str = "operator-key-for-the-page-test";
    with_page(Some(KEY), |b, base| {
        // Without the key the API refuses; the page's download matches what the key reads.
        if fetch(&format!("{base}/jobs"), None).is_ok() {
            return Err("GET /jobs answered without the key".into());
        }
        let downloaded = downloaded_svg(b)?;
        let served = served_svg(base, Some(KEY))?;
        if downloaded.as_str() != Some(served.as_str()) {
            return Err(format!(
                "download differs from result.svg: {downloaded:.200} vs {served:.200}"
            ));
        }
        Ok(())
    });
}
