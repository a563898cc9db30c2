//! What the walker reports, and to whom: the [`PathSink`] of one path.
//!
//! The step ([`super::step`]) calls the sink at fixed points of a vertex, always in this
//! order: [`PathSink::arrive`], [`PathSink::emitted`], [`PathSink::has_room`],
//! [`PathSink::scatter`], [`PathSink::connect`] (zero or more times: one per branch where a
//! path splits), [`PathSink::extended`]; an escaped ray calls [`PathSink::escaped`]. A light
//! connection's shadow ray is traced later, in a batch; its answer comes back through
//! [`PathSink::answered`] with the record `connect` returned.

use super::WalkState;
use crate::shading::{Connection, Shading};
use flowlight_core::bsdf::{Bsdf, BsdfAt, BsdfSample};
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::LightSample;
use flowlight_core::path::NodeType;
use flowlight_core::Rgb;
use flowlight_sdk::Scene;
use std::borrow::Cow;

/// A light connection made at a vertex, before its shadow ray is traced.
pub struct ConnectionEvent<'a, 'b> {
    pub scene: &'a Scene<'b>,
    /// The vertex's BSDF: borrowed where it is its material's table entry
    /// ([`Scene::constant_bsdf`]; it can be evaluated again after the shadow ray), owned
    /// where it was built for this hit.
    pub bsdf: &'a Cow<'a, Bsdf>,
    /// The BSDF at the vertex's outgoing direction.
    pub at: &'a BsdfAt<'a>,
    pub hit: &'a SurfaceHit,
    pub shading: &'a Shading,
    pub light: &'a LightSample,
    pub conn: &'a Connection,
    /// β before the vertex's roulette (the connection is made whether or not the path goes on).
    pub beta: Rgb,
    /// The vertex's lighting depth: the layer the connection adds to.
    pub depth: u32,
}

/// What the rest of a vertex did after its light connection: the roulette and the BSDF
/// sample ([`super::step::extend`]).
#[derive(Clone, Copy, Debug)]
pub struct Extension {
    /// The termination probability T_k the path survived (β was divided by 1 − T_k); `None`
    /// where no roulette was played (T_k = 0, or the vertex is the path's last).
    pub survived: Option<f32>,
    /// The BSDF sample's node type and the first number of its pair (which chose the
    /// component, [`Bsdf::choose_component`]), where a sample was drawn.
    pub sampled: Option<(NodeType, f32)>,
    /// The BSDF sample the path went on with (a light subpath re-weights it with the
    /// adjoint BSDF, `crate::bidir`); `None` where the path stopped.
    pub sample: Option<BsdfSample>,
}

/// Where one path's reports go. Every method but [`PathSink::connect`] and
/// [`PathSink::answered`] defaults to doing nothing, so a sink pays only for what it uses.
pub trait PathSink {
    /// What the sink keeps per path beside the walker's state, carried with the path (and
    /// cloned with it where a path splits into branches).
    type Trail: Clone;
    /// A light connection waiting for its shadow ray.
    type Pending: Copy;

    /// The path leaves the eye along `ray`.
    #[inline(always)]
    fn begin(&mut self, _trail: &mut Self::Trail, _scene: &Scene, _ray: &Ray) {}

    /// The path reached `hit` by `state.step` from `state.prev_p` (before its emission).
    #[inline(always)]
    fn arrive<S>(&mut self, _trail: &mut Self::Trail, _state: &WalkState<S>, _hit: &SurfaceHit) {}

    /// Emission found at `hit`: its estimate β L_e w and MIS weight `w`, at `state.depth`.
    fn emitted<S>(
        &mut self,
        trail: &mut Self::Trail,
        state: &WalkState<S>,
        hit: &SurfaceHit,
        estimate: Rgb,
        w: f32,
    );

    /// The ray `state.ray` escaped: the environment's estimate β L_e w and MIS weight `w`.
    fn escaped<S>(
        &mut self,
        trail: &mut Self::Trail,
        state: &WalkState<S>,
        scene: &Scene,
        estimate: Rgb,
        w: f32,
    );

    /// Whether the path may scatter at one more vertex (a sink that stores vertices may run
    /// out of room).
    #[inline(always)]
    fn has_room(&self) -> bool {
        true
    }

    /// The path scatters at `hit` (it is within both depths): before its light connection.
    #[inline(always)]
    fn scatter(&mut self, _trail: &mut Self::Trail, _hit: &SurfaceHit) {}

    /// A light connection of the vertex: the record to answer once its shadow ray is traced,
    /// or `None` where it carries nothing (its shadow ray is then not traced).
    fn connect(
        &mut self,
        trail: &mut Self::Trail,
        event: &ConnectionEvent,
    ) -> Option<Self::Pending>;

    /// The vertex's roulette and BSDF sample, after its connection.
    #[inline(always)]
    fn extended(&mut self, _trail: &mut Self::Trail, _bsdf: &Bsdf, _extension: &Extension) {}

    /// The shadow ray of `pending` came back: `visible` where nothing blocked it.
    fn answered(&mut self, scene: &Scene, pending: Self::Pending, visible: bool);
}
