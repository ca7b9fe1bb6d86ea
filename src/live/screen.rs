//! A live session drawn on the CPU ([`Screen`]).

use super::{LiveError, LiveFrame, Session, Stage};
use crate::render::Renderer;

/// One picture of a [`Screen`]: a frame of the session drawn over its footage frame, or the
/// footage as it is while nothing is said.
#[derive(Clone, Debug)]
pub struct Picture {
    /// Frame number since the session began; shown at `index / fps` seconds of its sound.
    pub index: usize,
    /// Its presentation time, seconds of the session's sound.
    pub time: f64,
    /// The picture, in the footage's size or the size asked for ([`Screen::with_size`]).
    pub image: image::RgbImage,
    /// The face's 68 iBUG landmarks in the picture's pixels: the face drawn, or the footage's
    /// own as tracked.
    pub landmarks: Vec<crate::shape::Point>,
    /// Whether the face was synthesised (speech, or a pause inside it) rather than the
    /// footage's own.
    pub face: bool,
    /// Whether a phone (not silence) is spoken at it.
    pub speaking: bool,
}

/// A live session drawn on the server's CPU: every frame index gets a picture, in order — the
/// frames the session settles drawn over their footage frames ([`Stage`], lips and jaw
/// feathered in as `say` draws), and the footage as it is for frames with nothing said (before
/// speech, after [`Screen::clear`], or skipped while quiet by [`Screen::idle_until`]). For
/// hosts that want pixels (a voice agent's video track); the page renders face-space itself.
pub struct Screen<'s, 't> {
    session: Session<'t>,
    stage: &'s Stage<'t>,
    renderer: crate::render::CpuRenderer<'t>,
    /// Picks each drawn frame's recorded detail, when the talker keeps recorded mouths.
    chooser: Option<crate::mouths::Chooser<'t>>,
    /// The stage's loop of footage, decoded in order.
    footage: crate::footage::Shown,
    /// The next picture's index.
    next: usize,
    /// Settled frames not yet drawn.
    settled: std::collections::VecDeque<LiveFrame>,
    /// The footage's size to the pictures' size, when they differ.
    scaler: Option<crate::render::scale::Scaler>,
}

impl<'s, 't> Screen<'s, 't> {
    /// `session` drawn on `stage` (a stage of the session's talker). The talker's recorded
    /// mouths are decoded here, for the first screen (about a second), not with the stage: a
    /// page renders face-space itself and never needs them.
    pub fn new(session: Session<'t>, stage: &'s Stage<'t>) -> Result<Self, LiveError> {
        let talker = stage.talker;
        let edge = crate::render::Edge::Articulators(crate::render::DEFAULT_FEATHER);
        Ok(Screen {
            session,
            stage,
            renderer: crate::render::CpuRenderer::with_edge(&talker.model, edge),
            chooser: talker
                .mouths()
                .map_err(Box::new)?
                .map(|m| crate::mouths::Chooser::new(m, &talker.model)),
            footage: talker.footage.shown(stage.plan()),
            next: 0,
            settled: std::collections::VecDeque::new(),
            scaler: None,
        })
    }

    /// [`Screen::new`] with pictures of `size` (width, height): each drawn in the footage's
    /// size, then scaled to fit ([`crate::render::scale::Fit`]).
    pub fn with_size(
        session: Session<'t>,
        stage: &'s Stage<'t>,
        size: (u32, u32),
        fit: crate::render::scale::Fit,
    ) -> Result<Self, LiveError> {
        let scaler = crate::render::scale::Scaler::new(stage.talker.footage.size, size, fit);
        Ok(Screen {
            scaler: (!scaler.is_identity()).then_some(scaler),
            ..Self::new(session, stage)?
        })
    }

    /// The pictures' size.
    pub fn size(&self) -> (u32, u32) {
        self.scaler
            .as_ref()
            .map_or(self.stage.talker.footage.size, |s| s.size())
    }

    /// The session, to push sound or phones into.
    pub fn session(&mut self) -> &mut Session<'t> {
        &mut self.session
    }

    /// An interruption: the next picture is the footage's own face, and so is every frame of
    /// the sound already taken.
    pub fn clear(&mut self) {
        self.settled.clear();
        if let Some(c) = &mut self.chooser {
            c.reset();
        }
        let next = self.next as f64 / self.session.fps;
        self.session.skip_to(self.session.seconds().max(next));
    }

    /// Ends the speech: every frame of it can then be drawn.
    pub fn finish(&mut self) -> Result<Drawing<'_, 's, 't>, LiveError> {
        let frames = self.session.finish()?;
        self.take(frames)
    }

    /// The pictures the session has settled since the last call, in order.
    pub fn pull(&mut self) -> Result<Drawing<'_, 's, 't>, LiveError> {
        let frames = self.session.pull()?;
        self.take(frames)
    }

    /// [`Screen::pull`], and while the session is quiet the footage as it is up to (not
    /// including) frame `until` — a video track keeps its rate while nothing is said.
    pub fn idle_until(&mut self, until: usize) -> Result<Drawing<'_, 's, 't>, LiveError> {
        let frames = self.session.pull()?;
        self.stage_frames(frames)?;
        if self.session.is_quiet() && until > self.session.next_frame() {
            self.session.skip_to(until as f64 / self.session.fps);
        }
        Ok(Drawing { screen: self })
    }

    /// Pictures ready to draw: frame indices up to the session's next.
    pub fn ready(&self) -> usize {
        self.session.next_frame().saturating_sub(self.next)
    }

    /// Settled frames placed on the stage and queued for drawing.
    fn stage_frames(&mut self, mut frames: Vec<LiveFrame>) -> Result<(), LiveError> {
        self.stage.place(&mut frames)?;
        self.settled.extend(frames);
        Ok(())
    }

    fn take(&mut self, frames: Vec<LiveFrame>) -> Result<Drawing<'_, 's, 't>, LiveError> {
        self.stage_frames(frames)?;
        Ok(Drawing { screen: self })
    }

    /// Draws the next picture ready, if any: a settled frame over its footage frame, or the
    /// footage as it is (a frame skipped, or dropped by a clear). Pictures are drawn only as
    /// they are asked for, so a burst of frames (an utterance's end) holds one at a time.
    pub fn next_picture(&mut self) -> Result<Option<Picture>, LiveError> {
        if self.next >= self.session.next_frame() {
            return Ok(None);
        }
        let fps = self.session.fps;
        let index = self.next;
        let loop_len = self.stage.len().max(1);
        if index.is_multiple_of(loop_len) && index > 0 {
            self.footage = self.footage.fresh();
        }
        let mut image = self.footage.next_frame()?;
        while self.settled.front().is_some_and(|f| f.index < index) {
            self.settled.pop_front();
        }
        let (face, speaking, mut landmarks) = match self.settled.front() {
            Some(f) if f.index == index => {
                let model = &self.stage.talker.model;
                let params = model.layout().split(&f.values)?;
                match self.chooser.as_mut().map(|c| (c.mouths(), c.next(params))) {
                    Some((mouths, pick)) => {
                        self.renderer.render_with(params, mouths.drawing(&pick), &mut image)?
                    }
                    None => self.renderer.render_into(params, &mut image)?,
                }
                (true, f.speaking, model.landmarks(params)?.points)
            }
            _ => {
                if let Some(c) = &mut self.chooser {
                    c.reset();
                }
                (false, false, self.stage.landmarks[index % loop_len].points.clone())
            }
        };
        if let Some(scaler) = &self.scaler {
            image = scaler.scale(&image);
            landmarks.iter_mut().for_each(|p| *p = scaler.point(*p));
        }
        self.next += 1;
        Ok(Some(Picture {
            index,
            time: index as f64 / fps,
            image,
            landmarks,
            face,
            speaking,
        }))
    }
}

/// The pictures a [`Screen`] call made ready, drawn one by one as they are iterated
/// ([`Screen::next_picture`]); those not iterated stay ready for the next call.
pub struct Drawing<'a, 's, 't> {
    screen: &'a mut Screen<'s, 't>,
}

impl Drawing<'_, '_, '_> {
    /// Every picture, drawn.
    pub fn all(self) -> Result<Vec<Picture>, LiveError> {
        self.collect()
    }
}

impl Iterator for Drawing<'_, '_, '_> {
    type Item = Result<Picture, LiveError>;
    fn next(&mut self) -> Option<Self::Item> {
        self.screen.next_picture().transpose()
    }
}
