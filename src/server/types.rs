//! Request parsing/validation and response shapes of the HTTP API (see `openapi.yaml`).

use super::error::ApiError;
use crate::pipeline::{
    Executor, JobKind, JobSpec, Limits, Method, Preset, RunPlan, SpecError, Style, request_of,
};
use crate::pipeline::{RerankReport, RunReport, VariationReport};
use crate::progress::Stage;
use crate::store::JobRow;
use crate::vector::VectorOptions;
use crate::vector::palette::ColorPlan;
use base64::Engine;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

mod views;
use views::rfc3339;
pub use views::{AttemptView, ProgressView};

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
    "fill",
    "variations",
    "aspect",
    "width",
    "height",
    "negative_prompt",
    "size_conditioning",
];

/// Fields whose omission means "the preset decides": the job's [`crate::pipeline::RunPlan`]
/// holds the resolved values, the stored request only what was given.
pub const PRESET_FIELDS: &[&str] = &["paths", "steps", "samples"];

fn field<T: DeserializeOwned>(obj: &Map<String, Value>, name: &str) -> Result<Option<T>, ApiError> {
    match obj.get(name) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => T::deserialize(v)
            .map(Some)
            .map_err(|e| ApiError::invalid(name, e.to_string())),
    }
}

/// [`field`] for a JSON object (serde alone would also read a struct from an array).
fn object_field<T: DeserializeOwned>(
    obj: &Map<String, Value>,
    name: &str,
) -> Result<Option<T>, ApiError> {
    match obj.get(name) {
        Some(v) if !v.is_object() && !v.is_null() => {
            Err(ApiError::invalid(name, "must be a JSON object"))
        }
        _ => field(obj, name),
    }
}

/// JSON Schema (and so `openapi.yaml`) counts `7374.0` as an integer; serde does not. Whole-number
/// floats within `i64::MIN..2^64`, at the top level and in nested objects, become integers (the
/// range checks then apply).
fn whole_numbers_as_integers(obj: &mut Map<String, Value>) {
    for v in obj.values_mut() {
        if let Value::Object(inner) = v {
            whole_numbers_as_integers(inner);
            continue;
        }
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

/// A parsed `POST /jobs` body.
pub struct Submission {
    /// The request as given, typed and validated, with the plan resolved from it.
    pub spec: JobSpec,
    /// SHA-256 (hex) of the canonical request: the spec with defaults applied, `null` the same as
    /// an absent field, keys in one order, the image as its decoded bytes and the seed only when
    /// given. Idempotency compares this, so the same request re-serialised is the same request.
    pub digest: String,
}

/// The [`Submission::digest`] of `spec`, whose seed was given by the caller if `seed_given`.
fn canonical_digest(spec: &JobSpec, seed_given: bool) -> Result<String, ApiError> {
    use sha2::Digest;
    let mut value = serde_json::to_value(spec).map_err(|e| ApiError::Internal(e.to_string()))?;
    if let Value::Object(m) = &mut value {
        m.remove("plan");
        // The image is hashed as bytes below, not re-encoded.
        m.remove("image");
        if !seed_given {
            m.insert("seed".into(), Value::Null);
        }
    }
    let text = serde_json::to_string(&value).map_err(|e| ApiError::Internal(e.to_string()))?;
    let mut hasher = sha2::Sha256::new();
    hasher.update(text.as_bytes());
    if let Some(image) = &spec.image {
        hasher.update([0u8]);
        hasher.update(image);
    }
    Ok(format!("{:x}", hasher.finalize()))
}

/// Parses and validates a `POST /jobs` body into a [`Submission`]: the request as given and the
/// plan resolved from it. `default_seed` seeds jobs that give no seed (so every job is
/// reproducible from its stored spec). A text job the executor is not ready for is refused
/// ([`ApiError::ModelsNotConfigured`]). Image decoding is checked separately ([`check_image`])
/// because it is CPU work.
pub fn parse_submit(
    body: &[u8],
    limits: &Limits,
    default_seed: u64,
    executor: &dyn Executor,
) -> Result<Submission, ApiError> {
    let obj = submit_object(body)?;
    let mut spec = request_from(&obj, default_seed)?;
    let seed_given = obj.get("seed").is_some_and(|v| !v.is_null());
    // The request's own fields first ...
    spec.validate(limits)
        .map_err(|e| ApiError::invalid(e.field, e.reason))?;
    // ... then whether it can run: a text job the executor cannot run yet is refused with the
    // configuration hint (the submit path's one readiness check, before any upload is decoded)
    // ...
    if spec.kind == JobKind::Text
        && let Err(e) = executor.text_ready()
    {
        tracing::warn!(reason = %e, "text job refused: text models are not configured");
        return Err(ApiError::ModelsNotConfigured(e.to_string()));
    }
    // ... then the plan: omitted paths/steps/samples are the preset's, resolved once, exactly
    // as the CLI resolves them, and checked against the limits.
    let plan = executor
        .plan(&request_of(&spec), limits)
        .map_err(|e| plan_error(e, &obj, spec.preset))?;
    spec.plan = Some(plan);
    let digest = canonical_digest(&spec, seed_given)?;
    Ok(Submission { spec, digest })
}

/// The body as a JSON object of known fields, whole-number floats made integers.
fn submit_object(body: &[u8]) -> Result<Map<String, Value>, ApiError> {
    let value: Value =
        serde_json::from_slice(body).map_err(|e| ApiError::MalformedJson(e.to_string()))?;
    let Value::Object(mut obj) = value else {
        return Err(ApiError::MalformedJson(
            "expected a JSON object at the top level".into(),
        ));
    };
    whole_numbers_as_integers(&mut obj);
    if let Some(key) = obj.keys().find(|k| !SUBMIT_FIELDS.contains(&k.as_str())) {
        return Err(ApiError::invalid(
            key.clone(),
            format!(
                "unknown field; expected one of {}",
                SUBMIT_FIELDS.join(", ")
            ),
        ));
    }
    Ok(obj)
}

/// The `image` field's bytes: base64, optionally as a `data:` URL; not empty.
fn image_bytes(obj: &Map<String, Value>) -> Result<Option<Vec<u8>>, ApiError> {
    let Some(s) = field::<String>(obj, "image")? else {
        return Ok(None);
    };
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
    Ok(Some(bytes))
}

/// The request of a submit body as a spec without a plan (fields typed, not yet validated).
fn request_from(obj: &Map<String, Value>, default_seed: u64) -> Result<JobSpec, ApiError> {
    let kind: JobKind = field(obj, "kind")?
        .ok_or_else(|| ApiError::invalid("kind", "is required: \"text\" or \"vectorize\""))?;
    let image = image_bytes(obj)?;
    let method: Option<Method> = field(obj, "method")?;
    if kind == JobKind::Vectorize && method.is_some() {
        return Err(ApiError::invalid("method", "only applies to kind \"text\""));
    }
    let style = field::<Style>(obj, "style")?.unwrap_or_default();
    let preset = field::<Preset>(obj, "preset")?.unwrap_or_default();
    let (paths, steps, samples) = (
        field(obj, "paths")?,
        field(obj, "steps")?,
        field(obj, "samples")?,
    );
    Ok(JobSpec {
        kind,
        caption: field(obj, "caption")?,
        image,
        svg: field(obj, "svg")?,
        style,
        method: method.unwrap_or_default(),
        paths,
        steps,
        seed: field(obj, "seed")?.unwrap_or(default_seed),
        samples,
        preset,
        priority: field(obj, "priority")?.unwrap_or(0),
        retrieval: field(obj, "retrieval")?.unwrap_or(true),
        variations: field(obj, "variations")?,
        vector: VectorOptions {
            colors: ColorPlan {
                colors: field(obj, "colors")?,
                palette: field(obj, "palette")?.map(crate::vector::palette::dedup_palette),
                background: field(obj, "background")?.unwrap_or_default(),
                group: field(obj, "group")?.unwrap_or_default(),
            },
            target_psnr: field(obj, "target_psnr")?,
            max_bytes: field(obj, "max_bytes")?,
            fill: field(obj, "fill")?.unwrap_or_default(),
        },
        canvas: crate::pipeline::CanvasRequest {
            aspect: field(obj, "aspect")?,
            width: field(obj, "width")?,
            height: field(obj, "height")?,
        },
        negative_prompt: field(obj, "negative_prompt")?,
        size_conditioning: object_field(obj, "size_conditioning")?,
        plan: None,
    })
}

/// A plan error as a 400; a number the request left to `preset` says so.
fn plan_error(e: SpecError, obj: &Map<String, Value>, preset: Preset) -> ApiError {
    let from_preset =
        PRESET_FIELDS.contains(&e.field) && obj.get(e.field).is_none_or(Value::is_null);
    if !from_preset {
        return ApiError::invalid(e.field, e.reason);
    }
    let name = serde_json::to_value(preset)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    ApiError::invalid(
        e.field,
        format!(
            "{} (the value of preset {name}; pass {} explicitly or choose a smaller preset)",
            e.reason, e.field
        ),
    )
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
    /// The run's paths, SDS steps and samples: the plan's where the run has such a stage,
    /// otherwise as given (absent when not given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paths: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steps: Option<u32>,
    pub seed: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    pub preset: Preset,
    pub has_image: bool,
    pub has_svg: bool,
    pub retrieval: bool,
    /// Results the job returns (1 unless a text job asked for more).
    pub variations: u32,
    /// Colours, background, grouping and the vectorize stopping rules, as submitted.
    #[serde(flatten)]
    pub vector: VectorOptions,
    /// Text jobs: the canvas asked for (`aspect`, or `width` and `height`), as submitted.
    #[serde(flatten)]
    pub canvas: crate::pipeline::CanvasRequest,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub negative_prompt: Option<String>,
    /// Text jobs on SDXL: the size and crop conditioning, as submitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub size_conditioning: Option<crate::pipeline::SizeConditioningRequest>,
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
    pub result_pdf: String,
}

/// A job as returned by the API.
#[derive(Serialize)]
pub struct JobView {
    pub id: String,
    pub kind: String,
    pub status: String,
    pub stage: Option<Stage>,
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
    pub attempt_history: Option<Vec<AttemptView>>,
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
    pub chosen: usize,
    pub samples: u32,
}

impl From<&RerankReport> for RerankView {
    fn from(r: &RerankReport) -> Self {
        RerankView {
            scorer: r.scorer.clone(),
            scores: r.scores.clone(),
            chosen: r.chosen,
            samples: r.samples,
        }
    }
}

/// The part of a text job's checkpoint the job view reads: the run's report so far.
#[derive(Deserialize)]
struct CheckpointReport {
    #[serde(default)]
    detail: Option<RunReport>,
}

/// What a succeeded job produced besides the SVG.
#[derive(Serialize)]
pub struct ResultView {
    pub paths: i64,
    /// The run's [`RunReport`] as stored (results stored before a field existed lack it).
    pub detail: Value,
    /// Every result of the job, variation 1 (`result.svg`) first: one unless a text job
    /// asked for more.
    pub variations: Vec<VariationView>,
}

/// One result of a job: its number, sample, score, paths and downloads.
#[derive(Serialize)]
pub struct VariationView {
    #[serde(flatten)]
    pub report: VariationReport,
    pub svg: String,
    pub png: String,
    pub pdf: String,
}

impl VariationView {
    fn new(job_id: &str, report: VariationReport) -> Self {
        let link = |ext: &str| format!("/jobs/{job_id}/result/{}.{ext}", report.variation);
        VariationView {
            svg: link("svg"),
            png: link("png"),
            pdf: link("pdf"),
            report,
        }
    }
}

impl JobView {
    /// Adds the stored result (paths, detail, rerank scores) of a succeeded job.
    pub fn with_result(mut self, result: &crate::store::ResultRow) -> JobView {
        let detail: Value = serde_json::from_str(&result.detail).unwrap_or(Value::Null);
        let report = RunReport::deserialize(&detail).ok();
        self.rerank = report
            .as_ref()
            .and_then(|r| r.rerank.as_ref().map(RerankView::from));
        let report = report.unwrap_or_default();
        let mut variations = report.variations.clone();
        if variations.is_empty() {
            let paths = usize::try_from(result.paths).unwrap_or(0);
            variations.push(VariationReport::of(1, &report, paths));
        }
        self.result = Some(ResultView {
            paths: result.paths,
            detail,
            variations: variations
                .into_iter()
                .map(|v| VariationView::new(&self.id, v))
                .collect(),
        });
        self
    }

    /// Adds the rerank scores of an unfinished job from its last checkpoint (text jobs save
    /// them with their SDS state).
    pub fn with_checkpoint(mut self, checkpoint: &str) -> JobView {
        self.rerank = serde_json::from_str::<CheckpointReport>(checkpoint)
            .ok()
            .and_then(|c| c.detail?.rerank.as_ref().map(RerankView::from));
        self
    }
}

impl JobView {
    pub fn from_row(row: &JobRow) -> JobView {
        let spec: Option<JobSpec> = serde_json::from_str(&row.spec).ok();
        let base = format!("/jobs/{}", row.id);
        JobView {
            id: row.id.clone(),
            kind: row.kind.as_str().to_string(),
            status: row.status.as_str().to_string(),
            stage: row.stage.as_deref().and_then(Stage::from_name),
            progress: ProgressView::from(row),
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
                paths: s.plan.as_ref().and_then(RunPlan::paths).or(s.paths),
                steps: s.plan.as_ref().and_then(RunPlan::sds_steps).or(s.steps),
                seed: s.seed,
                samples: s.plan.as_ref().and_then(RunPlan::samples).or(s.samples),
                preset: s.preset,
                has_image: s.image.is_some(),
                has_svg: s.svg.is_some(),
                retrieval: s.retrieval,
                variations: s
                    .plan
                    .as_ref()
                    .map_or(s.variations.unwrap_or(1), RunPlan::variations),
                vector: s.vector,
                canvas: s.canvas,
                negative_prompt: s.negative_prompt,
                size_conditioning: s.size_conditioning,
                plan: s.plan,
            }),
            links: Links {
                events: format!("{base}/events"),
                result_svg: format!("{base}/result.svg"),
                result_png: format!("{base}/result.png"),
                result_pdf: format!("{base}/result.pdf"),
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
