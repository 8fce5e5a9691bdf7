//! The end of a LIVE run ([`Run::finish`]): the final pass, then the scene cleaned and cut to
//! the canvas and scaled to the output size.

use super::run::Run;
use super::{LiveError, PathBudget, prune};
use crate::scene::Scene;
use crate::vector::palette::{self, ColorPlan};

impl Run<'_> {
    /// The end of a trace after `stages` stages: colours settled, the final pass, then faint
    /// paths dropped, outlines made simple and cut to the canvas they will be written on
    /// ([`crate::vector::canvas`]), unseen paths dropped, overlapping paths of one fill merged
    /// ([`crate::vector::merge`]), paths past `max_bytes` and hidden paths dropped,
    /// near-straight segments made straight, outlines made simple.
    /// Returns the scene at the target's size and the counts.
    pub(super) fn finish(
        &mut self,
        mut scene: Scene,
        stages: usize,
    ) -> Result<(Scene, Finished), LiveError> {
        let cfg = self.cfg;
        self.switch_to_full(&mut scene);
        // Colours settle before the last pass, which then fits the geometry to them.
        if self.palette.is_some() {
            self.choose_colours(&mut scene);
        } else {
            palette::merge_similar(&mut scene, palette::MERGE_DISTANCE);
        }
        if cfg.final_iters > 0 && !scene.shapes.is_empty() {
            let n = scene.shapes.len();
            self.optimise(&mut scene, n..n, cfg.final_iters, stages + 1, false)?;
        }
        // Drop paths that stayed faint or tiny after the last re-initialisation.
        let weak = prune::weak_paths(&scene, cfg.reinit_min_opacity, 1.0);
        for &i in weak.iter().rev() {
            scene.shapes.remove(i);
        }
        // Clean geometry: the last pass may have folded outlines again; splitting keeps the
        // pixels.
        self.make_simple(&mut scene);
        let (tw, th) = (self.out_width, self.out_height);
        let scale = tw as f32 / self.target.width as f32;
        // The canvas of the SVG in the working units (the output's height is rounded on its
        // own), so that no piece ends short of its edge.
        let ww = self.target.width as f64;
        let cut = crate::vector::canvas::cut_scene_to(&mut scene, ww, th as f64 * ww / tw as f64);
        let mut pruned = crate::vector::drop_unseen(&mut scene, scale);
        let merged = crate::vector::merge::merge_touching(&mut scene, Default::default());
        if let PathBudget::Auto {
            prune_tolerance, ..
        } = cfg.budget
        {
            pruned += prune::prune_paths(&mut scene, prune_tolerance).len();
        }
        if let Some(max) = cfg.max_bytes {
            pruned += prune::trim_to_bytes(&mut scene, &self.target, max, |s| {
                svg_bytes(s, tw, th, &cfg.colors)
            });
        }
        // At the output size: flattening is finer there, and hidden paths are judged there.
        let mut out = output_scene(&scene, tw, th);
        crate::vector::straight::straighten(&mut out, crate::vector::straight::STRAIGHT_TOLERANCE);
        crate::vector::make_simple(&mut out, crate::vector::SIMPLE_MIN_AREA);
        pruned += crate::vector::drop_hidden(&mut out);
        if !cfg.fill.is_flat() {
            crate::vector::fill::tidy_gradients(&mut out);
        }
        out.validate()?;
        let done = Finished {
            pruned,
            merged,
            cut,
        };
        Ok((out, done))
    }
}

/// `scene` (at the working size) scaled to the target's `tw`×`th` canvas.
fn output_scene(scene: &Scene, tw: u32, th: u32) -> Scene {
    let mut out = scene.scaled_to_width(tw);
    out.height = th;
    out
}

/// Bytes of the SVG the run would write now.
pub(super) fn svg_bytes(scene: &Scene, tw: u32, th: u32, colors: &ColorPlan) -> usize {
    crate::vector::write_svg(&output_scene(scene, tw, th), colors).len()
}

/// What [`Run::finish`] did besides the final pass.
pub(super) struct Finished {
    /// Paths dropped as unseen, by `auto` pruning, past `max_bytes` or hidden (faint ones
    /// uncounted).
    pub pruned: usize,
    /// Merges of touching paths of one fill.
    pub merged: usize,
    /// Paths cut to the canvas.
    pub cut: usize,
}
