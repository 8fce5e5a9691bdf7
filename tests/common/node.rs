//! A `vectorfusion serve` or `worker` child process listening on a port the kernel picks.

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
    let line = super::first_from_lines(
        stderr,
        Duration::from_secs(30),
        |line| line.contains(" listening addr=").then(|| line.to_owned()),
        move |line| {
            if echo && !line.contains(" INFO ") {
                eprintln!("{line}");
            }
        },
    );
    let Some(line) = line else {
        let _ = child.kill();
        panic!("the child logged no listening address within 30 s");
    };
    assert!(
        !line.contains('\u{1b}'),
        "colour codes in a piped log: {line:?}"
    );
    let addr = line
        .split(" listening addr=")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    (child, addr)
}
