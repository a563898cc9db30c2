//! The MCPT/ERPT split: which paths the chains render (the *ERPT part* of path space); the
//! seeds of every other path go to the film directly, as path tracing would deposit them.
//!
//! A path's class is read from its stored vertices in Heckbert's alphabet (Heckbert 1990;
//! thesis §3.3, §5.6), eye first: `E` the eye, `L` the light, `D` a diffuse vertex, `G` a
//! glossy one (reflection or transmission alike), `S` a Dirac vertex (specular reflection or
//! transmission), e.g. `EDSSL` for a caustic through a glass sphere. Mutations keep the weak
//! type (Dirac versus smooth per vertex) and the stored node types, so a chain normally stays
//! in its part; a proposal outside it is a *part miss*: f = 0 in the chain's target, a domain
//! miss of the step (counted as `part_misses`), the whole quantum deposited at the current
//! state.
//!
//! Why the sum is the image: the seeds' energy density is f (entangled seeds: their MIS
//! weights sum to one; untangled seeds: one technique per path), so the seeds of the ERPT
//! part A carry the density f·1_A and those outside carry f·(1 − 1_A). The MCPT part deposits
//! its seeds' estimates at their pixels — E = ∫ f (1 − 1_A). The chains of the ERPT part run the
//! Metropolis flow with target lum f·1_A, which keeps the energy density f·1_A (thesis §5.3),
//! so they deposit ∫ f 1_A in expectation. The two add up to ∫ f.
//!
//! Selection (`chains_for` ∧ not direct when `direct = "mcpt"`):
//!
//! * **direct** (`direct = "mcpt"`, Mitsuba 0.6's `directSamples`): emitters seen directly,
//!   also through mirrors and glass, and one-bounce direct light: lighting layer ≤ 1, where a
//!   path's layer counts its interior vertices after the leading run of Dirac vertices (the
//!   primordial mirror chain, thesis §2) — `ES*L` and `ES*[DG]L`.
//! * `chains_for = "all"`: every path; `"caustics"`: paths with a Dirac vertex after a smooth
//!   one, i.e. a specular vertex between the light and the last diffuse or glossy vertex seen
//!   from the light (`E.*[DG].*S.*L`, the L…S…D…E caustic paths; glossy counts as smooth); or a
//!   pattern: a regular expression over the letters `EDGSL` with `.` (any letter), `[…]`
//!   (one of), `*`, `+`, `?`, `|` and parentheses, matched against the whole type, e.g.
//!   `"E[DG]+S+[DG]*L"`.

use flowlight_core::path::{NodeType, Path, MAX_PATH_VERTICES};

/// The Heckbert letter of a stored node type in the alphabet of the module docs.
pub fn letter(node: NodeType) -> u8 {
    match node {
        NodeType::Eye => b'E',
        NodeType::Light => b'L',
        NodeType::DiffuseReflection | NodeType::DiffuseTransmission => b'D',
        NodeType::GlossyReflection | NodeType::GlossyTransmission => b'G',
        NodeType::SpecularReflection | NodeType::SpecularTransmission => b'S',
    }
}

/// Lighting layer of a path from its type: interior vertices after the leading Dirac run.
pub fn type_layer(path: &Path) -> usize {
    let v = path.vertices();
    if v.len() < 2 {
        return 0;
    }
    let interior = &v[1..v.len() - 1];
    let leading = interior
        .iter()
        .take_while(|x| letter(x.node) == b'S')
        .count();
    interior.len() - leading
}

#[derive(Clone, Debug, PartialEq)]
enum Node {
    /// One letter out of a set (bit i: the letter `LETTERS[i]`).
    Class(u8),
    /// Alternatives, each a sequence.
    Group(Vec<Vec<Item>>),
}

#[derive(Clone, Debug, PartialEq)]
struct Item {
    node: Node,
    /// Repetitions: at least `min` (0 or 1), unbounded when `many`: `*` (0, many), `+` (1,
    /// many), `?` (0, at most one), none (exactly one).
    min: u8,
    many: bool,
}

const LETTERS: &[u8; 5] = b"EDGSL";

/// A compiled Heckbert pattern, matched against a whole path type.
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    alternatives: Vec<Vec<Item>>,
}

/// Set of string positions 0..=MAX_PATH_VERTICES.
type Positions = u64;
const _: () = assert!(MAX_PATH_VERTICES < 64);

impl Pattern {
    pub fn parse(text: &str) -> Result<Pattern, String> {
        let bytes = text.as_bytes();
        let mut pos = 0;
        let alternatives = parse_alternatives(bytes, &mut pos)?;
        if pos != bytes.len() {
            return Err(format!("unmatched ')' at position {pos} of \"{text}\""));
        }
        Ok(Pattern { alternatives })
    }

    /// Whether the whole of `letters` matches.
    pub fn matches(&self, letters: &[u8]) -> bool {
        let end = ends_alternatives(&self.alternatives, letters, 1);
        end & (1u64 << letters.len()) != 0
    }
}

fn parse_alternatives(b: &[u8], pos: &mut usize) -> Result<Vec<Vec<Item>>, String> {
    let mut alts = vec![Vec::new()];
    while *pos < b.len() {
        let c = b[*pos];
        let node = match c {
            b')' => break,
            b'|' => {
                *pos += 1;
                alts.push(Vec::new());
                continue;
            }
            b'(' => {
                *pos += 1;
                let inner = parse_alternatives(b, pos)?;
                if *pos >= b.len() || b[*pos] != b')' {
                    return Err("unclosed '('".into());
                }
                *pos += 1;
                Node::Group(inner)
            }
            b'[' => {
                let close = b[*pos..]
                    .iter()
                    .position(|&x| x == b']')
                    .ok_or("unclosed '['")?;
                let set = &b[*pos + 1..*pos + close];
                let (negate, set) = match set.first() {
                    Some(b'^') => (true, &set[1..]),
                    _ => (false, set),
                };
                let mut mask = 0u8;
                for &l in set {
                    mask |= letter_bit(l)?;
                }
                if negate {
                    mask = !mask & 0x1f;
                }
                *pos += close + 1;
                Node::Class(mask)
            }
            b'.' => {
                *pos += 1;
                Node::Class(0x1f)
            }
            _ => {
                *pos += 1;
                Node::Class(letter_bit(c)?)
            }
        };
        let (min, many) = match b.get(*pos) {
            Some(b'*') => (0, true),
            Some(b'+') => (1, true),
            Some(b'?') => (0, false),
            _ => (1, false),
        };
        if matches!(b.get(*pos), Some(b'*' | b'+' | b'?')) {
            *pos += 1;
        }
        alts.last_mut()
            .expect("one alternative at least")
            .push(Item { node, min, many });
    }
    Ok(alts)
}

fn letter_bit(c: u8) -> Result<u8, String> {
    LETTERS
        .iter()
        .position(|&l| l == c)
        .map(|i| 1u8 << i)
        .ok_or_else(|| {
            format!(
                "unexpected '{}' (letters are E, D, G, S, L; operators . [ ] ^ * + ? | ( ))",
                c as char
            )
        })
}

/// Positions reachable after matching `node` from any position in `from`.
fn ends_node(node: &Node, s: &[u8], from: Positions) -> Positions {
    match node {
        Node::Class(mask) => {
            let mut out = 0;
            for (i, &c) in s.iter().enumerate() {
                if from & (1 << i) != 0 && letter_bit(c).is_ok_and(|b| b & mask != 0) {
                    out |= 1 << (i + 1);
                }
            }
            out
        }
        Node::Group(alts) => ends_alternatives(alts, s, from),
    }
}

fn ends_alternatives(alts: &[Vec<Item>], s: &[u8], from: Positions) -> Positions {
    alts.iter().fold(0, |acc, seq| {
        acc | seq.iter().fold(from, |at, item| ends_item(item, s, at))
    })
}

fn ends_item(item: &Item, s: &[u8], from: Positions) -> Positions {
    let mut at = from;
    for _ in 0..item.min {
        at = ends_node(&item.node, s, at);
    }
    if item.many {
        let (mut all, mut frontier) = (at, at);
        while frontier != 0 {
            let next = ends_node(&item.node, s, frontier) & !all;
            all |= next;
            frontier = next;
        }
        all
    } else if item.min == 0 {
        at | ends_node(&item.node, s, at)
    } else {
        at
    }
}

/// Which paths the chains render.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    /// `None`: every path (`chains_for = "all"`).
    pub chains_for: Option<Pattern>,
    /// Direct lighting (layer ≤ 1) goes to MCPT.
    pub direct_by_mcpt: bool,
}

impl Part {
    /// Parses `chains_for` ("all", "caustics" or a pattern) and `direct` ("erpt" or "mcpt").
    pub fn new(chains_for: &str, direct_by_mcpt: bool) -> Result<Part, String> {
        let chains_for = match chains_for {
            "all" => None,
            "caustics" => Some(Pattern::parse("E.*[DG].*S.*L").expect("valid preset")),
            p => Some(
                Pattern::parse(p).map_err(|e| format!("parameter 'chains_for': {e} in \"{p}\""))?,
            ),
        };
        Ok(Part {
            chains_for,
            direct_by_mcpt,
        })
    }

    /// True when every path goes to the chains.
    pub fn is_everything(&self) -> bool {
        self.chains_for.is_none() && !self.direct_by_mcpt
    }

    /// Whether the chains render `path`.
    pub fn contains(&self, path: &Path) -> bool {
        if self.direct_by_mcpt && type_layer(path) <= 1 {
            return false;
        }
        let Some(p) = &self.chains_for else {
            return true;
        };
        let mut letters = [0u8; MAX_PATH_VERTICES];
        let v = path.vertices();
        for (l, x) in letters.iter_mut().zip(v) {
            *l = letter(x.node);
        }
        p.matches(&letters[..v.len()])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::path::PathVertex;
    use glam::Vec3;

    fn path_of(t: &str) -> Path {
        let mut p = Path::empty();
        for (i, c) in t.bytes().enumerate() {
            let mut v = PathVertex::eye(Vec3::ZERO, Vec3::Z);
            v.node = match c {
                b'E' => NodeType::Eye,
                b'L' => NodeType::Light,
                b'D' => NodeType::DiffuseReflection,
                b'd' => NodeType::DiffuseTransmission,
                b'G' => NodeType::GlossyReflection,
                b'S' => NodeType::SpecularReflection,
                b'T' => NodeType::SpecularTransmission,
                _ => unreachable!(),
            };
            p.vertices[i] = v;
        }
        p.vertex_count = t.len() as u32;
        p
    }

    #[test]
    fn patterns_match_whole_types_only() {
        let m = |pat: &str, t: &str| Pattern::parse(pat).unwrap().matches(t.as_bytes());
        assert!(m("E.*[DG].*S.*L", "EDSSL"));
        assert!(m("E.*[DG].*S.*L", "EDDSDL"));
        assert!(!m("E.*[DG].*S.*L", "ESDL"));
        assert!(!m("E.*[DG].*S.*L", "EDDL"));
        assert!(m("ES*[DG]?L", "EL") && m("ES*[DG]?L", "ESSGL"));
        assert!(!m("ES*[DG]?L", "EDDL"));
        assert!(m("E(DS|SD)+L", "EDSSDL") && !m("E(DS|SD)+L", "EDSDL"));
        assert!(m("E[^S]+L", "EDGDL") && !m("E[^S]+L", "EDSL"));
        assert!(m("ED|EL", "EL") && !m("ED", "EDL"));
        for bad in ["EX", "E[DS", "E(D", "ED)"] {
            assert!(Pattern::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_split_classifies_by_type_and_layer() {
        let caustics = Part::new("caustics", false).unwrap();
        let direct = Part::new("all", true).unwrap();
        let both = Part::new("caustics", true).unwrap();
        // Glass transmissions are S as mirrors are; diffuse transmission is D.
        for (t, layer, c) in [
            ("EL", 0, false),
            ("ESTL", 0, false),
            ("EDL", 1, false),
            ("ETTDL", 1, false),
            ("EDTTL", 3, true),
            ("EDdL", 2, false),
            ("EDSDL", 3, true),
            ("EGSL", 2, true),
        ] {
            let p = path_of(t);
            assert_eq!(type_layer(&p), layer, "{t}");
            assert_eq!(caustics.contains(&p), c, "{t}");
            assert_eq!(direct.contains(&p), layer > 1, "{t}");
            assert_eq!(both.contains(&p), c && layer > 1, "{t}");
        }
        assert!(Part::new("all", false).unwrap().is_everything());
        let e = Part::new("EQL", false).unwrap_err();
        assert!(e.contains("chains_for") && e.contains('Q'), "{e}");
    }
}
