//! The vector stage's flags, shared by `generate` and `vectorize`: colours, background and
//! grouping (one set of flags, one [`ColorPlan`] they turn into).

use super::CliError;
use crate::vector::fill::FillKind;
use crate::vector::palette::{Background, ColorPlan, Grouping, check_colors, parse_palette};

#[derive(clap::Args, Debug, Clone)]
pub struct VectorArgs {
    /// At most N distinct fill colours (1..=64): a palette of N found by k-means, each path's
    /// fill chosen from it [default: near-equal fills merged; text runs then keep the fewest
    /// colours whose render stays within 35 dB].
    #[arg(long)]
    pub colors: Option<u32>,
    /// Fills restricted to these colours, e.g. "#e63946,#f1faee,#1d3557" (with --colors N: at
    /// most N of them).
    #[arg(long)]
    pub palette: Option<String>,
    /// transparent (no background rectangle), auto (the border's colour; none where the image's
    /// border is transparent) or #rrggbb.
    #[arg(long, default_value = "auto")]
    pub background: String,
    /// Group the SVG's paths: none, color (runs of one fill in a `<g>`) or stage (runs of paths
    /// one LIVE stage added in a `<g id="s<k>">`), with stable ids.
    #[arg(long, value_enum, default_value = "none")]
    pub group: Grouping,
    /// What the paths are painted with: flat colours, or one linear or radial gradient each
    /// (optimised with the paths; not with --colors or --palette).
    #[arg(long, value_enum, default_value = "flat")]
    pub fill: FillKind,
}

impl VectorArgs {
    /// The flags as a checked [`ColorPlan`]; a bad value is a usage error naming its flag.
    pub fn color_plan(&self) -> Result<ColorPlan, CliError> {
        let usage =
            |flag: &str, e: &dyn std::fmt::Display| CliError::Usage(format!("--{flag}: {e}"));
        Ok(ColorPlan {
            colors: self
                .colors
                .map(check_colors)
                .transpose()
                .map_err(|e| usage("colors", &e))?,
            palette: self
                .palette
                .as_deref()
                .map(parse_palette)
                .transpose()
                .map_err(|e| usage("palette", &e))?,
            background: self
                .background
                .parse::<Background>()
                .map_err(|e| usage("background", &e))?,
            group: self.group,
        })
    }

    /// `--fill`, refused with `--colors` or `--palette` (a usage error naming `--fill`).
    pub fn fill(&self) -> Result<FillKind, CliError> {
        let palette = self.colors.is_some() || self.palette.is_some();
        self.fill
            .check_with_palette(palette)
            .map_err(|e| CliError::Usage(format!("--fill: {e}")))?;
        Ok(self.fill)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(colors: Option<u32>, palette: Option<&str>, background: &str) -> VectorArgs {
        VectorArgs {
            colors,
            palette: palette.map(str::to_string),
            background: background.into(),
            group: Grouping::None,
            fill: FillKind::Flat,
        }
    }

    #[test]
    fn bad_values_name_their_flag() {
        let msg = |a: VectorArgs| match a.color_plan() {
            Err(CliError::Usage(m)) => m,
            other => panic!("{other:?}"),
        };
        assert!(msg(args(Some(0), None, "auto")).starts_with("--colors: must be between 1 and 64"));
        assert!(msg(args(None, Some("#12,#fff"), "auto")).starts_with("--palette: \"#12\""));
        assert!(msg(args(None, None, "blue")).starts_with("--background:"));
        let ok = args(Some(3), Some("#fff, #000"), "#abc")
            .color_plan()
            .unwrap();
        assert_eq!(ok.palette.unwrap().len(), 2);
        assert_eq!(ok.background.to_string(), "#aabbcc");
        let gradient = VectorArgs {
            fill: FillKind::Linear,
            ..args(None, Some("#fff"), "auto")
        };
        assert!(msg_fill(gradient).starts_with("--fill: linear cannot be combined"));
        let free = VectorArgs {
            fill: FillKind::Radial,
            ..args(None, None, "auto")
        };
        assert_eq!(free.fill().unwrap(), FillKind::Radial);
    }

    fn msg_fill(a: VectorArgs) -> String {
        match a.fill() {
            Err(CliError::Usage(m)) => m,
            other => panic!("{other:?}"),
        }
    }
}
