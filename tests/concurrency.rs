//! Issue 27, F10: a reader loading a codebook while another process-like writer replaces it
//! again and again always gets one whole version (it retries a folder swapped under it),
//! never the consistency error of a torn read.
use crate::common;

use facespace::codebook::Codebook;

#[test]
fn readers_never_see_a_torn_codebook() {
    let (_, generated, cb) = common::demo_corpus_codebook();
    let train = generated.part(facespace::corpus::demo::Split::Train);
    // A second, different version: half the sentences.
    let half = common::codebook_like(&cb, train[..train.len() / 2].to_vec());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cb");
    cb.save(&path).unwrap();
    let sizes = [cb.sentences.len(), half.sentences.len()];
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let writer = {
        let (path, stop) = (path.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut saves = 0;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                [&half, &cb][saves % 2].save(&path).unwrap();
                saves += 1;
            }
            saves
        })
    };
    let mut loads = 0;
    let clock = std::time::Instant::now();
    // 4 s: about 3 500 loads across 240 replacements here (8 s took two cores for a
    // twelfth of the whole suite's run).
    while clock.elapsed().as_secs() < 4 || loads < 20 {
        let got = Codebook::load(&path).unwrap_or_else(|e| panic!("load {loads}: {e}"));
        assert!(
            sizes.contains(&got.sentences.len()),
            "{}",
            got.sentences.len()
        );
        loads += 1;
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let saves = writer.join().unwrap();
    eprintln!("{loads} whole loads during {saves} replacements");
    assert!(saves > 10, "{saves} replacements");
}
