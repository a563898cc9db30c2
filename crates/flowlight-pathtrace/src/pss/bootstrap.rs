//! The bootstrap of a render, built in pieces by every work unit that needs it, so that it
//! runs on all the host's threads instead of one while the others wait.
//!
//! A bootstrap ([`Bootstrap`]) and the scale estimate of the large steps
//! ([`super::large_steps::scale_estimate`]) are sums over independent vectors, vector i
//! drawn from a seed of (seed, i): any split of 0..count evaluates the same numbers. A
//! [`BootstrapPlan`] cuts them into [`Piece`]s of at most [`PIECE_VECTORS`] vectors, per
//! part (`mmlt` has one part per depth). [`BootstrapCell::get_or_build`] hands the pieces
//! to the units that ask for the bootstrap; each evaluates its piece with its own tracer,
//! outside the lock, and the unit that finishes the last piece assembles the bootstrap
//! ([`assemble_part`]) while the others wait. The sums are taken in vector order, as one
//! thread would take them, so the bootstrap is the same bits whatever the thread count and
//! whichever unit evaluated which piece.
//!
//! The bootstrap must come from the render seed (a fixed one would scale every render
//! alike, biasing the mean over renders), and the host's `prepare` does not know the seed:
//! so the units of a render build it, and build it again only for another seed.

use super::chain::{bootstrap_seed, scalar, Bootstrap, PssTarget};
use super::large_steps::scale_seed;
use super::samples::{Mutation, PrimarySamples};
use std::ops::Range;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

/// The most vectors of one piece: a few milliseconds of work, so that a bootstrap of 10⁵
/// vectors has dozens of pieces to share out.
pub const PIECE_VECTORS: u32 = 2048;

/// Which vectors a piece evaluates.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Piece {
    /// The part (`mmlt`'s depth; 0 for a single bootstrap).
    pub part: u32,
    /// The scale estimate's vectors rather than the bootstrap's.
    pub scale: bool,
    pub vectors: Range<u32>,
}

/// What a piece evaluated: each vector's scalar target in order (0 for an invalid one, as
/// [`scalar`] counts it), and how many were invalid.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Evaluated {
    pub scalars: Vec<f32>,
    pub invalid: u64,
}

/// Evaluates `vectors` of the bootstrap (or, with `scale`, of the scale estimate) of seed
/// `seed` over `target`.
pub fn evaluate<T: PssTarget>(
    target: &mut T,
    seed: u64,
    scale: bool,
    vectors: Range<u32>,
    mutation: Mutation,
) -> Evaluated {
    let streams = target.streams();
    let mut splats = Vec::new();
    let mut out = Evaluated {
        scalars: Vec::with_capacity(vectors.len()),
        invalid: 0,
    };
    for i in vectors {
        let vector_seed = if scale {
            scale_seed(seed, i)
        } else {
            bootstrap_seed(seed, i)
        };
        target.evaluate(
            &PrimarySamples::new(vector_seed, mutation, streams),
            &mut splats,
        );
        let f = scalar(&splats).unwrap_or_else(|| {
            out.invalid += 1;
            0.0
        });
        out.scalars.push(f);
    }
    out
}

/// The pieces of `parts` bootstraps of `count` vectors each and, when `scale_count` > 0, of
/// as many scale estimates of `scale_count` vectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootstrapPlan {
    pub parts: u32,
    pub count: u32,
    pub scale_count: u32,
}

impl BootstrapPlan {
    /// `parts` bootstraps of `count` vectors, each with a scale estimate of count/8 (at least
    /// one) vectors apart from its own when `combine_large_steps`
    /// ([`super::large_steps`]).
    pub fn new(parts: u32, count: u32, combine_large_steps: bool) -> BootstrapPlan {
        BootstrapPlan {
            parts,
            count,
            scale_count: if combine_large_steps {
                (count / 8).max(1)
            } else {
                0
            },
        }
    }

    /// The pieces, part by part, each part's bootstrap before its scale estimate, in vector
    /// order.
    pub fn pieces(&self) -> Vec<Piece> {
        let mut pieces = Vec::new();
        for part in 0..self.parts {
            for (scale, n) in [(false, self.count), (true, self.scale_count)] {
                for start in (0..n).step_by(PIECE_VECTORS as usize) {
                    let vectors = start..n.min(start + PIECE_VECTORS);
                    pieces.push(Piece {
                        part,
                        scale,
                        vectors,
                    });
                }
            }
        }
        pieces
    }
}

/// What a built bootstrap reports ([`super::PssCounters`]): the vectors it evaluated, how
/// many were invalid, and the normalisation of the film it found.
pub trait BootstrapTotals {
    fn samples(&self) -> u64;
    fn invalid(&self) -> u64;
    fn normalisation(&self) -> f64;
}

impl BootstrapTotals for Bootstrap {
    fn samples(&self) -> u64 {
        Bootstrap::samples(self)
    }

    fn invalid(&self) -> u64 {
        Bootstrap::invalid(self)
    }

    fn normalisation(&self) -> f64 {
        Bootstrap::normalisation(self)
    }
}

/// A scale estimate: c, the mean scalar of its vectors, how many vectors, and how many of
/// them were invalid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScaleEstimate {
    pub c: f64,
    pub vectors: u64,
    pub invalid: u64,
}

impl ScaleEstimate {
    /// The estimate from its pieces' evaluations, summed in order.
    pub fn from_pieces<'e>(pieces: impl IntoIterator<Item = &'e Evaluated>) -> ScaleEstimate {
        let (mut sum, mut count, mut invalid) = (0.0f64, 0u64, 0);
        for e in pieces {
            for &f in &e.scalars {
                sum += f as f64;
            }
            count += e.scalars.len() as u64;
            invalid += e.invalid;
        }
        ScaleEstimate {
            c: sum / count.max(1) as f64,
            vectors: count,
            invalid,
        }
    }
}

/// Part `part` of a plan assembled from `evaluated`, the evaluations of `pieces` (the plan's,
/// in its order): the bootstrap of seed `seed` over a target of `streams` streams, combined
/// with its scale estimate ([`Bootstrap::combine_large_steps`]) when the plan has one.
pub fn assemble_part(
    pieces: &[Piece],
    evaluated: &[Evaluated],
    part: u32,
    seed: u64,
    mutation: Mutation,
    streams: u32,
) -> Bootstrap {
    let of = |scale: bool| {
        pieces
            .iter()
            .zip(evaluated)
            .filter(move |(p, _)| p.part == part && p.scale == scale)
            .map(|(_, e)| e)
    };
    let mut bootstrap = Bootstrap::from_pieces(seed, mutation, streams, of(false));
    if of(true).next().is_some() {
        bootstrap.combine_large_steps(ScaleEstimate::from_pieces(of(true)));
    }
    bootstrap
}

/// The bootstrap of the latest render seed (a [`Bootstrap`], or `mmlt`'s per-depth one),
/// built by the work units that ask for it (module documentation).
pub struct BootstrapCell<B = Bootstrap> {
    inner: Mutex<Cell<B>>,
    changed: Condvar,
}

struct Cell<B> {
    state: State<B>,
    /// Numbers the builds, so that a unit finishing a piece of an abandoned build (one whose
    /// evaluation panicked) does not store it in the next.
    builds: u64,
}

enum State<B> {
    Empty,
    Building(Build),
    Ready(u64, Arc<B>),
}

struct Build {
    seed: u64,
    number: u64,
    /// The first piece not handed out yet.
    next: usize,
    evaluated: Vec<Option<Evaluated>>,
    finished: usize,
}

impl<B> Default for BootstrapCell<B> {
    fn default() -> Self {
        BootstrapCell {
            inner: Mutex::new(Cell {
                state: State::Empty,
                builds: 0,
            }),
            changed: Condvar::new(),
        }
    }
}

/// What a unit does next, decided under the lock.
enum Step<B> {
    Done(Arc<B>),
    Evaluate(usize, u64),
    Wait,
    Start,
}

impl<B> BootstrapCell<B> {
    fn lock(&self) -> MutexGuard<'_, Cell<B>> {
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The bootstrap of render seed `seed`, and whether this call assembled it (so that
    /// its cost is reported once). While it is missing, the call evaluates pieces
    /// 0..`pieces` that no other unit has taken (`evaluate(k)`, outside the lock); the call
    /// that finishes the last one assembles the bootstrap from all of them, in order
    /// (`assemble`), and the others wait for it.
    pub fn get_or_build(
        &self,
        seed: u64,
        pieces: usize,
        mut evaluate: impl FnMut(usize) -> Evaluated,
        assemble: impl FnOnce(Vec<Evaluated>) -> B,
    ) -> (Arc<B>, bool) {
        let mut assemble = Some(assemble);
        let mut cell = self.lock();
        loop {
            let step = match &mut cell.state {
                State::Ready(s, b) if *s == seed => Step::Done(b.clone()),
                State::Building(build) if build.seed == seed && build.next < pieces => {
                    build.next += 1;
                    Step::Evaluate(build.next - 1, build.number)
                }
                // Every piece is taken (or another seed is being built): wait for it.
                State::Building(_) => Step::Wait,
                State::Empty | State::Ready(..) => Step::Start,
            };
            match step {
                Step::Done(b) => return (b, false),
                Step::Wait => {
                    cell = self
                        .changed
                        .wait(cell)
                        .unwrap_or_else(PoisonError::into_inner);
                }
                Step::Start => {
                    cell.builds += 1;
                    cell.state = State::Building(Build {
                        seed,
                        number: cell.builds,
                        next: 0,
                        evaluated: (0..pieces).map(|_| None).collect(),
                        finished: 0,
                    });
                    if pieces == 0 {
                        return self.finish(cell, seed, &mut assemble);
                    }
                }
                Step::Evaluate(k, number) => {
                    drop(cell);
                    let abandon = AbandonOnUnwind { cell: self, number };
                    let e = evaluate(k);
                    std::mem::forget(abandon);
                    cell = self.lock();
                    if let State::Building(build) = &mut cell.state {
                        if build.number == number {
                            build.evaluated[k] = Some(e);
                            build.finished += 1;
                            if build.finished == pieces {
                                return self.finish(cell, seed, &mut assemble);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Assembles the build in `cell`, every piece of which is evaluated, stores it and wakes
    /// the waiting units.
    fn finish(
        &self,
        mut cell: MutexGuard<'_, Cell<B>>,
        seed: u64,
        assemble: &mut Option<impl FnOnce(Vec<Evaluated>) -> B>,
    ) -> (Arc<B>, bool) {
        let State::Building(build) = std::mem::replace(&mut cell.state, State::Empty) else {
            unreachable!("finish is called on a build");
        };
        let evaluated = build
            .evaluated
            .into_iter()
            .map(|e| e.expect("every piece is evaluated"))
            .collect();
        let assemble = assemble.take().expect("a call assembles at most once");
        let b = Arc::new(assemble(evaluated));
        cell.state = State::Ready(seed, b.clone());
        self.changed.notify_all();
        (b, true)
    }
}

/// Abandons build `number` if the evaluation of one of its pieces unwinds (a panicking
/// plugin: the host reports the unit's failure), so that the units waiting for it start
/// over instead of waiting for a piece that will never come. Forgotten when the evaluation
/// returns.
struct AbandonOnUnwind<'c, B> {
    cell: &'c BootstrapCell<B>,
    number: u64,
}

impl<B> Drop for AbandonOnUnwind<'_, B> {
    fn drop(&mut self) {
        let mut cell = self.cell.lock();
        if matches!(&cell.state, State::Building(b) if b.number == self.number) {
            cell.state = State::Empty;
            self.cell.changed.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pss::chain::Splat;
    use flowlight_core::sampler::SampleStream;
    use flowlight_core::Rgb;
    use glam::Vec2;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// f(u) = 4 u₀ u₁ at raster (0, 0): a cheap target with a known mean (1).
    struct Product;

    impl PssTarget for Product {
        fn streams(&self) -> u32 {
            1
        }

        fn evaluate(&mut self, samples: &PrimarySamples, splats: &mut Vec<Splat>) {
            splats.clear();
            let mut s = samples.start_stream(0);
            let v = 4.0 * s.uniform() * s.uniform();
            splats.push(Splat {
                raster: Vec2::ZERO,
                layer: 0,
                value: Rgb::splat(v),
            });
        }
    }

    /// Two parts of 5000 vectors, each with a scale estimate of 5000 / 8 = 625.
    const PLAN: BootstrapPlan = BootstrapPlan {
        parts: 2,
        count: 5000,
        scale_count: 625,
    };

    /// The plan's parts on one thread: `Bootstrap::run` combined with `scale_estimate`.
    fn serial(mutation: Mutation) -> Vec<Bootstrap> {
        (0..PLAN.parts)
            .map(|part| {
                let seed = 10 + u64::from(part);
                let mut b = Bootstrap::run(&mut Product, seed, PLAN.count, mutation);
                let scale = super::super::large_steps::scale_estimate(
                    &mut Product,
                    seed,
                    PLAN.scale_count,
                    mutation,
                );
                b.combine_large_steps(scale);
                b
            })
            .collect()
    }

    /// Every field the same bits (Debug prints each f64 so that it reads back exactly).
    fn same(a: &[Bootstrap], b: &[Bootstrap]) {
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
    }

    #[test]
    fn a_plan_covers_every_vector_once_in_pieces_of_at_most_piece_vectors() {
        let pieces = PLAN.pieces();
        assert_eq!(PLAN, BootstrapPlan::new(2, 5000, true));
        assert_eq!(pieces.len(), 2 * (3 + 1));
        for part in 0..2 {
            for (scale, n) in [(false, 5000), (true, 625)] {
                let mut next = 0;
                for p in pieces.iter().filter(|p| p.part == part && p.scale == scale) {
                    assert_eq!(p.vectors.start, next);
                    assert!(p.vectors.len() as u32 <= PIECE_VECTORS && !p.vectors.is_empty());
                    next = p.vectors.end;
                }
                assert_eq!(next, n);
            }
        }
    }

    /// Four threads share the pieces: each piece is evaluated once, one call assembles, and
    /// the bootstrap is the same bits as one thread's `Bootstrap::run` and `scale_estimate`.
    #[test]
    fn units_on_many_threads_build_the_one_threads_bootstrap() {
        let mutation = Mutation::new(0.3, 0.05);
        let pieces = PLAN.pieces();
        let evaluations: Vec<AtomicUsize> = pieces.iter().map(|_| AtomicUsize::new(0)).collect();
        let cell = BootstrapCell::default();
        let build = || {
            cell.get_or_build(
                7,
                pieces.len(),
                |k| {
                    evaluations[k].fetch_add(1, Ordering::Relaxed);
                    let p = &pieces[k];
                    let seed = 10 + u64::from(p.part);
                    evaluate(&mut Product, seed, p.scale, p.vectors.clone(), mutation)
                },
                |evaluated| {
                    (0..PLAN.parts)
                        .map(|part| {
                            let seed = 10 + u64::from(part);
                            assemble_part(&pieces, &evaluated, part, seed, mutation, 1)
                        })
                        .collect::<Vec<_>>()
                },
            )
        };
        let results: Vec<_> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4).map(|_| s.spawn(build)).collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(
            results.iter().filter(|(_, assembled)| *assembled).count(),
            1
        );
        assert!(results.iter().all(|(b, _)| Arc::ptr_eq(b, &results[0].0)));
        assert!(evaluations.iter().all(|n| n.load(Ordering::Relaxed) == 1));
        same(&results[0].0, &serial(mutation));
        // The same seed again: stored, nothing evaluated.
        let (again, assembled) = build();
        assert!(!assembled && Arc::ptr_eq(&again, &results[0].0));
        assert!(evaluations.iter().all(|n| n.load(Ordering::Relaxed) == 1));
    }

    /// A unit whose evaluation panics abandons the build: the next unit builds it afresh
    /// instead of waiting for the lost piece forever.
    #[test]
    fn a_panicking_piece_abandons_the_build_instead_of_blocking_the_others() {
        let cell: BootstrapCell<usize> = BootstrapCell::default();
        let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            cell.get_or_build(
                1,
                3,
                |k| {
                    if k == 1 {
                        panic!("piece")
                    } else {
                        Evaluated::default()
                    }
                },
                |e| e.len(),
            )
        }));
        assert!(panicked.is_err());
        // On a thread of its own, so that a unit left waiting fails the test, not hangs it.
        let cell = Arc::new(cell);
        let (send, receive) = std::sync::mpsc::channel();
        let unit = cell.clone();
        std::thread::spawn(move || {
            let (b, assembled) = unit.get_or_build(1, 3, |_| Evaluated::default(), |e| e.len());
            send.send((*b, assembled)).unwrap();
        });
        let built = receive.recv_timeout(std::time::Duration::from_secs(30));
        assert_eq!(
            built,
            Ok((3, true)),
            "the next unit waited for the lost piece"
        );
    }

    #[test]
    fn another_seed_is_built_again_and_no_pieces_assemble_at_once() {
        let cell: BootstrapCell<u64> = BootstrapCell::default();
        let (a, _) = cell.get_or_build(1, 0, |_| unreachable!(), |_| 1);
        let (b, assembled) = cell.get_or_build(2, 1, |_| Evaluated::default(), |_| 2);
        assert_eq!((*a, *b, assembled), (1, 2, true));
    }
}
