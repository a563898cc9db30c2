//! How a scene is built and traced: Embree's build quality, robust mode, hit filters, and
//! whether batches go through packets.

use crate::queries::BatchMode;
use embree4_sys::RTCBuildQuality;

/// Embree's BVH build quality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildQuality {
    Low,
    Medium,
    High,
}

impl BuildQuality {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "low" => Ok(Self::Low),
            "medium" => Ok(Self::Medium),
            "high" => Ok(Self::High),
            _ => Err(format!(
                "unknown Embree build quality {s:?}; expected \"low\", \"medium\" or \"high\""
            )),
        }
    }
    pub(crate) fn raw(self) -> RTCBuildQuality {
        match self {
            Self::Low => RTCBuildQuality::LOW,
            Self::Medium => RTCBuildQuality::MEDIUM,
            Self::High => RTCBuildQuality::HIGH,
        }
    }
}

/// How a scene is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneOptions {
    /// `RTC_SCENE_FLAG_ROBUST`: rays on shared edges and vertices never slip through.
    pub robust: bool,
    pub quality: BuildQuality,
    /// `RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS`: needed by
    /// [`EmbreeScene::intersect_filtered`](crate::EmbreeScene::intersect_filtered) and [`EmbreeScene::occluded_filtered`](crate::EmbreeScene::occluded_filtered) (alpha
    /// testing); without it their filter is never called.
    pub hit_filter: bool,
    /// How [`EmbreeScene::intersect_batch`](crate::EmbreeScene::intersect_batch) and [`EmbreeScene::occluded_batch`](crate::EmbreeScene::occluded_batch) trace.
    pub packets: Packets,
    /// Whether [`EmbreeScene::intersect_coherent_batch`](crate::EmbreeScene::intersect_coherent_batch) takes Embree's coherent packet
    /// traversal (unless `packets` is [`Packets::Never`]): several times faster on camera
    /// rays, and the same hits but for ties (a ray meeting two triangles at the same
    /// distance may get the other one). Off, it is the plain batch call.
    pub coherent: bool,
}

impl Default for SceneOptions {
    fn default() -> Self {
        SceneOptions {
            robust: true,
            quality: BuildQuality::Medium,
            hit_filter: false,
            packets: Packets::Auto,
            coherent: true,
        }
    }
}

/// Whether a scene (flat or instanced) answers batches of rays with Embree's 8-lane packet
/// traversal (`rtcIntersect8` / `rtcOccluded8`) or one `rtcIntersect1` / `rtcOccluded1`
/// per ray. Both give the same hits bit for bit (the tests); only the speed differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Packets {
    /// Packets for scenes of at most [`PACKET_MAX_TRIANGLES`] triangles, single rays above.
    Auto,
    Always,
    Never,
}

/// The largest scene [`Packets::Auto`] traces in packets: the largest size measured. A
/// packet of incoherent rays descends into the union of the nodes its rays need: in a small
/// tree that union is nearly the whole tree anyway, so one call serves all lanes at little
/// extra work, while in a large one the lanes part ways. Embree's 16-lane packets (until the
/// twenty-second session) paid only up to about 100k triangles: the `rays` bench had them at
/// 0.93–0.98× single rays at 100k and 0.97–1.03× at 1M, and renders of the dragon (871k)
/// unchanged. Its 8-lane packets are 1.07–1.14× as fast as single rays at 10k triangles,
/// 1.05–1.10× at 100k and 1.02–1.11× at 1M (robust mode, closest and any hit, 1 and 2
/// threads); a Cornell box render takes 9% less CPU with them than with the 16-lane ones,
/// and a dragon render 4% less than with single rays (docs/performance.md, "Twenty-second
/// session"). Above 1M: untested, single rays as before.
pub const PACKET_MAX_TRIANGLES: usize = 1_000_000;

impl Packets {
    /// Whether a scene of `triangles` triangles uses packets.
    pub fn resolve(self, triangles: usize) -> bool {
        match self {
            Packets::Auto => triangles <= PACKET_MAX_TRIANGLES,
            Packets::Always => true,
            Packets::Never => false,
        }
    }

    /// `FLOWLIGHT_EMBREE_PACKETS` (`auto` | `always` | `never`), [`Packets::Auto`] when unset:
    /// renders and the benchmarks read it.
    pub fn from_env() -> Result<Packets, String> {
        match std::env::var("FLOWLIGHT_EMBREE_PACKETS") {
            Ok(p) => Packets::parse(&p).map_err(|e| format!("FLOWLIGHT_EMBREE_PACKETS: {e}")),
            Err(_) => Ok(Packets::Auto),
        }
    }

    pub fn parse(s: &str) -> Result<Packets, String> {
        match s {
            "auto" => Ok(Packets::Auto),
            "always" => Ok(Packets::Always),
            "never" => Ok(Packets::Never),
            _ => Err(format!("{s:?}: expected auto, always or never")),
        }
    }
}

impl SceneOptions {
    /// How a scene built with these options traces coherent batches, given how it traces
    /// the others (`plain`): Embree's coherent packets when [`SceneOptions::coherent`] is on
    /// and packets are not off altogether, else as the others.
    pub(crate) fn coherent_mode(&self, plain: BatchMode) -> BatchMode {
        if self.coherent && self.packets != Packets::Never {
            BatchMode::CoherentPackets
        } else {
            plain
        }
    }

    /// The defaults (robust, medium quality, packets by size), changed by
    /// `FLOWLIGHT_EMBREE_QUALITY` (`low` | `medium` | `high`), `FLOWLIGHT_EMBREE_ROBUST`
    /// (`0` | `1`) and `FLOWLIGHT_EMBREE_PACKETS` (`auto` | `always` | `never`).
    pub fn from_env() -> Result<Self, String> {
        let mut o = SceneOptions::default();
        if let Ok(q) = std::env::var("FLOWLIGHT_EMBREE_QUALITY") {
            o.quality =
                BuildQuality::parse(&q).map_err(|e| format!("FLOWLIGHT_EMBREE_QUALITY: {e}"))?;
        }
        if let Ok(r) = std::env::var("FLOWLIGHT_EMBREE_ROBUST") {
            o.robust = match r.as_str() {
                "1" | "true" => true,
                "0" | "false" => false,
                _ => return Err(format!("FLOWLIGHT_EMBREE_ROBUST={r:?}: expected 0 or 1")),
            };
        }
        o.packets = Packets::from_env()?;
        Ok(o)
    }
}
