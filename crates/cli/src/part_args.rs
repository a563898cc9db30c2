//! The `--part K/N` and `--samples A..B` flags of `flowlight render` (docs/distributed.md).

use anyhow::{anyhow, Result};
use flowlight_host::parts::{parse_part, parse_samples, PartSpec};
use flowlight_host::renderer::Renderer;
use std::path::{Path, PathBuf};

/// Restricts `renderer` to the part the flags name, if any: part K of N of the renderer's
/// samples per pixel, or samples A..B. Without `--out` (`out_given` false) the part's files
/// go beside the config's image under names of their own ([`part_path`]): a part never
/// replaces the final image.
pub fn apply(
    renderer: &mut Renderer,
    part: Option<&str>,
    samples: Option<&str>,
    out_given: bool,
) -> Result<()> {
    if part.is_none() && samples.is_none() {
        return Ok(());
    }
    renderer.check_part_budget().map_err(|e| anyhow!(e))?;
    let total = renderer.options.spp;
    let spec = match (part, samples) {
        (Some(p), _) => {
            let (k, n) = parse_part(p).map_err(|e| anyhow!(e))?;
            PartSpec::part(k, n, total).map_err(|e| anyhow!(e))?
        }
        (None, Some(s)) => {
            let (a, b) = parse_samples(s).map_err(|e| anyhow!(e))?;
            PartSpec::samples(a, b, total).map_err(|e| anyhow!(e))?
        }
        (None, None) => return Ok(()),
    };
    if !out_given {
        renderer.exr_path = renderer.exr_path.as_deref().map(|p| part_path(p, &spec));
        renderer.png_path = renderer.png_path.as_deref().map(|p| part_path(p, &spec));
    }
    renderer.set_part(spec).map_err(|e| anyhow!(e))
}

/// `image.exr` → `image.part-1-of-4.exr` (or `image.samples-8-12.exr`): where a part goes
/// when `--out` does not say.
pub fn part_path(path: &Path, spec: &PartSpec) -> PathBuf {
    let tag = match spec.part {
        Some((k, n)) => format!("part-{k}-of-{n}"),
        None => format!("samples-{}-{}", spec.begin, spec.end),
    };
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let name = match path.extension() {
        Some(ext) => format!("{stem}.{tag}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{tag}"),
    };
    path.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d7_parts_without_out_get_names_of_their_own() {
        let part = PartSpec::part(1, 4, 8).unwrap();
        assert_eq!(
            part_path(Path::new("/r/out/image.exr"), &part),
            PathBuf::from("/r/out/image.part-1-of-4.exr")
        );
        let samples = PartSpec::samples(2, 6, 8).unwrap();
        assert_eq!(
            part_path(Path::new("image.png"), &samples),
            PathBuf::from("image.samples-2-6.png")
        );
    }
}
