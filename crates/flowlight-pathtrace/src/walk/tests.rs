//! The step's reports on a hand-built scene, without a tracer: a Lambert floor (albedo ½) in
//! the plane y = 0, a mirror, an emitting triangle at height 2 facing down and a constant sky.
//! Each test drives [`step::vertex`] or [`step::escape`] at a chosen hit and reads what a
//! recording sink was told.

use super::sink::{ConnectionEvent, Extension, PathSink};
use super::step::{self, VertexAhead};
use super::{Step, WalkState, Walker};
use crate::settings::PathSettings;
use flowlight_core::bsdf::Bsdf;
use flowlight_core::camera::Camera;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::{area_to_solid_angle, light_powers, Emitter, Environment, Lights};
use flowlight_core::material::Material;
use flowlight_core::rng::Rng;
use flowlight_core::sampling::{build_cdf, power_heuristic};
use flowlight_core::termination::{TerminationDistribution, TerminationSchedule};
use flowlight_core::Rgb;
use flowlight_sdk::{Params, Scene};
use glam::{Vec2, Vec3};

const LAMP: f32 = 3.0;
const SKY: f32 = 0.25;
const MIRROR: u32 = 1;

fn scene() -> Scene<'static> {
    let materials: &'static [Material] = Box::leak(Box::new([
        Material {
            base_color: Rgb::splat(0.5),
            specular: 0.0,
            ..Default::default()
        },
        Material {
            base_color: Rgb::ONE,
            metallic: 1.0,
            roughness: 0.0,
            ..Default::default()
        },
    ]));
    let emitters: &'static [Emitter] = Box::leak(Box::new([Emitter {
        p0: Vec3::new(-1.0, 2.0, -1.0),
        p1: Vec3::new(1.0, 2.0, -1.0),
        p2: Vec3::new(0.0, 2.0, 1.0),
        n: -Vec3::Y,
        area: 2.0,
        radiance: Rgb::splat(LAMP),
        double_sided: 0,
        prim: 7,
        material: u32::MAX,
        uv0: [Vec2::ZERO; 3],
        uv1: [Vec2::ZERO; 3],
        color: [Rgb::ONE; 3],
        vertex_colored: 0,
    }]));
    let environment = Environment::constant(Rgb::splat(SKY));
    let cdf = build_cdf(&light_powers(emitters, &[], &environment, 3.0)).unwrap();
    Scene {
        camera: Camera::look_along(Vec3::new(0.0, 1.0, 2.0), -Vec3::Z, Vec3::Y, 60.0, 16, 16),
        materials,
        textures: &[],
        lights: Lights {
            emitters,
            punctual: &[],
            environment,
            power_cdf: Box::leak(cdf.into_boxed_slice()),
            materials: &[],
            textures: &[],
        },
        bounds_min: Vec3::splat(-3.0),
        bounds_max: Vec3::splat(3.0),
        mesh: Default::default(),
        material_bsdfs: &[],
        light_bound: None,
    }
    .with_light_bound()
}

/// A hit at `p` with normal `n` on material `material` (emitter `emitter`, or −1), at ray
/// parameter `t`.
fn hit(p: Vec3, n: Vec3, material: u32, emitter: i32, t: f32) -> SurfaceHit {
    SurfaceHit {
        t,
        p,
        p_error: Vec3::splat(1e-6),
        ng: n,
        ns: n,
        uv: Vec2::ZERO,
        uv1: Vec2::ZERO,
        color: [1.0; 4],
        prim: 0,
        material,
        emitter,
    }
}

fn floor_hit() -> SurfaceHit {
    hit(Vec3::ZERO, Vec3::Y, 0, -1, 1.0)
}

fn lamp_hit() -> SurfaceHit {
    hit(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, 0, 0, 1.0)
}

/// What a sink was told, in order.
#[derive(Clone, Debug, PartialEq)]
enum Report {
    Emitted { estimate: Rgb, w: f32, depth: u32 },
    Escaped { estimate: Rgb, w: f32 },
    Scatter,
    Connect { beta: Rgb, depth: u32 },
    Extended(Option<f32>, bool),
}

#[derive(Default)]
struct Recorder {
    reports: Vec<Report>,
}

impl PathSink for Recorder {
    type Trail = ();
    type Pending = ();

    fn emitted<S>(&mut self, _: &mut (), s: &WalkState<S>, _: &SurfaceHit, estimate: Rgb, w: f32) {
        let depth = s.depth;
        self.reports.push(Report::Emitted { estimate, w, depth });
    }
    fn escaped<S>(&mut self, _: &mut (), _: &WalkState<S>, _: &Scene, estimate: Rgb, w: f32) {
        self.reports.push(Report::Escaped { estimate, w });
    }
    fn scatter(&mut self, _: &mut (), _: &SurfaceHit) {
        self.reports.push(Report::Scatter);
    }
    fn connect(&mut self, _: &mut (), c: &ConnectionEvent) -> Option<()> {
        let (beta, depth) = (c.beta, c.depth);
        self.reports.push(Report::Connect { beta, depth });
        Some(())
    }
    fn extended(&mut self, _: &mut (), _: &Bsdf, e: &Extension) {
        self.reports
            .push(Report::Extended(e.survived, e.sampled.is_some()));
    }
    fn answered(&mut self, _: &Scene, _: (), _: bool) {}
}

fn settings(path_depth: u32, termination: TerminationDistribution) -> PathSettings {
    let mut s = PathSettings::from_params(&Params::from_slice(&[])).unwrap();
    s.path_depth = path_depth;
    s.termination = TerminationSchedule::new(termination, path_depth);
    s
}

/// A path arriving along `dir` from `from`, drawn by `step`.
fn arriving(from: Vec3, to: Vec3, step: Step, seed: u64) -> Walker<Rng, ()> {
    let mut state = WalkState::start(
        Rng::new(seed, 0),
        Ray::new(from, (to - from).normalize(), f32::INFINITY),
    );
    state.step = step;
    Walker { state, trail: () }
}

/// Runs the step at `hit`; returns whether the path goes on, the reports, the branches and
/// the number of shadow rays.
fn run(
    settings: &PathSettings,
    path: &mut Walker<Rng, ()>,
    hit: &SurfaceHit,
) -> (bool, Vec<Report>, usize, usize) {
    let scene = scene();
    let mut sink = Recorder::default();
    let (mut rays, mut pending, mut branches) = (Vec::new(), Vec::new(), Vec::new());
    let ahead = VertexAhead::of(&path.state);
    let going = step::vertex(
        &scene,
        settings,
        path,
        0,
        hit,
        &mut sink,
        (&mut rays, &mut pending),
        &mut branches,
        ahead,
    );
    assert_eq!(rays.len(), pending.len());
    (going, sink.reports, branches.len(), rays.len())
}

/// An emitter hit after a smooth step is weighed against the light sample that could have
/// drawn it (power heuristic of the two solid-angle densities); after the eye or a Dirac
/// step it has one technique, weight 1.
#[test]
fn emitter_hits_are_weighted_by_the_power_heuristic() {
    let scene = scene();
    let from = Vec3::new(0.3, 0.0, 0.2);
    let lamp = lamp_hit();
    let pdf_light = area_to_solid_angle(scene.lights.pdf_area(0), from, lamp.p, lamp.ng);
    for (step, want) in [
        (Step::Smooth(0.4), power_heuristic(0.4, pdf_light)),
        (Step::Dirac(1.0), 1.0),
        (Step::Eye, 1.0),
    ] {
        let mut path = arriving(from, lamp.p, step, 1);
        path.state.beta = Rgb::splat(0.5);
        let (_, reports, _, _) = run(
            &settings(8, TerminationDistribution::Bxdf),
            &mut path,
            &lamp,
        );
        let Report::Emitted { estimate, w, depth } = reports[0].clone() else {
            panic!("no emission first: {reports:?}");
        };
        assert_eq!((w, depth), (want, 0), "{step:?}");
        assert_eq!(estimate, Rgb::splat(0.5) * Rgb::splat(LAMP) * want);
        assert!(w < 1.0 || step.mis_density().is_none());
    }
}

/// An escaped ray reports the sky, weighted against the environment's light sample after a
/// smooth step.
#[test]
fn escapes_report_the_environment() {
    let scene = scene();
    let dir = Vec3::new(0.2, 1.0, 0.1).normalize();
    for (step, want) in [
        (
            Step::Smooth(0.3),
            power_heuristic(0.3, scene.lights.pdf_environment(dir)),
        ),
        (Step::Eye, 1.0),
    ] {
        let mut path = arriving(Vec3::ZERO, dir, step, 2);
        let mut sink = Recorder::default();
        step::escape(&scene, &mut path, &mut sink);
        assert_eq!(
            sink.reports,
            vec![Report::Escaped {
                estimate: Rgb::splat(SKY) * want,
                w: want
            }]
        );
    }
}

/// A mirror seen from the eye does not use up a lighting layer (virtual depth), a diffuse
/// vertex does; both count as a physical bounce.
#[test]
fn dirac_vertices_seen_from_the_eye_keep_lighting_depth_zero() {
    let s = settings(8, TerminationDistribution::Bxdf);
    let mirror = hit(Vec3::ZERO, Vec3::Y, MIRROR, -1, 1.0);
    let mut path = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Eye, 3);
    let (going, reports, _, _) = run(&s, &mut path, &mirror);
    assert!(going);
    assert_eq!((path.state.depth, path.state.physical), (0, 1));
    // No light connection from a Dirac vertex; its sample is a Dirac step.
    assert!(!reports.iter().any(|r| matches!(r, Report::Connect { .. })));
    assert!(matches!(path.state.step, Step::Dirac(_)));

    let mut path = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Eye, 3);
    let (_, reports, _, shadows) = run(&s, &mut path, &floor_hit());
    assert_eq!((path.state.depth, path.state.physical), (1, 1));
    assert_eq!(reports[0], Report::Scatter);
    assert_eq!(shadows, 1, "the lamp is above the floor: one shadow ray");
    assert_eq!(
        reports[1],
        Report::Connect {
            beta: Rgb::ONE,
            depth: 1
        }
    );
}

/// At the deepest layer the path cannot go on: the vertex still connects and traces its
/// BSDF sample, for emission only (`last`), with no roulette; the next vertex only reports
/// its emission. Past the path depth nothing scatters.
#[test]
fn the_last_vertex_connects_and_samples_for_emission_only() {
    let s = settings(1, TerminationDistribution::Equi);
    let mut path = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Eye, 4);
    let (going, reports, _, _) = run(&s, &mut path, &floor_hit());
    assert!(path.state.last);
    assert!(going, "the BSDF sample is traced");
    assert_eq!(*reports.last().unwrap(), Report::Extended(None, true));

    let lamp = lamp_hit();
    let (going, reports, _, shadows) = run(&s, &mut path, &lamp);
    assert!(!going);
    assert!(matches!(reports[..], [Report::Emitted { depth: 1, .. }]));
    assert_eq!(shadows, 0);

    let mut deep = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Smooth(1.0), 4);
    deep.state.depth = 1;
    let (going, reports, _, _) = run(&s, &mut deep, &floor_hit());
    assert!(!going && reports.is_empty(), "{reports:?}");
}

/// The physical cap: a vertex at `max_ray_depth` is the path's last.
#[test]
fn max_ray_depth_makes_a_vertex_the_last() {
    let mut s = settings(8, TerminationDistribution::Bxdf);
    s.max_ray_depth = 3;
    let mut path = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Eye, 5);
    path.state.physical = 2;
    run(&s, &mut path, &floor_hit());
    assert_eq!(path.state.physical, 3);
    assert!(path.state.last);
}

/// A survivor of the roulette has β divided by 1 − T_k, and its connection was made with β
/// before the roulette. `equi` at N = 4 stops at lighting depth 1 with T = 1/4.
#[test]
fn roulette_survivors_are_divided_by_the_survival_probability() {
    let s = settings(4, TerminationDistribution::Equi);
    let mut survived = 0;
    for seed in 0..64 {
        let mut path = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Eye, seed);
        let (_, reports, _, _) = run(&s, &mut path, &floor_hit());
        assert!(reports.contains(&Report::Connect {
            beta: Rgb::ONE,
            depth: 1
        }));
        match reports.last().unwrap() {
            Report::Extended(Some(t), true) => {
                assert_eq!(*t, 0.25);
                survived += 1;
                // Lambert: f cos / pdf = albedo, so β = ½ / (1 − ¼).
                let want = 0.5 / 0.75;
                assert!((path.state.beta.max_component() - want).abs() < 1e-6);
            }
            Report::Extended(None, false) => {}
            other => panic!("unexpected {other:?}"),
        }
    }
    // 64 tries at survival ¾: 48 expected; far from 0 and 64.
    assert!((30..=60).contains(&survived), "{survived}");
}

/// With k branches the first lighting vertex reports k connections, each with β/k, and hands
/// back the branches that survived (up to k − 1); deeper vertices do not split again.
#[test]
fn branches_split_once_at_the_first_lighting_vertex() {
    let mut s = settings(8, TerminationDistribution::Bxdf);
    s.branches = 4;
    let mut path = arriving(Vec3::new(0.0, 1.0, 1.0), Vec3::ZERO, Step::Eye, 6);
    let (_, reports, branches, shadows) = run(&s, &mut path, &floor_hit());
    let connects: Vec<_> = reports
        .iter()
        .filter(|r| matches!(r, Report::Connect { .. }))
        .collect();
    assert_eq!(connects.len(), 4);
    assert_eq!(shadows, 4);
    for c in connects {
        assert_eq!(
            *c,
            Report::Connect {
                beta: Rgb::splat(0.25),
                depth: 1
            }
        );
    }
    assert!(branches <= 3);
    assert_eq!(
        reports
            .iter()
            .filter(|r| matches!(r, Report::Extended(..)))
            .count(),
        4
    );
    let mut deeper = path.clone();
    let (_, reports, branches, _) = run(&s, &mut deeper, &floor_hit());
    assert_eq!(branches, 0);
    assert_eq!(
        reports
            .iter()
            .filter(|r| matches!(r, Report::Connect { .. }))
            .count(),
        1
    );
}
