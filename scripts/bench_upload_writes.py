"""Disk writes per job against its request body (issue #21's "≤ 3× the body size per job"):
starts `vectorfusion serve` (test executor, one worker, a fresh database), submits one vectorize
job with a PNG of random pixels (incompressible, so the body is what it says), waits until it
succeeds, lets the WAL checkpoint run, and reads the server's write_bytes from /proc/PID/io.

    python scripts/bench_upload_writes.py [--vf target/debug/vectorfusion] [--mb 4] [--steps 200]
"""

import argparse
import base64
import io
import json
import os
import socket
import subprocess
import tempfile
import time
import urllib.request

import numpy as np
from PIL import Image


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def write_bytes(pid):
    for line in open(f"/proc/{pid}/io"):
        if line.startswith("write_bytes:"):
            return int(line.split()[1])
    raise RuntimeError("no write_bytes")


def call(url, body=None):
    req = urllib.request.Request(url, data=body, headers={"Content-Type": "application/json"} if body else {})
    with urllib.request.urlopen(req, timeout=60) as r:
        return json.loads(r.read())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--vf", default="target/debug/vectorfusion")
    ap.add_argument("--mb", type=float, default=4.0, help="approximate PNG size")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--step-ms", type=int, default=20)
    args = ap.parse_args()
    side = int((args.mb * 1e6 / 3) ** 0.5)
    rng = np.random.default_rng(0)
    buf = io.BytesIO()
    Image.fromarray(rng.integers(0, 256, (side, side, 3), dtype=np.uint8)).save(buf, "PNG")
    body = json.dumps({"kind": "vectorize", "image": base64.b64encode(buf.getvalue()).decode(),
                       "steps": args.steps, "paths": 16}).encode()
    with tempfile.TemporaryDirectory() as d:
        port = free_port()
        cfg = os.path.join(d, "config.toml")
        with open(cfg, "w") as f:
            f.write("[server]\nmax_body_bytes = 67108864\nmax_stored_upload_bytes = 1073741824\n")
        srv = subprocess.Popen([args.vf, "serve", "--config", cfg, "--bind", f"127.0.0.1:{port}", "--db",
                                os.path.join(d, "jobs.db"), "--workers", "1", "--test-executor", str(args.step_ms)],
                               stderr=subprocess.DEVNULL)
        try:
            base = f"http://127.0.0.1:{port}"
            for _ in range(100):
                try:
                    call(base + "/healthz")
                    break
                except OSError:
                    time.sleep(0.1)
            time.sleep(1.5)
            w0 = write_bytes(srv.pid)
            job = call(base + "/jobs", body)
            while True:
                v = call(f"{base}/jobs/{job['id']}")
                if v["status"] in ("succeeded", "failed", "cancelled"):
                    break
                time.sleep(0.2)
            time.sleep(3)  # the WAL checkpoint runs about once a second
            w1 = write_bytes(srv.pid)
        finally:
            srv.terminate()
            srv.wait(timeout=30)
    out = {"body_bytes": len(body), "server_write_bytes": w1 - w0, "ratio": (w1 - w0) / len(body),
           "status": v["status"], "steps": args.steps, "snapshots_kept": None}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
