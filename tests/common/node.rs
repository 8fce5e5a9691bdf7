//! A `vectorfusion serve` or `worker` child process listening on a port the kernel picks.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// Spawns `cmd` (a `serve` or `worker` command without `--bind`) on `127.0.0.1:0` with the log
/// filter `log` (plus the server's start-up line) and returns it with the address it logged
/// (`listening addr=…`). The port is the child's from its bind on, so no other process can take
/// it between a probe and the bind, as a port found free beforehand could be. The child's other
/// log lines go to this process's stderr when `echo` is set, else nowhere. Also checks that logs
/// written to a pipe carry no terminal colour codes.
pub fn spawn_listening(mut cmd: Command, log: &str, echo: bool) -> (Child, SocketAddr) {
    cmd.args(["--bind", "127.0.0.1:0"])
        .env("RUST_LOG", format!("{log},vectorfusion::server=info"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let mut child = cmd.spawn().expect("spawn the vectorfusion binary");
    let stderr = child.stderr.take().expect("piped stderr");
    let (tx, rx) = std::sync::mpsc::channel();
    // Drains the pipe until the child exits, so the child never blocks on a full pipe.
    std::thread::spawn(move || {
        let mut tx = Some(tx);
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(rest) = line.split(" listening addr=").nth(1) {
                if let Some(tx) = tx.take() {
                    let _ = tx.send((
                        line.clone(),
                        rest.split_whitespace().next().map(str::to_owned),
                    ));
                }
            } else if echo && !line.contains(" INFO ") {
                eprintln!("{line}");
            }
        }
    });
    let (line, addr) = match rx.recv_timeout(Duration::from_secs(30)) {
        Ok(v) => v,
        Err(e) => {
            let _ = child.kill();
            panic!("the child logged no listening address within 30 s ({e})");
        }
    };
    assert!(
        !line.contains('\u{1b}'),
        "colour codes in a piped log: {line:?}"
    );
    let addr = addr
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    (child, addr)
}
