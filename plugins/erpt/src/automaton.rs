//! A Heckbert pattern (`part.rs`) compiled to a deterministic automaton over the five letters
//! `E D G S L`, so that classifying a path type costs one table lookup per vertex.
//!
//! The entangled seed sampler asks for the class of every seed it makes (a few per camera
//! sample), so the classification sits on the path tracer's hot loop; the pattern's own
//! matcher (sets of string positions, re-walked per item) costs ~50× more per letter.
//!
//! Construction (Thompson 1968; Aho, Lam, Sethi & Ullman, *Compilers*, §3.7): each item becomes
//! an ε-NFA fragment — a letter class one transition; `?` an ε-edge around its fragment;
//! `*` and `+` a fresh loop state, so that a loop never re-enters a state that other items
//! leave from; a group the union of its alternatives. The subset construction then turns the
//! at most [`MAX_NFA_STATES`] NFA states into DFA states (bit sets of NFA states), all of them,
//! eagerly: patterns are a few letters long, so the table has a handful of rows.

use crate::part::{Item, Node};

/// NFA states a pattern may compile to (one bit each in a DFA state).
pub const MAX_NFA_STATES: usize = 128;

/// Letter index of `E D G S L` (the bit order of [`Node::Class`] masks).
pub type LetterIndex = usize;

#[derive(Default)]
struct Nfa {
    /// Per state: ε-successors.
    eps: Vec<Vec<usize>>,
    /// Per state: (letter mask, successor).
    on: Vec<Vec<(u8, usize)>>,
}

impl Nfa {
    fn state(&mut self) -> usize {
        self.eps.push(Vec::new());
        self.on.push(Vec::new());
        self.eps.len() - 1
    }

    fn alternatives(&mut self, alts: &[Vec<Item>], from: usize) -> usize {
        let end = self.state();
        for seq in alts {
            let e = seq.iter().fold(from, |at, item| self.item(item, at));
            self.eps[e].push(end);
        }
        end
    }

    fn node(&mut self, node: &Node, from: usize) -> usize {
        match node {
            Node::Class(mask) => {
                let to = self.state();
                self.on[from].push((*mask, to));
                to
            }
            Node::Group(alts) => self.alternatives(alts, from),
        }
    }

    fn item(&mut self, item: &Item, from: usize) -> usize {
        match (item.min, item.many) {
            (_, true) => {
                // A fresh loop head: entered from `from`, re-entered after each repetition.
                let head = self.state();
                self.eps[from].push(head);
                let end = self.node(&item.node, head);
                self.eps[end].push(head);
                if item.min == 0 {
                    head
                } else {
                    end
                }
            }
            (0, false) => {
                let end = self.node(&item.node, from);
                self.eps[from].push(end);
                end
            }
            _ => self.node(&item.node, from),
        }
    }

    fn closure(&self, mut set: u128) -> u128 {
        let mut stack: Vec<usize> = (0..self.eps.len()).filter(|&i| set >> i & 1 != 0).collect();
        while let Some(s) = stack.pop() {
            for &t in &self.eps[s] {
                if set >> t & 1 == 0 {
                    set |= 1 << t;
                    stack.push(t);
                }
            }
        }
        set
    }

    fn step(&self, set: u128, letter: LetterIndex) -> u128 {
        let mut out = 0u128;
        for (s, on) in self.on.iter().enumerate() {
            if set >> s & 1 != 0 {
                for &(mask, t) in on {
                    if mask >> letter & 1 != 0 {
                        out |= 1 << t;
                    }
                }
            }
        }
        self.closure(out)
    }
}

/// The DFA of a pattern: state 0 is the start; every state has a successor per letter (a
/// dead state where nothing matches any more).
#[derive(Clone, Debug, PartialEq)]
pub struct Dfa {
    next: Vec<[u16; 5]>,
    accepting: Vec<bool>,
}

impl Dfa {
    /// Compiles the alternatives of a parsed pattern; `Err` when it needs more than
    /// [`MAX_NFA_STATES`] NFA states.
    pub fn new(alts: &[Vec<Item>]) -> Result<Dfa, String> {
        let mut nfa = Nfa::default();
        let start = nfa.state();
        let accept = nfa.alternatives(alts, start);
        if nfa.eps.len() > MAX_NFA_STATES {
            return Err(format!(
                "the pattern is too long ({} automaton states, at most {MAX_NFA_STATES})",
                nfa.eps.len()
            ));
        }
        let mut sets = vec![nfa.closure(1 << start)];
        let mut dfa = Dfa {
            next: Vec::new(),
            accepting: Vec::new(),
        };
        let mut i = 0;
        while i < sets.len() {
            let set = sets[i];
            let mut row = [0u16; 5];
            for (letter, slot) in row.iter_mut().enumerate() {
                let to = nfa.step(set, letter);
                let k = match sets.iter().position(|&s| s == to) {
                    Some(k) => k,
                    None => {
                        sets.push(to);
                        sets.len() - 1
                    }
                };
                *slot = u16::try_from(k).map_err(|_| "the pattern's automaton is too large")?;
            }
            dfa.next.push(row);
            dfa.accepting.push(set >> accept & 1 != 0);
            i += 1;
        }
        Ok(dfa)
    }

    /// Whether the whole word (letter indices) is accepted.
    #[inline]
    pub fn accepts(&self, word: impl IntoIterator<Item = LetterIndex>) -> bool {
        let state = word
            .into_iter()
            .fold(0usize, |s, l| self.next[s][l] as usize);
        self.accepting[state]
    }

    /// Whether some word over the letters in `allowed` (bit i: letter i of `E D G S L`) is
    /// accepted: an accepting state reachable from the start through those letters only.
    pub fn accepts_some(&self, allowed: u8) -> bool {
        let mut seen = vec![false; self.next.len()];
        let mut stack = vec![0usize];
        seen[0] = true;
        while let Some(s) = stack.pop() {
            if self.accepting[s] {
                return true;
            }
            for (letter, &t) in self.next[s].iter().enumerate() {
                let t = t as usize;
                if allowed >> letter & 1 != 0 && !seen[t] {
                    seen[t] = true;
                    stack.push(t);
                }
            }
        }
        false
    }

    /// Number of DFA states (dead state included).
    #[cfg(test)]
    pub fn state_count(&self) -> usize {
        self.next.len()
    }
}
