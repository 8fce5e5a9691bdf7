//! The allocator tuning of `vectorfusion::alloc` sets the option it means to.

/// Our index for `mi_option_purge_delay` is the option `MIMALLOC_PURGE_DELAY` sets: the test
/// re-runs itself in a child process with the variable set and reads the option back.
#[test]
fn purge_delay_index_is_the_one_mimalloc_reads_from_its_environment() {
    if vectorfusion::alloc::purge_delay().is_none() {
        return; // built without the mimalloc feature
    }
    if std::env::var("MIMALLOC_PURGE_DELAY").as_deref() == Ok("4321") {
        assert_eq!(vectorfusion::alloc::purge_delay(), Some(4321));
        // A user's choice wins over ours.
        vectorfusion::alloc::tune();
        assert_eq!(vectorfusion::alloc::purge_delay(), Some(4321));
        return;
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "purge_delay_index_is_the_one_mimalloc_reads_from_its_environment",
            "--test-threads=1",
        ])
        .env("MIMALLOC_PURGE_DELAY", "4321")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("1 passed"), "{text}");
}

#[test]
fn tune_sets_the_purge_delay_unless_the_user_chose_one() {
    if vectorfusion::alloc::purge_delay().is_none()
        || std::env::var_os("MIMALLOC_PURGE_DELAY").is_some()
    {
        return;
    }
    vectorfusion::alloc::tune();
    assert_eq!(
        vectorfusion::alloc::purge_delay(),
        Some(vectorfusion::alloc::PURGE_DELAY_MS)
    );
}
