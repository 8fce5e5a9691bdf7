//! A minimal W3C WebDriver client (blocking, over `ureq`) for the playground page test: enough
//! to start headless Chromium through `chromedriver`, type, click, read and screenshot.

use serde_json::{Value, json};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const ELEMENT: &str = "element-6066-11e4-a52e-4f735466cecf";

/// A running chromedriver and one browser session; both end on drop.
pub struct Browser {
    base: String,
    session: String,
    driver: Child,
}

/// Where the Debian packages put the driver and the browser.
pub fn installed() -> Option<(String, String)> {
    let find = |names: &[&str]| {
        names
            .iter()
            .find(|p| std::path::Path::new(p).exists())
            .map(|p| p.to_string())
    };
    Some((
        find(&["/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver"])?,
        find(&["/usr/bin/chromium", "/usr/bin/chromium-browser"])?,
    ))
}

fn post(url: &str, body: Value) -> Result<Value, String> {
    match ureq::post(url).send_json(body) {
        Ok(r) => r.into_json().map_err(|e| e.to_string()),
        Err(ureq::Error::Status(code, r)) => {
            Err(format!("{code} {}", r.into_string().unwrap_or_default()))
        }
        Err(e) => Err(e.to_string()),
    }
}

fn get(url: &str) -> Result<Value, String> {
    match ureq::get(url).call() {
        Ok(r) => r.into_json().map_err(|e| e.to_string()),
        Err(ureq::Error::Status(code, r)) => {
            Err(format!("{code} {}", r.into_string().unwrap_or_default()))
        }
        Err(e) => Err(e.to_string()),
    }
}

impl Browser {
    pub fn start(driver: &str, chromium: &str) -> Browser {
        // Port 0: chromedriver binds a port the kernel picks and names it on stdout ("…
        // started successfully on port N."), so no other process can take it first.
        let mut child = Command::new(driver)
            .arg("--port=0")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let port = super::first_from_lines(
            stdout,
            Duration::from_secs(20),
            |line| {
                let rest = line.split("started successfully on port ").nth(1)?;
                rest.trim_end_matches('.').trim().parse::<u16>().ok()
            },
            |_| {},
        );
        let Some(port) = port else {
            let _ = child.kill();
            panic!("chromedriver named no port within 20 s");
        };
        let base = format!("http://127.0.0.1:{port}");
        let deadline = Instant::now() + Duration::from_secs(20);
        while get(&format!("{base}/status")).is_err() {
            assert!(Instant::now() < deadline, "chromedriver did not answer");
            std::thread::sleep(Duration::from_millis(100));
        }
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": chromium,
                "args": ["--headless=new", "--no-sandbox", "--disable-gpu",
                         "--disable-dev-shm-usage", "--window-size=1280,1000"]
            }
        }}});
        let v = post(&format!("{base}/session"), caps).expect("a browser session");
        let session = v["value"]["sessionId"]
            .as_str()
            .expect("session id")
            .to_string();
        Browser {
            base,
            session,
            driver: child,
        }
    }

    fn url(&self, tail: &str) -> String {
        format!("{}/session/{}{tail}", self.base, self.session)
    }

    pub fn goto(&self, url: &str) {
        post(&self.url("/url"), json!({ "url": url })).expect("navigate");
    }

    /// The element for a CSS selector, waiting up to `timeout` for it to exist.
    pub fn find(&self, css: &str, timeout: Duration) -> Result<String, String> {
        let deadline = Instant::now() + timeout;
        loop {
            match post(
                &self.url("/element"),
                json!({"using": "css selector", "value": css}),
            ) {
                Ok(v) => return Ok(v["value"][ELEMENT].as_str().unwrap_or("").to_string()),
                Err(e) if Instant::now() >= deadline => return Err(format!("{css}: {e}")),
                Err(_) => std::thread::sleep(Duration::from_millis(100)),
            }
        }
    }

    pub fn type_into(&self, el: &str, text: &str) -> Result<(), String> {
        post(
            &self.url(&format!("/element/{el}/value")),
            json!({ "text": text }),
        )
        .map(|_| ())
    }

    pub fn click(&self, el: &str) -> Result<(), String> {
        post(&self.url(&format!("/element/{el}/click")), json!({})).map(|_| ())
    }

    /// Runs `script` (a function body; `arguments` are `args`) and returns its value.
    pub fn eval(&self, script: &str, args: Value) -> Result<Value, String> {
        post(
            &self.url("/execute/sync"),
            json!({"script": script, "args": args}),
        )
        .map(|v| v["value"].clone())
    }

    /// Like [`Browser::eval`], for a script that calls `arguments[arguments.length - 1]` when done.
    pub fn eval_async(&self, script: &str, args: Value) -> Result<Value, String> {
        post(
            &self.url("/execute/async"),
            json!({"script": script, "args": args}),
        )
        .map(|v| v["value"].clone())
    }

    /// Polls `script` until it returns a truthy value.
    pub fn wait_for(&self, script: &str, timeout: Duration) -> Result<Value, String> {
        let deadline = Instant::now() + timeout;
        loop {
            let v = self.eval(script, json!([]))?;
            let truthy =
                !matches!(&v, Value::Null | Value::Bool(false)) && v != json!("") && v != json!(0);
            if truthy {
                return Ok(v);
            }
            if Instant::now() >= deadline {
                return Err(format!("timed out waiting for: {script}"));
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// A PNG of the viewport.
    pub fn screenshot(&self) -> Result<Vec<u8>, String> {
        use base64::Engine;
        let v = get(&self.url("/screenshot"))?;
        base64::engine::general_purpose::STANDARD
            .decode(v["value"].as_str().unwrap_or(""))
            .map_err(|e| e.to_string())
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = ureq::delete(&self.url("")).call();
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}
