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

use crate::automaton::Dfa;
use flowlight_core::path::{NodeType, Path, MAX_PATH_VERTICES};
use flowlight_pathtrace::seeds::SeedFilter;

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
#[cfg(test)]
pub fn type_layer(path: &Path) -> usize {
    let mut types = [NodeType::Eye; MAX_PATH_VERTICES];
    let v = path.vertices();
    for (t, x) in types.iter_mut().zip(v) {
        *t = x.node;
    }
    layer_of(&types[..v.len()])
}

/// [`type_layer`] of the node types of a path (eye first, light last).
fn layer_of(types: &[NodeType]) -> usize {
    if types.len() < 2 {
        return 0;
    }
    let interior = &types[1..types.len() - 1];
    let leading = interior.iter().take_while(|&&t| letter(t) == b'S').count();
    interior.len() - leading
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Node {
    /// One letter out of a set (bit i: the letter `LETTERS[i]`).
    Class(u8),
    /// Alternatives, each a sequence.
    Group(Vec<Vec<Item>>),
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Item {
    pub node: Node,
    /// Repetitions: at least `min` (0 or 1), unbounded when `many`: `*` (0, many), `+` (1,
    /// many), `?` (0, at most one), none (exactly one).
    pub min: u8,
    pub many: bool,
}

const LETTERS: &[u8; 5] = b"EDGSL";

/// Index of a node type's letter in [`LETTERS`] (the bit of [`Node::Class`] masks).
#[inline]
fn letter_index(node: NodeType) -> usize {
    match node {
        NodeType::Eye => 0,
        NodeType::DiffuseReflection | NodeType::DiffuseTransmission => 1,
        NodeType::GlossyReflection | NodeType::GlossyTransmission => 2,
        NodeType::SpecularReflection | NodeType::SpecularTransmission => 3,
        NodeType::Light => 4,
    }
}

/// The bit of a node type's letter in a letter mask (bit i: letter i of `E D G S L`).
#[inline]
pub fn letter_bit_of(node: NodeType) -> u8 {
    1 << letter_index(node)
}

/// A compiled Heckbert pattern, matched against a whole path type: the parsed items, and the
/// deterministic automaton that matches them (`automaton.rs`).
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    /// The parse; the position-set matcher over it is the automaton's test oracle.
    #[cfg_attr(not(test), allow(dead_code))]
    alternatives: Vec<Vec<Item>>,
    dfa: Dfa,
}

/// Set of string positions 0..=MAX_PATH_VERTICES + 1 (a seed's type has at most one vertex
/// more than a stored path).
#[cfg(test)]
type Positions = u64;
const _: () = assert!(MAX_PATH_VERTICES + 1 < 64);

impl Pattern {
    pub fn parse(text: &str) -> Result<Pattern, String> {
        let bytes = text.as_bytes();
        let mut pos = 0;
        let alternatives = parse_alternatives(bytes, &mut pos)?;
        if pos != bytes.len() {
            return Err(format!("unmatched ')' at position {pos} of \"{text}\""));
        }
        let dfa = Dfa::new(&alternatives)?;
        Ok(Pattern { alternatives, dfa })
    }

    /// Whether the whole of `letters` (from `E D G S L`) matches.
    #[cfg(test)]
    pub fn matches(&self, letters: &[u8]) -> bool {
        self.dfa.accepts(letters.iter().map(|&l| {
            LETTERS
                .iter()
                .position(|&x| x == l)
                .expect("a Heckbert letter")
        }))
    }

    /// Whether the path type `types` (eye first, light last) matches.
    #[inline]
    pub fn matches_types(&self, types: &[NodeType]) -> bool {
        self.dfa.accepts(types.iter().map(|&t| letter_index(t)))
    }

    /// [`Pattern::matches`] by the position-set matcher over the parse (the test oracle).
    #[cfg(test)]
    fn matches_by_positions(&self, letters: &[u8]) -> bool {
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

#[cfg(test)]
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

#[cfg(test)]
fn ends_alternatives(alts: &[Vec<Item>], s: &[u8], from: Positions) -> Positions {
    alts.iter().fold(0, |acc, seq| {
        acc | seq.iter().fold(from, |at, item| ends_item(item, s, at))
    })
}

#[cfg(test)]
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

    /// True when no path can be in the part if its interior vertices only take letters of
    /// `interior` (a letter mask, [`letter_bit_of`]): the pattern accepts no word over those
    /// letters, the eye and the light. E.g. `caustics` in a scene without a Dirac surface.
    pub fn is_empty_for(&self, interior: u8) -> bool {
        let ends = letter_bit_of(NodeType::Eye) | letter_bit_of(NodeType::Light);
        match &self.chains_for {
            None => false,
            Some(p) => !p.dfa.accepts_some(interior | ends),
        }
    }

    /// Whether the chains render `path`.
    pub fn contains(&self, path: &Path) -> bool {
        let mut types = [NodeType::Eye; MAX_PATH_VERTICES];
        let v = path.vertices();
        for (t, x) in types.iter_mut().zip(v) {
            *t = x.node;
        }
        self.contains_type(&types[..v.len()])
    }

    /// Whether the chains render the paths of node types `types` (eye first, light last).
    pub fn contains_type(&self, types: &[NodeType]) -> bool {
        if self.direct_by_mcpt && layer_of(types) <= 1 {
            return false;
        }
        let Some(p) = &self.chains_for else {
            return true;
        };
        p.matches_types(types)
    }
}

/// Entangled seeds are split while they are traced: those outside the part never become
/// records (`flowlight_pathtrace::seeds::trace_split`).
impl SeedFilter for Part {
    fn keeps(&self, types: &[NodeType]) -> bool {
        self.contains_type(types)
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

    /// The automaton against the position-set matcher on every word over `EDGSL` of up to 7
    /// letters, for patterns with nested groups, empty alternatives and loops over optional
    /// items (where a naive Thompson construction re-enters a shared state).
    #[test]
    fn the_automaton_matches_as_the_pattern_does() {
        let patterns = [
            "E.*[DG].*S.*L",
            "ES*[DG]?L",
            "E(DS|SD)+L",
            "E[^S]+L",
            "ED|EL",
            "E(D?S?)*L",
            "E((D|G)+S)?L",
            "(E|)D*(|S)L",
            "E(D*G*)+L",
            "E(S(D|G)*)*L",
            "E[DG]+S+[DG]*L",
            ".*",
            "",
        ];
        let mut words: Vec<Vec<u8>> = vec![Vec::new()];
        let mut all = vec![Vec::new()];
        for _ in 0..7 {
            words = words
                .iter()
                .flat_map(|w| {
                    LETTERS.iter().map(move |&l| {
                        let mut w = w.clone();
                        w.push(l);
                        w
                    })
                })
                .collect();
            all.extend(words.iter().cloned());
        }
        for text in patterns {
            let p = Pattern::parse(text).unwrap();
            let mut accepted = 0;
            for w in &all {
                let want = p.matches_by_positions(w);
                assert_eq!(
                    p.matches(w),
                    want,
                    "{text} on {}",
                    String::from_utf8_lossy(w)
                );
                accepted += want as usize;
            }
            assert!(
                p.dfa.state_count() < 64,
                "{text}: {} states",
                p.dfa.state_count()
            );
            // Every pattern but the empty one accepts some word and rejects another.
            if !text.is_empty() && text != ".*" {
                assert!(accepted > 0 && accepted < all.len(), "{text}");
            }
        }
    }

    #[test]
    fn a_part_is_empty_where_the_scene_lacks_its_letters() {
        let bit = letter_bit_of;
        let d = bit(NodeType::DiffuseReflection);
        let g = bit(NodeType::GlossyTransmission);
        let s = bit(NodeType::SpecularReflection);
        let caustics = Part::new("caustics", true).unwrap();
        assert!(caustics.is_empty_for(d) && caustics.is_empty_for(d | g));
        assert!(
            caustics.is_empty_for(s),
            "a Dirac surface alone makes no caustic"
        );
        assert!(!caustics.is_empty_for(d | s) && !caustics.is_empty_for(g | s));
        let glossy = Part::new("E.*G.*L", false).unwrap();
        assert!(glossy.is_empty_for(d | s) && !glossy.is_empty_for(g));
        // Chains for every path (direct light or not) are never empty by letters.
        assert!(!Part::new("all", true).unwrap().is_empty_for(0));
        // A pattern that needs no interior vertex (emitters seen directly).
        assert!(!Part::new("EL", false).unwrap().is_empty_for(0));
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
