//! `--tev [HOST:PORT]` and `--preview-every SECONDS`: the live preview of `flowlight render`
//! (`flowlight_host::output::live`), refreshed from the progress callback.

use crate::render::LiveFlags;
use anyhow::{anyhow, Result};
use flowlight_host::output::live::LivePreview;
use flowlight_host::renderer::Renderer;
use std::sync::Mutex;
use std::time::Duration;

/// The live preview the flags ask for, or `None`. `--preview-every` needs the PNG preview
/// the config names (`[output] png`); tev shows the image under the EXR's file name.
pub fn start(renderer: &Renderer, live: LiveFlags) -> Result<Option<Mutex<LivePreview>>> {
    if live.tev.is_none() && live.preview_every.is_none() {
        return Ok(None);
    }
    let png = match live.preview_every {
        None => None,
        Some(seconds) => {
            let path = renderer.png_path.clone().ok_or_else(|| {
                anyhow!("--preview-every: the config writes no PNG preview; give [output] png")
            })?;
            Some((path, Duration::from_secs_f64(seconds)))
        }
    };
    let name = renderer
        .exr_path
        .as_ref()
        .and_then(|p| p.file_name())
        .map_or_else(
            || "flowlight".to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
    let (w, h) = (renderer.camera.width, renderer.camera.height);
    Ok(Some(Mutex::new(LivePreview::new(
        w, h, live.tev, &name, png,
    ))))
}
