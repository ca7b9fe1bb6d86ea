//! The README's picture of the live page: `facespace serve`'s page in headless Chromium
//! (WebGL2 on SwiftShader), caught while the talker says a typed sentence.
//!
//! `cargo run --release --example live_page_screenshot -- docs/live-page.png`

#[path = "../tests/common/cdp.rs"]
#[allow(dead_code)]
mod cdp;

fn main() {
    let out = std::env::args().nth(1).unwrap_or_else(|| "docs/live-page.png".into());
    let talker = facespace::talker::Talker::load("models/grid".as_ref()).expect("the GRID talker");
    let server = facespace::serve::LiveServer::bind(&talker, "127.0.0.1:0", false).expect("a port");
    let url = server.url();
    let stop = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|scope| {
        scope.spawn(|| server.run(|_| {}, || stop.load(std::sync::atomic::Ordering::Relaxed)));
        let switches = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--window-size=760,760"]
            .map(String::from);
        let mut browser = cdp::Browser::launch_with("chromium", &switches);
        let page = browser.open(&url);
        browser.wait_for(&page, "facespace.ready");
        // Typed into the box and sent as a person would; caught mid-sentence.
        browser.eval(
            &page,
            "document.getElementById('text').value = 'Bob made a map of the moor.'; document.querySelector('#say button').click(); true",
        );
        browser.wait_for(&page, "facespace.stats.said.length > 0");
        let at = browser.eval(&page, "facespace.stats.said[0].at").as_u64().unwrap();
        browser.wait_for(&page, &format!("facespace.log[facespace.log.length - 1].t >= {}", at + 14));
        println!("{}", browser.eval(&page, "document.getElementById('stats').textContent + ' | ' + document.getElementById('status').textContent"));
        std::fs::write(&out, browser.screenshot(&page)).expect("writing the picture");
        // The canvas itself, at full size, for a close look.
        let canvas = browser.eval(&page, "document.getElementById('view').toDataURL('image/png').split(',')[1]");
        let canvas = cdp::base64(canvas.as_str().unwrap());
        std::fs::write(std::path::Path::new(&out).with_extension("canvas.png"), canvas).expect("writing the canvas");
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
    });
    println!("wrote {out}");
}
