//! The ISO 9283 test cube (pose accuracy and repeatability): its five points and their joint
//! positions (see [`super`], "Pose sources").

use super::err;
use super::spec::Iso9283;
use crate::error::Result;
use crate::kinematics::ik::solve_ik;
use crate::kinematics::{Data, forward_kinematics};
use crate::model::Model;
use nalgebra::Vector3;

/// The five ISO 9283 points (base frame, m) of a cube of side `side` centred at `c`, `P1 … P5`.
pub fn iso9283_points(c: &Vector3<f64>, side: f64) -> [Vector3<f64>; 5] {
    let h = 0.5 * side;
    // Corners of the diagonal plane through the edges y = z = −L/2 and y = z = +L/2.
    let a = c + Vector3::new(-h, -h, -h);
    let b = c + Vector3::new(h, -h, -h);
    let cc = c + Vector3::new(h, h, h);
    let d = c + Vector3::new(-h, h, h);
    let at = |from: Vector3<f64>, to: Vector3<f64>| from + (to - from) * 0.1;
    [*c, at(a, cc), at(b, d), at(cc, a), at(d, b)]
}

/// The joint positions of the five ISO 9283 points of `iso` for `model` (row-major, `P1 … P5`): the
/// points of the cube ([`iso9283_points`]; centred at the target of `seed_q` unless given) reached by
/// inverse kinematics ([`solve_ik`]) with the flange orientation of `seed_q`, `p_flange` being the
/// target in the flange frame (m). Errors name scenario `file` and the key `campaign.iso9283`.
pub(super) fn iso9283_list(
    model: &Model,
    iso: &Iso9283,
    p_flange: &Vector3<f64>,
    file: &str,
) -> Result<Vec<f64>> {
    let n = model.nq();
    let key = "campaign.iso9283";
    if iso.seed_q.len() != n {
        return Err(err(
            file,
            &format!("{key}.seed_q"),
            format!("{} values, but the robot has {n} joints", iso.seed_q.len()),
        ));
    }
    if !(iso.cube_side_m.is_finite() && iso.cube_side_m > 0.0) {
        return Err(err(
            file,
            &format!("{key}.cube_side_m"),
            format!("{} must be a finite length > 0 m", iso.cube_side_m),
        ));
    }
    model
        .check_q(&iso.seed_q)
        .map_err(|e| err(file, &format!("{key}.seed_q"), e.to_string()))?;
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, &iso.seed_q);
    let r_seed = *data.flange.rotation.matrix();
    let c = iso
        .center_base_m
        .map(Vector3::from)
        .unwrap_or_else(|| (data.flange * nalgebra::Point3::from(*p_flange)).coords);
    let mut list = Vec::with_capacity(5 * n);
    for (k, p) in iso9283_points(&c, iso.cube_side_m).iter().enumerate() {
        let q = solve_ik(model, &iso.seed_q, p_flange, p, &r_seed).ok_or_else(|| {
            err(
                file,
                key,
                format!(
                    "inverse kinematics did not converge for P{} = ({:.4}, {:.4}, {:.4}) m: the cube \
                     leaves the workspace; make it smaller or move its centre",
                    k + 1,
                    p.x,
                    p.y,
                    p.z
                ),
            )
        })?;
        for (i, (j, v)) in model.joints().iter().zip(&q).enumerate() {
            if let Some(l) = j.limits
                && (*v < l.lower || *v > l.upper)
            {
                return Err(err(
                    file,
                    key,
                    format!(
                        "P{}: inverse kinematics gives q{} = {v:.4} outside the limits [{}, {}]; \
                         choose another seed_q or a smaller cube",
                        k + 1,
                        i + 1,
                        l.lower,
                        l.upper
                    ),
                ));
            }
        }
        list.extend_from_slice(&q);
    }
    Ok(list)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso9283_points_lie_on_the_plane_diagonals_at_ten_percent() {
        let c = Vector3::new(0.5, 0.1, 0.4);
        let l = 0.3;
        let p = iso9283_points(&c, l);
        assert_eq!(p[0], c);
        // Diagonal length L√3; P2..P5 are 0.1·L√3 from a corner and 0.4·L√3 from the centre.
        for q in &p[1..] {
            assert!(((q - c).norm() - 0.4 * l * 3f64.sqrt()).abs() < 1e-15);
            // On the plane y = z (relative to the centre).
            assert!(((q - c).y - (q - c).z).abs() < 1e-15);
        }
        // Hand value of P2: corner (−L/2)(1,1,1) moved 10 % towards (+L/2)(1,1,1): −0.4 L (1,1,1).
        assert!((p[1] - (c - Vector3::repeat(0.4 * l))).amax() < 1e-15);
    }
}
