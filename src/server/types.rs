//! Request parsing/validation and response shapes of the HTTP API (see `openapi.yaml`).

use super::error::ApiError;
use crate::pipeline::{
    Executor, JobKind, JobSpec, Limits, Method, PlanRequest, Preset, RunPlan, Style, request_of,
};
use crate::store::{AttemptRow, JobRow, JobStatus};
use crate::vector::VectorOptions;
use crate::vector::palette::ColorPlan;
use base64::Engine;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

/// Fields accepted by `POST /jobs` (anything else is rejected as unknown).
pub const SUBMIT_FIELDS: &[&str] = &[
    "kind",
    "caption",
    "image",
    "svg",
    "style",
    "method",
    "paths",
    "steps",
    "seed",
    "samples",
    "preset",
    "priority",
    "retrieval",
    "colors",
    "palette",
    "background",
    "group",
    "target_psnr",
    "max_bytes",
];

/// Fields whose omission means "the preset decides" (the job's [`crate::pipeline::RunPlan`]);
/// the resolved values are stored in the job.
pub const PRESET_FIELDS: &[&str] = &["paths", "steps", "samples"];

fn field<T: DeserializeOwned>(obj: &Map<String, Value>, name: &str) -> Result<Option<T>, ApiError> {
    match obj.get(name) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => T::deserialize(v)
            .map(Some)
            .map_err(|e| ApiError::invalid(name, e.to_string())),
    }
}

/// JSON Schema (and so `openapi.yaml`) counts `7374.0` as an integer; serde does not. Top-level
/// whole-number floats within `i64::MIN..2^64` become integers (the range checks then apply).
fn whole_numbers_as_integers(obj: &mut Map<String, Value>) {
    for v in obj.values_mut() {
        let Value::Number(n) = v else { continue };
        let Some(f) = n.as_f64().filter(|f| n.is_f64() && f.fract() == 0.0) else {
            continue;
        };
        if (0.0..u64::MAX as f64).contains(&f) {
            *v = Value::from(f as u64);
        } else if (i64::MIN as f64..0.0).contains(&f) {
            *v = Value::from(f as i64);
        }
    }
}

/// Parses and validates a `POST /jobs` body into a [`JobSpec`]. `job_id_seed` seeds jobs that
/// give no seed (so every job is reproducible from its stored spec). Image decoding is checked
/// separately ([`check_image`]) because it is CPU work.
pub fn parse_submit(
    body: &[u8],
    limits: &Limits,
    default_seed: u64,
    executor: &dyn Executor,
) -> Result<JobSpec, ApiError> {
    let value: Value =
        serde_json::from_slice(body).map_err(|e| ApiError::MalformedJson(e.to_string()))?;
    let Value::Object(mut obj) = value else {
        return Err(ApiError::MalformedJson(
            "expected a JSON object at the top level".into(),
        ));
    };
    whole_numbers_as_integers(&mut obj);
    for key in obj.keys() {
        if !SUBMIT_FIELDS.contains(&key.as_str()) {
            return Err(ApiError::invalid(
                key.clone(),
                format!(
                    "unknown field; expected one of {}",
                    SUBMIT_FIELDS.join(", ")
                ),
            ));
        }
    }
    let kind: JobKind = field(&obj, "kind")?
        .ok_or_else(|| ApiError::invalid("kind", "is required: \"text\" or \"vectorize\""))?;
    let image_b64: Option<String> = field(&obj, "image")?;
    let image = match image_b64 {
        Some(s) => {
            let trimmed = s.trim();
            let data = trimmed
                .strip_prefix("data:")
                .and_then(|rest| rest.split_once(";base64,").map(|(_, d)| d))
                .unwrap_or(trimmed);
            let bytes = base64::engine::general_purpose::STANDARD
                .decode(data)
                .map_err(|e| ApiError::invalid("image", format!("is not valid base64: {e}")))?;
            if bytes.is_empty() {
                return Err(ApiError::invalid("image", "is empty"));
            }
            Some(bytes)
        }
        None => None,
    };
    let method: Option<Method> = field(&obj, "method")?;
    if kind == JobKind::Vectorize && method.is_some() {
        return Err(ApiError::invalid("method", "only applies to kind \"text\""));
    }
    let style = field::<Style>(&obj, "style")?.unwrap_or_default();
    let preset = field::<Preset>(&obj, "preset")?.unwrap_or_default();
    let paths: Option<u32> = field(&obj, "paths")?;
    let steps: Option<u32> = field(&obj, "steps")?;
    let samples: Option<u32> = field(&obj, "samples")?;
    let mut spec = JobSpec {
        kind,
        caption: field(&obj, "caption")?,
        image,
        svg: field(&obj, "svg")?,
        style,
        method: method.unwrap_or_default(),
        paths: paths.unwrap_or(1),
        steps: steps.unwrap_or(1),
        seed: field(&obj, "seed")?.unwrap_or(default_seed),
        samples: samples.unwrap_or(1),
        preset,
        priority: field(&obj, "priority")?.unwrap_or(0),
        retrieval: field(&obj, "retrieval")?.unwrap_or(true),
        vector: VectorOptions {
            colors: ColorPlan {
                colors: field(&obj, "colors")?,
                palette: field(&obj, "palette")?.map(crate::vector::palette::dedup_palette),
                background: field(&obj, "background")?.unwrap_or_default(),
                group: field(&obj, "group")?.unwrap_or_default(),
            },
            target_psnr: field(&obj, "target_psnr")?,
            max_bytes: field(&obj, "max_bytes")?,
        },
        plan: None,
    };
    // The request's own fields first (omitted numbers stand in as 1) ...
    spec.validate(limits)
        .map_err(|e| ApiError::invalid(e.field, e.reason))?;
    // ... then the plan: omitted paths/steps/samples are the preset's, resolved once, exactly
    // as the CLI resolves them, and checked against the limits. A text job the executor cannot
    // run yet is refused by the caller with the configuration hint, not here.
    if kind == JobKind::Text && executor.text_ready().is_err() {
        return Ok(spec);
    }
    let request = PlanRequest {
        paths,
        steps,
        samples,
        ..request_of(&spec)
    };
    let plan = executor.plan(&request, limits).map_err(|e| {
        let from_preset =
            PRESET_FIELDS.contains(&e.field) && obj.get(e.field).is_none_or(Value::is_null);
        let reason = if from_preset {
            format!(
                "{} (the value of preset {}; pass {} explicitly or choose a smaller preset)",
                e.reason,
                serde_json::to_value(preset)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_string))
                    .unwrap_or_default(),
                e.field
            )
        } else {
            e.reason
        };
        ApiError::invalid(e.field, reason)
    })?;
    // The stored fields show the resolved numbers.
    let ps = preset.settings_for(plan.text.as_ref().is_some_and(|t| t.model.small_prior));
    spec.paths = match (&plan.text, &plan.vectorize) {
        (Some(t), _) => t.paths,
        (None, Some(v)) => u32::try_from(v.budget.max_paths()).unwrap_or(u32::MAX),
        (None, None) => spec.paths,
    };
    let text = plan.text.as_ref();
    spec.steps = text
        .and_then(|t| t.sds.as_ref().map(|s| s.steps))
        .or(steps)
        .unwrap_or(ps.steps);
    spec.samples = text
        .and_then(|t| t.sample.as_ref().map(|s| s.samples))
        .or(samples)
        .unwrap_or(ps.samples);
    spec.plan = Some(plan);
    Ok(spec)
}

/// Checks that `bytes` is a PNG or JPEG within the size limit (decodes it fully).
pub fn check_image(bytes: &[u8], limits: &Limits) -> Result<(), ApiError> {
    let fmt = image::guess_format(bytes).map_err(|_| {
        ApiError::invalid("image", "is not a PNG or JPEG image (unrecognised bytes)")
    })?;
    if !matches!(fmt, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
        return Err(ApiError::invalid(
            "image",
            format!("must be PNG or JPEG, got {fmt:?}"),
        ));
    }
    let reader = image::ImageReader::with_format(std::io::Cursor::new(bytes), fmt);
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| ApiError::invalid("image", format!("cannot be read: {e}")))?;
    if w.max(h) > limits.max_image_side {
        return Err(ApiError::invalid(
            "image",
            format!(
                "is {w}x{h}; the longest side may be at most {}",
                limits.max_image_side
            ),
        ));
    }
    // Decoded to 8-bit RGBA and dropped: a full check of the data at a quarter of the memory of
    // the f32 image the job will make (64 MB for 4096², not 330).
    image::load_from_memory_with_format(bytes, fmt)
        .map_err(|e| ApiError::invalid("image", format!("cannot be decoded: {e}")))?;
    Ok(())
}

/// Checks that `svg` parses as SVG.
pub fn check_svg(svg: &str) -> Result<(), ApiError> {
    crate::svg::parse_usvg(svg)
        .map(|_| ())
        .map_err(|e| ApiError::invalid("svg", format!("is not a valid SVG: {e}")))
}

fn rfc3339(ms: Option<i64>) -> Option<String> {
    ms.and_then(chrono::DateTime::from_timestamp_millis)
        .map(|t| t.to_rfc3339_opts(chrono::SecondsFormat::Millis, true))
}

#[derive(Serialize)]
pub struct ProgressView {
    pub stage: Option<String>,
    pub step: i64,
    pub total: i64,
    pub fraction: f64,
    pub loss: Option<f64>,
}

#[derive(Serialize)]
pub struct ErrorView {
    pub code: crate::store::FailureCode,
    pub message: String,
}

#[derive(Serialize)]
pub struct ParamsView {
    pub caption: Option<String>,
    pub style: Style,
    pub method: Option<Method>,
    pub paths: u32,
    pub steps: u32,
    pub seed: u64,
    pub samples: u32,
    pub preset: Preset,
    pub has_image: bool,
    pub has_svg: bool,
    pub retrieval: bool,
    /// Colours, background, grouping and the vectorize stopping rules, as submitted.
    #[serde(flatten)]
    pub vector: VectorOptions,
    /// The run plan resolved when the job was accepted: every number the job runs with.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan: Option<RunPlan>,
}

#[derive(Serialize)]
pub struct Links {
    #[serde(rename = "self")]
    pub this: String,
    pub events: String,
    pub result_svg: String,
    pub result_png: String,
}

/// A job as returned by the API.
#[derive(Serialize)]
pub struct JobView {
    pub id: String,
    pub kind: String,
    pub status: String,
    pub stage: Option<String>,
    pub progress: ProgressView,
    pub priority: i64,
    pub attempts: i64,
    pub max_attempts: i64,
    pub cancel_requested: bool,
    pub created_at: Option<String>,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
    pub updated_at: Option<String>,
    pub queued_ms: Option<i64>,
    pub run_ms: Option<i64>,
    pub error: Option<ErrorView>,
    pub params: Option<ParamsView>,
    pub links: Links,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub attempt_history: Option<Vec<AttemptRow>>,
    /// Rejection sampling of an `sd_live*` text job: once it succeeded, or from its last
    /// checkpoint while it runs (`GET /jobs/{id}` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rerank: Option<RerankView>,
    /// Summary of a succeeded job's result (`GET /jobs/{id}` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<ResultView>,
}

/// The CLIP rerank of the K sampled images: one score per sample, the index kept.
#[derive(Serialize)]
pub struct RerankView {
    /// Scorer name; `null` when no scorer is configured (the first sample is kept).
    pub scorer: Option<String>,
    /// Cosine similarity of each sample with the caption (empty without a scorer).
    pub scores: Vec<f64>,
    /// Index of the kept sample.
    pub chosen: u64,
    pub samples: u64,
}

/// What a succeeded job produced besides the SVG.
#[derive(Serialize)]
pub struct ResultView {
    pub paths: i64,
    /// The executor's details (method, preset, timings, per-stage statistics).
    pub detail: Value,
}

impl JobView {
    /// Adds the stored result (paths, detail, rerank scores) of a succeeded job.
    pub fn with_result(mut self, result: &crate::store::ResultRow) -> JobView {
        let detail: Value = serde_json::from_str(&result.detail).unwrap_or(Value::Null);
        self.rerank = detail.get("rerank").and_then(RerankView::from_detail);
        self.result = Some(ResultView {
            paths: result.paths,
            detail,
        });
        self
    }

    /// Adds the rerank scores of an unfinished job from its last checkpoint (text jobs save
    /// them with their SDS state).
    pub fn with_checkpoint(mut self, checkpoint: &str) -> JobView {
        self.rerank = serde_json::from_str::<Value>(checkpoint)
            .ok()
            .and_then(|c| {
                c.get("detail")?
                    .get("rerank")
                    .and_then(RerankView::from_detail)
            });
        self
    }
}

impl RerankView {
    /// From the `rerank` object of a run's detail.
    fn from_detail(r: &Value) -> Option<RerankView> {
        Some(RerankView {
            scorer: r.get("scorer")?.as_str().map(str::to_string),
            scores: r
                .get("scores")?
                .as_array()?
                .iter()
                .filter_map(Value::as_f64)
                .collect(),
            chosen: r.get("best")?.as_u64()?,
            samples: r.get("samples")?.as_u64()?,
        })
    }
}

impl JobView {
    pub fn from_row(row: &JobRow) -> JobView {
        let spec: Option<JobSpec> = serde_json::from_str(&row.spec).ok();
        let fraction = if row.total > 0 {
            (row.step as f64 / row.total as f64).clamp(0.0, 1.0)
        } else if row.status == JobStatus::Succeeded {
            1.0
        } else {
            0.0
        };
        let base = format!("/jobs/{}", row.id);
        JobView {
            id: row.id.clone(),
            kind: row.kind.as_str().to_string(),
            status: row.status.as_str().to_string(),
            stage: row.stage.clone(),
            progress: ProgressView {
                stage: row.stage.clone(),
                step: row.step,
                total: row.total,
                fraction,
                loss: row.loss,
            },
            priority: row.priority,
            attempts: row.attempts,
            max_attempts: row.max_attempts,
            cancel_requested: row.cancel_requested != 0,
            created_at: rfc3339(Some(row.created_at)),
            started_at: rfc3339(row.started_at),
            finished_at: rfc3339(row.finished_at),
            updated_at: rfc3339(Some(row.updated_at)),
            queued_ms: row.started_at.map(|s| s - row.created_at),
            run_ms: row.started_at.zip(row.finished_at).map(|(s, f)| f - s),
            error: row.error_code.map(|code| ErrorView {
                code,
                message: row.error_message.clone().unwrap_or_default(),
            }),
            params: spec.map(|s| ParamsView {
                caption: s.caption,
                style: s.style,
                method: (s.kind == JobKind::Text).then_some(s.method),
                paths: s.paths,
                steps: s.steps,
                seed: s.seed,
                samples: s.samples,
                preset: s.preset,
                has_image: s.image.is_some(),
                has_svg: s.svg.is_some(),
                retrieval: s.retrieval,
                vector: s.vector,
                plan: s.plan,
            }),
            links: Links {
                events: format!("{base}/events"),
                result_svg: format!("{base}/result.svg"),
                result_png: format!("{base}/result.png"),
                this: base,
            },
            attempt_history: None,
            rerank: None,
            result: None,
        }
    }
}

#[derive(Serialize)]
pub struct JobList {
    pub jobs: Vec<JobView>,
    pub next_cursor: Option<String>,
}
