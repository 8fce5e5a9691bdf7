//! Helpers shared by the integration tests (`mod common;`): service clients, fixtures, tensors.
#![allow(dead_code)]

pub mod golden;
pub mod http;
pub mod node;
pub mod recording;
pub mod runs;
pub mod server;
pub mod tensors;
pub mod webdriver;

#[allow(unused_imports)]
pub use tensors::{abs_max, assert_close, fixture, max_abs, tc};

use base64::Engine;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// A small real PNG (checkerboard), base64-encoded.
pub fn png_b64(side: u32) -> String {
    let mut data = Vec::new();
    for y in 0..side {
        for x in 0..side {
            let v = if (x / 2 + y / 2) % 2 == 0 { 1.0 } else { 0.2 };
            data.extend_from_slice(&[v, v * 0.5, 0.3, 1.0]);
        }
    }
    let img = vectorfusion::image::Image {
        width: side,
        height: side,
        data,
    };
    base64::engine::general_purpose::STANDARD.encode(img.encode_png().unwrap())
}

/// Polls `GET /jobs/{id}` until its status is one of `want`.
pub async fn wait_status(
    addr: SocketAddr,
    id: &str,
    want: &[&str],
    timeout: Duration,
) -> serde_json::Value {
    let deadline = Instant::now() + timeout;
    loop {
        let r = http::get(addr, &format!("/jobs/{id}")).await;
        assert_eq!(r.status, 200, "{}", r.text());
        let v = r.json();
        let st = v["status"].as_str().unwrap_or("").to_string();
        if want.contains(&st.as_str()) {
            return v;
        }
        assert!(
            Instant::now() < deadline,
            "job {id} stuck in {st}, wanted {want:?}: {v}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// `dir/targets/red.png`, a red 16 px square on a white 32 px image: the analytic test
/// teacher's one target (`--teacher analytic:DIR`). Returns the targets directory.
pub fn red_square_targets(dir: &std::path::Path) -> std::path::PathBuf {
    let targets = dir.join("targets");
    std::fs::create_dir_all(&targets).unwrap();
    let mut im = vectorfusion::image::Image::filled(32, 32, [1.0; 4]);
    for y in 8..24 {
        for x in 8..24 {
            im.data[4 * (y * 32 + x)..4 * (y * 32 + x) + 4].copy_from_slice(&[0.8, 0.1, 0.1, 1.0]);
        }
    }
    im.save_png(&targets.join("red.png")).unwrap();
    targets
}

/// The variable `.ci/run` sets: there a test whose tool or data is missing fails instead of
/// skipping, so a green CI run means every half of every test ran.
pub const REQUIRE_ALL_ENV: &str = "VF_REQUIRE_ALL";

/// Skips the rest of `test` because `why` (a tool or data is missing): prints `SKIP test: why`
/// locally, and panics where [`REQUIRE_ALL_ENV`] is set to anything but `0`.
pub fn skip(test: &str, why: &str) {
    let required = std::env::var(REQUIRE_ALL_ENV).is_ok_and(|v| !v.is_empty() && v != "0");
    assert!(
        !required,
        "{test}: {why} — {REQUIRE_ALL_ENV} is set, so missing tools fail the test"
    );
    eprintln!("SKIP {test}: {why}");
}

/// Reads a child's `pipe` line by line on a thread of its own until it closes (so the child
/// never blocks on a full pipe) and returns the first value `pick` takes from a line, waiting
/// at most `timeout`; the lines before and after it go to `other`.
pub fn first_from_lines<T: Send + 'static>(
    pipe: impl std::io::Read + Send + 'static,
    timeout: Duration,
    pick: impl Fn(&str) -> Option<T> + Send + 'static,
    other: impl Fn(&str) + Send + 'static,
) -> Option<T> {
    use std::io::BufRead;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut tx = Some(tx);
        for line in std::io::BufReader::new(pipe).lines().map_while(Result::ok) {
            match tx.as_ref().and_then(|_| pick(&line)) {
                Some(v) => {
                    let _ = tx.take().map(|tx| tx.send(v));
                }
                None => other(&line),
            }
        }
    });
    rx.recv_timeout(timeout).ok()
}
