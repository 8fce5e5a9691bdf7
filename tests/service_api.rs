//! The HTTP API on a real server (127.0.0.1, ephemeral port) with a real SQLite file in a temp
//! dir. Jobs run through the service test double (`worker::test_executor`), which draws a real
//! SVG with `scene`, or through small executors defined here.

mod common;

use common::http::{self, get, post_json, request, sse};
use common::server::TestServer;
use common::{png_b64, wait_status};
use serde_json::{Value, json};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;
use vectorfusion::pipeline::{
    DefaultExecutor, Executor, JobContext, JobSpec, PipelineError, RunOutput,
};
use vectorfusion::progress::{Progress, Stage};
use vectorfusion::worker::test_executor::{TestExecutor, scene_at, scene_svg};

fn vectorize_body(paths: u32, steps: u32, seed: u64) -> Value {
    json!({"kind": "vectorize", "image": png_b64(8), "paths": paths, "steps": steps, "seed": seed})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn vectorize_job_end_to_end_with_events_and_results() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(10)), |_| {}).await;
    let a = srv.addr;
    let r = post_json(a, "/jobs", &vectorize_body(6, 12, 42)).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let job = r.json();
    let id = job["id"].as_str().unwrap().to_string();
    assert_eq!(r.header("location"), Some(format!("/jobs/{id}").as_str()));
    assert!(["queued", "running"].contains(&job["status"].as_str().unwrap()));
    assert_eq!(job["params"]["seed"], 42);

    let (status, events) = sse(
        a,
        &format!("/jobs/{id}/events"),
        &[],
        Duration::from_secs(20),
        |e| e.event == "done" || e.event == "failed",
    )
    .await;
    assert_eq!(status, 200);
    let names: Vec<&str> = events.iter().map(|e| e.event.as_str()).collect();
    assert_eq!(names[0], "state", "{names:?}");
    assert_eq!(*names.last().unwrap(), "done", "{names:?}");
    assert!(
        names.contains(&"progress") || names.contains(&"snapshot"),
        "{names:?}"
    );
    let snaps: Vec<_> = events.iter().filter(|e| e.event == "snapshot").collect();
    assert!(!snaps.is_empty(), "{names:?}");
    for s in &snaps {
        let v = s.json();
        assert_eq!(s.id.as_deref(), Some(v["n"].to_string().as_str()));
        assert!(v["svg"].as_str().unwrap().starts_with("<svg"));
    }
    let done = events.last().unwrap().json();
    assert_eq!(done["status"], "succeeded");

    // the result is exactly the executor's final drawing, and valid SVG
    let r = get(a, &format!("/jobs/{id}/result.svg")).await;
    assert_eq!(r.status, 200);
    assert!(
        r.header("content-type")
            .unwrap()
            .starts_with("image/svg+xml")
    );
    // opened directly, it can run and load nothing, and is not sniffed as another type
    assert_eq!(
        r.header("content-security-policy"),
        Some("default-src 'none'; style-src 'unsafe-inline'")
    );
    assert_eq!(r.header("x-content-type-options"), Some("nosniff"));
    let expected = scene_svg(&scene_at(42, 6, 12, 12).unwrap());
    assert_eq!(r.text(), expected);
    resvg::usvg::Tree::from_str(&r.text(), &resvg::usvg::Options::default()).unwrap();
    vectorfusion::svg::check_safe_output(&r.text()).unwrap();

    let r = get(a, &format!("/jobs/{id}/result.png")).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), Some("image/png"));
    let png = vectorfusion::image::Image::decode(&r.body).unwrap();
    assert_eq!((png.width, png.height), (64, 64));

    let r = get(a, &format!("/jobs/{id}/snapshots/1.svg")).await;
    assert_eq!(r.status, 200);
    assert!(r.text().starts_with("<svg"));
    vectorfusion::svg::check_safe_output(&r.text()).unwrap();

    let v = wait_status(a, &id, &["succeeded"], Duration::from_secs(1)).await;
    assert_eq!(v["attempts"], 1);
    assert_eq!(v["progress"]["step"], 12);
    assert_eq!(v["progress"]["fraction"], 1.0);
    assert_eq!(v["attempt_history"][0]["outcome"], "succeeded");
    // Times in RFC 3339, as every other time of the job.
    let started = v["attempt_history"][0]["started_at"].as_str().unwrap();
    chrono::DateTime::parse_from_rfc3339(started).unwrap();
    assert!(v["attempt_history"][0]["finished_at"].is_string());
    assert!(v["run_ms"].as_i64().unwrap() >= 0);

    let r = get(a, "/jobs?status=succeeded&limit=10").await;
    assert_eq!(r.status, 200);
    assert_eq!(r.json()["jobs"][0]["id"], id.as_str());
    // Cache-busters (names starting with _) are ignored; a typo is a 400 naming it.
    let r = get(a, "/jobs?status=succeeded&_=1712").await;
    assert_eq!(r.status, 200, "{}", r.text());
    let r = get(a, "/jobs?stauts=succeeded").await;
    assert_eq!(r.status, 400);
    assert_eq!(r.json()["error"]["field"], "stauts");

    let m = get(a, "/metrics").await.text();
    assert!(m.contains("vectorfusion_jobs_succeeded_total 1"), "{m}");
    assert!(
        m.contains("vectorfusion_jobs{status=\"succeeded\"} 1"),
        "{m}"
    );
    assert!(
        m.contains("vectorfusion_stage_duration_seconds_count{stage=\"test\"} 1"),
        "{m}"
    );

    // Resuming with Last-Event-ID replays only later snapshots, then the terminal event.
    let last_n: i64 = snaps.last().unwrap().id.as_ref().unwrap().parse().unwrap();
    let (_, replay) = sse(
        a,
        &format!("/jobs/{id}/events"),
        &[("Last-Event-ID", "1")],
        Duration::from_secs(5),
        |e| e.event == "done",
    )
    .await;
    let ns: Vec<i64> = replay
        .iter()
        .filter(|e| e.event == "snapshot")
        .map(|e| e.json()["n"].as_i64().unwrap())
        .collect();
    assert_eq!(ns, (2..=last_n).collect::<Vec<_>>());
    assert_eq!(replay.first().unwrap().event, "state");
    assert_eq!(replay.last().unwrap().event, "done");
    // Every event is a resumption point: its id is the last snapshot sent so far (1 before the
    // replayed ones here, as the client said), never going back.
    let ids: Vec<i64> = replay
        .iter()
        .map(|e| {
            e.id.as_deref()
                .expect("every event has an id")
                .parse()
                .unwrap()
        })
        .collect();
    assert_eq!(ids[0], 1, "{ids:?}");
    assert!(ids.windows(2).all(|w| w[0] <= w[1]), "{ids:?}");
    assert_eq!(*ids.last().unwrap(), last_n);

    // A first connection asks for a full replay with ?from=0 (cache-busters are ignored).
    let (_, full) = sse(
        a,
        &format!("/jobs/{id}/events?from=0&_=123"),
        &[],
        Duration::from_secs(5),
        |e| e.event == "done",
    )
    .await;
    let ns: Vec<i64> = full
        .iter()
        .filter(|e| e.event == "snapshot")
        .map(|e| e.json()["n"].as_i64().unwrap())
        .collect();
    assert_eq!(ns, (1..=last_n).collect::<Vec<_>>());
    assert_eq!(full.first().unwrap().id.as_deref(), Some("0"));
    let r = get(a, &format!("/jobs/{id}/events?from=-1")).await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert_eq!(r.json()["error"]["field"], "from");

    // Generated clients that only know files ask for application/octet-stream: same bytes.
    for (path, native) in [
        ("result.svg", "image/svg+xml"),
        ("result.png", "image/png"),
        ("result.pdf", "application/pdf"),
        ("snapshots/1.svg", "image/svg+xml"),
    ] {
        let path = format!("/jobs/{id}/{path}");
        let plain = get(a, &path).await;
        let octet = request(
            a,
            "GET",
            &path,
            &[("Accept", "application/octet-stream")],
            None,
        )
        .await;
        assert_eq!(octet.status, 200);
        assert_eq!(
            octet.header("content-type"),
            Some("application/octet-stream")
        );
        assert_eq!(octet.body, plain.body);
        let both = request(
            a,
            "GET",
            &path,
            &[("Accept", &format!("{native}, application/octet-stream"))],
            None,
        )
        .await;
        assert!(both.header("content-type").unwrap().starts_with(native));
    }
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn list_paginates_with_cursor() {
    // no workers would be ideal; one slow worker leaves the rest queued
    let srv = TestServer::start(Arc::new(TestExecutor::new(200)), |c| c.queue.workers = 1).await;
    let mut ids = Vec::new();
    for i in 0..5 {
        let r = post_json(srv.addr, "/jobs", &vectorize_body(2, 500, i)).await;
        assert_eq!(r.status, 202);
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }
    let mut seen = Vec::new();
    let mut path = "/jobs?limit=2".to_string();
    loop {
        let page = get(srv.addr, &path).await.json();
        for j in page["jobs"].as_array().unwrap() {
            seen.push(j["id"].as_str().unwrap().to_string());
        }
        match page["next_cursor"].as_str() {
            Some(c) => path = format!("/jobs?limit=2&cursor={c}"),
            None => break,
        }
    }
    ids.reverse();
    assert_eq!(seen, ids, "newest first, every job once");
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_running_and_queued_jobs() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(20)), |c| c.queue.workers = 1).await;
    let a = srv.addr;
    let running = post_json(a, "/jobs", &vectorize_body(3, 5000, 1))
        .await
        .json();
    let rid = running["id"].as_str().unwrap().to_string();
    wait_status(a, &rid, &["running"], Duration::from_secs(5)).await;
    let queued = post_json(a, "/jobs", &vectorize_body(3, 10, 2))
        .await
        .json();
    let qid = queued["id"].as_str().unwrap().to_string();

    // queued → cancelled at once
    let r = request(a, "DELETE", &format!("/jobs/{qid}"), &[], None).await;
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json()["status"], "cancelled");

    // running → stops at its next step
    let (_, events) = {
        let path = format!("/jobs/{rid}/events");
        let watcher = tokio::spawn(async move {
            sse(a, &path, &[], Duration::from_secs(10), |e| {
                e.event == "cancelled"
            })
            .await
        });
        tokio::time::sleep(Duration::from_millis(100)).await;
        let r = request(a, "DELETE", &format!("/jobs/{rid}"), &[], None).await;
        assert_eq!(r.status, 200, "{}", r.text());
        assert_eq!(r.json()["cancel_requested"], true);
        watcher.await.unwrap()
    };
    assert_eq!(events.last().unwrap().event, "cancelled");
    let v = wait_status(a, &rid, &["cancelled"], Duration::from_secs(5)).await;
    assert!(v["progress"]["step"].as_i64().unwrap() < 5000);
    assert_eq!(v["attempt_history"][0]["outcome"], "cancelled");
    // cancelling again is harmless; there is no result
    assert_eq!(
        request(a, "DELETE", &format!("/jobs/{rid}"), &[], None)
            .await
            .status,
        200
    );
    let r = get(a, &format!("/jobs/{rid}/result.svg")).await;
    assert_eq!(r.status, 409);
    assert_eq!(r.json()["error"]["code"], "conflict");
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idempotency_key_returns_the_same_job() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |_| {}).await;
    let body = serde_json::to_vec(&vectorize_body(2, 3, 5)).unwrap();
    let h = [
        ("Content-Type", "application/json"),
        ("Idempotency-Key", "abc-123"),
    ];
    let r1 = request(srv.addr, "POST", "/jobs", &h, Some(&body)).await;
    let r2 = request(srv.addr, "POST", "/jobs", &h, Some(&body)).await;
    assert_eq!(r1.status, 202);
    assert_eq!(r2.status, 202);
    assert_eq!(r1.json()["id"], r2.json()["id"]);
    assert_eq!(r2.header("idempotent-replayed"), Some("true"));
    assert_eq!(r1.header("idempotent-replayed"), None);
    // The same request re-serialised is the same request: keys reordered, other spacing, a
    // trailing newline, null for an omitted field, a default spelled out, the image as a data URL.
    let same = format!(
        "{{ \"seed\": 5,\n  \"steps\": 3, \"style\": null, \"background\": \"auto\",\n  \
         \"image\": \"data:image/png;base64,{}\", \"paths\": 2, \"kind\": \"vectorize\" }}\n",
        png_b64(8)
    );
    let r = request(srv.addr, "POST", "/jobs", &h, Some(same.as_bytes())).await;
    assert_eq!(r.status, 202, "{}", r.text());
    assert_eq!(r.json()["id"], r1.json()["id"]);
    assert_eq!(r.header("idempotent-replayed"), Some("true"));
    let other = serde_json::to_vec(&vectorize_body(2, 3, 6)).unwrap();
    let r3 = request(srv.addr, "POST", "/jobs", &h, Some(&other)).await;
    assert_eq!(r3.status, 409);
    assert_eq!(r3.json()["error"]["code"], "idempotency_conflict");
    let all = get(srv.addr, "/jobs").await.json();
    assert_eq!(all["jobs"].as_array().unwrap().len(), 1);
    // The canvas and the negative prompt are part of the request: another one conflicts.
    let text = |extra: Value| {
        let mut b = json!({"kind": "text", "caption": "a cat", "seed": 1, "aspect": "16:9",
            "negative_prompt": "blurry"});
        b.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        serde_json::to_vec(&b).unwrap()
    };
    let h = [
        ("Content-Type", "application/json"),
        ("Idempotency-Key", "text-1"),
    ];
    let first = request(srv.addr, "POST", "/jobs", &h, Some(&text(json!({})))).await;
    assert_eq!(first.status, 202, "{}", first.text());
    let again = request(
        srv.addr,
        "POST",
        "/jobs",
        &h,
        Some(&text(json!({"width": null}))),
    )
    .await;
    assert_eq!(again.json()["id"], first.json()["id"]);
    for other in [
        json!({"aspect": "9:16"}),
        json!({"negative_prompt": "text"}),
    ] {
        let r = request(srv.addr, "POST", "/jobs", &h, Some(&text(other.clone()))).await;
        assert_eq!(r.status, 409, "{other}: {}", r.text());
    }
    srv.stop().await;
}

/// Expected status, error code and field for one bad request.
struct Case {
    name: &'static str,
    method: &'static str,
    path: String,
    content_type: Option<&'static str>,
    body: Option<Vec<u8>>,
    status: u16,
    code: &'static str,
    field: Option<&'static str>,
}

fn json_case(name: &'static str, body: Value, code: &'static str, field: &'static str) -> Case {
    Case {
        name,
        method: "POST",
        path: "/jobs".into(),
        content_type: Some("application/json"),
        body: Some(serde_json::to_vec(&body).unwrap()),
        status: 400,
        code,
        field: Some(field),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_input_gets_clear_4xx_json_never_500() {
    let limit = 256 * 1024;
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.max_body_bytes = limit;
        c.limits.max_paths = 256;
    })
    .await;
    let a = srv.addr;
    let b64 = |b: &[u8]| {
        use base64::Engine;
        base64::engine::general_purpose::STANDARD.encode(b)
    };
    let unknown = uuid::Uuid::new_v4();
    let raw = |name, method, path: &str, ct, body: Option<&[u8]>, status, code| Case {
        name,
        method,
        path: path.to_string(),
        content_type: ct,
        body: body.map(|b| b.to_vec()),
        status,
        code,
        field: None,
    };
    let mut cases = vec![
        raw(
            "malformed json",
            "POST",
            "/jobs",
            Some("application/json"),
            Some(b"{\"kind\": "),
            400,
            "malformed_json",
        ),
        raw(
            "not an object",
            "POST",
            "/jobs",
            Some("application/json"),
            Some(b"[1,2]"),
            400,
            "malformed_json",
        ),
        raw(
            "empty body",
            "POST",
            "/jobs",
            Some("application/json"),
            Some(b""),
            400,
            "malformed_json",
        ),
        raw(
            "invalid utf-8",
            "POST",
            "/jobs",
            Some("application/json"),
            Some(b"{\"kind\":\"text\",\"caption\":\"\xff\xfe\"}"),
            400,
            "malformed_json",
        ),
        raw(
            "form body",
            "POST",
            "/jobs",
            Some("application/x-www-form-urlencoded"),
            Some(b"kind=text"),
            415,
            "unsupported_media_type",
        ),
        raw(
            "no content type",
            "POST",
            "/jobs",
            None,
            Some(b"{}"),
            415,
            "unsupported_media_type",
        ),
        raw(
            "huge body",
            "POST",
            "/jobs",
            Some("application/json"),
            Some(&vec![b' '; limit + 10]),
            413,
            "payload_too_large",
        ),
        raw(
            "unknown job",
            "GET",
            &format!("/jobs/{unknown}"),
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "not a uuid",
            "GET",
            "/jobs/12345",
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "unknown job events",
            "GET",
            &format!("/jobs/{unknown}/events"),
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "unknown job result",
            "GET",
            &format!("/jobs/{unknown}/result.svg"),
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "unknown job png",
            "GET",
            &format!("/jobs/{unknown}/result.png"),
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "unknown job cancel",
            "DELETE",
            &format!("/jobs/{unknown}"),
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "bad snapshot name",
            "GET",
            &format!("/jobs/{unknown}/snapshots/abc.svg"),
            None,
            None,
            404,
            "not_found",
        ),
        raw(
            "unknown route",
            "GET",
            "/nope",
            None,
            None,
            404,
            "no_such_route",
        ),
        raw(
            "wrong method",
            "PUT",
            "/jobs",
            None,
            None,
            405,
            "method_not_allowed",
        ),
        raw(
            "bad status filter",
            "GET",
            "/jobs?status=done",
            None,
            None,
            400,
            "invalid_query",
        ),
        raw(
            "empty status filter (not in the enum)",
            "GET",
            "/jobs?status=",
            None,
            None,
            400,
            "invalid_query",
        ),
        raw(
            "empty cursor",
            "GET",
            "/jobs?cursor=",
            None,
            None,
            400,
            "invalid_query",
        ),
        raw(
            "bad limit",
            "GET",
            "/jobs?limit=0",
            None,
            None,
            400,
            "invalid_query",
        ),
        raw(
            "bad cursor",
            "GET",
            "/jobs?cursor=xyz",
            None,
            None,
            400,
            "invalid_query",
        ),
        raw(
            "unknown query param",
            "GET",
            "/jobs?colour=red",
            None,
            None,
            400,
            "invalid_query",
        ),
        raw(
            "unknown events query param",
            "GET",
            "/jobs/00000000-0000-4000-8000-000000000000/events?colour=red",
            None,
            None,
            400,
            "invalid_query",
        ),
    ];
    cases.extend([
        json_case(
            "a seed JavaScript cannot keep exactly",
            json!({"kind": "text", "caption": "a cat", "seed": 9007199254740992_u64}),
            "invalid_field",
            "seed",
        ),
        json_case(
            "a command-line alias of a style",
            json!({"kind": "text", "caption": "a cat", "style": "pixel"}),
            "invalid_field",
            "style",
        ),
        json_case(
            "a command-line alias of a preset",
            json!({"kind": "text", "caption": "a cat", "preset": "quality"}),
            "invalid_field",
            "preset",
        ),
        json_case(
            "missing kind",
            json!({"caption": "a cat"}),
            "invalid_field",
            "kind",
        ),
        json_case(
            "unknown kind",
            json!({"kind": "draw", "caption": "a cat"}),
            "invalid_field",
            "kind",
        ),
        json_case(
            "kind wrong type",
            json!({"kind": 7}),
            "invalid_field",
            "kind",
        ),
        json_case(
            "unknown field",
            json!({"kind": "text", "caption": "a cat", "colour": "red"}),
            "invalid_field",
            "colour",
        ),
        json_case(
            "colors zero",
            json!({"kind": "vectorize", "image": png_b64(8), "colors": 0}),
            "invalid_field",
            "colors",
        ),
        json_case(
            "colors above the cap",
            json!({"kind": "text", "caption": "a cat", "colors": 65}),
            "invalid_field",
            "colors",
        ),
        json_case(
            "malformed palette",
            json!({"kind": "vectorize", "image": png_b64(8), "palette": ["#ff0000", "red"]}),
            "invalid_field",
            "palette",
        ),
        json_case(
            "empty palette",
            json!({"kind": "vectorize", "image": png_b64(8), "palette": []}),
            "invalid_field",
            "palette",
        ),
        json_case(
            "bad background",
            json!({"kind": "vectorize", "image": png_b64(8), "background": "blue"}),
            "invalid_field",
            "background",
        ),
        json_case(
            "bad group",
            json!({"kind": "vectorize", "image": png_b64(8), "group": "layers"}),
            "invalid_field",
            "group",
        ),
        json_case(
            "target_psnr out of range",
            json!({"kind": "vectorize", "image": png_b64(8), "target_psnr": 0}),
            "invalid_field",
            "target_psnr",
        ),
        json_case(
            "max_bytes too small",
            json!({"kind": "vectorize", "image": png_b64(8), "max_bytes": 10}),
            "invalid_field",
            "max_bytes",
        ),
        json_case(
            "fill unknown",
            json!({"kind": "vectorize", "image": png_b64(8), "fill": "conic"}),
            "invalid_field",
            "fill",
        ),
        json_case(
            "fill gradient with a palette",
            json!({"kind": "vectorize", "image": png_b64(8), "fill": "linear", "colors": 4}),
            "invalid_field",
            "fill",
        ),
        json_case(
            "max_bytes on a text job",
            json!({"kind": "text", "caption": "a cat", "max_bytes": 4000}),
            "invalid_field",
            "max_bytes",
        ),
        json_case(
            "paths wrong type",
            json!({"kind": "text", "caption": "a cat", "paths": "many"}),
            "invalid_field",
            "paths",
        ),
        json_case(
            "paths zero",
            json!({"kind": "text", "caption": "a cat", "paths": 0}),
            "invalid_field",
            "paths",
        ),
        json_case(
            "paths over limit",
            json!({"kind": "text", "caption": "a cat", "paths": 257}),
            "invalid_field",
            "paths",
        ),
        json_case(
            "paths negative",
            json!({"kind": "text", "caption": "a cat", "paths": -3}),
            "invalid_field",
            "paths",
        ),
        json_case(
            "paths fractional",
            json!({"kind": "text", "caption": "a cat", "paths": 1.5}),
            "invalid_field",
            "paths",
        ),
        json_case(
            "steps huge",
            json!({"kind": "text", "caption": "a cat", "steps": 99999999999u64}),
            "invalid_field",
            "steps",
        ),
        json_case(
            "seed negative",
            json!({"kind": "text", "caption": "a cat", "seed": -1}),
            "invalid_field",
            "seed",
        ),
        json_case(
            "samples zero",
            json!({"kind": "text", "caption": "a cat", "samples": 0}),
            "invalid_field",
            "samples",
        ),
        json_case(
            "priority out of range",
            json!({"kind": "text", "caption": "a cat", "priority": 1000}),
            "invalid_field",
            "priority",
        ),
        json_case(
            "bad style",
            json!({"kind": "text", "caption": "a cat", "style": "oil"}),
            "invalid_field",
            "style",
        ),
        json_case(
            "bad method",
            json!({"kind": "text", "caption": "a cat", "method": "magic"}),
            "invalid_field",
            "method",
        ),
        json_case(
            "bad preset",
            json!({"kind": "text", "caption": "a cat", "preset": "turbo"}),
            "invalid_field",
            "preset",
        ),
        json_case(
            "empty caption",
            json!({"kind": "text", "caption": "   "}),
            "invalid_field",
            "caption",
        ),
        json_case(
            "caption missing",
            json!({"kind": "text"}),
            "invalid_field",
            "caption",
        ),
        json_case(
            "caption too long",
            json!({"kind": "text", "caption": "x".repeat(1001)}),
            "invalid_field",
            "caption",
        ),
        json_case(
            "caption control chars",
            json!({"kind": "text", "caption": "a\u{0}b"}),
            "invalid_field",
            "caption",
        ),
        json_case(
            "image missing",
            json!({"kind": "vectorize"}),
            "invalid_field",
            "image",
        ),
        json_case(
            "bad base64",
            json!({"kind": "vectorize", "image": "!!!not base64!!!"}),
            "invalid_field",
            "image",
        ),
        json_case(
            "non-image bytes",
            json!({"kind": "vectorize", "image": b64(b"hello, I am not a picture")}),
            "invalid_field",
            "image",
        ),
        json_case(
            "truncated png",
            json!({"kind": "vectorize", "image": b64(&b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR"[..])}),
            "invalid_field",
            "image",
        ),
        json_case(
            "gif not allowed",
            json!({"kind": "vectorize", "image": b64(b"GIF89a\x01\0\x01\0\0\0\0;")}),
            "invalid_field",
            "image",
        ),
        json_case(
            "image on text",
            json!({"kind": "text", "caption": "a", "image": png_b64(4)}),
            "invalid_field",
            "image",
        ),
        json_case(
            "method on vectorize",
            json!({"kind": "vectorize", "image": png_b64(4), "method": "scratch"}),
            "invalid_field",
            "method",
        ),
        json_case(
            "bad svg",
            json!({"kind": "text", "caption": "a cat", "svg": "<not really svg"}),
            "invalid_field",
            "svg",
        ),
        json_case(
            "svg wrong type",
            json!({"kind": "text", "caption": "a cat", "svg": {"d": 1}}),
            "invalid_field",
            "svg",
        ),
    ]);
    // The canvas and the negative prompt: each refusal names its field.
    for (name, body, field) in [
        ("unknown aspect", json!({"aspect": "5:4"}), "aspect"),
        (
            "aspect and size",
            json!({"aspect": "16:9", "width": 640, "height": 360}),
            "width",
        ),
        ("width alone", json!({"width": 640}), "height"),
        ("height alone", json!({"height": 640}), "width"),
        (
            "narrow canvas",
            json!({"width": 63, "height": 640}),
            "width",
        ),
        (
            "huge canvas",
            json!({"width": 640, "height": 4096}),
            "height",
        ),
        (
            "blank negative prompt",
            json!({"negative_prompt": "  "}),
            "negative_prompt",
        ),
        (
            "long negative prompt",
            json!({"negative_prompt": "x".repeat(1001)}),
            "negative_prompt",
        ),
        (
            "size conditioning out of range",
            json!({"size_conditioning": {"original_width": 0.0}}),
            "size_conditioning.original_width",
        ),
        (
            "unknown size conditioning field",
            json!({"size_conditioning": {"width": 1024}}),
            "size_conditioning",
        ),
        (
            "size conditioning not an object",
            json!({"size_conditioning": "1024x1024"}),
            "size_conditioning",
        ),
        (
            "size conditioning as an array",
            json!({"size_conditioning": [1024, 1024, 0, 0]}),
            "size_conditioning",
        ),
    ] {
        let mut b = json!({"kind": "text", "caption": "a cat"});
        b.as_object_mut()
            .unwrap()
            .extend(body.as_object().unwrap().clone());
        cases.push(json_case(name, b, "invalid_field", field));
    }
    for field in ["aspect", "negative_prompt", "size_conditioning"] {
        let v = match field {
            "aspect" => json!("16:9"),
            "negative_prompt" => json!("blurry"),
            _ => json!({"original_width": 1024}),
        };
        cases.push(json_case(
            "canvas on vectorize",
            json!({"kind": "vectorize", "image": png_b64(4), field: v}),
            "invalid_field",
            field,
        ));
    }
    for c in &cases {
        let mut headers = Vec::new();
        if let Some(ct) = c.content_type {
            headers.push(("Content-Type", ct));
        }
        let r = request(a, c.method, &c.path, &headers, c.body.as_deref()).await;
        assert_eq!(r.status, c.status, "{}: {}", c.name, r.text());
        assert!(
            r.header("content-type")
                .unwrap_or("")
                .starts_with("application/json"),
            "{}: content type {:?}",
            c.name,
            r.header("content-type")
        );
        let v = r.json();
        assert_eq!(v["error"]["code"], c.code, "{}: {v}", c.name);
        assert!(
            !v["error"]["reason"].as_str().unwrap().is_empty(),
            "{}",
            c.name
        );
        if let Some(f) = c.field {
            assert_eq!(v["error"]["field"], f, "{}: {v}", c.name);
        }
    }
    // Captions in any language are accepted.
    for caption in ["自転車", "велосипед", "دراجة", "🚲 a bicycle", "vélo"] {
        let r = post_json(
            a,
            "/jobs",
            &json!({"kind": "text", "caption": caption, "steps": 2, "paths": 2}),
        )
        .await;
        assert_eq!(r.status, 202, "{caption}: {}", r.text());
        let v = r.json();
        assert_eq!(v["params"]["caption"], caption);
        let id = v["id"].as_str().unwrap().to_string();
        let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(10)).await;
        assert_eq!(done["status"], "succeeded", "{done}");
        assert_eq!(done["params"]["caption"], caption);
    }
    // Nothing above was a server error.
    let m = get(a, "/metrics").await.text();
    assert!(
        !m.contains("vectorfusion_http_responses_total{code=\"500\"}"),
        "{m}"
    );
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn text_jobs_refused_at_submit_when_models_are_missing() {
    let srv = TestServer::start(Arc::new(DefaultExecutor::default()), |_| {}).await;
    let r = post_json(
        srv.addr,
        "/jobs",
        &json!({"kind": "text", "caption": "a red bicycle"}),
    )
    .await;
    assert_eq!(r.status, 503, "{}", r.text());
    let v = r.json();
    assert_eq!(v["error"]["code"], "models_not_configured");
    let reason = v["error"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("sd_dir") && reason.contains("config.toml"),
        "{reason}"
    );
    let ready = get(srv.addr, "/readyz").await;
    assert_eq!(ready.status, 200);
    assert_eq!(ready.json()["text_jobs_accepted"], false);
    // nothing was queued
    assert_eq!(
        get(srv.addr, "/jobs").await.json()["jobs"]
            .as_array()
            .unwrap()
            .len(),
        0
    );
    // vectorize jobs need no models: accepted and traced with LIVE by the real executor
    let mut body = vectorize_body(4, 10, 1);
    body["preset"] = json!("draft");
    let r = post_json(srv.addr, "/jobs", &body).await;
    assert_eq!(r.status, 202);
    let id = r.json()["id"].as_str().unwrap().to_string();
    let v = wait_status(srv.addr, &id, &["succeeded"], Duration::from_secs(60)).await;
    assert_eq!(v["attempts"], 1);
    let svg = get(srv.addr, &format!("/jobs/{id}/result.svg"))
        .await
        .text();
    assert!(svg.starts_with("<svg"), "{svg}");
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_queue_answers_429_with_retry_after() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(50)), |c| {
        c.queue.workers = 1;
        c.server.max_queue_depth = 2;
    })
    .await;
    let first = post_json(srv.addr, "/jobs", &vectorize_body(2, 1000, 1))
        .await
        .json();
    wait_status(
        srv.addr,
        first["id"].as_str().unwrap(),
        &["running"],
        Duration::from_secs(5),
    )
    .await;
    assert_eq!(
        post_json(srv.addr, "/jobs", &vectorize_body(2, 10, 0))
            .await
            .status,
        202
    );
    let keyed = |key: &'static str| {
        [
            ("Content-Type", "application/json"),
            ("Idempotency-Key", key),
        ]
    };
    let body = serde_json::to_vec(&vectorize_body(2, 10, 1)).unwrap();
    let kept = request(srv.addr, "POST", "/jobs", &keyed("k-1"), Some(&body)).await;
    assert_eq!(kept.status, 202);
    let r = post_json(srv.addr, "/jobs", &vectorize_body(2, 10, 9)).await;
    assert_eq!(r.status, 429, "{}", r.text());
    assert_eq!(r.json()["error"]["code"], "queue_full");
    assert!(r.header("retry-after").is_some());
    // A retry with a known Idempotency-Key gets its job back although the queue is full; the
    // same key with another body is still a conflict, and a new key is still refused.
    let again = request(srv.addr, "POST", "/jobs", &keyed("k-1"), Some(&body)).await;
    assert_eq!(again.status, 202, "{}", again.text());
    assert_eq!(again.json()["id"], kept.json()["id"]);
    assert_eq!(again.header("idempotent-replayed"), Some("true"));
    let other = serde_json::to_vec(&vectorize_body(2, 10, 2)).unwrap();
    let r = request(srv.addr, "POST", "/jobs", &keyed("k-1"), Some(&other)).await;
    assert_eq!(r.status, 409, "{}", r.text());
    let r = request(srv.addr, "POST", "/jobs", &keyed("k-2"), Some(&other)).await;
    assert_eq!(r.status, 429, "{}", r.text());
    let m = get(srv.addr, "/metrics").await.text();
    assert!(m.contains("vectorfusion_jobs_rejected_total 2"), "{m}");
    assert!(m.contains("vectorfusion_queue_depth 2"), "{m}");
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn omitted_paths_steps_samples_are_the_presets_and_are_recorded() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.limits.max_steps = 600;
    })
    .await;
    let params = |body: Value| async move {
        let r = post_json(srv.addr, "/jobs", &body).await;
        assert_eq!(r.status, 202, "{}", r.text());
        let id = r.json()["id"].as_str().unwrap().to_string();
        let job = get(srv.addr, &format!("/jobs/{id}")).await.json();
        let p = &job["params"];
        (p["paths"].clone(), p["steps"].clone(), p["samples"].clone())
    };
    // The same resolution as `generate --preset` (the run plan).
    let text = |preset: &str, style: &str| json!({"kind": "text", "caption": "a crown", "preset": preset, "style": style});
    assert_eq!(
        params(text("draft", "iconography")).await,
        (json!(8), json!(8), json!(2))
    );
    assert_eq!(
        params(text("fast", "iconography")).await,
        (json!(16), json!(100), json!(4))
    );
    assert_eq!(
        params(text("fast", "pixel_art")).await,
        (json!(1024), json!(100), json!(4))
    );
    assert_eq!(
        params(text("balanced", "sketch")).await,
        (json!(16), json!(500), json!(8))
    );
    // Explicit values win, one at a time.
    let mut b = text("fast", "iconography");
    b["steps"] = json!(3);
    assert_eq!(params(b).await, (json!(16), json!(3), json!(4)));
    // No preset: the default (balanced).
    let no_preset = json!({"kind": "text", "caption": "a crown"});
    assert_eq!(params(no_preset).await, (json!(64), json!(500), json!(8)));
    // Vectorize: the preset's LIVE budget.
    let v = json!({"kind": "vectorize", "image": png_b64(8), "preset": "fast"});
    assert_eq!(params(v).await.0, json!(64));
    // The new styles are stored and shown with the plan the job runs with.
    for (given, canonical, paths) in [("low_poly", "low_poly", 8), ("painting", "painting", 8)] {
        let r = post_json(srv.addr, "/jobs", &text("draft", given)).await;
        assert_eq!(r.status, 202, "{}", r.text());
        let id = r.json()["id"].as_str().unwrap().to_string();
        let job = get(srv.addr, &format!("/jobs/{id}")).await.json();
        assert_eq!(job["params"]["style"], canonical, "{job}");
        let plan = &job["params"]["plan"]["text"];
        assert_eq!(plan["style"], canonical, "{job}");
        assert_eq!(plan["paths"], paths, "{job}");
        assert_eq!(plan["sds"]["steps"], 8, "{job}");
        assert_eq!(plan["size"], 32, "{job}");
        assert!(plan["seeds"]["init"].is_u64(), "{job}");
    }
    let r = post_json(srv.addr, "/jobs", &text("draft", "oil")).await;
    assert_eq!(r.status, 400, "{}", r.text());
    // A preset value above this server's limit names the preset.
    let r = post_json(srv.addr, "/jobs", &text("paper", "iconography")).await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert_eq!(r.json()["error"]["field"], "steps");
    let reason = r.json()["error"]["reason"].as_str().unwrap().to_string();
    assert!(reason.contains("preset paper"), "{reason}");
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn vector_options_are_stored_and_reach_the_plan() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |_| {}).await;
    let body = json!({
        "kind": "vectorize", "image": png_b64(8), "colors": 3,
        "palette": ["#E63946", " #fff", "#e63946"], "background": "#abc", "group": "color",
        "target_psnr": 31.5, "max_bytes": 4000, "style": null
    });
    let r = post_json(srv.addr, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let job = get(srv.addr, &format!("/jobs/{id}")).await.json();
    let p = &job["params"];
    // Normalised once: lower-case #rrggbb, repeated colours kept once.
    assert_eq!(p["colors"], json!(3));
    assert_eq!(p["palette"], json!(["#e63946", "#ffffff"]));
    assert_eq!(p["background"], json!("#aabbcc"));
    assert_eq!(p["group"], json!("color"));
    assert_eq!(p["target_psnr"], json!(31.5));
    assert_eq!(p["max_bytes"], json!(4000));
    let live = &p["plan"]["vectorize"];
    assert_eq!(live["colors"]["palette"], json!(["#e63946", "#ffffff"]));
    assert_eq!(live["colors"]["background"], json!("#aabbcc"));
    assert_eq!(live["max_bytes"], json!(4000));
    // Omitted: the defaults, and nothing extra in params.
    let r = post_json(srv.addr, "/jobs", &vectorize_body(3, 10, 1)).await;
    let id = r.json()["id"].as_str().unwrap().to_string();
    let p = get(srv.addr, &format!("/jobs/{id}")).await.json()["params"].clone();
    assert_eq!(p["background"], json!("auto"));
    assert_eq!(p["group"], json!("none"));
    // Grouping by LIVE stage is the other grouping.
    let body = json!({"kind": "vectorize", "image": png_b64(8), "group": "stage"});
    let r = post_json(srv.addr, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let p = get(srv.addr, &format!("/jobs/{id}")).await.json()["params"].clone();
    assert_eq!(p["group"], json!("stage"));
    assert!(
        p.get("palette").is_none() && p.get("max_bytes").is_none() && p.get("fill").is_none(),
        "{p}"
    );
    // A gradient fill is stored and reaches the LIVE settings.
    let body = json!({"kind": "vectorize", "image": png_b64(8), "fill": "radial"});
    let r = post_json(srv.addr, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let p = get(srv.addr, &format!("/jobs/{id}")).await.json()["params"].clone();
    assert_eq!(p["fill"], json!("radial"));
    assert_eq!(p["plan"]["vectorize"]["fill"], json!("radial"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn api_key_guards_everything_but_health() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.api_key = "s3cret".into()
    })
    .await;
    let a = srv.addr;
    let r = get(a, "/jobs").await;
    assert_eq!(r.status, 401);
    assert_eq!(r.json()["error"]["code"], "unauthorized");
    assert_eq!(
        request(
            a,
            "GET",
            "/jobs",
            &[("Authorization", "Bearer wrong")],
            None
        )
        .await
        .status,
        401
    );
    assert_eq!(
        request(
            a,
            "GET",
            "/jobs",
            &[("Authorization", "Bearer s3cret")],
            None
        )
        .await
        .status,
        200
    );
    assert_eq!(
        request(a, "GET", "/metrics", &[("X-API-Key", "s3cret")], None)
            .await
            .status,
        200
    );
    assert_eq!(get(a, "/metrics").await.status, 401);
    assert_eq!(get(a, "/healthz").await.status, 200);
    assert_eq!(get(a, "/readyz").await.status, 200);
    srv.stop().await;
}

/// Fails its first attempt with a retryable error, then succeeds.
struct FlakyExecutor {
    calls: AtomicU32,
}

impl Executor for FlakyExecutor {
    fn run(&self, _spec: &JobSpec, ctx: &JobContext) -> Result<RunOutput, PipelineError> {
        ctx.report(Progress::new(Stage::Test, 1, 1));
        if self.calls.fetch_add(1, Ordering::SeqCst) == 0 {
            return Err(PipelineError::Transient("simulated out-of-memory".into()));
        }
        Ok(common::runs::blank_output())
    }
    fn text_ready(&self) -> Result<(), vectorfusion::pipeline::NotReady> {
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn transient_failures_are_retried_with_backoff() {
    let exec = Arc::new(FlakyExecutor {
        calls: AtomicU32::new(0),
    });
    let srv = TestServer::start(exec.clone(), |c| c.queue.workers = 1).await;
    let r = post_json(srv.addr, "/jobs", &vectorize_body(2, 2, 1)).await;
    let id = r.json()["id"].as_str().unwrap().to_string();
    let v = wait_status(
        srv.addr,
        &id,
        &["succeeded", "failed"],
        Duration::from_secs(10),
    )
    .await;
    assert_eq!(v["status"], "succeeded", "{v}");
    assert_eq!(v["attempts"], 2);
    let outcomes: Vec<&str> = v["attempt_history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["outcome"].as_str().unwrap())
        .collect();
    assert_eq!(outcomes, ["retry", "succeeded"]);
    assert_eq!(exec.calls.load(Ordering::SeqCst), 2);
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn graceful_shutdown_requeues_running_job_and_restart_resumes_it() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("keep.db");
    let db2 = db.clone();
    let srv = TestServer::start(Arc::new(TestExecutor::new(10)), move |c| {
        c.database.path = db2;
        c.queue.checkpoint_every_steps = 5;
    })
    .await;
    let r = post_json(srv.addr, "/jobs", &vectorize_body(3, 300, 3)).await;
    let id = r.json()["id"].as_str().unwrap().to_string();
    // wait for progress past a checkpoint
    loop {
        let v = get(srv.addr, &format!("/jobs/{id}")).await.json();
        if v["progress"]["step"].as_i64().unwrap_or(0) >= 20 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    srv.stop().await;
    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let row = store.get_job(&id).await.unwrap().unwrap();
    assert_eq!(
        row.status,
        vectorfusion::store::JobStatus::Queued,
        "handed back to the queue"
    );
    assert!(row.checkpoint.is_some(), "checkpoint kept");
    assert_eq!(store.attempts(&id).await.unwrap()[0].outcome, "interrupted");
    store.close().await;

    let db3 = db.clone();
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), move |c| {
        c.database.path = db3
    })
    .await;
    let v = wait_status(
        srv.addr,
        &id,
        &["succeeded", "failed"],
        Duration::from_secs(20),
    )
    .await;
    assert_eq!(v["status"], "succeeded");
    assert_eq!(v["attempts"], 2);
    let _ = http::get(srv.addr, "/healthz").await;
    srv.stop().await;
    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let result = store.result(&id).await.unwrap().unwrap();
    let detail: Value = serde_json::from_str(&result.detail).unwrap();
    // checkpointed when shutdown cancelled it, not just at the last periodic checkpoint
    assert!(detail["resumed_from"].as_u64().unwrap() >= 20, "{detail}");
    assert_eq!(
        result.svg,
        scene_svg(&scene_at(3, 3, 300, 300).unwrap()),
        "a resumed job produces the same drawing"
    );
}
