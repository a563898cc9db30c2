//! The live preview of a render in progress: the film streamed to tev ([`super::tev`]) and
//! the PNG preview rewritten, each at a limited rate, from the frame's accumulators
//! ([`crate::render::Progress::image`]).
//!
//! Neither can fail a render: a tev that cannot be reached, or that goes away, and a
//! preview file that cannot be written are one warning each, after which that part of the
//! preview stops. The outputs written at the end are the same with or without a preview:
//! the preview only reads the frame. When the render ends, tev gets the final film
//! ([`LivePreview::finish`]), the image the EXR holds.

use super::tev::TevClient;
use super::PngPreview;
use crate::render::Progress;
use flowlight_core::spectrum::Rgb;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How often the film is sent to tev while rendering.
pub const TEV_INTERVAL: Duration = Duration::from_millis(500);
/// How long connecting (and each write) to tev may take.
pub const TEV_TIMEOUT: Duration = Duration::from_secs(2);
/// The shortest interval at which a live preview has the worker threads move their private
/// accumulation buffers into the frame ([`crate::render::RenderOptions::preview_flush`]): a
/// whole-image buffer is a pass over the image, so not at tev's own rate.
pub const PREVIEW_FLUSH_MIN: Duration = Duration::from_secs(2);

/// How often a render previewed to tev (`tev`) and/or as a PNG every `png_every` seconds has
/// its threads flush their private buffers: [`PREVIEW_FLUSH_MIN`], or the PNG's interval when
/// it is longer and no tev is watching; `None` without a preview.
pub fn preview_flush(tev: bool, png_every: Option<f64>) -> Option<Duration> {
    match (tev, png_every) {
        (false, None) => None,
        (true, _) => Some(PREVIEW_FLUSH_MIN),
        (false, Some(s)) => Some(Duration::from_secs_f64(s).max(PREVIEW_FLUSH_MIN)),
    }
}

/// The live preview's outputs and when each was last refreshed.
pub struct LivePreview {
    width: u32,
    height: u32,
    tev: Option<TevClient>,
    tev_address: String,
    png: Option<(PathBuf, Duration)>,
    last_tev: Option<Instant>,
    last_png: Option<Instant>,
    /// PNG previews written while rendering.
    pub png_writes: u64,
    /// Images sent to tev (the final one included).
    pub tev_updates: u64,
}

impl LivePreview {
    /// A preview of a `width` × `height` render: to tev at `tev` (HOST:PORT), shown as
    /// `name`, and rewriting `png` every `interval`. A tev that cannot be reached is one
    /// warning and no stream.
    pub fn new(
        width: u32,
        height: u32,
        tev: Option<&str>,
        name: &str,
        png: Option<(PathBuf, Duration)>,
    ) -> LivePreview {
        let client = tev.and_then(|address| {
            match TevClient::connect(address, name, width, height, TEV_TIMEOUT) {
                Ok(c) => {
                    tracing::info!("streaming the film to tev at {address} as \"{name}\"");
                    Some(c)
                }
                Err(e) => {
                    tracing::warn!("--tev: cannot connect to tev at {address} ({e}); rendering without the live view");
                    None
                }
            }
        });
        LivePreview {
            width,
            height,
            tev: client,
            tev_address: tev.unwrap_or_default().to_string(),
            png,
            last_tev: None,
            last_png: None,
            png_writes: 0,
            tev_updates: 0,
        }
    }

    /// Whether anything is left to refresh.
    pub fn is_active(&self) -> bool {
        self.tev.is_some() || self.png.is_some()
    }

    /// Refreshes what is due at `progress` (one copy of the frame for both).
    pub fn update(&mut self, progress: &Progress) {
        let now = Instant::now();
        let due = |last: Option<Instant>, every: Duration| last.is_none_or(|t| now - t >= every);
        let tev_due = self.tev.is_some() && due(self.last_tev, TEV_INTERVAL);
        let png_due = self
            .png
            .as_ref()
            .is_some_and(|(_, e)| due(self.last_png, *e));
        if !(tev_due || png_due) {
            return;
        }
        let Some(image) = progress.image() else {
            return;
        };
        if tev_due {
            self.last_tev = Some(now);
            self.send(&image);
        }
        if png_due {
            self.last_png = Some(now);
            self.write_png(&image);
        }
    }

    /// Sends the final `image` (the film as the EXR holds it) to tev.
    pub fn finish(&mut self, image: &[Rgb]) {
        self.send(image);
    }

    fn send(&mut self, image: &[Rgb]) {
        let Some(client) = &mut self.tev else {
            return;
        };
        match client.send_image(image) {
            Ok(()) => self.tev_updates += 1,
            Err(e) => {
                tracing::warn!(
                    "--tev: lost the connection to tev at {} ({e}); rendering on without the live view",
                    self.tev_address
                );
                self.tev = None;
            }
        }
    }

    fn write_png(&mut self, image: &[Rgb]) {
        let Some((path, _)) = &self.png else {
            return;
        };
        let (w, h) = (self.width as usize, self.height as usize);
        // Pixels not finite yet (a NaN deposit is discarded, but a preview must not fail on
        // anything) are shown black.
        let clean: Vec<Rgb> = image
            .iter()
            .map(|c| if c.is_valid_radiance() { *c } else { Rgb::ZERO })
            .collect();
        let written = PngPreview::new(path, w, h, &clean, 0.0).and_then(|p| p.write(path));
        match written {
            Ok(()) => self.png_writes += 1,
            Err(e) => {
                tracing::warn!("--preview-every: {e}; no more previews during this render");
                self.png = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn previews_flush_the_threads_buffers_at_most_every_two_seconds() {
        assert_eq!(preview_flush(false, None), None);
        assert_eq!(preview_flush(true, None), Some(PREVIEW_FLUSH_MIN));
        assert_eq!(preview_flush(true, Some(30.0)), Some(PREVIEW_FLUSH_MIN));
        assert_eq!(preview_flush(false, Some(0.5)), Some(PREVIEW_FLUSH_MIN));
        assert_eq!(
            preview_flush(false, Some(10.0)),
            Some(Duration::from_secs(10))
        );
    }
}
