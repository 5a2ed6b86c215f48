//! Joint compliance settled by the rapier physics engine instead of the analytic Newton solve: the
//! compliance stage of [`super::Truth`] when it was made with [`super::ComplianceSolver::Rapier`].
//!
//! # What goes into the engine
//!
//! The same physical robot as the analytic stage ([`super::joint_compliance`]): the *real* geometry
//! (thermally grown links at the measurement's `ΔT`, kinematic error twists, base and tool errors) with
//! the nominal inertials attached to the real joint frames, the payload at the real flange, gravity in
//! the nominal base frame. `Chain::model_at` turns that geometry into a
//! [`Model`], and [`RapierArm::new`] builds the multibody from it; the motor-side anchor of every
//! joint spring is the chain angle after zero offset, zero drift and backlash (`φ − s`, see
//! [`super`]). The engine returns the link-side chain angles at rest and `T_base_flange` from its own
//! forward kinematics; the target is that flange pose times the reflector offset.
//!
//! # Preparation per thread
//!
//! An arm depends on `ΔT`, the payload and gravity; building one (a rapier world with one body per
//! link) costs about as much as a settle. Each [`super::TruthScratch`] keeps the last
//! [`CACHE_ENTRIES`] arms it built, keyed by the exact bits of those inputs, so a campaign with a few
//! payloads at one temperature builds a few arms per thread. A settle starts from rest at its
//! commanded pose and resets the whole engine state, so its result does not depend on which arm was
//! cached or what it settled before: same inputs, same bits, whatever the thread count.

use super::chain::Chain;
use crate::error::Result;
use crate::lie::Pose;
use crate::model::Model;
use crate::rapier_truth::{RapierArm, RapierWorkspace};
use crate::springs::SettleOptions;
use crate::statics::Payload;
use nalgebra::Vector3;

/// Arms kept per thread (see the module docs).
pub const CACHE_ENTRIES: usize = 4;

/// What the rapier compliance stage needs besides the chain: the nominal model (names, kinds and
/// inertials), the joint stiffness and the settle options.
#[derive(Clone, Debug)]
pub(crate) struct RapierCompliance {
    /// Identity of the owning truth, so a scratch used with another truth never reuses its arms.
    id: u64,
    nominal: Model,
    /// Stiffness per joint (N m/rad or N/m; infinite = rigid).
    stiffness: Vec<f64>,
    /// Deflection compliance `[c_u, c_v]` per joint (rad/(N m); all 0 without link deflection).
    deflection: Vec<[f64; 2]>,
    options: SettleOptions,
}

/// Exact bits of `(ΔT, payload mass, payload centre of mass, gravity)`.
type Key = [u64; 8];

struct Entry {
    id: u64,
    key: Key,
    arm: RapierArm,
    ws: RapierWorkspace,
}

/// Per-thread cache of prepared rapier arms. Cloning gives an empty cache (a settle does not depend on
/// the cache, see the module docs).
#[derive(Default)]
pub(crate) struct RapierCache {
    entries: Vec<Entry>,
}

impl Clone for RapierCache {
    fn clone(&self) -> Self {
        RapierCache::default()
    }
}

impl std::fmt::Debug for RapierCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RapierCache")
            .field("arms", &self.entries.len())
            .finish()
    }
}

fn next_id() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

impl RapierCompliance {
    /// Checks that an arm of `nominal` with `stiffness_nm_per_rad` and `options` can be built (length
    /// and sign of the stiffness, inertials, options) and keeps what later builds need.
    pub fn new(
        nominal: &Model,
        stiffness_nm_per_rad: &[f64],
        options: SettleOptions,
    ) -> Result<RapierCompliance> {
        let none = vec![[0.0; 2]; nominal.nq()];
        RapierCompliance::with_deflection(nominal, stiffness_nm_per_rad, &none, options)
    }

    /// As [`RapierCompliance::new`], the arms with link-deflection hinges of compliance
    /// `deflection_rad_per_nm` (`[c_u, c_v]` per joint, rad/(N m); see
    /// [`RapierArm::with_deflection`]).
    pub fn with_deflection(
        nominal: &Model,
        stiffness_nm_per_rad: &[f64],
        deflection_rad_per_nm: &[[f64; 2]],
        options: SettleOptions,
    ) -> Result<RapierCompliance> {
        RapierArm::with_deflection(
            nominal,
            stiffness_nm_per_rad,
            deflection_rad_per_nm,
            None,
            &Vector3::from(crate::statics::DEFAULT_GRAVITY),
            options,
        )?;
        Ok(RapierCompliance {
            id: next_id(),
            nominal: nominal.clone(),
            stiffness: stiffness_nm_per_rad.to_vec(),
            deflection: deflection_rad_per_nm.to_vec(),
            options,
        })
    }

    /// The settle options.
    pub fn options(&self) -> &SettleOptions {
        &self.options
    }

    /// Settles the real robot `chain` at temperature offset `dt` (K) with `payload` and `gravity`
    /// (base frame, m/s²), springs anchored at the chain angles `q_motor` (rad or m). Writes the
    /// link-side chain angles at rest into `theta` and returns the engine steps and `T_base_flange`
    /// (m, rapier's forward kinematics). Fails with [`crate::SimError::NotSettled`] when the arm does
    /// not come to rest.
    #[allow(clippy::too_many_arguments)]
    pub fn settle(
        &self,
        chain: &Chain,
        dt: f64,
        payload: Option<&Payload>,
        gravity: &Vector3<f64>,
        q_motor: &[f64],
        theta: &mut [f64],
        cache: &mut RapierCache,
    ) -> Result<(usize, Pose)> {
        let (mass, com) = payload.map_or((0.0, [0.0; 3]), |p| (p.mass, p.com));
        let key: Key = [
            dt.to_bits(),
            mass.to_bits(),
            com[0].to_bits(),
            com[1].to_bits(),
            com[2].to_bits(),
            gravity.x.to_bits(),
            gravity.y.to_bits(),
            gravity.z.to_bits(),
        ];
        let hit = cache
            .entries
            .iter()
            .position(|e| e.id == self.id && e.key == key);
        let k = match hit {
            Some(k) => k,
            None => {
                let real = chain.model_at(&self.nominal, dt)?;
                let arm = RapierArm::with_deflection(
                    &real,
                    &self.stiffness,
                    &self.deflection,
                    payload,
                    gravity,
                    self.options,
                )?;
                let ws = arm.workspace();
                if cache.entries.len() >= CACHE_ENTRIES {
                    cache.entries.remove(0);
                }
                cache.entries.push(Entry {
                    id: self.id,
                    key,
                    arm,
                    ws,
                });
                cache.entries.len() - 1
            }
        };
        let Entry { arm, ws, .. } = &mut cache.entries[k];
        let s = arm.settle(ws, q_motor)?;
        theta.copy_from_slice(&s.q_link);
        Ok((s.steps, s.flange))
    }
}
