//! More of the store's conformance suite (both backends): a job of several results.

use super::*;

async fn a_result_of_several_variations_reads_back_each_and_goes_with_its_job(b: Backend) {
    let Some((_d, _loc, store)) = temp_store(b, 2).await else {
        return;
    };
    let job = store.insert_job(&new_job(0), 0).await.unwrap().0;
    let (_, lease) = store.claim("w", 1, 1000).await.unwrap().unwrap();
    let more = [("<svg id=\"2\"/>", 3), ("<svg id=\"3\"/>", 4)];
    assert!(
        store
            .complete_variations(&lease, "<svg id=\"1\"/>", 2, "{}", &more, 3)
            .await
            .unwrap()
    );
    let result = store.result(&job.id).await.unwrap().unwrap();
    assert_eq!((result.svg.as_str(), result.paths), ("<svg id=\"1\"/>", 2));
    for (n, want) in [
        (2, Some("<svg id=\"2\"/>")),
        (3, Some("<svg id=\"3\"/>")),
        (4, None),
    ] {
        let got = store.result_variation(&job.id, n).await.unwrap();
        assert_eq!(got.as_deref(), want, "variation {n}");
    }
    // A lease that no longer holds the job writes no variation either.
    let other = store.insert_job(&new_job(1), 4).await.unwrap().0;
    let (_, lease2) = store.claim("w", 5, 1000).await.unwrap().unwrap();
    let stale = Lease {
        attempt: lease2.attempt + 1,
        ..lease2
    };
    assert!(
        !store
            .complete_variations(&stale, "<svg/>", 1, "{}", &more, 6)
            .await
            .unwrap()
    );
    assert!(
        store
            .result_variation(&other.id, 2)
            .await
            .unwrap()
            .is_none()
    );
    // Retention removes them with the job.
    assert_eq!(store.prune(4).await.unwrap(), 1);
    assert!(store.result_variation(&job.id, 2).await.unwrap().is_none());
}

conformance!(a_result_of_several_variations_reads_back_each_and_goes_with_its_job);
