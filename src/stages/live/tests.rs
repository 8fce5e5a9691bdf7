use super::*;
use std::ops::Range;

/// A white `side × side` image with rectangles `(xs, ys, colour)` painted on it (where two
/// overlap, the first wins): the targets of the init and tracer tests.
pub(super) fn white_with_rects(side: u32, rects: &[(Range<u32>, Range<u32>, [f32; 4])]) -> Image {
    let mut im = Image::filled(side, side, [1.0, 1.0, 1.0, 1.0]);
    for y in 0..side {
        for x in 0..side {
            let i = 4 * (y * side + x) as usize;
            if let Some((_, _, c)) = rects
                .iter()
                .find(|(xs, ys, _)| xs.contains(&x) && ys.contains(&y))
            {
                im.data[i..i + 4].copy_from_slice(c);
            }
        }
    }
    im
}

#[test]
fn default_is_valid_with_live_proportions() {
    let d = LiveConfig::default();
    d.validate().unwrap();
    assert_eq!(d.budget, PathBudget::fixed(64));
    assert_eq!(d.reinit_min_opacity, MIN_OPACITY);
    assert_eq!(
        PathBudget::auto_up_to(5),
        PathBudget::Auto {
            stage: 5,
            max_paths: 5,
            min_gain_db_per_path: 0.05,
            prune_tolerance: 2e-5,
        }
    );
    assert_eq!(PathBudget::auto().max_paths(), 64);
}

#[test]
fn validate_rejects_bad_settings() {
    let ok = LiveConfig::default();
    let cases = [
        LiveConfig {
            lr_points: f32::NAN,
            ..ok.clone()
        },
        LiveConfig {
            xing_weight: -1.0,
            ..ok.clone()
        },
        LiveConfig {
            init_segments: 0,
            ..ok.clone()
        },
        LiveConfig {
            budget: PathBudget::Auto {
                stage: 0,
                max_paths: 8,
                min_gain_db_per_path: 0.1,
                prune_tolerance: 0.0,
            },
            ..ok.clone()
        },
        LiveConfig {
            budget: PathBudget::Schedule {
                stages: vec![MAX_PATHS, 1],
            },
            ..ok.clone()
        },
    ];
    for c in cases {
        assert!(matches!(c.validate(), Err(LiveError::Config(_))), "{c:?}");
    }
}

#[test]
fn border_colour_is_the_frame_mean() {
    let mut im = Image::filled(8, 8, [0.0, 0.0, 1.0, 1.0]);
    // Transparent frame counts as white.
    for y in 0..8u32 {
        for x in 0..8u32 {
            if x == 0 || y == 0 || x == 7 || y == 7 {
                let i = 4 * (y * 8 + x) as usize;
                im.data[i..i + 4].copy_from_slice(&[0.0; 4]);
            }
        }
    }
    assert_eq!(border_colour(&im), Rgba::WHITE);
}

/// The working canvas has the area of the working square: a square target as before, a 16:1
/// banner's parts as large as a square's would be (not a quarter of it), nothing upsampled.
#[test]
fn the_working_size_keeps_the_area_of_the_working_square() {
    assert_eq!(working_size(160, 256, 256), (160, 160));
    assert_eq!(working_size(80, 1000, 1000), (80, 80));
    assert_eq!(working_size(160, 100, 100), (100, 100));
    assert_eq!(working_size(160, 1024, 64), (640, 40));
    assert_eq!(working_size(160, 64, 1024), (40, 640));
    assert_eq!(working_size(160, 256, 170), (196, 130));
    assert_eq!(working_size(160, 300, 1), (300, 1));
}
