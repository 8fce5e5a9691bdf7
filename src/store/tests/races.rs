//! Conformance cases where several callers race: submits against a full queue, cancel against
//! complete, a reclaimed job's checkpoint.

use super::*;

pub(super) async fn concurrent_submits_never_overshoot_a_full_queue(b: Backend) {
    let Some((_d, loc, store)) = temp_store(b, 8).await else {
        return;
    };
    // 48 submits at once from four handles (16 connections) against a limit of 20; 16 of them
    // retry one idempotency key.
    let mut stores = Vec::new();
    for _ in 0..4 {
        stores.push(Store::connect(&loc, 4).await.unwrap());
    }
    let start = std::sync::Arc::new(tokio::sync::Barrier::new(48));
    let mut handles = Vec::new();
    for i in 0..48 {
        let s = stores[i % 4].clone();
        let start = start.clone();
        handles.push(tokio::spawn(async move {
            let mut j = new_job(i);
            j.max_queued = Some(20);
            if i % 3 == 0 {
                j.idempotency_key = Some("same".into());
            }
            start.wait().await;
            vec![s.insert_job(&j, 1).await]
        }));
    }
    let (mut created, mut full, mut same) = (0, 0, HashSet::new());
    for h in handles {
        for r in h.await.unwrap() {
            match r {
                Ok((row, true)) => {
                    created += 1;
                    if row.idempotency_key.is_some() {
                        same.insert(row.id);
                    }
                }
                Ok((row, false)) => {
                    same.insert(row.id);
                }
                Err(StoreError::QueueFull { .. }) => full += 1,
                Err(e) => panic!("unexpected error {e}"),
            }
        }
    }
    assert_eq!(store.queue_depth().await.unwrap(), 20, "the limit holds");
    assert_eq!(created, 20);
    assert!(same.len() <= 1, "one job for one key, got {same:?}");
    assert!(full >= 48 - 20 - 16, "{full} refused");
}

pub(super) async fn cancel_and_complete_race_ends_each_job_once(b: Backend) {
    let Some((_d, loc, store)) = temp_store(b, 8).await else {
        return;
    };
    let other = Store::connect(&loc, 4).await.unwrap();
    let n = 30;
    for i in 0..n {
        store.insert_job(&new_job(i), 1).await.unwrap();
    }
    let mut leases = Vec::new();
    while let Some((_, lease)) = store.claim("w", 10, 60_000).await.unwrap() {
        leases.push(lease);
    }
    assert_eq!(leases.len(), n);
    // For each job at once: the worker completes, a client cancels, and a second worker whose
    // lease is stale tries to complete as well.
    let mut tasks = Vec::new();
    for lease in leases {
        let (a, c) = (store.clone(), other.clone());
        let stale = Lease {
            attempt: lease.attempt + 1,
            ..lease.clone()
        };
        tasks.push(tokio::spawn(async move {
            let (done, _, late) = tokio::join!(
                a.complete(&lease, "<svg/>", 1, "{}", 20),
                c.request_cancel(&lease.job_id, 20),
                c.complete(&stale, "<svg/>", 1, "{}", 20),
            );
            assert!(!late.unwrap(), "a stale lease completed a job");
            (lease.job_id, done.unwrap())
        }));
    }
    for t in tasks {
        let (id, completed) = t.await.unwrap();
        let row = store.get_job(&id).await.unwrap().unwrap();
        let results: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM results WHERE job_id = $1")
            .bind(&id)
            .fetch_one(store.pool())
            .await
            .unwrap();
        // A cancel request on a running job only flags it: the worker's completion wins.
        assert!(completed);
        assert_eq!(row.status, JobStatus::Succeeded);
        assert_eq!(results, 1);
        let attempts = store.attempts(&id).await.unwrap();
        assert_eq!(attempts.len(), 1);
        assert_eq!(attempts[0].outcome, "succeeded");
    }
}

pub(super) async fn a_reclaimed_job_carries_its_checkpoint_to_the_next_worker(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let job = store.insert_job(&new_job(0), 0).await.unwrap().0;
    let (_, a) = store.claim("a", 10, 1000).await.unwrap().unwrap();
    assert!(
        store
            .save_checkpoint(&a, r#"{"step":4}"#, 20)
            .await
            .unwrap()
    );
    // a dies; b reclaims the job after the lease and sees a's checkpoint
    let (row, lease_b) = store.claim("b", 2000, 1000).await.unwrap().unwrap();
    assert_eq!(row.id, job.id);
    assert_eq!(row.checkpoint.as_deref(), Some(r#"{"step":4}"#));
    // a's late checkpoint is refused and does not overwrite b's
    assert!(
        store
            .save_checkpoint(&lease_b, r#"{"step":8}"#, 2100)
            .await
            .unwrap()
    );
    assert!(
        !store
            .save_checkpoint(&a, r#"{"step":5}"#, 2200)
            .await
            .unwrap()
    );
    // a graceful hand-back keeps the checkpoint for the next claim too
    assert!(store.release(&lease_b, 2300).await.unwrap().is_some());
    let (row, _) = store.claim("c", 2400, 1000).await.unwrap().unwrap();
    assert_eq!(row.checkpoint.as_deref(), Some(r#"{"step":8}"#));
    assert_eq!(
        outcomes(&store, &job.id).await,
        vec!["lost", "interrupted", "running"]
    );
}
