//! Loading a serial chain from a URDF file into a [`Model`].
//!
//! Only revolute, continuous, prismatic and fixed joints are accepted on the chain; fixed joints are
//! folded into the neighbouring joint origins and their links' inertials merged into the moving body
//! they are attached to. Meshes, `package://` paths, `<gazebo>`, `<transmission>` and `<ros2_control>`
//! blocks are never read.
//!
//! # Which chain
//! Without `--base-link`, the base is the one root link (several roots: an error listing them). Without
//! `--tip-link`, the chain must be clear from the tree, and nothing is chosen between alternatives:
//! every movable joint below the base must lie on one path, and one leaf link must hang off its last
//! movable joint (through fixed joints only: `flange`, `tool0`); that leaf is the tip. Leaves hanging
//! off earlier links through fixed joints only (a ROS-Industrial `base` frame off the root, a camera on
//! link 3) are frames on the chain, not branches of it: their masses are welded to the body they hang
//! from. So are the links of a branch off a chosen chain (`--tip-link` on one arm of a torso with two):
//! with the branch's movable joints at zero, the second arm, a head or a cable carrier load the chain
//! in the statics, and the model's notes name those joints. Two cases are errors that list the leaf
//! links to choose from:
//! * movable joints on two branches (gripper fingers, a second arm): the chain's joints are ambiguous,
//!   whatever the joint counts (an earlier rule took the branch with the most movable joints);
//! * several leaves below the last movable joint (`tool0` and `ft_frame` off the last link): the joints
//!   are clear, but the tip frame is not, and the flange pose (`fk`), the target offset of a scenario
//!   and the calibrated URDF's flange joint depend on it. Their deepest common link is named, as is
//!   the last joint's own frame.
//!
//! The shipped robots and the two third-party iiwa 7 exports have one leaf each (their fixed `world`,
//! floating and flange frames lie on the chain), so none depends on a rule. Loops of joints, a link
//! with two parent joints, a joint from a link to itself and duplicated names are refused first.

use crate::branches::{BranchJoint, Branches};
use crate::coupled_joints::{CouplingDecl, Couplings};
use crate::error::{Result, SimError};
use crate::lie::{Pose, pose_from, rotation_from_rpy};
use crate::model::{Body, Joint, JointKind, JointLimits, Model, ModelParts};
use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;
use std::path::Path;

/// Which part of the URDF tree to use.
#[derive(Clone, Debug, Default)]
pub struct ChainSpec {
    /// Root of the chain; default: the tree's root link.
    pub base_link: Option<String>,
    /// Tip of the chain; default: the one leaf link below the last movable joint, when every movable
    /// joint below the base lies on one path and one leaf hangs off its end (leaves hanging off
    /// earlier links through fixed joints only, such as a `base` or camera frame, are frames, not
    /// tips). Anything else is an error listing the leaves: movable joints on two branches, or
    /// several fixed frames off the last joint (`tool0` and `ft_frame`: the joints are clear, the
    /// tip frame, which `fk` and the target offset depend on, is not).
    pub tip_link: Option<String>,
}

/// Reads a URDF file and builds the model of the chain `spec` selects.
pub fn load_file(path: &Path, spec: &ChainSpec) -> Result<Model> {
    let text = std::fs::read_to_string(path).map_err(|source| SimError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    if path.extension().is_some_and(|e| e == "xacro") {
        return Err(SimError::Xacro {
            source_name: path.display().to_string(),
        });
    }
    load_str(&text, &path.display().to_string(), spec)
}

/// Builds a model from URDF text; `source_name` names the text in error messages.
pub fn load_str(text: &str, source_name: &str, spec: &ChainSpec) -> Result<Model> {
    let robot = parse(text, source_name)?;
    let declared = Couplings::from_urdf_text(text, source_name)?;
    Builder::new(&robot, source_name)?.build(spec, &declared)
}

/// One URDF joint of the chain from the base link to the tip link, as the file writes it.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfJoint {
    /// URDF joint name.
    pub name: String,
    /// Revolute, continuous or prismatic (fixed joints are `false`).
    pub movable: bool,
    /// Its `<origin>`: the child link frame in the parent link frame at q = 0 (m).
    pub origin: Pose,
    /// The origin's `rpy` as written (rad): of the two roll-pitch-yaw triples of a rotation, an editor
    /// keeps the one nearer to it.
    pub rpy: [f64; 3],
}

/// The URDF joints (movable and fixed, base to tip) of the chain that [`load_str`] builds with the
/// same `spec`, each with its own origin: what a tool that edits the file needs ([`load_str`] folds
/// the fixed ones into the movable joints' origins).
pub fn chain_joints(text: &str, source_name: &str, spec: &ChainSpec) -> Result<Vec<UrdfJoint>> {
    let robot = parse(text, source_name)?;
    let b = Builder::new(&robot, source_name)?;
    let base = b.choose_base(spec)?;
    let tip = b.choose_tip(base, spec)?;
    b.path(base, tip)?
        .into_iter()
        .map(|j| {
            Ok(UrdfJoint {
                name: j.name.clone(),
                movable: is_movable(j),
                origin: b.joint_origin(j)?,
                rpy: [j.origin.rpy[0], j.origin.rpy[1], j.origin.rpy[2]],
            })
        })
        .collect()
}

/// Checks what the XML parser cannot be trusted with, then parses.
fn parse(text: &str, source_name: &str) -> Result<urdf_rs::Robot> {
    let src = || source_name.to_string();
    if text.contains("xmlns:xacro") || text.contains("<xacro:") {
        return Err(SimError::Xacro { source_name: src() });
    }
    if !text.contains("<robot") {
        return Err(SimError::Parse {
            source_name: src(),
            message: "no <robot> element".into(),
        });
    }
    if let Some((depth, line)) = nesting_beyond(text, MAX_XML_DEPTH) {
        return Err(SimError::Parse {
            source_name: src(),
            message: format!(
                "XML elements nested {depth} deep at line {line}, more than the {MAX_XML_DEPTH} a URDF \
                 could need: not a robot description"
            ),
        });
    }
    urdf_rs::read_from_string(text).map_err(|e| SimError::Parse {
        source_name: src(),
        message: one_line(&e.to_string()),
    })
}

/// Deepest element nesting accepted in a URDF. A robot description nests about six deep
/// (`robot/link/visual/geometry/mesh`, `gazebo/plugin/...`); the XML parser recurses per level, so a
/// file nested tens of thousands deep would overflow the stack, and is refused before parsing.
pub const MAX_XML_DEPTH: usize = 256;

/// The first place where `text` nests elements deeper than `limit`: (depth, 1-based line). One pass,
/// without parsing: comments, CDATA sections, processing instructions and declarations are skipped,
/// quoted attribute values may hold `>`, and `<x/>` does not nest.
fn nesting_beyond(text: &str, limit: usize) -> Option<(usize, usize)> {
    let b = text.as_bytes();
    let (mut i, mut depth) = (0usize, 0usize);
    let skip_to = |from: usize, end: &[u8]| -> usize {
        b[from..]
            .windows(end.len())
            .position(|w| w == end)
            .map_or(b.len(), |k| from + k + end.len())
    };
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &b[i..];
        if rest.starts_with(b"<!--") {
            i = skip_to(i + 4, b"-->");
        } else if rest.starts_with(b"<![CDATA[") {
            i = skip_to(i + 9, b"]]>");
        } else if rest.starts_with(b"<?") {
            i = skip_to(i + 2, b"?>");
        } else if rest.starts_with(b"<!") {
            i = skip_to(i + 2, b">");
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            i = skip_to(i + 2, b">");
        } else {
            // An opening tag: find its end outside quoted attribute values.
            let start = i;
            let mut quote = None;
            i += 1;
            while i < b.len() {
                match (quote, b[i]) {
                    (None, b'"' | b'\'') => quote = Some(b[i]),
                    (Some(q), c) if c == q => quote = None,
                    (None, b'>') => break,
                    _ => {}
                }
                i += 1;
            }
            let self_closing = i > start && b[i - 1] == b'/';
            i += 1;
            if !self_closing {
                depth += 1;
                if depth > limit {
                    let line = 1 + b[..start].iter().filter(|&&c| c == b'\n').count();
                    return Some((depth, line));
                }
            }
        }
    }
    None
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

struct Builder<'a> {
    robot: &'a urdf_rs::Robot,
    source: &'a str,
    links: HashMap<&'a str, &'a urdf_rs::Link>,
    /// child link -> joint whose child it is
    parent_joint: HashMap<&'a str, &'a urdf_rs::Joint>,
    /// parent link -> joints whose parent it is
    child_joints: HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
}

impl<'a> Builder<'a> {
    fn new(robot: &'a urdf_rs::Robot, source: &'a str) -> Result<Self> {
        let mut b = Builder {
            robot,
            source,
            links: HashMap::new(),
            parent_joint: HashMap::new(),
            child_joints: HashMap::new(),
        };
        if robot.links.is_empty() {
            return Err(b.structure("the URDF has no links".into()));
        }
        for l in &robot.links {
            if b.links.insert(l.name.as_str(), l).is_some() {
                return Err(b.structure(format!("link '{}' is defined twice", l.name)));
            }
        }
        let mut joint_names = std::collections::HashSet::new();
        for j in &robot.joints {
            if !joint_names.insert(j.name.as_str()) {
                return Err(b.structure(format!("joint '{}' is defined twice", j.name)));
            }
            if j.parent.link == j.child.link {
                return Err(b.structure(format!(
                    "joint '{}' connects link '{}' to itself: not a tree",
                    j.name, j.parent.link
                )));
            }
            for end in [&j.parent.link, &j.child.link] {
                if !b.links.contains_key(end.as_str()) {
                    return Err(b.structure(format!(
                        "joint '{}' refers to link '{}', which does not exist",
                        j.name, end
                    )));
                }
            }
            if let Some(other) = b.parent_joint.insert(j.child.link.as_str(), j) {
                return Err(b.structure(format!(
                    "link '{}' is the child of two joints ('{}' and '{}'): not a tree",
                    j.child.link, other.name, j.name
                )));
            }
            b.child_joints
                .entry(j.parent.link.as_str())
                .or_default()
                .push(j);
        }
        b.refuse_loops()?;
        Ok(b)
    }

    /// Every link has at most one parent joint (checked before), so a link that does not lead up to a
    /// root lies on (or below) a loop: refused, naming the loop's links in joint order.
    fn refuse_loops(&self) -> Result<()> {
        // 1: on the current walk up; 2: known to lead up to a root.
        let mut state: HashMap<&str, u8> = HashMap::with_capacity(self.links.len());
        for l in &self.robot.links {
            let mut walk: Vec<&str> = Vec::new();
            let mut cur = l.name.as_str();
            loop {
                match state.get(cur) {
                    Some(2) => break,
                    Some(_) => {
                        let start = walk.iter().position(|w| *w == cur).unwrap_or(0);
                        let mut cycle: Vec<&str> = walk[start..].to_vec();
                        cycle.reverse(); // parent before child
                        cycle.push(cycle[0]);
                        return Err(self.structure(format!(
                            "the joints form a loop: links {}; a URDF must be a tree",
                            path_list(&cycle)
                        )));
                    }
                    None => {}
                }
                state.insert(cur, 1);
                walk.push(cur);
                match self.parent_joint.get(cur) {
                    Some(j) => cur = j.parent.link.as_str(),
                    None => break,
                }
            }
            for w in walk {
                state.insert(w, 2);
            }
        }
        Ok(())
    }

    fn structure(&self, message: String) -> SimError {
        SimError::Structure {
            source_name: self.source.to_string(),
            message,
        }
    }

    fn bad(
        &self,
        element: &'static str,
        name: &str,
        field: &'static str,
        value: f64,
        problem: &'static str,
    ) -> SimError {
        SimError::BadValue {
            source_name: self.source.to_string(),
            element,
            name: name.to_string(),
            field,
            value,
            problem,
        }
    }

    fn finite(&self, el: &'static str, name: &str, field: &'static str, v: &[f64]) -> Result<()> {
        match v.iter().find(|x| !x.is_finite()) {
            Some(x) => Err(self.bad(el, name, field, *x, "not finite")),
            None => Ok(()),
        }
    }

    fn joint_origin(&self, j: &urdf_rs::Joint) -> Result<Pose> {
        self.finite("joint", &j.name, "origin xyz", &j.origin.xyz[..])?;
        self.finite("joint", &j.name, "origin rpy", &j.origin.rpy[..])?;
        self.length("joint", &j.name, "origin xyz", &j.origin.xyz[..])?;
        Ok(urdf_pose(&j.origin))
    }

    /// Refuses a length beyond [`MAX_LENGTH_M`]: no robot arm has one (and the fuzzing suite found
    /// joint origins of 9e18 m loaded without a word).
    fn length(&self, el: &'static str, name: &str, field: &'static str, v: &[f64]) -> Result<()> {
        match v.iter().find(|x| x.abs() > MAX_LENGTH_M) {
            Some(x) => Err(self.bad(
                el,
                name,
                field,
                *x,
                "beyond 1000 m: not a robot arm's dimension (metres are expected)",
            )),
            None => Ok(()),
        }
    }

    fn roots(&self) -> Vec<&'a str> {
        let mut r: Vec<&str> = self
            .robot
            .links
            .iter()
            .map(|l| l.name.as_str())
            .filter(|n| !self.parent_joint.contains_key(n))
            .collect();
        r.sort_unstable();
        r
    }

    /// Links from `base` down to `tip`, and the joints between them (same order).
    fn path(&self, base: &str, tip: &str) -> Result<Vec<&'a urdf_rs::Joint>> {
        let mut joints = Vec::new();
        let mut link = tip;
        while link != base {
            match self.parent_joint.get(link) {
                Some(j) => {
                    joints.push(*j);
                    link = j.parent.link.as_str();
                }
                None => {
                    return Err(
                        self.structure(format!("tip link '{tip}' is not below base link '{base}'"))
                    );
                }
            }
            if joints.len() > self.robot.joints.len() {
                return Err(self.structure("the joints form a cycle".into()));
            }
        }
        joints.reverse();
        Ok(joints)
    }

    fn choose_base(&self, spec: &ChainSpec) -> Result<&'a str> {
        if let Some(b) = &spec.base_link {
            return self
                .links
                .get_key_value(b.as_str())
                .map(|(k, _)| *k)
                .ok_or_else(|| self.structure(format!("base link '{b}' does not exist")));
        }
        let roots = self.roots();
        match roots.as_slice() {
            [one] => Ok(one),
            [] => Err(self.structure("no root link: the joints form a cycle".into())),
            many => Err(self.structure(format!(
                "the links form {} separate trees (root links {}); join them or choose one with \
                 --base-link",
                many.len(),
                name_list(many)
            ))),
        }
    }

    fn choose_tip(&self, base: &'a str, spec: &ChainSpec) -> Result<&'a str> {
        if let Some(t) = &spec.tip_link {
            return self
                .links
                .get_key_value(t.as_str())
                .map(|(k, _)| *k)
                .ok_or_else(|| self.structure(format!("tip link '{t}' does not exist")));
        }
        let ends = self.chain_ends(base);
        match ends.as_slice() {
            [] => Err(self.structure(format!(
                "no movable joint below base link '{base}': not a robot arm"
            ))),
            [end] => match end.leaves.as_slice() {
                [leaf] => Ok(leaf),
                leaves => Err(self.structure(format!(
                    "the tip frame is ambiguous: leaf links {} hang off '{}' (after the last movable \
                     joint '{}') by fixed joints only; choose one with --tip-link ('{}' for the last \
                     joint's own frame)",
                    name_list(leaves),
                    end.common_link,
                    end.joint,
                    end.link
                ))),
            },
            many => {
                let mut leaves: Vec<&str> = many.iter().flat_map(|e| e.leaves.clone()).collect();
                leaves.sort_unstable();
                Err(self.structure(format!(
                    "the tree branches into {} chains of movable joints (leaf links {}); choose one \
                     with --tip-link",
                    many.len(),
                    name_list(&leaves)
                )))
            }
        }
    }

    /// Where the chains of movable joints below `base` end: one entry per movable joint with no
    /// movable joint below it, with the leaf links that hang off it through fixed joints only. A
    /// serial arm has exactly one entry; its leaves are the candidate tip frames. One pass over the
    /// subtree (no recursion: trees of any depth).
    fn chain_ends(&self, base: &'a str) -> Vec<ChainEnd<'a>> {
        // Pre-order walk, remembering for every link the last movable joint above it (below base).
        let mut order: Vec<(&'a str, Option<&'a urdf_rs::Joint>)> = Vec::new();
        let mut stack = vec![(base, None)];
        while let Some((link, last)) = stack.pop() {
            order.push((link, last));
            for j in self.child_joints.get(link).into_iter().flatten() {
                let last = if is_movable(j) { Some(*j) } else { last };
                stack.push((j.child.link.as_str(), last));
            }
        }
        // Movable joints strictly below each link (post-order sums over the pre-order list).
        let mut movable_below: HashMap<&str, usize> = HashMap::new();
        for (link, _) in order.iter().rev() {
            let n: usize = self
                .child_joints
                .get(link)
                .into_iter()
                .flatten()
                .map(|j| usize::from(is_movable(j)) + movable_below[j.child.link.as_str()])
                .sum();
            movable_below.insert(link, n);
        }
        let mut ends: Vec<ChainEnd<'a>> = Vec::new();
        for (link, last) in &order {
            let Some(j) = last else { continue };
            let is_leaf = self.child_joints.get(link).is_none_or(|c| c.is_empty());
            if !is_leaf || movable_below[j.child.link.as_str()] > 0 {
                continue;
            }
            match ends.iter_mut().find(|e| e.joint == j.name) {
                Some(e) => e.leaves.push(link),
                None => ends.push(ChainEnd {
                    joint: j.name.as_str(),
                    link: j.child.link.as_str(),
                    common_link: j.child.link.as_str(),
                    leaves: vec![link],
                }),
            }
        }
        for e in &mut ends {
            e.leaves.sort_unstable();
            e.common_link = self.common_ancestor(&e.leaves, e.link);
        }
        ends.sort_by(|a, b| a.leaves.cmp(&b.leaves));
        ends
    }

    /// The deepest link above all of `leaves` (which all lie below `top`).
    fn common_ancestor(&self, leaves: &[&'a str], top: &'a str) -> &'a str {
        let up = |leaf: &'a str| -> Vec<&'a str> {
            let mut path = vec![leaf];
            let mut l = leaf;
            while l != top {
                match self.parent_joint.get(l) {
                    Some(j) => l = j.parent.link.as_str(),
                    None => break,
                }
                path.push(l);
            }
            path.reverse();
            path
        };
        let first = up(leaves[0]);
        let mut depth = first.len();
        for leaf in &leaves[1..] {
            let other = up(leaf);
            depth = depth.min(first.iter().zip(&other).take_while(|(a, b)| a == b).count());
        }
        first[depth.max(1) - 1]
    }

    /// The chain `spec` selects, with the `<mimic>` couplings of its joints and the `declared`
    /// (`<robocal:coupling>`) ones.
    fn build(&self, spec: &ChainSpec, declared: &[CouplingDecl]) -> Result<Model> {
        let base = self.choose_base(spec)?;
        let tip = self.choose_tip(base, spec)?;
        let path = self.path(base, tip)?;

        let mut joints: Vec<Joint> = Vec::new();
        // Links whose mass goes into body i: chain links after joint i up to the next movable joint.
        let mut body_links: Vec<Vec<&str>> = Vec::new();
        // Pose of each chain link in its body's joint frame.
        let mut link_in_body: HashMap<&str, Pose> = HashMap::new();
        let mut pending = Pose::identity(); // T_prevframe_link for the current link
        for j in &path {
            let origin = self.joint_origin(j)?;
            let kind = match j.joint_type {
                urdf_rs::JointType::Fixed => {
                    pending *= origin;
                    if let Some(links) = body_links.last_mut() {
                        links.push(j.child.link.as_str());
                        link_in_body.insert(j.child.link.as_str(), pending);
                    }
                    continue;
                }
                urdf_rs::JointType::Revolute => JointKind::Revolute,
                urdf_rs::JointType::Continuous => JointKind::Continuous,
                urdf_rs::JointType::Prismatic => JointKind::Prismatic,
                ref other => {
                    return Err(self.structure(format!(
                        "joint '{}' is of type {:?}; only revolute, continuous, prismatic and fixed joints are supported",
                        j.name, other
                    )));
                }
            };
            self.finite("joint", &j.name, "axis xyz", &j.axis.xyz[..])?;
            let axis = Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]);
            let norm = axis.norm();
            if norm < 1e-9 {
                return Err(self.bad("joint", &j.name, "axis xyz", norm, "a zero-length axis"));
            }
            let axis = axis / norm;
            let origin = pending * origin;
            pending = Pose::identity();
            let limits = self.limits(j, kind)?;
            joints.push(Joint::new(j.name.clone(), kind, origin, axis, limits));
            body_links.push(vec![j.child.link.as_str()]);
            link_in_body.insert(j.child.link.as_str(), Pose::identity());
        }
        if joints.is_empty() {
            return Err(self.structure(format!(
                "no movable joint between base link '{base}' and tip link '{tip}'"
            )));
        }
        let flange_offset = pending;
        let mimics: Vec<CouplingDecl> = path
            .iter()
            .filter_map(|j| {
                j.mimic.as_ref().map(|m| CouplingDecl {
                    joint: j.name.clone(),
                    sources: vec![m.joint.clone()],
                    multipliers: vec![m.multiplier.unwrap_or(1.0)],
                    offset: m.offset.unwrap_or(0.0),
                })
            })
            .collect();
        let names: Vec<&str> = joints.iter().map(|j| j.name.as_str()).collect();
        let mut couplings = Couplings::resolve(&mimics, &names, true, self.source)?;
        couplings.extend(Couplings::resolve(declared, &names, false, self.source)?);

        let mut notes = Vec::new();
        let on_chain: std::collections::HashSet<&str> =
            body_links.iter().flatten().copied().collect();
        let mut bodies = Vec::with_capacity(joints.len());
        let mut branches: Vec<BranchBuild<'_>> = Vec::new();
        for (i, links) in body_links.iter().enumerate() {
            let mut parts: Vec<(&str, Pose)> = Vec::new();
            for l in links {
                let t = link_in_body[l];
                parts.push((l, t));
                // Fixed-joint subtrees hanging off this chain link (not the chain itself).
                self.fixed_subtree(l, t, i, &on_chain, &mut parts, &mut branches, &mut notes)?;
            }
            bodies.push(self.merge(&parts)?);
        }
        let mut branch_joints = Vec::with_capacity(branches.len());
        for b in branches {
            let moving = self.merge(&b.links)?;
            branch_joints.push(BranchJoint {
                mass: moving.mass,
                com: moving.com,
                ..b.joint
            });
        }
        Model::new(ModelParts {
            name: self.robot.name.clone(),
            base_link: base.to_string(),
            tip_link: tip.to_string(),
            joints,
            bodies,
            flange_offset,
            notes,
            couplings,
            branches: Branches::new(branch_joints),
        })
    }

    /// Links fixed to chain body `body` below `link` (pose `t` in the body's frame) into `parts`,
    /// except the chain's own; a movable joint off the chain starts a branch ([`Builder::branch_edge`]).
    #[allow(clippy::too_many_arguments)]
    fn fixed_subtree(
        &self,
        link: &'a str,
        t: Pose,
        body: usize,
        on_chain: &std::collections::HashSet<&str>,
        parts: &mut Vec<(&'a str, Pose)>,
        branches: &mut Vec<BranchBuild<'a>>,
        notes: &mut Vec<String>,
    ) -> Result<()> {
        for j in self.child_joints.get(link).into_iter().flatten() {
            let child = j.child.link.as_str();
            if on_chain.contains(child) {
                continue;
            }
            if is_movable(j) {
                let first = branches.len();
                let mut held = Vec::new();
                let at = BranchAt {
                    body,
                    owner: None,
                    t_owner: t,
                    t_body: t,
                };
                self.branch_edge(j, at, parts, branches, &mut held)?;
                let quoted = |names: &mut dyn Iterator<Item = &str>| {
                    names
                        .map(|n| format!("'{n}'"))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let mut note = format!(
                    "a branch leaves the chain at joint '{}': its links' masses load the chain",
                    j.name
                );
                if branches.len() > first {
                    note += &format!(
                        ", posed by its movable joints ({}) at the values of the measurement table's \
                         columns q_<joint name>, or at zero",
                        quoted(&mut branches[first..].iter().map(|b| b.joint.name.as_str()))
                    );
                }
                if !held.is_empty() {
                    note += &format!(
                        "; joints {} (floating or planar) are held at zero",
                        quoted(&mut held.iter().copied())
                    );
                }
                notes.push(note);
                continue;
            }
            let tc = t * self.joint_origin(j)?;
            parts.push((child, tc));
            self.fixed_subtree(child, tc, body, on_chain, parts, branches, notes)?;
        }
        Ok(())
    }

    /// The edge `j` of a branch off the chain and everything below it: every link into `parts` at
    /// its pose in the body's frame with the branch at zero; each revolute, continuous or prismatic
    /// joint into `branches` with the links that move with it; joints of other movable types are
    /// held at zero (their names into `held`).
    fn branch_edge(
        &self,
        j: &'a urdf_rs::Joint,
        at: BranchAt,
        parts: &mut Vec<(&'a str, Pose)>,
        branches: &mut Vec<BranchBuild<'a>>,
        held: &mut Vec<&'a str>,
    ) -> Result<()> {
        let child = j.child.link.as_str();
        let origin = self.joint_origin(j)?;
        let t_owner = at.t_owner * origin;
        let t_body = at.t_body * origin;
        parts.push((child, t_body));
        let kind = match j.joint_type {
            urdf_rs::JointType::Revolute => Some(JointKind::Revolute),
            urdf_rs::JointType::Continuous => Some(JointKind::Continuous),
            urdf_rs::JointType::Prismatic => Some(JointKind::Prismatic),
            urdf_rs::JointType::Fixed => None,
            _ => {
                held.push(j.name.as_str());
                None
            }
        };
        let below = match kind {
            Some(kind) => {
                self.finite("joint", &j.name, "axis xyz", &j.axis.xyz[..])?;
                let axis = Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]);
                let norm = axis.norm();
                if norm < 1e-9 {
                    return Err(self.bad("joint", &j.name, "axis xyz", norm, "a zero-length axis"));
                }
                branches.push(BranchBuild {
                    joint: BranchJoint {
                        name: j.name.clone(),
                        kind,
                        axis: axis / norm,
                        limits: self.limits(j, kind)?,
                        body: at.body,
                        parent: at.owner,
                        origin: t_owner,
                        mass: 0.0,
                        com: Vector3::zeros(),
                    },
                    links: vec![(child, Pose::identity())],
                });
                BranchAt {
                    body: at.body,
                    owner: Some(branches.len() - 1),
                    t_owner: Pose::identity(),
                    t_body,
                }
            }
            None => {
                if let Some(k) = at.owner {
                    branches[k].links.push((child, t_owner));
                }
                BranchAt {
                    t_owner,
                    t_body,
                    ..at
                }
            }
        };
        for next in self.child_joints.get(child).into_iter().flatten() {
            self.branch_edge(next, below, parts, branches, held)?;
        }
        Ok(())
    }

    fn merge(&self, parts: &[(&str, Pose)]) -> Result<Body> {
        let mut mass = 0.0;
        let mut first_moment = Vector3::zeros();
        let mut items = Vec::new();
        for (name, t_body_link) in parts {
            let l = self.links[name];
            let i = &l.inertial;
            let m = i.mass.value;
            self.finite("link", name, "mass", &[m])?;
            if m < 0.0 {
                return Err(self.bad("link", name, "mass", m, "negative"));
            }
            self.finite("link", name, "inertial origin xyz", &i.origin.xyz[..])?;
            self.finite("link", name, "inertial origin rpy", &i.origin.rpy[..])?;
            self.length("link", name, "inertial origin xyz", &i.origin.xyz[..])?;
            let it = &i.inertia;
            self.finite(
                "link",
                name,
                "inertia",
                &[it.ixx, it.ixy, it.ixz, it.iyy, it.iyz, it.izz],
            )?;
            if m == 0.0 {
                continue;
            }
            let t_body_com = t_body_link * urdf_pose(&i.origin);
            let r = t_body_com.rotation.matrix();
            let i_local = Matrix3::new(
                it.ixx, it.ixy, it.ixz, it.ixy, it.iyy, it.iyz, it.ixz, it.iyz, it.izz,
            );
            // A rotational inertia has no negative principal moment (to rounding: 1e-9 of the
            // largest). Only that is checked: CAD exports often miss the triangle inequality by a
            // little, and MuJoCo refuses them, but nothing here depends on it.
            let moments = i_local.symmetric_eigenvalues();
            let largest = moments.amax();
            if let Some(&low) = moments
                .iter()
                .find(|&&v| v < -1e-9 * largest.max(f64::MIN_POSITIVE))
            {
                return Err(self.bad(
                    "link",
                    name,
                    "inertia",
                    low,
                    "a negative principal moment: not a rotational inertia",
                ));
            }
            let i_body = r * i_local * r.transpose();
            let c = t_body_com.translation.vector;
            mass += m;
            first_moment += c * m;
            items.push((m, c, i_body));
        }
        let com = if mass > 0.0 {
            first_moment / mass
        } else {
            Vector3::zeros()
        };
        let mut inertia = Matrix3::zeros();
        for (m, c, i) in items {
            let d = c - com;
            inertia += i + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * m;
        }
        Ok(Body {
            mass,
            com,
            inertia,
            links: parts.iter().map(|(n, _)| n.to_string()).collect(),
        })
    }

    fn limits(&self, j: &urdf_rs::Joint, kind: JointKind) -> Result<Option<JointLimits>> {
        if kind == JointKind::Continuous {
            return Ok(None);
        }
        let l = &j.limit;
        for (field, v) in [("limit lower", l.lower), ("limit upper", l.upper)] {
            if v.is_nan() {
                return Err(self.bad("joint", &j.name, field, v, "not a number"));
            }
        }
        if l.lower.is_finite() && l.upper.is_finite() && l.lower < l.upper {
            Ok(Some(JointLimits {
                lower: l.lower,
                upper: l.upper,
                velocity: if l.velocity.is_finite() {
                    l.velocity
                } else {
                    0.0
                },
                effort: if l.effort.is_finite() { l.effort } else { 0.0 },
            }))
        } else if l.lower > l.upper {
            Err(self.bad(
                "joint",
                &j.name,
                "limit lower",
                l.lower,
                "above the upper limit",
            ))
        } else {
            Ok(None)
        }
    }
}

/// The largest joint or centre-of-mass offset a URDF may give (m).
pub const MAX_LENGTH_M: f64 = 1000.0;

/// A branch joint while its branch is read: the joint, and the links that move with it (pose in its
/// frame).
struct BranchBuild<'a> {
    joint: BranchJoint,
    links: Vec<(&'a str, Pose)>,
}

/// Where [`Builder::branch_edge`] is in a branch: the chain body, the branch joint whose frame the
/// current link moves with (`None`: the body's), and the link's pose in that frame and in the body's
/// frame with the branch at zero.
#[derive(Clone, Copy)]
struct BranchAt {
    body: usize,
    owner: Option<usize>,
    t_owner: Pose,
    t_body: Pose,
}

/// Where one chain of movable joints ends ([`Builder::chain_ends`]).
struct ChainEnd<'a> {
    /// The last movable joint of the chain.
    joint: &'a str,
    /// Its child link (the last joint's own frame).
    link: &'a str,
    /// The deepest link above every leaf in `leaves`.
    common_link: &'a str,
    /// Leaf links below `joint` through fixed joints only (sorted).
    leaves: Vec<&'a str>,
}

/// At most this many names are listed in an error message; the rest are counted.
const MAX_LISTED: usize = 12;

/// `'a', 'b', 'c'` (the first [`MAX_LISTED`], then "and N more").
fn name_list(names: &[&str]) -> String {
    let mut s: Vec<String> = names
        .iter()
        .take(MAX_LISTED)
        .map(|n| format!("'{n}'"))
        .collect();
    if names.len() > MAX_LISTED {
        s.push(format!("and {} more", names.len() - MAX_LISTED));
    }
    s.join(", ")
}

/// `'a' -> 'b' -> 'a'` (shortened in the middle beyond [`MAX_LISTED`] names).
fn path_list(names: &[&str]) -> String {
    let quoted = |n: &&str| format!("'{n}'");
    if names.len() <= MAX_LISTED {
        return names.iter().map(quoted).collect::<Vec<_>>().join(" -> ");
    }
    let head: Vec<String> = names[..MAX_LISTED / 2].iter().map(quoted).collect();
    let tail: Vec<String> = names[names.len() - 2..].iter().map(quoted).collect();
    format!(
        "{} -> ({} more) -> {}",
        head.join(" -> "),
        names.len() - MAX_LISTED / 2 - 2,
        tail.join(" -> ")
    )
}

fn is_movable(j: &urdf_rs::Joint) -> bool {
    !matches!(j.joint_type, urdf_rs::JointType::Fixed)
}

fn urdf_pose(p: &urdf_rs::Pose) -> Pose {
    pose_from(
        rotation_from_rpy(p.rpy[0], p.rpy[1], p.rpy[2]),
        Vector3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
    )
}
