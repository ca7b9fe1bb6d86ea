//! `facespace serve`: the live page, where the talker's face speaks typed sentences or the
//! microphone's speech, rendered by the browser from face-space.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::serve::{Event, LiveServer};
use facespace::talker::Talker;

use super::say::DEFAULT_TALKER;

#[derive(Args)]
#[command(
    after_help = "Example: facespace serve --call models/grid/demo/bbbf9a.mp4   (then open the printed address in a browser with WebGL2)"
)]
pub struct ServeArgs {
    /// The talker folder (`talker build`; default: GRID s1, models/grid).
    #[arg(long, default_value = DEFAULT_TALKER, value_parser = super::committed_path)]
    talker: PathBuf,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8019")]
    listen: String,
    /// Also offer a call: this recording of the talker (at the talker's frame rate) streamed
    /// through face-space to the page, 8 bits per value, paced at real time, with its sound.
    #[arg(long)]
    call: Option<PathBuf>,
    /// Allow a non-loopback address (the page has no login: anyone who can reach it can use
    /// the talker and the machine's text-to-speech).
    #[arg(long)]
    allow_remote: bool,
}

pub fn run(a: ServeArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let talker = Talker::load(&a.talker)
        .with_context(|| format!("loading the talker {}", super::shown(&a.talker)))?;
    let mut server = LiveServer::bind(&talker, &a.listen, a.allow_remote)
        .with_context(|| format!("serving {}", talker.manifest.name))?;
    if let Some(video) = &a.call {
        server = server
            .with_call(video)
            .with_context(|| format!("preparing the call from {}", video.display()))?;
    }
    println!(
        "{} live at {} (ready in {:.1} s; Ctrl+C to stop; the page needs a browser with WebGL2)",
        talker.manifest.name,
        server.url(),
        started.elapsed().as_secs_f64()
    );
    if facespace::tts::available().is_none() {
        eprintln!("note: {}", facespace::tts::TtsError::Missing);
    }
    let refusals = std::sync::Mutex::new(super::Refusals::default());
    server.run(
        |event| match event {
            Event::Opened(id) => println!("session {id} opened"),
            Event::Said(id, frames, seconds) => {
                println!("session {id}: {frames} frames in {seconds:.2} s")
            }
            Event::Refused(path, why) => refusals
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .log(&path, &why),
            Event::Notice(what) => eprintln!("note: {what}"),
        },
        || false,
    );
    Ok(())
}
