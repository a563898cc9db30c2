//! The `--part K/N` and `--samples A..B` flags of `flowlight render` (docs/distributed.md).

use anyhow::{anyhow, Result};
use flowlight_host::parts::{parse_part, parse_samples, PartSpec};
use flowlight_host::session::Session;

/// Restricts `session` to the part the flags name, if any: part K of N of the session's
/// samples per pixel, or samples A..B.
pub fn apply(session: &mut Session, part: Option<&str>, samples: Option<&str>) -> Result<()> {
    let total = session.options.spp;
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
    session.set_part(spec).map_err(|e| anyhow!(e))
}
