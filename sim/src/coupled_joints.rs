//! Coupled joints: a passive joint of the chain whose angle follows other joints, its *sources*,
//! `θₖ = Σᵢ aᵢ θᵢ + b` (rad or m), as in a parallelogram waist (`q4 = −(q2 + q3)`) or a belt-coupled
//! wrist. A coupled joint has no drive: the controller neither reports nor commands it, and the
//! measurement table has no column of its own for it (see [`crate::measurement_table::couple`]).
//!
//! Three ways to declare a coupling, all resolved against the chain by [`Couplings::resolve`]:
//! * URDF `<mimic joint="source" multiplier="a" offset="b"/>` inside a chain joint (one source);
//! * a `<robocal:coupling joint="j4" sources="j2 j3" multipliers="-1 -1" offset="0"/>` element under
//!   `<robot>` (declare `xmlns:robocal="https://robocal.dev/urdf"` on `<robot>`; other tools ignore it);
//! * a TOML file beside the URDF (`--couplings FILE`), one `[[coupling]]` table per coupled joint with
//!   the same keys: `joint`, `sources`, `multipliers` and `offset` (default 0).
//!
//! A source must be a driven joint of the chain: couplings of couplings are refused, as are a joint
//! coupled twice and a coupling to itself. A `<mimic>` on a joint off the chain (a gripper finger, a
//! joint of another arm) is not the chain's business and is ignored.
//!
//! # Statics
//! The coupling is a rigid linkage on the link side: with `A` the `n × n` matrix of
//! `∂θ/∂θ_drive` (identity columns for drives, zero columns for coupled joints, `Aₖⱼ = aⱼ` in a
//! coupled joint's row), virtual work sends a coupled joint's torque to its sources: the drives feel
//! `Aᵀ τ`. The passive joint carries no spring of its own; compliance lives in the drives, and the
//! sag of the whole chain is `A C Aᵀ τ`.

use crate::error::{Result, SimError};

/// One coupled joint, by chain index (0-based): `θ[joint] = Σ a θ[source] + offset`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CoupledJoint {
    /// Chain index of the coupled (passive) joint.
    pub joint: usize,
    /// `(chain index of a driven joint, multiplier aᵢ)` (rad/rad; m/m or m/rad for mixed kinds).
    pub sources: Vec<(usize, f64)>,
    /// Offset `b` (rad or m).
    pub offset: f64,
}

/// A coupling as declared, by joint names: what a URDF element or a `[[coupling]]` table says.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingDecl {
    /// The coupled joint's URDF name.
    pub joint: String,
    /// Its sources' URDF names.
    pub sources: Vec<String>,
    /// One multiplier per source.
    pub multipliers: Vec<f64>,
    /// Offset (rad or m); 0 when not given.
    #[serde(default)]
    pub offset: f64,
}

/// `--couplings FILE`: `[[coupling]]` tables.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CouplingFile {
    #[serde(default)]
    coupling: Vec<CouplingDecl>,
}

/// The couplings of a chain: which joints are driven, which follow, and how.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Couplings {
    list: Vec<CoupledJoint>,
    /// Chain indices of the driven joints, ascending.
    drives: Vec<usize>,
    /// Per chain joint: `(coupled joint, multiplier)` of every coupled joint it drives.
    followers: Vec<Vec<(usize, f64)>>,
    /// Per chain joint: whether it is coupled.
    coupled: Vec<bool>,
}

impl Couplings {
    /// No coupling on a chain of `nq` joints: every joint is driven.
    pub fn none(nq: usize) -> Couplings {
        Couplings {
            list: Vec::new(),
            drives: (0..nq).collect(),
            followers: vec![Vec::new(); nq],
            coupled: vec![false; nq],
        }
    }

    /// Couplings from chain indices, checked: indices within the `nq` joints, a source is driven,
    /// no joint coupled twice or to itself, finite multipliers and offset. `name(i)` names joint `i`
    /// in errors; `source_name` names the robot.
    pub fn new(
        list: Vec<CoupledJoint>,
        nq: usize,
        name: &dyn Fn(usize) -> String,
        source_name: &str,
    ) -> Result<Couplings> {
        let structure = |message: String| SimError::Structure {
            source_name: source_name.to_string(),
            message,
        };
        let mut coupled = vec![false; nq];
        for c in &list {
            if c.joint >= nq {
                return Err(structure(format!(
                    "a coupling names joint {} of a chain of {nq}",
                    c.joint + 1
                )));
            }
            if coupled[c.joint] {
                return Err(structure(format!(
                    "joint '{}' is coupled twice",
                    name(c.joint)
                )));
            }
            coupled[c.joint] = true;
        }
        let mut followers = vec![Vec::new(); nq];
        for c in &list {
            if c.sources.is_empty() {
                return Err(structure(format!(
                    "the coupling of joint '{}' has no source joint",
                    name(c.joint)
                )));
            }
            if !c.offset.is_finite() {
                return Err(structure(format!(
                    "the coupling of joint '{}' has offset {}: not finite",
                    name(c.joint),
                    c.offset
                )));
            }
            for &(s, a) in &c.sources {
                if s >= nq {
                    return Err(structure(format!(
                        "the coupling of joint '{}' names source joint {} of a chain of {nq}",
                        name(c.joint),
                        s + 1
                    )));
                }
                if s == c.joint {
                    return Err(structure(format!(
                        "joint '{}' is coupled to itself",
                        name(c.joint)
                    )));
                }
                if coupled[s] {
                    return Err(structure(format!(
                        "joint '{}' is coupled to '{}', itself coupled: write the coupling on the \
                         driven joints",
                        name(c.joint),
                        name(s)
                    )));
                }
                if !a.is_finite() {
                    return Err(structure(format!(
                        "the coupling of joint '{}' has multiplier {a} for '{}': not finite",
                        name(c.joint),
                        name(s)
                    )));
                }
                followers[s].push((c.joint, a));
            }
        }
        let mut list = list;
        list.sort_by_key(|c| c.joint);
        Ok(Couplings {
            list,
            drives: (0..nq).filter(|&i| !coupled[i]).collect(),
            followers,
            coupled,
        })
    }

    /// Resolves declarations by name against the names of the chain's movable joints, base to tip. A declaration whose coupled joint
    /// is not on the chain is skipped when `skip_off_chain` (a URDF `<mimic>` on a gripper finger) and
    /// an error otherwise; a source off the chain is an error.
    pub fn resolve(
        decls: &[CouplingDecl],
        joints: &[&str],
        skip_off_chain: bool,
        source_name: &str,
    ) -> Result<Vec<CoupledJoint>> {
        let index = |n: &str| joints.iter().position(|j| *j == n);
        let structure = |message: String| SimError::Structure {
            source_name: source_name.to_string(),
            message,
        };
        let mut out = Vec::new();
        for d in decls {
            let Some(k) = index(&d.joint) else {
                if skip_off_chain {
                    continue;
                }
                return Err(structure(format!(
                    "coupled joint '{}' is not a movable joint of the chain",
                    d.joint
                )));
            };
            if d.sources.len() != d.multipliers.len() {
                return Err(structure(format!(
                    "the coupling of joint '{}' has {} sources and {} multipliers: give one multiplier \
                     per source",
                    d.joint,
                    d.sources.len(),
                    d.multipliers.len()
                )));
            }
            let mut sources = Vec::with_capacity(d.sources.len());
            for (s, &a) in d.sources.iter().zip(&d.multipliers) {
                let Some(i) = index(s) else {
                    return Err(structure(format!(
                        "joint '{}' is coupled to '{s}', which is not a movable joint of the chain",
                        d.joint
                    )));
                };
                sources.push((i, a));
            }
            out.push(CoupledJoint {
                joint: k,
                sources,
                offset: d.offset,
            });
        }
        Ok(out)
    }

    /// Reads a `--couplings` TOML file (module docs).
    pub fn read_file(path: &std::path::Path) -> Result<Vec<CouplingDecl>> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let f: CouplingFile = toml::from_str(&text).map_err(|e| SimError::Parse {
            source_name: path.display().to_string(),
            message: e.to_string().replace('\n', " "),
        })?;
        if f.coupling.is_empty() {
            return Err(SimError::Parse {
                source_name: path.display().to_string(),
                message: "no [[coupling]] table: nothing is coupled".into(),
            });
        }
        Ok(f.coupling)
    }

    /// The `<robocal:coupling …/>` elements of a URDF text (module docs), children of `<robot>` read by
    /// [`crate::urdf_text::robot_children`] (a commented-out element is not read); `source_name`
    /// names the text in errors.
    pub fn from_urdf_text(text: &str, source_name: &str) -> Result<Vec<CouplingDecl>> {
        let bad = |message: String| SimError::Parse {
            source_name: source_name.to_string(),
            message,
        };
        let mut out = Vec::new();
        for attrs in crate::urdf_text::robot_children(text, source_name, "robocal:coupling")? {
            let get = |key: &str| attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone());
            let joint = get("joint")
                .ok_or_else(|| bad("a <robocal:coupling> element without joint=\"…\"".into()))?;
            let sources: Vec<String> = get("sources")
                .ok_or_else(|| {
                    bad(format!(
                        "<robocal:coupling joint=\"{joint}\"> without sources=\"…\""
                    ))
                })?
                .split_whitespace()
                .map(str::to_string)
                .collect();
            let numbers = |key: &str, text: &str| -> Result<Vec<f64>> {
                text.split_whitespace()
                    .map(|v| {
                        v.parse::<f64>().map_err(|_| {
                            bad(format!(
                                "<robocal:coupling joint=\"{joint}\">: {key} value '{v}' is not a number"
                            ))
                        })
                    })
                    .collect()
            };
            let multipliers = match get("multipliers") {
                Some(m) => numbers("multipliers", &m)?,
                None => vec![1.0; sources.len()],
            };
            let offset = match get("offset") {
                Some(o) => *numbers("offset", &o)?.first().unwrap_or(&0.0),
                None => 0.0,
            };
            out.push(CouplingDecl {
                joint,
                sources,
                multipliers,
                offset,
            });
        }
        Ok(out)
    }

    /// The couplings, by coupled joint.
    pub fn list(&self) -> &[CoupledJoint] {
        &self.list
    }

    /// True without any coupling.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Chain indices of the driven joints, ascending: the joints with a column `q1 … qD` in the
    /// measurement table, in that order.
    pub fn drives(&self) -> &[usize] {
        &self.drives
    }

    /// Number of driven joints.
    pub fn n_drives(&self) -> usize {
        self.drives.len()
    }

    /// Whether chain joint `i` is coupled (passive).
    #[inline]
    pub fn is_coupled(&self, i: usize) -> bool {
        self.coupled.get(i).copied().unwrap_or(false)
    }

    /// `(coupled joint, multiplier)` of every coupled joint that chain joint `i` drives.
    #[inline]
    pub fn followers(&self, i: usize) -> &[(usize, f64)] {
        &self.followers[i]
    }

    /// The chain's joint values from the driven joints' `q_drives` (in [`Couplings::drives`] order)
    /// into `q` (all `nq` joints, rad or m).
    pub fn expand(&self, q_drives: &[f64], q: &mut [f64]) {
        for (&i, &v) in self.drives.iter().zip(q_drives) {
            q[i] = v;
        }
        self.apply(q);
    }

    /// Sets every coupled joint of `q` (all `nq` joints) from its sources.
    #[inline]
    pub fn apply(&self, q: &mut [f64]) {
        for c in &self.list {
            q[c.joint] = c.offset + c.sources.iter().map(|&(s, a)| a * q[s]).sum::<f64>();
        }
    }

    /// Adds to every coupled joint of `dq` the change its sources' entries of `dq` carry through the
    /// linkage: `dqₖ += Σ aᵢ dqᵢ` (a change of the drives' link-side angles, rad or m).
    #[inline]
    pub fn propagate(&self, dq: &mut [f64]) {
        for c in &self.list {
            dq[c.joint] += c.sources.iter().map(|&(s, a)| a * dq[s]).sum::<f64>();
        }
    }

    /// `Aᵀ τ` in place over the drives: each driven joint's entry gains `Σ aₖ τₖ` from the coupled
    /// joints it drives, and coupled joints' entries become 0 (virtual work; N m or N).
    #[inline]
    pub fn to_drives(&self, tau: &mut [f64]) {
        for c in &self.list {
            let t = tau[c.joint];
            for &(s, a) in &c.sources {
                tau[s] += a * t;
            }
            tau[c.joint] = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn torso() -> Couplings {
        // q4 = −(q2 + q3) + 0.1 on a chain of 5 (0-based: joint 3 from joints 1 and 2).
        Couplings::new(
            vec![CoupledJoint {
                joint: 3,
                sources: vec![(1, -1.0), (2, -1.0)],
                offset: 0.1,
            }],
            5,
            &|i| format!("j{}", i + 1),
            "t",
        )
        .unwrap()
    }

    #[test]
    fn expansion_follows_the_coupling_by_hand() {
        let c = torso();
        assert_eq!(c.drives(), &[0, 1, 2, 4]);
        let mut q = [0.0; 5];
        c.expand(&[0.5, 0.2, 0.3, -0.7], &mut q);
        assert_eq!(q[0], 0.5);
        assert!((q[3] - (-(0.2 + 0.3) + 0.1)).abs() < 1e-15);
        assert_eq!(q[4], -0.7);
    }

    #[test]
    fn virtual_work_sends_the_passive_torque_to_its_sources() {
        // Aᵀ τ by hand: τ = [1, 2, 3, 4, 5] → drives 2 and 3 take −4 each, joint 4 carries nothing.
        let c = torso();
        let mut t = [1.0, 2.0, 3.0, 4.0, 5.0];
        c.to_drives(&mut t);
        assert_eq!(t, [1.0, -2.0, -1.0, 0.0, 5.0]);
        // Propagation is A on link-side changes: drive 2 turning 0.01 turns joint 4 by −0.01.
        let mut d = [0.0, 0.01, 0.0, 0.0, 0.0];
        c.propagate(&mut d);
        assert_eq!(d, [0.0, 0.01, 0.0, -0.01, 0.0]);
    }

    #[test]
    fn bad_couplings_are_refused_naming_the_joints() {
        let name = |i: usize| format!("j{}", i + 1);
        let one = |joint, sources: Vec<(usize, f64)>| CoupledJoint {
            joint,
            sources,
            offset: 0.0,
        };
        for (list, words) in [
            (vec![one(1, vec![(1, 1.0)])], "'j2' is coupled to itself"),
            (
                vec![one(1, vec![(0, 1.0)]), one(2, vec![(1, 1.0)])],
                "itself coupled",
            ),
            (
                vec![one(1, vec![(0, 1.0)]), one(1, vec![(2, 1.0)])],
                "coupled twice",
            ),
            (vec![one(1, vec![(0, f64::NAN)])], "not finite"),
            (vec![one(1, vec![])], "no source"),
        ] {
            let e = Couplings::new(list, 3, &name, "r").unwrap_err().to_string();
            assert!(e.contains(words), "{e}");
        }
    }

    /// The attributes as written; a commented-out element is not a coupling.
    #[test]
    fn the_robocal_element_is_read_with_its_attributes() {
        let text = r#"<robot name="r" xmlns:robocal="https://robocal.dev/urdf">
          <robocal:coupling joint="j4" sources="j2  j3" multipliers="-1 -1.5" offset="0.25"/>
          <robocal:coupling joint='j6' sources='j5'/>
          <!-- <robocal:coupling joint="j7" sources="j1"/> -->
        </robot>"#;
        let d = Couplings::from_urdf_text(text, "t").unwrap();
        assert_eq!(d.len(), 2);
        assert_eq!(d[0].joint, "j4");
        assert_eq!(d[0].sources, vec!["j2", "j3"]);
        assert_eq!(d[0].multipliers, vec![-1.0, -1.5]);
        assert_eq!(d[0].offset, 0.25);
        assert_eq!(d[1].multipliers, vec![1.0]);
        assert_eq!(d[1].offset, 0.0);
        let e = Couplings::from_urdf_text(
            r#"<robot name="r"><robocal:coupling joint="j4" sources="j2" multipliers="x"/></robot>"#,
            "t",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("'x' is not a number"), "{e}");
    }
}
