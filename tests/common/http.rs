//! A minimal HTTP/1.1 client over a loopback TcpStream for the service tests and the load bench
//! (one connection per request, `Connection: close`; chunked responses and SSE supported).
#![allow(dead_code)]

use std::net::SocketAddr;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

#[derive(Debug)]
pub struct Resp {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Resp {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "status {} body is not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn parse_head(head: &[u8]) -> (u16, Vec<(String, String)>) {
    let text = String::from_utf8_lossy(head);
    let mut lines = text.split("\r\n");
    let status_line = lines.next().unwrap_or("");
    let status = status_line
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect();
    (status, headers)
}

/// Decodes as many complete chunks from `raw` as possible into `out`; returns true at the end.
pub fn dechunk(raw: &mut Vec<u8>, out: &mut Vec<u8>) -> bool {
    loop {
        let Some(eol) = find(raw, b"\r\n") else {
            return false;
        };
        let size_txt = String::from_utf8_lossy(&raw[..eol]).to_string();
        let size =
            usize::from_str_radix(size_txt.split(';').next().unwrap_or("").trim(), 16).unwrap_or(0);
        if size == 0 {
            return true;
        }
        if raw.len() < eol + 2 + size + 2 {
            return false;
        }
        out.extend_from_slice(&raw[eol + 2..eol + 2 + size]);
        raw.drain(..eol + 2 + size + 2);
    }
}

async fn write_request(
    s: &mut TcpStream,
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: Option<&[u8]>,
    expect_continue: bool,
) -> std::io::Result<()> {
    let mut req = format!("{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n");
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    if let Some(b) = body {
        req.push_str(&format!("Content-Length: {}\r\n", b.len()));
    }
    if expect_continue {
        req.push_str("Expect: 100-continue\r\n");
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).await
}

/// Sends one request and reads the whole response. Bodies over 64 KiB are sent with
/// `Expect: 100-continue` so a server that refuses them answers before the upload.
pub async fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: Option<&[u8]>,
) -> Resp {
    let mut s = TcpStream::connect(addr).await.expect("connect");
    s.set_nodelay(true).ok();
    let big = body.is_some_and(|b| b.len() > 64 * 1024);
    write_request(&mut s, addr, method, path, headers, body, big)
        .await
        .expect("write head");
    let mut buf = Vec::new();
    let mut tmp = vec![0u8; 64 * 1024];
    if let Some(b) = body {
        if big {
            // wait for "100 Continue" or the final answer
            let head_end = loop {
                let n = s.read(&mut tmp).await.expect("read");
                assert!(n > 0, "connection closed before any response");
                buf.extend_from_slice(&tmp[..n]);
                if let Some(p) = find(&buf, b"\r\n\r\n") {
                    break p;
                }
            };
            let (status, _) = parse_head(&buf[..head_end]);
            if status == 100 {
                buf.drain(..head_end + 4);
                s.write_all(b).await.expect("write body");
            }
        } else {
            s.write_all(b).await.expect("write body");
        }
    }
    loop {
        match s.read(&mut tmp).await {
            Ok(0) => break,
            Ok(n) => buf.extend_from_slice(&tmp[..n]),
            Err(e) if !buf.is_empty() => {
                eprintln!("read error after {} bytes: {e}", buf.len());
                break;
            }
            Err(e) => panic!("read: {e}"),
        }
    }
    let head_end = find(&buf, b"\r\n\r\n").expect("response head");
    let (status, headers) = parse_head(&buf[..head_end]);
    let mut raw = buf[head_end + 4..].to_vec();
    let chunked = headers.iter().any(|(k, v)| {
        k.eq_ignore_ascii_case("transfer-encoding") && v.eq_ignore_ascii_case("chunked")
    });
    let body = if chunked {
        let mut out = Vec::new();
        dechunk(&mut raw, &mut out);
        out
    } else {
        raw
    };
    Resp {
        status,
        headers,
        body,
    }
}

pub async fn get(addr: SocketAddr, path: &str) -> Resp {
    request(addr, "GET", path, &[], None).await
}

pub async fn post_json(addr: SocketAddr, path: &str, body: &serde_json::Value) -> Resp {
    let b = serde_json::to_vec(body).unwrap();
    request(
        addr,
        "POST",
        path,
        &[("Content-Type", "application/json")],
        Some(&b),
    )
    .await
}

/// One server-sent event.
#[derive(Clone, Debug, Default)]
pub struct SseEvent {
    pub event: String,
    pub id: Option<String>,
    pub data: String,
}

impl SseEvent {
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_str(&self.data).unwrap()
    }
}

/// Opens an event stream and collects events until `stop` returns true, the stream ends or
/// `timeout` passes. Returns (status, events).
pub async fn sse(
    addr: SocketAddr,
    path: &str,
    headers: &[(&str, &str)],
    timeout: Duration,
    mut stop: impl FnMut(&SseEvent) -> bool,
) -> (u16, Vec<SseEvent>) {
    let mut s = TcpStream::connect(addr).await.expect("connect");
    write_request(&mut s, addr, "GET", path, headers, None, false)
        .await
        .unwrap();
    let deadline = Instant::now() + timeout;
    let mut buf = Vec::new();
    let mut tmp = vec![0u8; 64 * 1024];
    let mut head: Option<(u16, bool)> = None;
    let mut raw = Vec::new();
    let mut text = Vec::new();
    let mut events = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        let n = match tokio::time::timeout(left, s.read(&mut tmp)).await {
            Ok(Ok(n)) => n,
            _ => break,
        };
        if n == 0 {
            break;
        }
        if head.is_none() {
            buf.extend_from_slice(&tmp[..n]);
            let Some(p) = find(&buf, b"\r\n\r\n") else {
                continue;
            };
            let (status, hs) = parse_head(&buf[..p]);
            let chunked = hs.iter().any(|(k, v)| {
                k.eq_ignore_ascii_case("transfer-encoding") && v.eq_ignore_ascii_case("chunked")
            });
            head = Some((status, chunked));
            raw.extend_from_slice(&buf[p + 4..]);
            if status != 200 {
                // error body: read it as JSON later if needed
            }
        } else {
            raw.extend_from_slice(&tmp[..n]);
        }
        let ended = if head.is_some_and(|h| h.1) {
            dechunk(&mut raw, &mut text)
        } else {
            text.append(&mut raw);
            false
        };
        while let Some(p) = find(&text, b"\n\n") {
            let block = String::from_utf8_lossy(&text[..p]).to_string();
            text.drain(..p + 2);
            let mut ev = SseEvent::default();
            let mut is_event = false;
            for line in block.lines() {
                if let Some(v) = line.strip_prefix("event:") {
                    ev.event = v.trim().to_string();
                    is_event = true;
                } else if let Some(v) = line.strip_prefix("data:") {
                    if !ev.data.is_empty() {
                        ev.data.push('\n');
                    }
                    ev.data.push_str(v.strip_prefix(' ').unwrap_or(v));
                    is_event = true;
                } else if let Some(v) = line.strip_prefix("id:") {
                    ev.id = Some(v.trim().to_string());
                }
            }
            if is_event {
                let done = stop(&ev);
                events.push(ev);
                if done {
                    return (head.map_or(0, |h| h.0), events);
                }
            }
        }
        if ended {
            break;
        }
    }
    (head.map_or(0, |h| h.0), events)
}
