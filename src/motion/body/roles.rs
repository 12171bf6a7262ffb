//! The roles a point can play in a body: the vocabulary every rig and marker set is mapped
//! to, so that axes, root motion, retargeting and search can speak of "the left knee"
//! whatever a file calls it.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A side of the body, as its owner sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Side {
    Left,
    Right,
}

impl Side {
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    pub fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// A part of a limb, found on both sides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Part {
    Clavicle,
    /// The shoulder joint (glenohumeral), where the upper arm turns.
    Shoulder,
    Elbow,
    Wrist,
    /// The hip joint, where the thigh turns.
    Hip,
    Knee,
    Ankle,
    Toe,
}

impl Part {
    pub const ALL: [Part; 8] = [
        Part::Clavicle,
        Part::Shoulder,
        Part::Elbow,
        Part::Wrist,
        Part::Hip,
        Part::Knee,
        Part::Ankle,
        Part::Toe,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Part::Clavicle => "clavicle",
            Part::Shoulder => "shoulder",
            Part::Elbow => "elbow",
            Part::Wrist => "wrist",
            Part::Hip => "hip",
            Part::Knee => "knee",
            Part::Ankle => "ankle",
            Part::Toe => "toe",
        }
    }
}

/// A role in a body: the trunk's, or a limb part on one side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Role {
    Pelvis,
    /// The chain from the pelvis to the neck (a skeleton's spine joints, or the back and
    /// chest markers of a marker set).
    Spine,
    Neck,
    Head,
    Limb(Side, Part),
}

impl Role {
    /// Every role: the trunk's, then each limb part left and right.
    pub fn all() -> Vec<Role> {
        let mut v = vec![Role::Pelvis, Role::Spine, Role::Neck, Role::Head];
        for p in Part::ALL {
            for s in Side::BOTH {
                v.push(Role::Limb(s, p));
            }
        }
        v
    }

    /// This role's place in [`Role::all`], without building it (read per frame).
    pub fn index(self) -> usize {
        match self {
            Role::Pelvis => 0,
            Role::Spine => 1,
            Role::Neck => 2,
            Role::Head => 3,
            Role::Limb(s, p) => {
                let part = Part::ALL.iter().position(|x| *x == p).unwrap_or(0);
                4 + part * 2 + usize::from(s == Side::Right)
            }
        }
    }

    /// The roles that make a body's limbs: shoulder, elbow, wrist, hip, knee, ankle and toe
    /// on both sides (clavicles are often not captured and are not counted).
    pub fn limbs() -> Vec<Role> {
        Role::all()
            .into_iter()
            .filter(|r| matches!(r, Role::Limb(_, p) if *p != Part::Clavicle))
            .collect()
    }

    pub fn left(p: Part) -> Role {
        Role::Limb(Side::Left, p)
    }

    pub fn right(p: Part) -> Role {
        Role::Limb(Side::Right, p)
    }

    pub fn name(self) -> String {
        match self {
            Role::Pelvis => "pelvis".into(),
            Role::Spine => "spine".into(),
            Role::Neck => "neck".into(),
            Role::Head => "head".into(),
            Role::Limb(s, p) => format!("{}_{}", s.name(), p.name()),
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for Role {
    type Err = String;
    fn from_str(s: &str) -> Result<Role, String> {
        let t = s.trim().to_ascii_lowercase();
        Role::all()
            .into_iter()
            .find(|r| r.name() == t)
            .ok_or_else(|| {
                format!(
                    "{s:?} is not a role (pelvis, spine, neck, head, left_knee, right_wrist, …)"
                )
            })
    }
}

impl Serialize for Role {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

impl<'de> Deserialize<'de> for Role {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Role, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// Which points play each role: one joint for a skeleton's role (the spine: its chain,
/// pelvis to neck), the markers whose centroid is the role's place for a marker set.
pub type RoleMap = BTreeMap<Role, Vec<String>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_are_named_once_and_parse_back() {
        let all = Role::all();
        assert_eq!(all.len(), 20);
        assert_eq!(Role::limbs().len(), 14);
        for (i, r) in all.iter().enumerate() {
            assert_eq!(r.name().parse::<Role>().unwrap(), *r);
            assert_eq!(r.index(), i, "{r}");
        }
        assert_eq!(Role::left(Part::Knee).name(), "left_knee");
        assert!("knee".parse::<Role>().is_err());
        let m: RoleMap = [(Role::right(Part::Toe), vec!["RTOE".to_string()])].into();
        let text = serde_json::to_string(&m).unwrap();
        assert_eq!(text, r#"{"right_toe":["RTOE"]}"#);
        assert_eq!(serde_json::from_str::<RoleMap>(&text).unwrap(), m);
    }
}
