//! Checkpoint/resume of real pipeline jobs: the SDS stage of `DefaultExecutor` text jobs saves
//! its state through the `JobContext` (every N steps and on cancellation); a second run with
//! that state (a restarted worker) skips sampling, rerank and tracing, resumes at the saved step
//! and ends with exactly the SVG an uninterrupted run gives. Tiny random SD + CLIP fixtures.

mod common;

use common::http::{get, post_json};
use common::wait_status;
use serde_json::{Value, json};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use vectorfusion::pipeline::{
    DefaultExecutor, Executor, JobContext, JobKind, JobSpec, Method, ModelDirs, PipelineError,
    Preset, ResumePoint, RunOutput, Style,
};
use vectorfusion::progress::{CancelToken, Progress, Stage};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn exec() -> DefaultExecutor {
    DefaultExecutor::new(ModelDirs {
        sd_dir: Some(fixture("sd-tiny")),
        clip_dir: Some(fixture("clip-tiny")),
        ..ModelDirs::default()
    })
}

fn spec(method: Method, style: Style) -> JobSpec {
    JobSpec {
        kind: JobKind::Text,
        caption: Some("a crown".into()),
        image: None,
        svg: None,
        style,
        method,
        paths: Some(6),
        steps: Some(8),
        seed: 11,
        samples: Some(2),
        preset: Preset::Draft,
        priority: 0,
        retrieval: true,
        vector: Default::default(),
        canvas: Default::default(),
        negative_prompt: None,
        size_conditioning: None,
        plan: None,
        variations: None,
    }
}

/// One attempt: progress events, the checkpoints it saved (through JSON text, as the store
/// keeps them), and its outcome. `cancel_at` cancels at the first report of that stage at or
/// past that step.
struct Attempt {
    events: Vec<Progress>,
    checkpoints: Vec<Value>,
    out: Result<RunOutput, PipelineError>,
}

fn attempt(
    exec: &DefaultExecutor,
    spec: &JobSpec,
    every: u32,
    resume: Option<Value>,
    cancel_at: Option<(Stage, u32)>,
) -> Attempt {
    attempt_until(exec, spec, every, resume, move |p, _| {
        cancel_at.is_some_and(|(stage, step)| p.stage == stage && p.step >= step)
    })
}

/// [`attempt`], cancelled at the first report for which `stop(report, reports before it)`
/// holds.
fn attempt_until(
    exec: &DefaultExecutor,
    spec: &JobSpec,
    every: u32,
    resume: Option<Value>,
    stop: impl Fn(&Progress, &[Progress]) -> bool + Send + Sync + 'static,
) -> Attempt {
    let events = Arc::new(Mutex::new(Vec::new()));
    let saved = Arc::new(Mutex::new(Vec::new()));
    let cancel = CancelToken::new();
    let (ev, tok) = (events.clone(), cancel.clone());
    let sink = move |p: Progress| {
        let mut seen = ev.lock().unwrap();
        if stop(&p, &seen) {
            tok.cancel();
        }
        seen.push(p);
    };
    let s2 = saved.clone();
    let ctx = JobContext::new(
        Arc::new(sink),
        cancel,
        every,
        Box::new(move |v: Value| {
            let text = serde_json::to_string(&v)?;
            s2.lock()
                .unwrap()
                .push(serde_json::from_str(&text).unwrap());
            Ok(())
        }),
        resume,
    );
    let out = exec.run(spec, &ctx);
    Attempt {
        events: events.lock().unwrap().clone(),
        checkpoints: saved.lock().unwrap().clone(),
        out,
    }
}

fn step_of(ckpt: &Value) -> u64 {
    ckpt["sds"]["step"].as_u64().unwrap()
}

#[test]
fn sds_checkpoints_and_a_restart_resumes_to_the_same_svg() {
    let exec = exec();
    let spec = spec(Method::SdLiveSds, Style::Iconography);
    // Uninterrupted, checkpointing every 3 steps: at 3 and 6 (not after the last step).
    let full = attempt(&exec, &spec, 3, None, None);
    let full_out = full.out.unwrap();
    let steps: Vec<u64> = full.checkpoints.iter().map(step_of).collect();
    assert_eq!(steps, [3, 6]);
    let ck = &full.checkpoints[0];
    assert!(ck["sds"]["adam"].is_object() && ck["sds"]["scene"]["shapes"].is_array());
    assert_eq!(
        ck["detail"]["rerank"]["scores"].as_array().unwrap().len(),
        2
    );
    assert!(full_out.report.resumed.is_none());

    // A restart from the step-3 checkpoint: no sampling/rerank/LIVE, SDS from step 4, same SVG.
    let resumed = attempt(&exec, &spec, 3, Some(ck.clone()), None);
    let out = resumed.out.unwrap();
    assert_eq!(
        out.report.resumed,
        Some(ResumePoint::Step(3)),
        "{:?}",
        out.report
    );
    assert!(
        resumed
            .events
            .iter()
            .all(|p| !["sample", "rerank", "live"].contains(&p.stage.as_str())),
        "{:?}",
        resumed.events.iter().map(|p| &p.stage).collect::<Vec<_>>()
    );
    let first_sds = resumed
        .events
        .iter()
        .find(|p| p.stage == Stage::Sds)
        .unwrap();
    assert_eq!(first_sds.step, 4);
    // The rerank scores of the first attempt are kept in the result.
    assert_eq!(out.report.rerank, full_out.report.rerank);
    assert_eq!(
        out.svg, full_out.svg,
        "resumed run differs from the uninterrupted one"
    );
    assert_eq!(out.paths, full_out.paths);
    let scene = vectorfusion::svg::from_svg(&out.svg).unwrap();
    scene.validate().unwrap();
    // Its own later checkpoint continues the count.
    assert_eq!(
        resumed.checkpoints.iter().map(step_of).collect::<Vec<_>>(),
        [6]
    );
}

#[test]
fn cancellation_saves_a_checkpoint_that_resumes_exactly() {
    let exec = exec();
    for (method, style) in [
        (Method::Scratch, Style::Iconography),
        (Method::SdLiveSds, Style::PixelArt),
    ] {
        let spec = spec(method, style);
        let full = attempt(&exec, &spec, 100, None, None).out.unwrap();
        // Shutdown after step 5: the job stops with Cancelled and saves step 5.
        let stopped = attempt(&exec, &spec, 100, None, Some((Stage::Sds, 5)));
        assert!(matches!(stopped.out, Err(PipelineError::Cancelled)));
        let last = stopped.checkpoints.last().expect("checkpoint on cancel");
        assert_eq!(step_of(last), 5);
        let resumed = attempt(&exec, &spec, 100, Some(last.clone()), None);
        let out = resumed.out.unwrap();
        assert_eq!(out.report.resumed, Some(ResumePoint::Step(5)));
        assert_eq!(out.svg, full.svg, "{method:?} {style:?}");
    }
}

/// A text job of 3 variations stopped in the SDS of its second: the checkpoint holds the
/// finished first and the start of the third, and the restart skips sampling, rerank and
/// tracing, goes on from that step and ends with the 3 distinct SVGs of an uninterrupted run.
#[test]
fn a_job_of_several_variations_resumes_from_the_one_it_was_distilling() {
    let exec = exec();
    let spec = JobSpec {
        variations: Some(3),
        ..spec(Method::SdLiveSds, Style::Iconography)
    };
    let full = attempt(&exec, &spec, 100, None, None).out.unwrap();
    let svgs = |o: &RunOutput| {
        std::iter::once(&o.svg)
            .chain(o.variations.iter().map(|v| &v.svg))
            .cloned()
            .collect::<Vec<_>>()
    };
    let want = svgs(&full);
    assert_eq!(want.len(), 3);
    assert!(want[0] != want[1] && want[1] != want[2] && want[0] != want[2]);
    // Each variation's SDS counts from step 1: stop at step 5 of the second.
    let stopped = attempt_until(&exec, &spec, 100, None, |p, seen| {
        let sds_starts = seen
            .iter()
            .filter(|e| e.stage == Stage::Sds && e.step == 1)
            .count();
        p.stage == Stage::Sds && p.step >= 5 && sds_starts == 2
    });
    assert!(matches!(stopped.out, Err(PipelineError::Cancelled)));
    let last = stopped.checkpoints.last().expect("checkpoint on cancel");
    assert_eq!(step_of(last), 5);
    assert_eq!(
        last["done"].as_array().map(Vec::len),
        Some(1),
        "{last:.300}"
    );
    assert_eq!(last["pending"].as_array().map(Vec::len), Some(1));
    let resumed = attempt(&exec, &spec, 100, Some(last.clone()), None);
    assert!(
        resumed
            .events
            .iter()
            .all(|p| ![Stage::Sample, Stage::Rerank, Stage::Live].contains(&p.stage)),
        "{:?}",
        resumed.events.iter().map(|p| &p.stage).collect::<Vec<_>>()
    );
    let out = resumed.out.unwrap();
    assert_eq!(svgs(&out), want, "the resumed variations differ");
    assert_eq!(out.report.variations.len(), 3);
}

#[test]
fn a_checkpoint_of_another_request_is_ignored() {
    let exec = exec();
    let spec_a = spec(Method::Scratch, Style::Iconography);
    let ck = attempt(&exec, &spec_a, 2, None, None).checkpoints[0].clone();
    let mut spec_b = spec_a.clone();
    spec_b.seed = 12;
    let fresh = attempt(&exec, &spec_b, 100, None, None).out.unwrap();
    let with_foreign = attempt(&exec, &spec_b, 100, Some(ck), None).out.unwrap();
    assert!(with_foreign.report.resumed.is_none());
    assert_eq!(with_foreign.svg, fresh.svg);
    // Garbage resume state is ignored too (runs from the start).
    let junk = attempt(
        &exec,
        &spec_b,
        100,
        Some(serde_json::json!({"step": 3})),
        None,
    );
    assert_eq!(junk.out.unwrap().svg, fresh.svg);
}

/// A vectorize job (LIVE only, no caption) saves its state after every LIVE stage; a restart
/// from a saved stage, or from the last one before a cancellation, ends with the same SVG.
#[test]
fn vectorize_jobs_checkpoint_each_live_stage_and_resume_exactly() {
    // A 6x6 board of random colours: every stage of 8 paths still finds error to fix.
    let side = 48u32;
    let mut img = vectorfusion::image::Image::filled(side, side, [1.0, 1.0, 1.0, 1.0]);
    let mut x = 12345u32;
    let mut next = || {
        x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (x >> 8) as f32 / (1u32 << 24) as f32
    };
    for cy in 0..6 {
        for cx in 0..6 {
            let c = [next(), next(), next(), 1.0];
            for y in cy * 8..cy * 8 + 8 {
                for xx in cx * 8..cx * 8 + 8 {
                    let i = 4 * (y * side + xx) as usize;
                    img.data[i..i + 4].copy_from_slice(&c);
                }
            }
        }
    }
    let spec = JobSpec {
        kind: JobKind::Vectorize,
        caption: None,
        image: Some(img.encode_png().unwrap()),
        svg: None,
        style: Style::Iconography,
        method: Method::SdLive,
        paths: Some(24),
        steps: Some(1),
        seed: 5,
        samples: Some(1),
        preset: Preset::Draft,
        priority: 0,
        retrieval: true,
        vector: Default::default(),
        canvas: Default::default(),
        negative_prompt: None,
        size_conditioning: None,
        plan: None,
        variations: None,
    };
    let exec = DefaultExecutor::new(ModelDirs::default());
    let full = attempt(&exec, &spec, 100, None, None);
    let full_out = full.out.unwrap();
    let stages: Vec<u64> = full
        .checkpoints
        .iter()
        .map(|c| c["live"]["next_stage"].as_u64().unwrap())
        .collect();
    assert!(stages.len() >= 2, "{stages:?}");
    assert_eq!(stages, (1..=stages.len() as u64).collect::<Vec<_>>());
    assert!(full_out.report.resumed.is_none());

    // Restart from the first stage's state: LIVE continues after it, same SVG.
    let first = &full.checkpoints[0];
    let done_steps = first["live"]["step"].as_u64().unwrap() as u32;
    let resumed = attempt(&exec, &spec, 100, Some(first.clone()), None);
    let out = resumed.out.unwrap();
    assert_eq!(
        out.report.resumed,
        Some(ResumePoint::LiveStage(1)),
        "{:?}",
        out.report
    );
    let first_live = resumed
        .events
        .iter()
        .find(|p| p.stage == Stage::Live)
        .unwrap();
    assert!(first_live.step > done_steps, "{first_live:?}");
    assert_eq!(out.svg, full_out.svg, "resumed vectorize differs");

    // Cancelled mid-run (a shutdown): the last saved stage resumes to the same SVG.
    let stopped = attempt(&exec, &spec, 100, None, Some((Stage::Live, done_steps + 3)));
    assert!(matches!(stopped.out, Err(PipelineError::Cancelled)));
    let last = stopped
        .checkpoints
        .last()
        .expect("a stage was saved")
        .clone();
    let out = attempt(&exec, &spec, 100, Some(last), None).out.unwrap();
    assert_eq!(out.svg, full_out.svg);

    // A text job's checkpoint, or another image's, is ignored.
    let mut other = spec.clone();
    other.seed = 6;
    let fresh = attempt(&exec, &other, 100, None, None).out.unwrap();
    let foreign = attempt(&exec, &other, 100, Some(first.clone()), None)
        .out
        .unwrap();
    assert!(foreign.report.resumed.is_none());
    assert_eq!(foreign.svg, fresh.svg);
}

/// Starts the real service with the tiny models on `db`.
async fn serve(
    db: &std::path::Path,
) -> (
    std::net::SocketAddr,
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<Result<(), vectorfusion::server::ServerError>>,
) {
    let mut cfg = vectorfusion::config::Config::default();
    cfg.database.path = db.to_path_buf();
    cfg.queue.workers = 1;
    cfg.queue.poll_interval_ms = 20;
    cfg.queue.checkpoint_every_steps = 5;
    cfg.server.progress_interval_ms = 0;
    cfg.server.snapshot_interval_ms = 0;
    cfg.server.shutdown_grace_secs = 30;
    cfg.models.sd_dir = fixture("sd-tiny").display().to_string();
    cfg.models.clip_dir = fixture("clip-tiny").display().to_string();
    let exec: Arc<dyn Executor> = Arc::new(DefaultExecutor::new(cfg.model_dirs()));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(vectorfusion::server::run(cfg, exec, listener, async move {
        let _ = rx.await;
    }));
    (addr, tx, task)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn service_shutdown_mid_sds_and_restart_resumes_from_the_stored_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("jobs.db");
    let (a, stop, task) = serve(&db).await;
    let body = json!({"kind": "text", "caption": "a crown", "method": "sd_live_sds",
        "preset": "draft", "paths": 6, "steps": 120, "samples": 2, "seed": 9});
    let r = post_json(a, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    // Wait until SDS is past a few checkpoints, then shut the server down (SIGTERM path).
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let j = get(a, &format!("/jobs/{id}")).await.json();
        if j["stage"] == "sds" && j["progress"]["step"].as_u64().unwrap_or(0) >= 12 {
            break;
        }
        assert!(
            j["status"] != "succeeded",
            "finished before the shutdown: {j}"
        );
        assert!(Instant::now() < deadline, "{j}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // While it runs, the rerank scores come from its stored checkpoint.
    let running = get(a, &format!("/jobs/{id}")).await.json();
    assert_eq!(running["status"], "running");
    assert_eq!(
        running["rerank"]["scores"].as_array().unwrap().len(),
        2,
        "{running}"
    );
    let _ = stop.send(());
    tokio::time::timeout(Duration::from_secs(60), task)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let row = store.get_job(&id).await.unwrap().unwrap();
    assert_eq!(row.status, vectorfusion::store::JobStatus::Queued);
    let ck: Value = serde_json::from_str(row.checkpoint.as_deref().unwrap()).unwrap();
    let saved = step_of(&ck);
    assert!((12..120).contains(&saved), "{saved}");
    store.close().await;

    // Restart: the job resumes at the saved step and succeeds.
    let (a, stop, task) = serve(&db).await;
    let job = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(180)).await;
    assert_eq!(job["status"], "succeeded", "{job}");
    let job = get(a, &format!("/jobs/{id}")).await.json();
    assert_eq!(job["result"]["detail"]["resumed_from"], saved, "{job}");
    assert_eq!(job["result"]["detail"]["sds"]["steps_done"], 120);
    assert_eq!(job["rerank"]["scores"].as_array().unwrap().len(), 2);
    let outcomes: Vec<&str> = job["attempt_history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["outcome"].as_str().unwrap())
        .collect();
    assert_eq!(outcomes, ["interrupted", "succeeded"]);
    let svg = get(a, &format!("/jobs/{id}/result.svg")).await.text();
    vectorfusion::svg::from_svg(&svg)
        .unwrap()
        .validate()
        .unwrap();
    let _ = stop.send(());
    tokio::time::timeout(Duration::from_secs(60), task)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
}
