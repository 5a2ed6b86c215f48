//! Evaluation of the kinematic error model: predicted target position (and orientation) in the tracker
//! frame, and its analytic Jacobian with respect to a step of every parameter.
//!
//! # Evaluation
//! With `Hᵢ` the home pose of joint frame `i` (base frame, q = 0) and `Aᵢ` its local unit screw, the real
//! screw is `Sᵢ' = Ad(Gᵢ Hᵢ) Aᵢ`, so `exp([Sᵢ'] θ) = Hᵢ' exp([Aᵢ] θ) Hᵢ'⁻¹` with `Hᵢ' = Gᵢ Hᵢ`. The product
//! collapses into the cheap chain of local joint frames
//!
//! ```text
//! F₀ = T_tracker_base,   Fᵢ = Fᵢ₋₁ Oᵢ exp([Aᵢ](qᵢ + δqᵢ)),   Oᵢ = H'ᵢ₋₁⁻¹ Hᵢ'  (H'₀ = I)
//! T_tracker_flange = Fₙ H'ₙ⁻¹ M,   p_tracker = T_tracker_flange p_flange
//! ```
//!
//! prepared once per parameter point ([`Chain::update`]). With several measurement campaigns, `F₀` is the
//! row's campaign's `T_tracker_base` and `p_flange` its target ([`Chain::forward_in`]).
//!
//! # Jacobian
//! With `Pᵢ = T_tracker_base E₁ ⋯ Eᵢ = Fᵢ Hᵢ'⁻¹` (tracker frame; `Eᵢ = exp([Sᵢ'] θᵢ)`, `P₀ = T_tracker_base`),
//! a step `Δξᵢ` of joint `i`'s error twist, `Sᵢ' ← Ad(exp[Δξᵢ]) Sᵢ'`, changes `Eᵢ` into
//! `exp([Δξᵢ]) Eᵢ exp(−[Δξᵢ])`, i.e. moves the flange by the tracker-frame twist
//! `(Ad(Pᵢ₋₁) − Ad(Pᵢ)) Δξᵢ` to first order. A twist `[ω; v]` moves the point `p` by `ω × p + v`, so the
//! 3×6 block of `∂p_tracker/∂ξᵢ` is `A(Pᵢ₋₁) − A(Pᵢ)` with `A(R, t) = [ −[p − t] R , R ]`, and the
//! rotation block is `[Rᵢ₋₁ − Rᵢ , 0]`. A zero offset moves the flange by the joint's current screw
//! (`ωᵢ × (p − oᵢ)` for a revolute joint with axis `ωᵢ` through `oᵢ`, `ωᵢ` for a prismatic one), the
//! base twist `β` by `[−[p], I]`, the target position by `R_tracker_flange`, and the target rotation
//! `ρ` (target frame) turns the target by `R_tracker_target ρ`.

use crate::lie3::{exp_rotation, left_jacobian};
use crate::model::params::{KinematicParams, ParamLayout};
use nalgebra::{Matrix3, Vector3};
use sim::lie::{Pose, pose_from};
use sim::{Joint, JointKind, Model};

/// The kinematic error model prepared at one parameter point: immutable during evaluations, which write
/// into a [`ChainScratch`].
#[derive(Clone, Debug)]
pub struct Chain {
    kind: Vec<JointKind>,
    /// Unit axis `aᵢ` in joint frame `i`.
    axis: Vec<Vector3<f64>>,
    /// `Oᵢ`: joint frame `i` in joint frame `i − 1` at zero angle (m).
    origin: Vec<Pose>,
    /// Folded Rodrigues terms of `Oᵢ`'s rotation times the joint rotation ([`Joint::rotation_terms`]).
    terms: Vec<[Matrix3<f64>; 3]>,
    /// `H'ᵢ⁻¹` (m).
    home_inv: Vec<Pose>,
    /// `H'ₙ⁻¹ M`: flange in the last joint frame (m).
    flange_offset: Pose,
    /// The nominal home pose `Hᵢ` of each joint frame (base frame, m).
    home: Vec<Pose>,
    /// The nominal flange at q = 0, `M` (base frame, m).
    home_flange: Pose,
    zero_offset: Vec<f64>,
    /// `T_tracker_base` per campaign (m).
    bases: Vec<Pose>,
    /// The target position per campaign (flange frame, m).
    targets: Vec<Vector3<f64>>,
    /// The target orientation per campaign (flange frame), with orientation parameters.
    target_rotations: Vec<Option<Matrix3<f64>>>,
}

/// Per-evaluation workspace of a [`Chain`]: made once, reused without allocating.
#[derive(Clone, Debug)]
pub struct ChainScratch {
    /// `Fᵢ`: joint frame `i` in the tracker frame at the last configuration (m).
    pub frames: Vec<Pose>,
    /// `T_tracker_flange` at the last configuration (m).
    pub t_tracker_flange: Pose,
    /// Predicted target position, tracker frame (m).
    pub p_tracker: Vector3<f64>,
    /// Predicted target orientation, tracker frame (identity without orientation parameters).
    pub r_tracker_target: Matrix3<f64>,
    /// Whether the last evaluation bent the chain ([`Chain::forward_bent`]).
    pub bent: bool,
    /// With a bent chain: each joint's axis, tracker frame, before its bend (the frames then carry
    /// the bend after the joint's rotation).
    pub axes: Vec<Vector3<f64>>,
    /// Campaign (index) of the last configuration: whose tracker frame the above are in.
    pub campaign: usize,
}

impl ChainScratch {
    /// Workspace for a chain of `n` joints.
    pub fn new(n: usize) -> Self {
        ChainScratch {
            frames: vec![Pose::identity(); n],
            t_tracker_flange: Pose::identity(),
            p_tracker: Vector3::zeros(),
            r_tracker_target: Matrix3::identity(),
            bent: false,
            axes: vec![Vector3::zeros(); n],
            campaign: 0,
        }
    }
}

impl Chain {
    /// Prepares `model` with the error parameters `params`.
    pub fn new(model: &Model, params: &KinematicParams) -> Self {
        let n = model.nq();
        let mut c = Chain {
            kind: model.joints().iter().map(|j| j.kind).collect(),
            axis: model.joints().iter().map(|j| j.axis).collect(),
            origin: vec![Pose::identity(); n],
            terms: vec![[Matrix3::zeros(); 3]; n],
            home_inv: vec![Pose::identity(); n],
            flange_offset: Pose::identity(),
            home: model.joints().iter().map(|j| j.home).collect(),
            home_flange: model.home_flange(),
            zero_offset: vec![0.0; n],
            bases: Vec::new(),
            targets: Vec::new(),
            target_rotations: Vec::new(),
        };
        c.update(model, params);
        c
    }

    /// Whether joint `i` (0-based) turns (revolute or continuous) rather than slides.
    #[inline]
    pub fn is_rotational(&self, i: usize) -> bool {
        self.kind[i].is_rotational()
    }

    /// Number of joints.
    #[inline]
    pub fn nq(&self) -> usize {
        self.kind.len()
    }

    /// Number of campaigns (tracker registrations).
    #[inline]
    pub fn n_campaigns(&self) -> usize {
        self.bases.len()
    }

    /// `T_tracker_base` of campaign `c` (m).
    #[inline]
    pub fn t_tracker_base(&self, c: usize) -> &Pose {
        &self.bases[c]
    }

    /// Re-prepares for new parameters of the same robot, without allocating (unless the number of
    /// campaigns changes).
    ///
    /// # Panics
    /// If `params` has a different joint count than `model`.
    pub fn update(&mut self, model: &Model, params: &KinematicParams) {
        assert_eq!(params.joint_error.len(), model.nq(), "joint count");
        self.update_params(params);
    }

    /// [`Chain::update`] for the robot this chain was made for, without allocating: a chain per
    /// evaluation thread can follow parameters that change from row to row.
    ///
    /// # Panics
    /// If `params` has a different joint count.
    pub fn update_params(&mut self, params: &KinematicParams) {
        assert_eq!(params.joint_error.len(), self.nq(), "joint count");
        let mut prev_inv = Pose::identity();
        for i in 0..self.nq() {
            let home = params.joint_error[i] * self.home[i];
            let origin = prev_inv * home;
            self.origin[i] = origin;
            self.terms[i] = Joint::rotation_terms_for(&origin, &self.axis[i]);
            prev_inv = home.inverse();
            self.home_inv[i] = prev_inv;
        }
        self.flange_offset = prev_inv * self.home_flange;
        self.zero_offset.copy_from_slice(&params.zero_offset);
        let k = params.n_campaigns();
        self.bases.resize(k, Pose::identity());
        self.targets.resize(k, Vector3::zeros());
        self.target_rotations.resize(k, None);
        for c in 0..k {
            self.bases[c] = *params.t_tracker_base_of(c);
            self.targets[c] = *params.p_flange_target_of(c);
            self.target_rotations[c] = params.r_flange_target_of(c).copied();
        }
    }

    /// Evaluates the chain at the controller's joint values `q` (rad or m) into `s`, in the first
    /// campaign's tracker frame.
    ///
    /// # Panics
    /// If `q.len()` differs from the joint count.
    #[inline]
    pub fn forward(&self, s: &mut ChainScratch, q: &[f64]) {
        self.forward_in(s, q, 0);
    }

    /// Evaluates the chain at the controller's joint values `q` (rad or m) into `s`, in campaign
    /// `campaign`'s tracker frame with its target.
    ///
    /// # Panics
    /// If `q.len()` differs from the joint count or the campaign is out of range.
    #[inline]
    pub fn forward_in(&self, s: &mut ChainScratch, q: &[f64], campaign: usize) {
        self.evaluate(s, q, campaign, None);
    }

    /// [`Chain::forward_in`] with everything beyond joint `i` turned about the joint's origin by the
    /// rotation vector `bend[i]` (rad, joint frame `i`: the child link's frame, turning with the
    /// joint), after the joint's own motion: `Fᵢ = Fᵢ₋₁ Oᵢ exp([Aᵢ] θᵢ) exp([φᵢ])` (link deflection).
    /// The bend is the robot's, the same in every campaign; `campaign` only selects the tracker frame
    /// (`F₀ = T_tracker_base` of the campaign) and the target.
    /// The joint-twist columns of the Jacobian keep their form (they depend on `Fᵢ` only through
    /// `Pᵢ = Fᵢ H'ᵢ⁻¹`); the zero-offset column turns about the axis before the bend, which
    /// [`ChainScratch::axes`] keeps; [`Chain::bend_axis`] gives the bend's own column.
    ///
    /// # Panics
    /// If `q.len()` or `bend.len()` differs from the joint count or the campaign is out of range.
    pub fn forward_bent(
        &self,
        s: &mut ChainScratch,
        q: &[f64],
        campaign: usize,
        bend: &[Vector3<f64>],
    ) {
        assert_eq!(bend.len(), self.nq(), "one bend per joint");
        self.evaluate(s, q, campaign, Some(bend));
    }

    #[inline(always)]
    fn evaluate(
        &self,
        s: &mut ChainScratch,
        q: &[f64],
        campaign: usize,
        bend: Option<&[Vector3<f64>]>,
    ) {
        assert_eq!(q.len(), self.nq(), "joint vector length");
        let base = &self.bases[campaign];
        s.campaign = campaign;
        let mut r = *base.rotation.matrix();
        let mut p = base.translation.vector;
        for (i, &qi) in q.iter().enumerate() {
            let theta = qi + self.zero_offset[i];
            let o = &self.origin[i];
            p += r * o.translation.vector;
            match self.kind[i] {
                JointKind::Revolute | JointKind::Continuous => {
                    let (sn, cs) = sim::trig::sin_cos(theta);
                    let [k0, k1, k2] = &self.terms[i];
                    r *= k0 + k1 * cs + k2 * sn;
                }
                JointKind::Prismatic => {
                    r *= o.rotation.matrix();
                    p += r * (self.axis[i] * theta);
                }
            }
            if let Some(b) = bend {
                s.axes[i] = r * self.axis[i];
                if b[i] != Vector3::zeros() {
                    r *= exp_rotation(&b[i]);
                }
            }
            s.frames[i] = pose_from(r, p);
        }
        s.bent = bend.is_some();
        s.t_tracker_flange = s.frames[self.nq() - 1] * self.flange_offset;
        s.p_tracker = (s.t_tracker_flange * nalgebra::Point3::from(self.targets[campaign])).coords;
        s.r_tracker_target = match &self.target_rotations[campaign] {
            Some(rf) => s.t_tracker_flange.rotation.matrix() * rf,
            None => Matrix3::identity(),
        };
    }

    /// The tracker-frame rotation `ω` (rad per unit) by which a unit step of the bend of joint `i` along
    /// `local` (joint frame) turns everything beyond the joint, and the point `oᵢ` (tracker frame, m) it
    /// turns about, at the last [`Chain::forward_bent`] evaluation with bend `phi` at that joint:
    /// `exp([φ + δ]) = exp([φ]) exp([J_r(φ) δ])` with the right Jacobian `J_r(φ) = J_l(φ)ᵀ`, so
    /// `ω = R(Fᵢ) J_l(φ)ᵀ local`. A point `p` beyond the joint moves by `ω × (p − oᵢ)`.
    pub fn bend_axis(
        &self,
        s: &ChainScratch,
        i: usize,
        local: &Vector3<f64>,
        phi: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let f = &s.frames[i];
        (
            f.rotation * (left_jacobian(phi).tr_mul(local)),
            f.translation.vector,
        )
    }

    /// Joint `i`'s axis (tracker frame) at the last evaluation: the frame's axis, or with a bent chain
    /// the axis before the bend.
    #[inline]
    pub fn axis_now(&self, s: &ChainScratch, i: usize) -> Vector3<f64> {
        if s.bent {
            s.axes[i]
        } else {
            s.frames[i].rotation.matrix() * self.axis[i]
        }
    }

    /// `∂p_tracker/∂qᵢ` (tracker frame; m/rad, or m/m for a prismatic joint) at the last
    /// [`Chain::forward`] configuration: how the target moves per unit of joint `i` (0-based), the
    /// zero-offset column of [`Chain::position_jacobian`].
    #[inline]
    pub fn joint_direction(&self, s: &ChainScratch, i: usize) -> Vector3<f64> {
        let f = &s.frames[i];
        let w = self.axis_now(s, i);
        if self.kind[i].is_rotational() {
            w.cross(&(s.p_tracker - f.translation.vector))
        } else {
            w
        }
    }

    /// Jacobian of the predicted target position (tracker frame, m per parameter unit) at the last
    /// [`Chain::forward`] configuration, row-major into `out` (3 rows of `layout.len()`). The columns
    /// of the campaigns other than the row's are zero.
    pub fn position_jacobian(&self, s: &ChainScratch, layout: &ParamLayout, out: &mut [f64]) {
        self.position_jacobian_of(s, layout, true, out);
    }

    /// [`Chain::position_jacobian`], with the joint columns (error twists and zero offsets) only when
    /// `joints` (else they are left as they are): a fit of the registration alone needs no more.
    pub fn position_jacobian_of(
        &self,
        s: &ChainScratch,
        layout: &ParamLayout,
        joints: bool,
        out: &mut [f64],
    ) {
        let np = layout.len();
        debug_assert_eq!(out.len(), 3 * np);
        if layout.n_campaigns() > 1 {
            for row in 0..3 {
                out[row * np + layout.base()..row * np + layout.kinematic_len()].fill(0.0);
            }
        }
        if joints {
            self.joint_columns(s, layout, out);
        }
        self.registration_columns(s, layout, out);
    }

    /// The joint columns of [`Chain::position_jacobian_of`].
    fn joint_columns(&self, s: &ChainScratch, layout: &ParamLayout, out: &mut [f64]) {
        let np = layout.len();
        let p = s.p_tracker;
        let base = &self.bases[s.campaign];
        let mut prev_r = *base.rotation.matrix();
        let mut prev_a = rot_block(&prev_r, &(p - base.translation.vector));
        for i in 0..self.nq() {
            let f = &s.frames[i];
            let fr = f.rotation.matrix();
            let hinv = &self.home_inv[i];
            let cur_r = fr * hinv.rotation.matrix();
            let cur_t = f.translation.vector + fr * hinv.translation.vector;
            let cur_a = rot_block(&cur_r, &(p - cur_t));
            let k0 = layout.joint_twist(i);
            for row in 0..3 {
                let o = &mut out[row * np + k0..row * np + k0 + 6];
                for c in 0..3 {
                    o[c] = prev_a[(row, c)] - cur_a[(row, c)];
                    o[3 + c] = prev_r[(row, c)] - cur_r[(row, c)];
                }
            }
            let col = self.joint_direction(s, i);
            let kz = layout.zero_offset(i);
            for row in 0..3 {
                out[row * np + kz] = col[row];
            }
            prev_r = cur_r;
            prev_a = cur_a;
        }
    }

    /// The registration (base twist and target) columns of [`Chain::position_jacobian_of`].
    fn registration_columns(&self, s: &ChainScratch, layout: &ParamLayout, out: &mut [f64]) {
        let np = layout.len();
        let p = s.p_tracker;
        let campaign = s.campaign;
        let kb = layout.campaign_base(campaign);
        let kt = layout.campaign_target_position(campaign);
        let rf = s.t_tracker_flange.rotation.matrix();
        // [−[p], I]: column c of −[p] is e_c × p.
        let ec_cross_p = [
            Vector3::new(0.0, -p.z, p.y),
            Vector3::new(p.z, 0.0, -p.x),
            Vector3::new(-p.y, p.x, 0.0),
        ];
        for row in 0..3 {
            let o = &mut out[row * np + kb..row * np + kb + 6];
            for c in 0..3 {
                o[c] = ec_cross_p[c][row];
                o[3 + c] = if row == c { 1.0 } else { 0.0 };
            }
            for c in 0..3 {
                out[row * np + kt + c] = rf[(row, c)];
            }
            if let Some(ko) = layout.campaign_target_orientation(campaign) {
                for a in 0..3 {
                    out[row * np + ko + a] = 0.0;
                }
            }
        }
    }

    /// Jacobian of the predicted target orientation at the last [`Chain::forward`] configuration: the
    /// tracker-frame rotation vector (rad) by which each parameter unit turns the target, row-major into
    /// `out` (3 rows of `layout.len()`). Only meaningful with orientation parameters.
    pub fn orientation_jacobian(&self, s: &ChainScratch, layout: &ParamLayout, out: &mut [f64]) {
        let np = layout.len();
        debug_assert_eq!(out.len(), 3 * np);
        out.fill(0.0);
        let campaign = s.campaign;
        let mut prev_r = *self.bases[campaign].rotation.matrix();
        for i in 0..self.nq() {
            let fr = s.frames[i].rotation.matrix();
            let cur_r = fr * self.home_inv[i].rotation.matrix();
            let k0 = layout.joint_twist(i);
            for row in 0..3 {
                for c in 0..3 {
                    out[row * np + k0 + c] = prev_r[(row, c)] - cur_r[(row, c)];
                }
            }
            if self.kind[i].is_rotational() {
                let w = self.axis_now(s, i);
                let kz = layout.zero_offset(i);
                for row in 0..3 {
                    out[row * np + kz] = w[row];
                }
            }
            prev_r = cur_r;
        }
        let kb = layout.campaign_base(campaign);
        for row in 0..3 {
            out[row * np + kb + row] = 1.0;
        }
        if let Some(ko) = layout.campaign_target_orientation(campaign) {
            for row in 0..3 {
                for c in 0..3 {
                    out[row * np + ko + c] = s.r_tracker_target[(row, c)];
                }
            }
        }
    }
}

/// `−[d] R`: column `c` is `R_c × d`.
#[inline]
fn rot_block(r: &Matrix3<f64>, d: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::from_columns(&[
        r.column(0).cross(d),
        r.column(1).cross(d),
        r.column(2).cross(d),
    ])
}
