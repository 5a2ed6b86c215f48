//! Loading a serial chain from a URDF file into a [`Model`].
//!
//! Only revolute, continuous, prismatic and fixed joints are accepted on the chain; fixed joints are
//! folded into the neighbouring joint origins and their links' inertials merged into the moving body
//! they are attached to. Meshes, `package://` paths, `<gazebo>`, `<transmission>` and `<ros2_control>`
//! blocks are never read.

use crate::error::{Result, SimError};
use crate::lie::{Pose, pose_from, rotation_from_rpy};
use crate::model::{Body, Joint, JointKind, JointLimits, Model};
use nalgebra::{Matrix3, Vector3, Vector6};
use std::collections::HashMap;
use std::path::Path;

/// Which part of the URDF tree to use.
#[derive(Clone, Debug, Default)]
pub struct ChainSpec {
    /// Root of the chain; default: the tree's root link.
    pub base_link: Option<String>,
    /// Tip of the chain; default: the single leaf link (or the leaf reached through the most movable
    /// joints when exactly one such leaf exists).
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
    let robot = urdf_rs::read_from_string(text).map_err(|e| SimError::Parse {
        source_name: src(),
        message: one_line(&e.to_string()),
    })?;
    Builder::new(&robot, source_name)?.build(spec)
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
        b.check_no_cycle()?;
        Ok(b)
    }

    /// Refuses joints that form a cycle, also one apart from the root's tree (which no chain from a
    /// root reaches, so it would otherwise be dropped without a word; found by the fuzzing suite):
    /// every link, followed up through its parent joints, must reach a link without a parent. Each
    /// link is walked once (O(links)).
    fn check_no_cycle(&self) -> Result<()> {
        // 1: on the walk in progress; 2: reaches a root.
        let mut state: HashMap<&str, u8> = HashMap::with_capacity(self.links.len());
        for l in &self.robot.links {
            let mut walk = Vec::new();
            let mut link = l.name.as_str();
            loop {
                match state.get(link) {
                    Some(2) => break,
                    Some(_) => {
                        let start = walk.iter().position(|&w| w == link).unwrap_or(0);
                        let cycle = &walk[start..];
                        let joints: Vec<String> = cycle
                            .iter()
                            .filter_map(|c| self.parent_joint.get(c))
                            .map(|j| format!("'{}'", j.name))
                            .collect();
                        return Err(self.structure(format!(
                            "joints {} form a cycle (links {} -> {}): not a tree",
                            joints.join(", "),
                            cycle.iter().rev().copied().collect::<Vec<_>>().join(" -> "),
                            cycle.last().copied().unwrap_or(link)
                        )));
                    }
                    None => {}
                }
                state.insert(link, 1);
                walk.push(link);
                match self.parent_joint.get(link) {
                    Some(j) => link = j.parent.link.as_str(),
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

    fn leaves_below(&self, base: &'a str) -> Vec<&'a str> {
        let mut out = Vec::new();
        let mut stack = vec![base];
        let mut guard = 0;
        while let Some(l) = stack.pop() {
            guard += 1;
            if guard > self.robot.links.len() + 1 {
                break;
            }
            match self.child_joints.get(l) {
                Some(js) if !js.is_empty() => {
                    stack.extend(js.iter().map(|j| j.child.link.as_str()))
                }
                _ => out.push(l),
            }
        }
        out.sort_unstable();
        out
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
                "the links form {} separate trees (roots: {}); join them or give --base-link",
                many.len(),
                many.join(", ")
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
        let leaves = self.leaves_below(base);
        if leaves.len() == 1 {
            return Ok(leaves[0]);
        }
        let movable = |leaf: &str| -> usize {
            self.path(base, leaf)
                .map(|p| p.iter().filter(|j| is_movable(j)).count())
                .unwrap_or(0)
        };
        let best = leaves.iter().map(|l| movable(l)).max().unwrap_or(0);
        let top: Vec<&str> = leaves
            .iter()
            .copied()
            .filter(|l| movable(l) == best)
            .collect();
        if top.len() == 1 && best > 0 {
            Ok(top[0])
        } else {
            Err(self.structure(format!(
                "the tree branches: leaf links {}; choose one with --tip-link",
                top.join(", ")
            )))
        }
    }

    fn build(&self, spec: &ChainSpec) -> Result<Model> {
        let base = self.choose_base(spec)?;
        let tip = self.choose_tip(base, spec)?;
        let path = self.path(base, tip)?;

        let mut joints: Vec<Joint> = Vec::new();
        // Links whose mass goes into body i: chain links after joint i up to the next movable joint.
        let mut body_links: Vec<Vec<&str>> = Vec::new();
        // Pose of each chain link in its body's joint frame.
        let mut link_in_body: HashMap<&str, Pose> = HashMap::new();
        let mut pending = Pose::identity(); // T_prevframe_link for the current link
        let mut home = Pose::identity();
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
            home *= origin;
            let w = home.rotation * axis;
            let p = home.translation.vector;
            let screw = if kind.is_rotational() {
                let v = -w.cross(&p);
                Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
            } else {
                Vector6::new(0.0, 0.0, 0.0, w.x, w.y, w.z)
            };
            let limits = self.limits(j, kind)?;
            joints.push(Joint {
                name: j.name.clone(),
                kind,
                origin,
                axis,
                home,
                screw,
                limits,
                rotation_terms: Joint::rotation_terms_for(&origin, &axis),
                aligned_axis: Joint::aligned_axis_for(&origin, &axis),
            });
            body_links.push(vec![j.child.link.as_str()]);
            link_in_body.insert(j.child.link.as_str(), Pose::identity());
        }
        if joints.is_empty() {
            return Err(self.structure(format!(
                "no movable joint between base link '{base}' and tip link '{tip}'"
            )));
        }
        let flange_offset = pending;
        let home_flange = home * flange_offset;

        let mut notes = Vec::new();
        let on_chain: std::collections::HashSet<&str> =
            body_links.iter().flatten().copied().collect();
        let mut bodies = Vec::with_capacity(joints.len());
        let mut massless = Vec::new();
        for links in &body_links {
            let mut parts: Vec<(&str, Pose)> = Vec::new();
            for l in links {
                let t = link_in_body[l];
                parts.push((l, t));
                // Fixed-joint subtrees hanging off this chain link (not the chain itself).
                self.fixed_subtree(l, t, &on_chain, &mut parts, &mut notes)?;
            }
            let body = self.merge(&parts)?;
            if body.mass <= 0.0 {
                massless.push(links[0].to_string());
            }
            bodies.push(body);
        }
        Ok(Model {
            name: self.robot.name.clone(),
            base_link: base.to_string(),
            tip_link: tip.to_string(),
            joints,
            bodies,
            flange_offset,
            home_flange,
            massless_links: massless,
            notes,
        })
    }

    fn fixed_subtree(
        &self,
        link: &'a str,
        t: Pose,
        on_chain: &std::collections::HashSet<&str>,
        parts: &mut Vec<(&'a str, Pose)>,
        notes: &mut Vec<String>,
    ) -> Result<()> {
        for j in self.child_joints.get(link).into_iter().flatten() {
            let child = j.child.link.as_str();
            if on_chain.contains(child) {
                continue;
            }
            if is_movable(j) {
                notes.push(format!(
                    "joint '{}' is off the chain and movable: its links' masses are ignored",
                    j.name
                ));
                continue;
            }
            let tc = t * self.joint_origin(j)?;
            parts.push((child, tc));
            self.fixed_subtree(child, tc, on_chain, parts, notes)?;
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

fn is_movable(j: &urdf_rs::Joint) -> bool {
    !matches!(j.joint_type, urdf_rs::JointType::Fixed)
}

fn urdf_pose(p: &urdf_rs::Pose) -> Pose {
    pose_from(
        rotation_from_rpy(p.rpy[0], p.rpy[1], p.rpy[2]),
        Vector3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
    )
}
