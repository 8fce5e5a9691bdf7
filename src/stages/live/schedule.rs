//! Path budgets: fixed stage schedules, the `auto` stopping rule, and parsing.

use super::LiveError;

/// LIVE's default stage schedule (64 paths).
pub const DEFAULT_SCHEDULE: [usize; 5] = [8, 8, 16, 16, 16];

/// Parses a comma-separated schedule such as `8,8,16,16,16`. Every stage adds at least one path;
/// at most `max_total` paths in all.
pub fn parse_schedule(text: &str, max_total: usize) -> Result<Vec<usize>, LiveError> {
    let mut out = Vec::new();
    for part in text.split(',') {
        let part = part.trim();
        let n: usize = part
            .parse()
            .map_err(|_| LiveError::Config(format!("schedule entry {part:?} is not a number")))?;
        if n == 0 {
            return Err(LiveError::Config("schedule entries must be >= 1".into()));
        }
        out.push(n);
    }
    // Saturating: absurd entries must give the error below, not an overflow.
    let total = out.iter().fold(0usize, |a, &n| a.saturating_add(n));
    if total > max_total {
        return Err(LiveError::Config(format!(
            "schedule adds {total} paths, more than the limit of {max_total}"
        )));
    }
    Ok(out)
}

/// A schedule adding `total` paths in LIVE's proportions (1/8, 1/8, 1/4, 1/4, 1/4): 64 gives
/// the default `8,8,16,16,16`, 16 gives `2,2,4,4,4`; small totals use fewer stages.
pub fn schedule_for(total: usize) -> Vec<usize> {
    if total == 0 {
        return Vec::new();
    }
    let parts = [1usize, 1, 2, 2, 2];
    let mut out: Vec<usize> = parts.iter().map(|p| total * p / 8).collect();
    let used: usize = out.iter().sum();
    if let Some(last) = out.last_mut() {
        *last += total - used;
    }
    out.retain(|&n| n > 0);
    out
}

/// The `--paths auto` rule: keep adding stages while the PSNR gain per added path (dB) exceeds
/// `min_gain_db_per_path`. A stage that added no path (nothing left to fix) stops.
pub fn auto_should_continue(
    prev_psnr: f64,
    new_psnr: f64,
    added: usize,
    min_gain_db_per_path: f64,
) -> bool {
    if added == 0 || !new_psnr.is_finite() {
        return false;
    }
    let prev = if prev_psnr.is_finite() {
        prev_psnr
    } else {
        0.0
    };
    (new_psnr - prev) / added as f64 > min_gain_db_per_path
}

#[cfg(test)]
mod tests {
    #[test]
    fn huge_entries_are_an_error_not_an_overflow() {
        assert!(super::parse_schedule("18446744073709551615,1", 1024).is_err());
    }

    use super::*;

    #[test]
    fn parse_accepts_lists_and_rejects_garbage() {
        assert_eq!(parse_schedule("8,8,16", 64).unwrap(), vec![8, 8, 16]);
        assert_eq!(parse_schedule(" 4 , 2", 64).unwrap(), vec![4, 2]);
        assert!(parse_schedule("8,x", 64).is_err());
        assert!(parse_schedule("8,0", 64).is_err());
        assert!(parse_schedule("", 64).is_err());
        assert!(parse_schedule("60,60", 64).is_err());
    }

    #[test]
    fn schedule_for_keeps_live_proportions_and_total() {
        assert_eq!(schedule_for(64), DEFAULT_SCHEDULE.to_vec());
        assert_eq!(schedule_for(16), vec![2, 2, 4, 4, 4]);
        assert_eq!(schedule_for(32), vec![4, 4, 8, 8, 8]);
        for n in 1..100 {
            let s = schedule_for(n);
            assert_eq!(s.iter().sum::<usize>(), n);
            assert!(s.iter().all(|&k| k > 0));
        }
        assert!(schedule_for(0).is_empty());
    }

    #[test]
    fn auto_budget_stops_when_gain_per_path_is_small() {
        assert!(auto_should_continue(20.0, 24.0, 8, 0.1));
        assert!(!auto_should_continue(30.0, 30.4, 8, 0.1));
        assert!(!auto_should_continue(30.0, 29.0, 8, 0.1));
        assert!(!auto_should_continue(30.0, 40.0, 0, 0.1));
        assert!(auto_should_continue(f64::NEG_INFINITY, 12.0, 8, 0.1));
    }
}
