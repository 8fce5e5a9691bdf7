//! The job contract: what a caller asks for ([`JobSpec`]: kind, inputs, style, method, preset,
//! the numbers it gave, and the [`RunPlan`] resolved from them), its vocabularies ([`JobKind`], [`Method`],
//! [`Preset`]) and the hard [`Limits`] every entry point checks it against.

use super::canvas::CanvasRequest;
use super::plan::{RunPlan, SizeConditioningRequest};
use crate::scene::MAX_PATHS;
pub use crate::stages::styles::Style;
use crate::vector::VectorOptions;
use serde::{Deserialize, Serialize};

/// What a job produces (the queue's typed `kind` column).
pub use crate::store::JobKind;

/// How a text job is produced (VectorFusion §4): sample+trace, sample+trace+SDS, or SDS alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    Scratch,
    SdLive,
    #[default]
    SdLiveSds,
}

impl Method {
    pub const ALL: &[Method] = &[Method::Scratch, Method::SdLive, Method::SdLiveSds];

    /// The method's name as in the API and on the command line (`sd_live_sds`).
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Scratch => "scratch",
            Method::SdLive => "sd_live",
            Method::SdLiveSds => "sd_live_sds",
        }
    }
}

/// Named speed/quality trade-offs, the one preset vocabulary of the service, `generate`,
/// `vectorize` and the benchmarks: for text runs resolution, steps, paths, samples and encoder
/// ([`Preset::settings_for`]), for vectorize runs LIVE's working size and iterations
/// ([`Preset::live_config`]). The command line also accepts `default` and `quality`, older names
/// of `balanced` and `paper` (`quality` was the vectorize command's name of its largest preset);
/// the API and stored jobs use the canonical names only.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    Draft,
    Fast,
    #[default]
    #[value(alias = "default")]
    Balanced,
    #[value(alias = "quality")]
    Paper,
    /// Stable Diffusion at 256 px through TAESD sized for a 2-core CPU (≤ 10 minutes per SVG);
    /// its sampler steps follow the model's sampler ([`Preset::settings_for_model`]).
    Cpu,
}

impl Preset {
    pub const ALL: &[Preset] = &[
        Preset::Draft,
        Preset::Fast,
        Preset::Balanced,
        Preset::Paper,
        Preset::Cpu,
    ];
}

/// Hard limits on a job's parameters: the `[limits]` section of `config.toml` (every field
/// optional there), checked by [`Limits::validate`] when the configuration loads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Limits {
    /// At most [`MAX_PATHS`].
    pub max_paths: u32,
    pub max_steps: u32,
    pub max_samples: u32,
    pub max_caption_chars: usize,
    pub max_svg_bytes: usize,
    pub max_image_side: u32,
    /// Largest canvas side a text job may ask for (`width`, `height`; at least
    /// [`super::canvas::MIN_CANVAS_SIDE`]).
    pub max_canvas_side: u32,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_paths: MAX_PATHS as u32,
            max_steps: 20_000,
            max_samples: 64,
            max_caption_chars: 1000,
            max_svg_bytes: 2 * 1024 * 1024,
            max_image_side: 4096,
            max_canvas_side: 2048,
        }
    }
}

impl Limits {
    /// Each limit is positive, and `max_paths` is at most [`MAX_PATHS`] (what the stages can
    /// run): a server never accepts a job its workers would refuse. `Err` names the key.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if self.max_paths == 0 || self.max_paths as usize > MAX_PATHS {
            return Err((
                "limits.max_paths",
                format!("must be between 1 and {MAX_PATHS}"),
            ));
        }
        for (key, v) in [
            ("limits.max_steps", self.max_steps as usize),
            ("limits.max_samples", self.max_samples as usize),
            ("limits.max_caption_chars", self.max_caption_chars),
            ("limits.max_svg_bytes", self.max_svg_bytes),
            ("limits.max_image_side", self.max_image_side as usize),
        ] {
            if v == 0 {
                return Err((key, "must be at least 1".into()));
            }
        }
        let min = super::canvas::MIN_CANVAS_SIDE;
        if self.max_canvas_side < min || self.max_canvas_side > crate::scene::MAX_SIDE {
            return Err((
                "limits.max_canvas_side",
                format!("must be between {min} and {}", crate::scene::MAX_SIDE),
            ));
        }
        Ok(())
    }
}

/// A validated job: the request as the caller made it and the plan resolved from it, which is
/// what the store keeps. Construct through the service's request validation (or fill it in
/// directly in code and call [`JobSpec::validate`]).
///
/// `paths`, `steps` and `samples` are the caller's: `None` means the preset's, and the numbers
/// that run are the plan's. Jobs stored before this held the resolved numbers there; they read
/// as explicit values equal to their plan's (or, for jobs stored before plans, are resolved
/// as explicit values when they run), so they run as they did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobSpec {
    pub kind: JobKind,
    pub caption: Option<String>,
    /// PNG or JPEG bytes (base64 in JSON).
    #[serde(default, with = "base64_bytes")]
    pub image: Option<Vec<u8>>,
    /// An SVG to start from.
    pub svg: Option<String>,
    pub style: Style,
    pub method: Method,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paths: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<u32>,
    pub seed: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    pub preset: Preset,
    pub priority: i32,
    /// Text jobs: start some samples from the training icons nearest to the caption
    /// (retrieval, when the model has an installed index); false samples from noise only.
    #[serde(default = "default_retrieval")]
    pub retrieval: bool,
    /// Text jobs: how many of the best distinct results to return (`None`: one; the plan
    /// checks the bounds).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variations: Option<u32>,
    /// Colours, background, grouping and (vectorize) the stopping rules of the vector stage;
    /// jobs stored before them take the defaults.
    #[serde(default, flatten)]
    pub vector: VectorOptions,
    /// Text jobs: the canvas (`aspect`, or `width` and `height`); none: the preset's square.
    #[serde(default, flatten)]
    pub canvas: CanvasRequest,
    /// Text jobs: what classifier-free guidance steers away from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub negative_prompt: Option<String>,
    /// Text jobs on SDXL: the size and crop conditioning (none: the drawn size, no crop).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size_conditioning: Option<SizeConditioningRequest>,
    /// The run, resolved once when the job was accepted ([`RunPlan`]): workers run this and
    /// nothing else, so a queued job runs the same whatever the preset table says later. Jobs
    /// stored before plans existed have none and are resolved when they run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<RunPlan>,
}

fn default_retrieval() -> bool {
    true
}

/// Why a [`JobSpec`] is invalid: which field, and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct SpecError {
    pub field: &'static str,
    pub reason: String,
}

impl SpecError {
    pub fn new(field: &'static str, reason: impl Into<String>) -> Self {
        SpecError {
            field,
            reason: reason.into(),
        }
    }
}

/// Allowed priority range (higher runs first).
pub const PRIORITY_RANGE: std::ops::RangeInclusive<i32> = -100..=100;

/// 2^53 − 1, the largest integer every JSON client keeps exactly (JavaScript numbers are
/// doubles): the bound of every integer the API hands out to be sent back (seeds, event ids).
pub const MAX_JSON_INTEGER: u64 = (1 << 53) - 1;

/// The largest seed ([`MAX_JSON_INTEGER`]), so a seed read back and resubmitted is the same
/// seed. Seeds derived from it (the plan's per-stage seeds, defaults from the job id) stay
/// within it too.
pub const MAX_SEED: u64 = MAX_JSON_INTEGER;

/// Parses a command-line seed (at most [`MAX_SEED`]).
pub fn parse_seed(s: &str) -> Result<u64, String> {
    let seed: u64 = s
        .trim()
        .parse()
        .map_err(|e| format!("not a whole number: {e}"))?;
    check_seed(seed).map_err(|e| e.reason)
}

/// `seed` if it is at most [`MAX_SEED`].
pub fn check_seed(seed: u64) -> Result<u64, SpecError> {
    if seed > MAX_SEED {
        return Err(SpecError::new(
            "seed",
            format!(
                "must be between 0 and {MAX_SEED} (2^53 - 1, the largest integer JavaScript \
                 clients keep exactly), got {seed}"
            ),
        ));
    }
    Ok(seed)
}

/// `v` when it is within `1..=max`, otherwise an error naming `field`.
pub(super) fn check_range(field: &'static str, v: u32, max: u32) -> Result<u32, SpecError> {
    if v == 0 || v > max {
        return Err(SpecError::new(
            field,
            format!("must be between 1 and {max}, got {v}"),
        ));
    }
    Ok(v)
}

impl JobSpec {
    /// Checks every field against `limits` and the kind's requirements (the numbers it gives;
    /// the plan checks the preset's).
    pub fn validate(&self, limits: &Limits) -> Result<(), SpecError> {
        check_seed(self.seed)?;
        for (field, v, max) in [
            ("paths", self.paths, limits.max_paths),
            ("steps", self.steps, limits.max_steps),
            ("samples", self.samples, limits.max_samples),
        ] {
            if let Some(v) = v {
                check_range(field, v, max)?;
            }
        }
        if !PRIORITY_RANGE.contains(&self.priority) {
            return Err(SpecError::new(
                "priority",
                format!(
                    "must be between {} and {}, got {}",
                    PRIORITY_RANGE.start(),
                    PRIORITY_RANGE.end(),
                    self.priority
                ),
            ));
        }
        if let Some(c) = &self.caption {
            check_text("caption", c, limits)?;
        }
        if let Some(n) = &self.negative_prompt {
            check_text("negative_prompt", n, limits)?;
        }
        self.canvas.check(limits.max_canvas_side)?;
        if let Some(svg) = &self.svg
            && svg.len() > limits.max_svg_bytes
        {
            return Err(SpecError::new(
                "svg",
                format!(
                    "is {} bytes, at most {} allowed",
                    svg.len(),
                    limits.max_svg_bytes
                ),
            ));
        }
        self.vector
            .validate()
            .map_err(|(field, reason)| SpecError::new(field, reason))?;
        match self.kind {
            JobKind::Text => self.check_text_inputs(),
            JobKind::Vectorize if self.image.is_none() => Err(SpecError::new(
                "image",
                "is required for kind \"vectorize\" (base64 PNG or JPEG)",
            )),
            JobKind::Vectorize => self.check_vectorize_inputs(),
        }
    }

    /// A vectorize job has no canvas and no negative prompt (its canvas is its image's).
    fn check_vectorize_inputs(&self) -> Result<(), SpecError> {
        for (set, field) in [
            (self.canvas.aspect.is_some(), "aspect"),
            (self.canvas.width.is_some(), "width"),
            (self.canvas.height.is_some(), "height"),
            (self.negative_prompt.is_some(), "negative_prompt"),
            (self.size_conditioning.is_some(), "size_conditioning"),
        ] {
            if set {
                return Err(SpecError::new(field, "only applies to kind \"text\""));
            }
        }
        Ok(())
    }

    /// A text job has a caption, no image and no vectorize stopping rule.
    fn check_text_inputs(&self) -> Result<(), SpecError> {
        for (set, field) in [
            (self.vector.target_psnr.is_some(), "target_psnr"),
            (self.vector.max_bytes.is_some(), "max_bytes"),
        ] {
            if set {
                return Err(SpecError::new(
                    field,
                    "only applies to kind \"vectorize\" (a text job's path count is its paths)",
                ));
            }
        }
        if self.caption.is_none() {
            return Err(SpecError::new("caption", "is required for kind \"text\""));
        }
        if self.image.is_some() {
            return Err(SpecError::new(
                "image",
                "only applies to kind \"vectorize\" (use \"svg\" to start a text job from a drawing)",
            ));
        }
        Ok(())
    }
}

/// A caption (or negative prompt: `field`) is not blank, within the caption length limit and
/// free of control characters (other than newlines and tabs).
pub(super) fn check_text(field: &'static str, c: &str, limits: &Limits) -> Result<(), SpecError> {
    if c.trim_matches(|ch: char| ch.is_whitespace() || ch == '\u{feff}')
        .is_empty()
    {
        return Err(SpecError::new(field, "must not be empty"));
    }
    let n = c.chars().count();
    if n > limits.max_caption_chars {
        return Err(SpecError::new(
            field,
            format!(
                "is {n} characters, at most {} allowed",
                limits.max_caption_chars
            ),
        ));
    }
    if c.chars()
        .any(|ch| ch.is_control() && ch != '\n' && ch != '\t')
    {
        return Err(SpecError::new(field, "contains control characters"));
    }
    Ok(())
}

/// A vocabulary word as serde spells it (snake_case), in any case and with `-` or spaces for `_`.
fn parse_word<T: serde::de::DeserializeOwned>(
    s: &str,
    what: &str,
    expected: &str,
) -> Result<T, String> {
    let word = s.trim().to_ascii_lowercase().replace(['-', ' '], "_");
    T::deserialize(serde_json::Value::String(word))
        .map_err(|_| format!("unknown {what} {s:?} (expected {expected})"))
}

impl std::str::FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "default" => return Ok(Preset::Balanced),
            "quality" => return Ok(Preset::Paper),
            _ => {}
        }
        parse_word(s, "preset", "draft, fast, balanced, paper or cpu")
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        parse_word(s, "method", "scratch, sd_live or sd_live_sds")
    }
}

mod base64_bytes {
    use base64::Engine;
    use base64::engine::general_purpose::STANDARD;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<Vec<u8>>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(bytes) => s.serialize_some(&STANDARD.encode(bytes)),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<u8>>, D::Error> {
        let v: Option<String> = Option::deserialize(d)?;
        v.map(|s| STANDARD.decode(s).map_err(serde::de::Error::custom))
            .transpose()
    }
}
