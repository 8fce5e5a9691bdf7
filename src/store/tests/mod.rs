//! The store's conformance suite (River's pattern): every test runs against SQLite and against
//! PostgreSQL. The PostgreSQL half needs a server whose user may create databases, named by
//! `VF_TEST_POSTGRES_URL` (`.ci/run` starts one with `scripts/pg_cluster.sh`); without it those
//! tests print SKIP and pass, except under `VF_REQUIRE_ALL` (set by `.ci/run`), where they fail.

use super::*;
use std::collections::HashSet;

mod races;
use races::*;

/// A fresh, empty database of `backend` (its temporary directory with SQLite), or `None` (SKIP)
/// for PostgreSQL without `VF_TEST_POSTGRES_URL`.
async fn temp_store(
    backend: Backend,
    conns: u32,
) -> Option<(Option<tempfile::TempDir>, DbLocation, Store)> {
    let (dir, loc) = match backend {
        Backend::Sqlite => {
            let dir = tempfile::tempdir().unwrap();
            let loc = DbLocation::Sqlite(dir.path().join("jobs.db"));
            (Some(dir), loc)
        }
        Backend::Postgres => {
            let Ok(admin) = std::env::var("VF_TEST_POSTGRES_URL") else {
                // `.ci/run` sets VF_REQUIRE_ALL: there the PostgreSQL half must run.
                let required =
                    std::env::var("VF_REQUIRE_ALL").is_ok_and(|v| !v.is_empty() && v != "0");
                assert!(
                    !required,
                    "VF_TEST_POSTGRES_URL is not set and VF_REQUIRE_ALL is: no PostgreSQL to test"
                );
                eprintln!("SKIP: VF_TEST_POSTGRES_URL is not set (no PostgreSQL server to test)");
                return None;
            };
            let url = create_test_database(&admin).await.unwrap();
            (None, DbLocation::Postgres(url))
        }
    };
    let store = Store::connect(&loc, conns).await.unwrap();
    Some((dir, loc, store))
}

/// Each named `async fn(Backend)` becomes a test per backend: `on_sqlite::NAME`,
/// `on_postgres::NAME`.
macro_rules! conformance {
    ($($name:ident),* $(,)?) => {
        mod on_sqlite {
            $(#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
            async fn $name() {
                super::$name(super::Backend::Sqlite).await
            })*
        }
        mod on_postgres {
            $(#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
            async fn $name() {
                super::$name(super::Backend::Postgres).await
            })*
        }
    };
}

fn new_job(i: usize) -> NewJob {
    NewJob::new(
        uuid::Uuid::new_v4().to_string(),
        JobKind::Vectorize,
        format!("{{\"i\":{i}}}"),
    )
}

/// The outcome of each attempt of job `id`, oldest first.
async fn outcomes(store: &Store, id: &str) -> Vec<String> {
    let attempts = store.attempts(id).await.unwrap();
    attempts.into_iter().map(|a| a.outcome).collect()
}

async fn status_check_constraint_and_sqlite_wal(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    if b == Backend::Sqlite {
        let mode: String = sqlx::query_scalar("PRAGMA journal_mode")
            .fetch_one(store.pool())
            .await
            .unwrap();
        assert_eq!(mode, "wal");
    }
    let (row, _) = store.insert_job(&new_job(0), 1).await.unwrap();
    let bad = sqlx::query("UPDATE jobs SET status = 'exploded' WHERE id = $1")
        .bind(&row.id)
        .execute(store.pool())
        .await;
    assert!(bad.is_err(), "CHECK constraint must reject unknown status");
    // running without a lease owner is rejected too
    let bad = sqlx::query("UPDATE jobs SET status = 'running' WHERE id = $1")
        .bind(&row.id)
        .execute(store.pool())
        .await;
    assert!(bad.is_err());
}

async fn idempotency_key_returns_same_job(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let mut a = new_job(0);
    a.idempotency_key = Some("k1".into());
    let mut b = new_job(1);
    b.idempotency_key = Some("k1".into());
    let (ra, created_a) = store.insert_job(&a, 1).await.unwrap();
    let (rb, created_b) = store.insert_job(&b, 2).await.unwrap();
    assert!(created_a);
    assert!(!created_b);
    assert_eq!(ra.id, rb.id);
    assert_eq!(store.queue_depth().await.unwrap(), 1);
}

async fn claim_order_priority_then_fifo(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let low = store.insert_job(&new_job(0), 1).await.unwrap().0;
    let mut hi = new_job(1);
    hi.priority = 5;
    let hi = store.insert_job(&hi, 2).await.unwrap().0;
    let low2 = store.insert_job(&new_job(2), 3).await.unwrap().0;
    let mut got = Vec::new();
    while let Some((row, _)) = store.claim("w", 10, 1000).await.unwrap() {
        got.push(row.id);
    }
    assert_eq!(got, vec![hi.id, low.id, low2.id]);
}

async fn concurrent_claims_never_share_a_job(b: Backend) {
    // Several Store handles on one database = several writer connections racing in the
    // database itself (as with several server processes or nodes), plus several tasks per handle.
    let Some((_d, loc, store)) = temp_store(b, 8).await else {
        return;
    };
    let mut handles_db = vec![store.clone()];
    for _ in 0..3 {
        handles_db.push(Store::connect(&loc, 2).await.unwrap());
    }
    let n = 60;
    for i in 0..n {
        store.insert_job(&new_job(i), 1).await.unwrap();
    }
    let mut handles = Vec::new();
    for w in 0..8 {
        let store = handles_db[w % handles_db.len()].clone();
        handles.push(tokio::spawn(async move {
            let mut mine = Vec::new();
            while let Some((row, lease)) = store.claim(&format!("w{w}"), 10, 60_000).await.unwrap()
            {
                assert_eq!(lease.worker, format!("w{w}"));
                mine.push(row.id);
                tokio::task::yield_now().await;
            }
            mine
        }));
    }
    let mut all = Vec::new();
    for h in handles {
        all.extend(h.await.unwrap());
    }
    let unique: HashSet<_> = all.iter().collect();
    assert_eq!(all.len(), n, "every job claimed once");
    assert_eq!(unique.len(), n, "no job claimed twice");
    // every claim opened exactly one attempt
    let attempts: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM attempts")
        .fetch_one(store.pool())
        .await
        .unwrap();
    assert_eq!(attempts, n as i64);
}

async fn expired_lease_is_reclaimed_and_old_worker_is_fenced(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let job = store.insert_job(&new_job(0), 0).await.unwrap().0;
    let (_, lease_a) = store.claim("a", 100, 1000).await.unwrap().unwrap();
    // lease still valid: nobody else can take it
    assert!(store.claim("b", 900, 1000).await.unwrap().is_none());
    // a heartbeat extends it
    assert_eq!(
        store.heartbeat(&lease_a, 1000, 1000).await.unwrap(),
        Heartbeat::Held { cancel: false }
    );
    assert!(store.claim("b", 1900, 1000).await.unwrap().is_none());
    // worker a dies: after expiry b reclaims the job as attempt 2
    let (row, lease_b) = store.claim("b", 2001, 1000).await.unwrap().unwrap();
    assert_eq!(row.id, job.id);
    assert_eq!(lease_b.attempt, 2);
    // a comes back: every write is refused
    assert_eq!(
        store.heartbeat(&lease_a, 2002, 1000).await.unwrap(),
        Heartbeat::Lost
    );
    assert!(!store.save_checkpoint(&lease_a, "{}", 2002).await.unwrap());
    assert!(
        !store
            .complete(&lease_a, "<svg/>", 1, "{}", 2003)
            .await
            .unwrap()
    );
    assert!(
        store
            .complete(&lease_b, "<svg/>", 1, "{}", 2004)
            .await
            .unwrap()
    );
    // the result was written once, by b
    assert!(
        !store
            .complete(&lease_b, "<svg/>", 1, "{}", 2005)
            .await
            .unwrap()
    );
    let attempts = store.attempts(&job.id).await.unwrap();
    let outcomes: Vec<&str> = attempts.iter().map(|a| a.outcome.as_str()).collect();
    assert_eq!(outcomes, vec!["lost", "succeeded"]);
    let row = store.get_job(&job.id).await.unwrap().unwrap();
    assert_eq!(row.status, JobStatus::Succeeded);
}

async fn lease_expiry_after_last_attempt_fails_job(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let mut j = new_job(0);
    j.max_attempts = 1;
    let job = store.insert_job(&j, 0).await.unwrap().0;
    store.claim("a", 0, 100).await.unwrap().unwrap();
    assert!(store.claim("b", 200, 100).await.unwrap().is_none());
    let reaped = store.reap_expired(200).await.unwrap();
    assert_eq!(reaped.len(), 1);
    let row = store.get_job(&job.id).await.unwrap().unwrap();
    assert_eq!(row.status, JobStatus::Failed);
    assert_eq!(row.error_code, Some(FailureCode::LeaseExpired));
    assert_eq!(store.attempts(&job.id).await.unwrap()[0].outcome, "lost");
}

async fn job_lost_max_lost_attempts_times_fails_as_poison(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let mut j = new_job(0);
    j.max_attempts = 5;
    j.max_lost_attempts = 2;
    let job = store.insert_job(&j, 0).await.unwrap().0;
    // First worker dies: its lease expires and another worker reclaims the job (lost once).
    store.claim("a", 0, 100).await.unwrap().unwrap();
    assert!(store.reap_expired(200).await.unwrap().is_empty());
    let (row, _) = store.claim("b", 200, 100).await.unwrap().unwrap();
    assert_eq!((row.attempts, row.lost_attempts), (2, 1));
    // Second worker dies too: not reclaimed although attempts are left, reaped as poison.
    assert!(store.claim("c", 400, 100).await.unwrap().is_none());
    let reaped = store.reap_expired(400).await.unwrap();
    assert_eq!(reaped.len(), 1);
    let row = store.get_job(&job.id).await.unwrap().unwrap();
    assert_eq!(row.status, JobStatus::Failed);
    assert_eq!(row.error_code, Some(FailureCode::Poison));
    assert_eq!(row.lost_attempts, 2);
    assert_eq!(outcomes(&store, &job.id).await, vec!["lost", "lost"]);
    // A job lost once with max_lost_attempts 1 is never reclaimed.
    let mut k = new_job(1);
    k.max_lost_attempts = 1;
    let k = store.insert_job(&k, 500).await.unwrap().0;
    store.claim("a", 500, 100).await.unwrap().unwrap();
    assert!(store.claim("b", 700, 100).await.unwrap().is_none());
    store.reap_expired(700).await.unwrap();
    let row = store.get_job(&k.id).await.unwrap().unwrap();
    assert_eq!(row.error_code, Some(FailureCode::Poison));
}

async fn retry_with_backoff_then_fail(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let mut j = new_job(0);
    j.max_attempts = 2;
    let job = store.insert_job(&j, 0).await.unwrap().0;
    let (_, l1) = store.claim("a", 0, 1000).await.unwrap().unwrap();
    let row = store
        .fail(&l1, FailureCode::Transient, "boom", Some(500), 10)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(row.status, JobStatus::Queued);
    assert!(
        store.claim("a", 499, 1000).await.unwrap().is_none(),
        "backoff"
    );
    let (_, l2) = store.claim("a", 500, 1000).await.unwrap().unwrap();
    let row = store
        .fail(&l2, FailureCode::Transient, "boom", None, 600)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(row.status, JobStatus::Failed);
    assert_eq!(outcomes(&store, &job.id).await, vec!["retry", "failed"]);
}

async fn cancel_queued_and_running(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let a = store.insert_job(&new_job(0), 0).await.unwrap().0;
    let (_, lease) = store.claim("w", 1, 1000).await.unwrap().unwrap();
    let b = store.insert_job(&new_job(1), 2).await.unwrap().0;
    let rb = store.request_cancel(&b.id, 3).await.unwrap().unwrap();
    assert_eq!(rb.status, JobStatus::Cancelled);
    let ra = store.request_cancel(&a.id, 3).await.unwrap().unwrap();
    assert_eq!(ra.status, JobStatus::Running);
    assert_eq!(
        store.heartbeat(&lease, 4, 1000).await.unwrap(),
        Heartbeat::Held { cancel: true }
    );
    let done = store.finish_cancelled(&lease, 5).await.unwrap().unwrap();
    assert_eq!(done.status, JobStatus::Cancelled);
    assert!(store.request_cancel("nope", 6).await.unwrap().is_none());
    assert!(store.claim("w", 10, 1000).await.unwrap().is_none());
}

async fn snapshots_numbered_trimmed_and_fenced(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let job = store.insert_job(&new_job(0), 0).await.unwrap().0;
    let (_, lease) = store.claim("w", 1, 1000).await.unwrap().unwrap();
    for i in 0..5u32 {
        let n = store
            .add_snapshot(&lease, "s", i, &format!("<svg>{i}</svg>"), 2, 3)
            .await
            .unwrap();
        assert_eq!(n, Some(i as i64 + 1));
    }
    let snaps = store.snapshots_after(&job.id, 0, 100).await.unwrap();
    assert_eq!(snaps.iter().map(|s| s.n).collect::<Vec<_>>(), vec![3, 4, 5]);
    let other = Lease {
        worker: "x".into(),
        ..lease.clone()
    };
    assert_eq!(
        store
            .add_snapshot(&other, "s", 9, "<svg/>", 3, 3)
            .await
            .unwrap(),
        None
    );
    // release keeps the checkpoint and re-queues
    assert!(
        store
            .save_checkpoint(&lease, "{\"step\":4}", 4)
            .await
            .unwrap()
    );
    let row = store.release(&lease, 5).await.unwrap().unwrap();
    assert_eq!(row.status, JobStatus::Queued);
    assert_eq!(row.checkpoint.as_deref(), Some("{\"step\":4}"));
}

async fn prune_removes_old_finished_jobs(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let job = store.insert_job(&new_job(0), 0).await.unwrap().0;
    let (_, lease) = store.claim("w", 1, 1000).await.unwrap().unwrap();
    store
        .add_snapshot(&lease, "s", 1, "<svg/>", 2, 10)
        .await
        .unwrap();
    assert!(store.complete(&lease, "<svg/>", 1, "{}", 3).await.unwrap());
    let queued = store.insert_job(&new_job(1), 0).await.unwrap().0;
    assert_eq!(store.prune(3).await.unwrap(), 0);
    assert_eq!(store.prune(4).await.unwrap(), 1);
    assert!(store.get_job(&job.id).await.unwrap().is_none());
    assert!(store.result(&job.id).await.unwrap().is_none());
    assert!(store.latest_snapshot(&job.id).await.unwrap().is_none());
    assert!(store.get_job(&queued.id).await.unwrap().is_some());
}

async fn uploads_live_apart_within_their_quotas_and_go_when_the_job_ends(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let up = |n: usize, tenant_cap: i64| NewUpload {
        image: Some(vec![b'A'; n]),
        svg: None,
        max_total_bytes: 1000,
        max_tenant_bytes: tenant_cap,
    };
    let mut a = new_job(0);
    a.upload = Some(up(600, 0));
    let (ra, _) = store.insert_job(&a, 1).await.unwrap();
    let row_bytes: i64 =
        sqlx::query_scalar("SELECT CAST(length(spec) AS BIGINT) FROM jobs WHERE id = $1")
            .bind(&ra.id)
            .fetch_one(store.pool())
            .await
            .unwrap();
    assert!(row_bytes < 100, "the job row holds {row_bytes} bytes");
    let stored = store.upload(&ra.id).await.unwrap().unwrap();
    assert_eq!(stored.image_bytes.map(|i| i.len()), Some(600));
    assert_eq!(stored.image_base64, None);
    assert_eq!(store.upload_bytes(None).await.unwrap(), 600);

    // 600 + 500 > 1000: refused, and the job is not inserted either.
    let mut b = new_job(1);
    b.upload = Some(up(500, 0));
    match store.insert_job(&b, 2).await {
        Err(StoreError::UploadQuota { limit }) => assert_eq!(limit, 1000),
        other => panic!("expected the upload quota, got {other:?}"),
    }
    assert!(store.get_job(&b.id).await.unwrap().is_none());
    assert_eq!(store.queue_depth().await.unwrap(), 1);
    // A tenant's own cap is checked against that tenant's uploads only.
    let mut c = new_job(2);
    c.tenant = Some("t".into());
    c.upload = Some(up(300, 200));
    match store.insert_job(&c, 3).await {
        Err(StoreError::UploadQuota { limit }) => assert_eq!(limit, 200),
        other => panic!("expected the tenant's upload quota, got {other:?}"),
    }
    c.upload = Some(up(150, 200));
    store.insert_job(&c, 4).await.unwrap();
    assert_eq!(store.upload_bytes(Some(Some("t"))).await.unwrap(), 150);
    assert_eq!(store.upload_bytes(Some(None)).await.unwrap(), 600);

    // Finishing the job deletes its upload, which frees the quota.
    let (row, lease) = store.claim("w", 10, 1000).await.unwrap().unwrap();
    assert_eq!(row.id, ra.id);
    assert!(store.complete(&lease, "<svg/>", 0, "{}", 11).await.unwrap());
    assert!(store.upload(&ra.id).await.unwrap().is_none());
    assert_eq!(store.upload_bytes(None).await.unwrap(), 150);
    store.insert_job(&b, 12).await.unwrap();
    // So does cancelling a queued one.
    store.request_cancel(&c.id, 13).await.unwrap().unwrap();
    assert!(store.upload(&c.id).await.unwrap().is_none());
}

async fn a_full_queue_refuses_the_insert_itself(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let mut keyed = new_job(0);
    keyed.idempotency_key = Some("k".into());
    keyed.max_queued = Some(3);
    store.insert_job(&keyed, 1).await.unwrap();
    for i in 1..3 {
        let mut j = new_job(i);
        j.max_queued = Some(3);
        store.insert_job(&j, 1).await.unwrap();
    }
    let mut j = new_job(3);
    j.max_queued = Some(3);
    match store.insert_job(&j, 2).await {
        Err(StoreError::QueueFull { limit }) => assert_eq!(limit, 3),
        other => panic!("expected a full queue, got {other:?}"),
    }
    assert_eq!(store.queue_depth().await.unwrap(), 3);
    // A retry with a known idempotency key still gets its job back at a full queue.
    let mut again = new_job(4);
    again.idempotency_key = Some("k".into());
    again.max_queued = Some(3);
    let (row, created) = store.insert_job(&again, 3).await.unwrap();
    assert!(!created);
    assert_eq!(row.id, keyed.id);
}
conformance!(
    status_check_constraint_and_sqlite_wal,
    idempotency_key_returns_same_job,
    claim_order_priority_then_fifo,
    concurrent_claims_never_share_a_job,
    expired_lease_is_reclaimed_and_old_worker_is_fenced,
    lease_expiry_after_last_attempt_fails_job,
    job_lost_max_lost_attempts_times_fails_as_poison,
    retry_with_backoff_then_fail,
    cancel_queued_and_running,
    snapshots_numbered_trimmed_and_fenced,
    prune_removes_old_finished_jobs,
    uploads_live_apart_within_their_quotas_and_go_when_the_job_ends,
    a_full_queue_refuses_the_insert_itself,
    concurrent_submits_never_overshoot_a_full_queue,
    cancel_and_complete_race_ends_each_job_once,
    a_reclaimed_job_carries_its_checkpoint_to_the_next_worker,
);

/// Conformance cases added since (this file is full): their own module, same macro.
mod more;
