//! Roles from a hierarchy's shape, for rigs whose names no convention knows: the pelvis is
//! where a spine and two legs meet, the chest where the spine meets two arms and a neck;
//! along a limb, the two longest bones in a row are the upper and lower limb; left and
//! right are told by the rest pose, with up from the head over the feet and forward the way
//! the toes point.

use nalgebra::Vector3;

use super::roles::{Part, Role, Side};
use crate::motion::skeleton::Joint;

/// The roles the shape of `joints` gives, as joint indices; empty when it is not a body
/// (no joint where three branches of two or more points meet). Sides are placed only when
/// the rest pose tells them.
pub fn roles(joints: &[Joint]) -> Vec<(Role, Vec<usize>)> {
    let n = joints.len();
    let mut children = vec![Vec::new(); n];
    for (i, j) in joints.iter().enumerate() {
        if let Some(p) = j.parent {
            children[p].push(i);
        }
    }
    // Joints come parents first, so sizes sum from the back.
    let mut size = vec![1usize; n];
    for i in (0..n).rev() {
        if let Some(p) = joints[i].parent {
            size[p] += size[i];
        }
    }
    let rest: Vec<Vector3<f64>> = crate::motion::skeleton::rest_places(joints)
        .into_iter()
        .map(Vector3::from)
        .collect();
    let branches = |i: usize| -> Vec<usize> {
        children[i]
            .iter()
            .copied()
            .filter(|&c| size[c] >= 2)
            .collect()
    };
    let Some(pelvis) = (0..n).find(|&i| branches(i).len() >= 3) else {
        return Vec::new();
    };
    // Down a branch, the child that carries the most of it.
    let main_chain = |from: usize| -> Vec<usize> {
        let mut chain = vec![from];
        let mut at = from;
        while let Some(&next) = children[at].iter().max_by_key(|&&c| size[c]) {
            chain.push(next);
            at = next;
        }
        chain
    };
    let chest_of = |from: usize| {
        main_chain(from)
            .into_iter()
            .find(|&i| branches(i).len() >= 3)
    };
    let mut legs: Vec<usize> = branches(pelvis);
    let Some(spine_root) = legs
        .iter()
        .copied()
        .filter(|&b| chest_of(b).is_some())
        .max_by_key(|&b| size[b])
    else {
        return vec![(Role::Pelvis, vec![pelvis])];
    };
    legs.retain(|&b| b != spine_root);
    legs.sort_by_key(|&b| std::cmp::Reverse(size[b]));
    legs.truncate(2);
    let chest = chest_of(spine_root).expect("found above");
    let spine: Vec<usize> = main_chain(spine_root)
        .into_iter()
        .take_while(|&i| i != chest)
        .chain([chest])
        .collect();
    let mut out = vec![(Role::Pelvis, vec![pelvis]), (Role::Spine, spine)];

    // The chest's neck: the branch whose far end lies straightest on from the spine.
    let tip = |b: usize| *main_chain(b).last().expect("a chain has its start");
    let spine_dir = (rest[chest] - rest[pelvis]).normalize();
    let mut top = branches(chest);
    let straightness = |b: usize| {
        let d = rest[tip(b)] - rest[chest];
        if d.norm() == 0.0 {
            -1.0
        } else {
            d.normalize().dot(&spine_dir)
        }
    };
    top.sort_by(|&a, &b| straightness(b).total_cmp(&straightness(a)));
    let neck_branch = top[0];
    let arms: Vec<usize> = top[1..].iter().copied().take(2).collect();
    let neck_chain: Vec<usize> = main_chain(neck_branch)
        .into_iter()
        .filter(|&i| !joints[i].end_site)
        .collect();
    match neck_chain[..] {
        [] => {}
        [head] => out.push((Role::Head, vec![head])),
        [neck, .., head] => {
            out.push((Role::Neck, vec![neck]));
            out.push((Role::Head, vec![head]));
        }
    }

    // Along a limb: the two longest bones in a row (upper and lower limb), the joint
    // before them and the one after.
    let limb = |b: usize| -> Option<Limb> {
        let chain = main_chain(b);
        if chain.len() < 3 {
            return None;
        }
        let bone = |k: usize| (rest[chain[k + 1]] - rest[chain[k]]).norm();
        let best = (0..chain.len() - 2)
            .max_by(|&a, &b| (bone(a) + bone(a + 1)).total_cmp(&(bone(b) + bone(b + 1))))?;
        Some(Limb {
            before: best.checked_sub(1).map(|k| chain[k]),
            joints: [chain[best], chain[best + 1], chain[best + 2]],
            after: chain.get(best + 3).copied(),
        })
    };
    let arm_parts: Vec<Vec<(Part, usize)>> = arms
        .iter()
        .filter_map(|&b| limb(b))
        .map(|l| {
            let [s, e, w] = l.joints;
            let mut v = vec![(Part::Shoulder, s), (Part::Elbow, e), (Part::Wrist, w)];
            v.extend(l.before.map(|c| (Part::Clavicle, c)));
            v
        })
        .collect();
    let leg_parts: Vec<Vec<(Part, usize)>> = legs
        .iter()
        .filter_map(|&b| limb(b))
        .map(|l| {
            let [h, k, a] = l.joints;
            let mut v = vec![(Part::Hip, h), (Part::Knee, k), (Part::Ankle, a)];
            v.extend(l.after.map(|t| (Part::Toe, t)));
            v
        })
        .collect();

    // Sides from the rest pose: up is head over the feet, forward the way the toes point.
    let at = |v: &[(Part, usize)], p: Part| v.iter().find(|x| x.0 == p).map(|x| x.1);
    let head = out.iter().find(|r| r.0 == Role::Head).map(|r| r.1[0]);
    let ankles: Vec<usize> = leg_parts
        .iter()
        .filter_map(|v| at(v, Part::Ankle))
        .collect();
    let toes: Vec<(usize, usize)> = leg_parts
        .iter()
        .filter_map(|v| Some((at(v, Part::Ankle)?, at(v, Part::Toe)?)))
        .collect();
    let left = match (head, ankles.is_empty(), toes.is_empty()) {
        (Some(h), false, false) => {
            let feet = ankles.iter().map(|&a| rest[a]).sum::<Vector3<f64>>() / ankles.len() as f64;
            let up = (rest[h] - feet).normalize();
            let ahead: Vector3<f64> = toes.iter().map(|&(a, t)| rest[t] - rest[a]).sum();
            let forward = ahead - up * ahead.dot(&up);
            (forward.norm() > 1e-9).then(|| up.cross(&forward.normalize()))
        }
        _ => None,
    };
    let Some(left) = left else {
        return out;
    };
    let mut sided = |pairs: Vec<Vec<(Part, usize)>>, key: Part| {
        if pairs.len() != 2 {
            return;
        }
        let lateral = |v: &Vec<(Part, usize)>| {
            at(v, key).map_or(0.0, |i| (rest[i] - rest[pelvis]).dot(&left))
        };
        let (l, r) = if lateral(&pairs[0]) >= lateral(&pairs[1]) {
            (&pairs[0], &pairs[1])
        } else {
            (&pairs[1], &pairs[0])
        };
        if lateral(l) <= lateral(r) {
            return;
        }
        for (side, v) in [(Side::Left, l), (Side::Right, r)] {
            for &(p, i) in v {
                out.push((Role::Limb(side, p), vec![i]));
            }
        }
    };
    sided(leg_parts, Part::Hip);
    sided(arm_parts, Part::Shoulder);
    out
}

/// A limb read along its main chain: the two longest bones in a row make `joints` (upper
/// joint, middle, end), with the joint before them and the one after, where there are.
struct Limb {
    before: Option<usize>,
    joints: [usize; 3],
    after: Option<usize>,
}
