//! Cuts frames `START..START+COUNT` of a video into an H.264 MP4 (how
//! `data/fgnet/background.mp4` was made from the FGNet talking-face video).
//! Run: cargo run --release --example cut_video -- INPUT START COUNT OUTPUT.mp4

use facespace::video::{Sink, Source};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, input, start, count, output] = args.as_slice() else {
        return Err("usage: cut_video INPUT START COUNT OUTPUT.mp4".into());
    };
    let (start, count): (usize, usize) = (start.parse()?, count.parse()?);
    let mut source = Source::open(input.as_ref())?;
    let info = source.info();
    let mut sink = Sink::create(output.as_ref(), info.width, info.height, info.fps, None)?;
    for (i, frame) in (&mut source).enumerate().take(start + count) {
        let frame = frame?;
        if i >= start {
            sink.write(&frame)?;
        }
    }
    let n = sink.finish()?;
    println!("{n} frames at {} fps → {output}", info.fps);
    Ok(())
}
