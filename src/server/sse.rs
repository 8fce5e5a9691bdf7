//! `GET /jobs/{id}/events`: server-sent events, EventSource compatible.
//!
//! Stream: `state` (the stored job) first; then stored snapshots the client has not seen; then
//! live `progress`, `snapshot` and `state` events; finally one of `done`, `failed`, `cancelled`
//! (data = the job) and the stream ends. Every event carries `id: N`, the number of the last
//! snapshot sent on the stream so far (0 before the first), so a reconnecting EventSource sends
//! `Last-Event-ID: N` and receives every stored snapshot after N, wherever it was cut off. A first
//! connection asks for the same with `?from=N` (`?from=0`: every stored snapshot); without
//! either only the latest snapshot is replayed. Other query parameters are
//! refused unless their names start with `_` (cache-busters). Keep-alive comments go out every
//! `server.sse_heartbeat_secs`.
//!
//! Each stream is fed by its own task from a per-job broadcast channel. The worker's publish
//! never waits; when a client reads too slowly its channel lags and the task resynchronises from
//! the database, so slow clients cost themselves events, never the workers time.
//!
//! On a shared database (PostgreSQL) the job may run on another node: its changes arrive as
//! `Changed` hints (`wakeups.rs`), and the task also re-reads the job every second, so the stream
//! shows every stored snapshot, each status change and the latest progress wherever the job runs.

use super::AppState;
use super::error::ApiError;
use super::routes::{check_other_params, job_id, load_job};
use super::tenant::Caller;
use super::types::{JobView, ProgressView};
use crate::progress::Stage;
use crate::store::{Backend, JobRow, JobStatus, SnapshotRow};
use crate::worker::events::JobEvent;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Extension, Path, Query, State};
use axum::http::HeaderMap;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::Stream;
use std::convert::Infallible;
use std::time::Duration;
use tokio::sync::{broadcast, mpsc};

/// Snapshots replayed at most on (re)connect.
const REPLAY_LIMIT: i64 = 500;

/// The largest `from`: event ids are snapshot numbers, which stay JSON-safe integers.
const MAX_FROM: i64 = crate::pipeline::MAX_JSON_INTEGER as i64;

/// The query of `GET /jobs/{id}/events`.
#[derive(serde::Deserialize)]
pub(super) struct EventsQuery {
    /// Replay every stored snapshot after this number (`0`: all), as `Last-Event-ID` does.
    from: Option<String>,
    /// Every other parameter ([`check_other_params`]: `_`-names ignored, others refused).
    #[serde(flatten)]
    other: std::collections::BTreeMap<String, String>,
}

/// Where the stream starts: the `Last-Event-ID` header of a reconnecting client, else the
/// `from` query parameter; `None`: the latest snapshot only.
fn start_after(headers: &HeaderMap, query: &EventsQuery) -> Result<Option<i64>, ApiError> {
    check_other_params(&query.other, "from")?;
    let header = headers
        .get("last-event-id")
        .and_then(|v| v.to_str().ok())
        .and_then(|s| s.trim().parse().ok());
    if header.is_some() {
        return Ok(header);
    }
    match query.from.as_deref() {
        None => Ok(None),
        Some(s) => match s.trim().parse::<i64>() {
            Ok(n) if (0..=MAX_FROM).contains(&n) => Ok(Some(n)),
            _ => Err(ApiError::InvalidQuery {
                field: "from".into(),
                reason: format!(
                    "must be a snapshot number (an integer from 0 to {MAX_FROM}), got {s:?}"
                ),
            }),
        },
    }
}

pub(super) async fn events(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
    query: Result<Query<EventsQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    let id = job_id(&raw)?;
    let Query(query) = query.map_err(|e| ApiError::InvalidQuery {
        field: "query".into(),
        reason: e.body_text(),
    })?;
    let last_seen = start_after(&headers, &query)?;
    let permit = state
        .sse_permits
        .clone()
        .try_acquire_owned()
        .map_err(|_| ApiError::Busy {
            what: "too many event streams are open",
            retry_after_secs: 5,
        })?;
    // Subscribe before reading the stored state so nothing falls between the two.
    let rx = state.hub.subscribe(&id);
    let row = load_job(&state, &id, &caller).await?;
    let (tx, out) = mpsc::channel::<Event>(64);
    let state_for_feed = state.clone();
    // The feed task holds the stream's permit: it ends when the client goes away.
    tokio::spawn(async move {
        let _permit = permit;
        feed(state_for_feed, row, last_seen, rx, tx).await
    });
    let stream = futures_util::stream::unfold(out, |mut out| async move {
        out.recv().await.map(|e| (Ok(e), out))
    });
    let every = Duration::from_secs(state.cfg.server.sse_heartbeat_secs.max(1));
    Ok(Sse::new(stream).keep_alive(KeepAlive::new().interval(every).text("heartbeat")))
}

fn json_event(name: &str, value: &impl serde::Serialize) -> Event {
    let data = serde_json::to_string(value).unwrap_or_else(|_| "{}".into());
    Event::default().event(name).data(data)
}

fn state_event(row: &JobRow) -> Event {
    json_event("state", &JobView::from_row(row))
}

/// The data of a `snapshot` event.
#[derive(serde::Serialize)]
struct SnapshotView<'a> {
    n: i64,
    stage: &'a str,
    step: i64,
    svg: &'a str,
}

fn snapshot_event(snapshot: &SnapshotView<'_>) -> Event {
    json_event("snapshot", snapshot)
}

fn progress_event(progress: &ProgressView) -> Event {
    json_event("progress", progress)
}

fn terminal_event(row: &JobRow) -> Option<Event> {
    let name = match row.status {
        JobStatus::Succeeded => "done",
        JobStatus::Failed => "failed",
        JobStatus::Cancelled => "cancelled",
        JobStatus::Queued | JobStatus::Running => return None,
    };
    Some(json_event(name, &JobView::from_row(row)))
}

struct Feed {
    state: AppState,
    id: String,
    tx: mpsc::Sender<Event>,
    sent_snapshot: i64,
    /// The status and (stage, step) last sent, so a re-read sends only what changed.
    sent_status: JobStatus,
    sent_progress: (Option<Stage>, i64),
}

impl Feed {
    /// Sends `e` with the stream's position as its id (the last snapshot sent, 0 before any),
    /// so a client cut off after any event resumes where it was.
    async fn send(&self, e: Event) -> Result<(), ()> {
        let e = e.id(self.sent_snapshot.to_string());
        self.tx.send(e).await.map_err(|_| ())
    }

    async fn send_snapshots(&mut self, rows: Vec<SnapshotRow>) -> Result<(), ()> {
        for s in rows {
            self.send_snapshot(&SnapshotView {
                n: s.n,
                stage: &s.stage,
                step: s.step,
                svg: &s.svg,
            })
            .await?;
        }
        Ok(())
    }

    /// Sends `snapshot` unless the client has it already.
    async fn send_snapshot(&mut self, snapshot: &SnapshotView<'_>) -> Result<(), ()> {
        if snapshot.n > self.sent_snapshot {
            self.sent_snapshot = snapshot.n;
            self.send(snapshot_event(snapshot)).await?;
        }
        Ok(())
    }

    /// The (stage, step) of a stored row, as `sent_progress` keeps them.
    fn progress_of(row: &JobRow) -> (Option<Stage>, i64) {
        (row.stage.as_deref().and_then(Stage::from_name), row.step)
    }

    /// Reloads the job and sends what a lagging client missed. `Ok(true)` when the job is
    /// finished (terminal event sent).
    async fn resync(&mut self) -> Result<bool, ()> {
        let Ok(Some(row)) = self.state.store.get_job(&self.id).await else {
            return Err(());
        };
        self.sent_status = row.status;
        self.sent_progress = Feed::progress_of(&row);
        self.send(state_event(&row)).await?;
        self.snapshots_and_end(&row).await
    }

    /// Re-reads the job after a change that may have happened on another node: a `state` event
    /// if its status changed, else a `progress` event if it moved, then new snapshots.
    async fn refresh(&mut self) -> Result<bool, ()> {
        let row = match self.state.store.get_job(&self.id).await {
            Ok(Some(row)) => row,
            Ok(None) => return Err(()),
            // The database is briefly unreachable: try again at the next tick.
            Err(_) => return Ok(false),
        };
        if row.status != self.sent_status {
            self.sent_status = row.status;
            self.send(state_event(&row)).await?;
        } else if Feed::progress_of(&row) != self.sent_progress && row.status == JobStatus::Running
        {
            self.send(progress_event(&ProgressView::from(&row))).await?;
        }
        self.sent_progress = Feed::progress_of(&row);
        self.snapshots_and_end(&row).await
    }

    async fn snapshots_and_end(&mut self, row: &JobRow) -> Result<bool, ()> {
        let snaps = self
            .state
            .store
            .snapshots_after(&self.id, self.sent_snapshot, REPLAY_LIMIT)
            .await
            .map_err(|_| ())?;
        self.send_snapshots(snaps).await?;
        if let Some(t) = terminal_event(row) {
            self.send(t).await?;
            return Ok(true);
        }
        Ok(false)
    }
}

/// The stream's start: the stored state, then the snapshots the client has not seen (all after
/// `last_seen`, else the latest), then the terminal event of a finished job. `Ok(true)` when
/// the job is finished.
async fn replay(f: &mut Feed, row: &JobRow, last_seen: Option<i64>) -> Result<bool, ()> {
    f.send(state_event(row)).await?;
    let stored = match last_seen {
        Some(n) => f.state.store.snapshots_after(&f.id, n, REPLAY_LIMIT).await,
        None => f
            .state
            .store
            .latest_snapshot(&f.id)
            .await
            .map(|s| s.into_iter().collect()),
    }
    .map_err(|_| ())?;
    f.send_snapshots(stored).await?;
    match terminal_event(row) {
        Some(t) => f.send(t).await.map(|()| true),
        None => Ok(false),
    }
}

/// Handles one live event (or the lack of one). `Ok(true)` when the stream is over.
async fn on_event(
    f: &mut Feed,
    ev: Result<JobEvent, broadcast::error::RecvError>,
    rx: &mut broadcast::Receiver<JobEvent>,
) -> Result<bool, ()> {
    match ev {
        Ok(JobEvent::Progress(p)) => {
            f.sent_progress = (Some(p.stage), i64::from(p.step));
            f.send(progress_event(&ProgressView::from(&p))).await?;
            Ok(false)
        }
        Ok(JobEvent::Snapshot {
            n,
            stage,
            step,
            svg,
        }) => {
            let snapshot = SnapshotView {
                n,
                stage: stage.as_str(),
                step: i64::from(step),
                svg: &svg,
            };
            f.send_snapshot(&snapshot).await?;
            Ok(false)
        }
        Ok(JobEvent::Changed) => f.refresh().await,
        Ok(JobEvent::Status(_)) | Ok(JobEvent::Finished(_)) => f.resync().await,
        Err(broadcast::error::RecvError::Lagged(_)) => f.resync().await,
        Err(broadcast::error::RecvError::Closed) => {
            // The final snapshot may have been stored just before: resync sends it, then the
            // terminal event.
            let done = f.resync().await?;
            if !done {
                // Channel gone without a terminal status: resubscribe.
                *rx = f.state.hub.subscribe(&f.id);
            }
            Ok(done)
        }
    }
}

async fn feed(
    state: AppState,
    row: JobRow,
    last_seen: Option<i64>,
    mut rx: broadcast::Receiver<JobEvent>,
    tx: mpsc::Sender<Event>,
) -> Result<(), ()> {
    let mut shutdown = state.shutdown.clone();
    let shared_db = state.store.backend() == Backend::Postgres;
    let mut f = Feed {
        id: row.id.clone(),
        state,
        tx,
        sent_snapshot: last_seen.unwrap_or(0),
        sent_status: row.status,
        sent_progress: Feed::progress_of(&row),
    };
    if replay(&mut f, &row, last_seen).await? {
        return Ok(());
    }
    let mut poll = tokio::time::interval(Duration::from_secs(1));
    poll.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let ev = tokio::select! {
            ev = rx.recv() => ev,
            _ = poll.tick(), if shared_db => Ok(JobEvent::Changed),
            _ = shutdown.changed() => return Ok(()),
            _ = f.tx.closed() => return Ok(()),
        };
        if on_event(&mut f, ev, &mut rx).await? {
            return Ok(());
        }
    }
}
