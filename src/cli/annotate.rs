//! `facespace annotate`: the landmark page for a folder of frames.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::annotate::{Annotator, Event};

use super::load_model;

#[derive(Args)]
pub struct AnnotateArgs {
    /// Folder of frames (png, jpg); NAME.pts is written beside each.
    dir: PathBuf,
    /// Model for the mean shape (and, with --fit, the starting fit).
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// Start unmarked frames from the model's fit (else: the previous frame's points, or the
    /// mean shape placed by three clicks: the two eye centres, then the mouth).
    #[arg(long)]
    fit: bool,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8017")]
    listen: String,
    /// Allow a non-loopback address (the page has no login: anyone who can reach it can edit).
    #[arg(long)]
    allow_remote: bool,
}

pub fn run(a: AnnotateArgs) -> Result<()> {
    let model = load_model(&a.model)?;
    let annotator = Annotator::bind(&a.dir, model, a.fit, &a.listen, a.allow_remote)
        .with_context(|| format!("annotating {}", a.dir.display()))?;
    println!(
        "annotating {} at {} (Ctrl+C to stop; every change is saved at once)",
        a.dir.display(),
        annotator.url()
    );
    for why in annotator.skipped() {
        eprintln!("left out {why}");
    }
    let mut refusals = super::Refusals::default();
    annotator.run(
        |event| match event {
            Event::Saved(path) => println!("saved {}", path.display()),
            Event::Removed(path) => println!("removed {} (undone)", path.display()),
            Event::Refused(path, why) => refusals.log(&path, &why),
            Event::Notice(what) => eprintln!("note: {what}"),
        },
        || false,
    );
    Ok(())
}
