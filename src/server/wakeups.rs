//! PostgreSQL wake-ups across nodes: the store of every node NOTIFYs (`store::backend::Hints`)
//! `vf_queue` when a job becomes claimable and `vf_job` (payload: the job id) when what its event
//! stream shows changes. This task LISTENs and turns them into local wake-ups: idle workers try
//! a claim, the job's event streams re-read it from the database.
//!
//! Notifications are hints: one can be lost (the listening connection drops, the database
//! restarts). Workers still poll every `queue.poll_interval_ms` and event streams re-read their
//! job every second on a shared database, so a lost hint delays, never loses, an event.

use super::AppState;
use crate::worker::events::JobEvent;
use sqlx::postgres::PgListener;
use std::time::Duration;
use tracing::{debug, warn};

pub(super) async fn listen(state: AppState, url: String) {
    let mut failures = 0u32;
    loop {
        match listen_once(&state, &url).await {
            Ok(()) => return,
            Err(e) => {
                failures = failures.saturating_add(1);
                // Log the first failure of a run of them, then every 30th.
                if failures % 30 == 1 {
                    warn!(error = %e, "listening for database notifications failed; retrying");
                }
                // Something may have been missed while disconnected: wake everyone once.
                state.pool.notify();
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

async fn listen_once(state: &AppState, url: &str) -> Result<(), sqlx::Error> {
    let mut listener = PgListener::connect(url).await?;
    listener.listen_all(["vf_queue", "vf_job"]).await?;
    debug!("listening for vf_queue and vf_job notifications");
    loop {
        match listener.try_recv().await? {
            Some(n) => match n.channel() {
                "vf_queue" => state.pool.notify(),
                "vf_job" => state.hub.publish(n.payload(), JobEvent::Changed),
                _ => {}
            },
            // The connection dropped and was re-established: what was sent in between is
            // lost, so idle workers look once (event streams re-read on their own timer).
            None => state.pool.notify(),
        }
    }
}
