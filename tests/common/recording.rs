//! A teacher that records what reaches it: the negative prompt of each sampling and SDS
//! conditioning, and SDXL's size conditioning where the run has one.

use std::sync::{Arc, Mutex};
use vectorfusion::image::Image;
use vectorfusion::pipeline::{Models, RunPlan, Start, run_text};
use vectorfusion::progress::{CancelToken, NullSink, ProgressSink};
use vectorfusion::teacher::{
    Conditioning, Latent, SampleConfig, SampleError, Teacher, TeacherError,
};

/// Wraps `inner`, noting in `seen`: `sample: <negative prompt>` (and `sample size: <size
/// conditioning>` when the config has one) per sampling, `sds: <negative prompt>` per SDS
/// conditioning, and `noise: <time ids>` whenever a noise prediction's SDXL time ids differ
/// from the last ones noted (none for models without them).
pub struct Recording<T: Teacher> {
    pub inner: T,
    pub seen: Arc<Mutex<Vec<String>>>,
}

impl<T: Teacher> Recording<T> {
    pub fn new(inner: T, seen: Arc<Mutex<Vec<String>>>) -> Self {
        Recording { inner, seen }
    }

    fn note(&self, s: String) {
        self.seen.lock().unwrap().push(s);
    }
}

/// Runs the text plan `plan` for "a crown" from its method on `teacher` (no scorer, no
/// retrieval), recording: the run's paths and what reached the teacher.
pub fn run_recorded<T: Teacher + 'static>(teacher: T, plan: &RunPlan) -> (usize, Vec<String>) {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let models = Models {
        teacher: Box::new(Recording::new(teacher, seen.clone())),
        scorer: None,
        retrieval: Err(vectorfusion::stages::sample::NoStarts::NoIconSets),
    };
    let text = plan.text.as_ref().expect("a text plan");
    let cancel = CancelToken::new();
    let out = run_text(
        &models,
        text,
        &plan.key(),
        "a crown",
        &Start::Method,
        &NullSink,
        &cancel,
        None,
    )
    .expect("the recorded run");
    let seen = seen.lock().unwrap().clone();
    (out.paths, seen)
}

impl<T: Teacher> Teacher for Recording<T> {
    fn sample(
        &self,
        prompt: &str,
        starts: &[Image],
        cfg: &SampleConfig,
        sink: &dyn ProgressSink,
        cancel: &CancelToken,
    ) -> Result<Vec<Image>, SampleError> {
        self.note(format!("sample: {}", cfg.negative_prompt));
        if let Some(s) = cfg.size_conditioning {
            self.note(format!("sample size: {s:?}"));
        }
        self.inner.sample(prompt, starts, cfg, sink, cancel)
    }
    fn name(&self) -> String {
        self.inner.name()
    }
    fn image_size(&self) -> u32 {
        self.inner.image_size()
    }
    fn image_dims(&self) -> (u32, u32) {
        self.inner.image_dims()
    }
    fn latent_shape(&self) -> [usize; 3] {
        self.inner.latent_shape()
    }
    fn alphas_cumprod(&self) -> &[f32] {
        self.inner.alphas_cumprod()
    }
    fn condition(&self, prompt: &str, negative: &str) -> Result<Conditioning, TeacherError> {
        self.note(format!("sds: {negative}"));
        self.inner.condition(prompt, negative)
    }
    fn encode(&self, image: &Image) -> Result<Latent, TeacherError> {
        self.inner.encode(image)
    }
    fn encode_vjp(&self, image: &Image, d: &Latent) -> Result<Vec<f32>, TeacherError> {
        self.inner.encode_vjp(image, d)
    }
    fn predict_noise(
        &self,
        z: &Latent,
        t: usize,
        cond: &Conditioning,
        guidance: f32,
    ) -> Result<Latent, TeacherError> {
        if let Some(a) = &cond.added {
            let note = format!("noise: {:?}", a.time_ids);
            let mut seen = self.seen.lock().unwrap();
            if seen.last() != Some(&note) {
                seen.push(note);
            }
        }
        self.inner.predict_noise(z, t, cond, guidance)
    }
}
