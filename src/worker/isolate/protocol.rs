//! What the server and a job process say to each other: one JSON object per line. The server
//! writes a [`Start`] (its line, then the job's image as raw bytes: [`write_start`]) and then, to
//! stop the job, the line `cancel`; the job process writes [`FromChild`] messages and exits after
//! `done` or `error`.

use crate::pipeline::{FailureCode, JobSpec, ModelDirs, RunOutput};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use std::io::{BufRead, Read, Write};

/// The executor a job process builds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ChildExecutor {
    /// The pipeline (`DefaultExecutor`) with these models.
    Pipeline { models: ModelDirs },
    /// The service test double (`worker::test_executor`), sleeping `step_ms` per step.
    Test { step_ms: u64 },
}

/// The first line the server writes. Its spec carries no image: the image's bytes follow the
/// line as they are (`image_len` of them), so they are never base64-encoded on the way.
#[derive(Debug, Serialize, Deserialize)]
pub struct Start {
    pub executor: ChildExecutor,
    pub spec: JobSpec,
    pub resume: Option<serde_json::Value>,
    pub checkpoint_every: u32,
    /// Bytes of the image after the line; `None`: the job has no image.
    #[serde(default)]
    pub image_len: Option<u64>,
}

/// Why the job process could not read its [`Start`].
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("cannot read the job: {0}")]
    Io(#[from] std::io::Error),
    #[error("the job is not a valid start message: {0}")]
    Json(#[from] serde_json::Error),
    #[error("the job's image ended after {got} of {want} bytes")]
    ShortImage { got: u64, want: u64 },
}

/// Writes the start of `spec`: the [`Start`] line (the spec without its image), then the image's
/// bytes.
pub fn write_start(
    w: &mut impl Write,
    executor: ChildExecutor,
    spec: &JobSpec,
    resume: Option<serde_json::Value>,
    checkpoint_every: u32,
) -> std::io::Result<()> {
    let image = spec.image.as_deref();
    let start = Start {
        executor,
        spec: JobSpec {
            image: None,
            ..spec.clone()
        },
        resume,
        checkpoint_every,
        image_len: image.map(|b| b.len() as u64),
    };
    let mut line = serde_json::to_vec(&start).map_err(std::io::Error::other)?;
    line.push(b'\n');
    w.write_all(&line)?;
    if let Some(bytes) = image {
        w.write_all(bytes)?;
    }
    w.flush()
}

/// Reads what [`write_start`] wrote, the image put back into the spec. `r` is left just after
/// the image (where the `cancel` line may come).
pub fn read_start(r: &mut impl BufRead) -> Result<Start, StartError> {
    let mut line = String::new();
    r.read_line(&mut line)?;
    let mut start: Start = serde_json::from_str(&line)?;
    if let Some(want) = start.image_len {
        let mut bytes = Vec::new();
        let got = r.take(want).read_to_end(&mut bytes)? as u64;
        if got != want {
            return Err(StartError::ShortImage { got, want });
        }
        start.spec.image = Some(bytes);
    }
    Ok(start)
}

/// A line the job process writes.
#[derive(Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FromChild {
    Progress(Progress),
    Checkpoint(serde_json::Value),
    Done(Box<RunOutput>),
    /// A `PipelineError` as its code and message (`PipelineError::reported` rebuilds it).
    Error {
        code: FailureCode,
        message: String,
    },
}

/// The line that asks the job to stop (it checkpoints and answers `cancelled`).
pub const CANCEL: &str = "cancel";

#[cfg(test)]
mod tests {
    use super::*;

    /// A vectorize spec (the image set by each test).
    fn spec() -> JobSpec {
        serde_json::from_str(
            r#"{"kind": "vectorize", "caption": null, "image": null, "svg": null,
                "style": "iconography", "method": "sd_live_sds", "seed": 1,
                "preset": "balanced", "priority": 0}"#,
        )
        .unwrap()
    }

    /// What the server writes for a vectorize job with `image`.
    fn wire(image: &[u8]) -> Vec<u8> {
        let mut spec = spec();
        spec.image = Some(image.to_vec());
        let mut wire = Vec::new();
        write_start(
            &mut wire,
            ChildExecutor::Test { step_ms: 1 },
            &spec,
            None,
            5,
        )
        .unwrap();
        wire
    }

    #[test]
    fn the_image_follows_the_line_as_raw_bytes() {
        // Not UTF-8, and a newline inside: only a length says where the image ends.
        let image = vec![0x89, b'P', b'N', b'G', b'\n', 0xff, 0x00];
        let mut wire = wire(&image);
        let line_end = wire.iter().position(|&b| b == b'\n').unwrap();
        let header: serde_json::Value = serde_json::from_slice(&wire[..line_end]).unwrap();
        assert_eq!(header["spec"]["image"], serde_json::Value::Null);
        assert_eq!(header["image_len"], 7);
        assert_eq!(&wire[line_end + 1..], &image[..]);

        wire.extend_from_slice(format!("{CANCEL}\n").as_bytes());
        let mut r = std::io::Cursor::new(wire);
        let start = read_start(&mut r).unwrap();
        assert_eq!(start.spec.image, Some(image));
        assert_eq!(start.checkpoint_every, 5);
        let mut rest = String::new();
        r.read_line(&mut rest).unwrap();
        assert_eq!(rest.trim(), CANCEL);
    }

    #[test]
    fn a_short_image_is_an_error() {
        let mut wire = wire(&[7; 10]);
        wire.truncate(wire.len() - 7);
        let err = read_start(&mut std::io::Cursor::new(wire)).unwrap_err();
        assert!(
            matches!(err, StartError::ShortImage { got: 3, want: 10 }),
            "{err}"
        );
    }
}
