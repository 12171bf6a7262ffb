//! Roles from names: one table of the naming conventions people use for skeletons and
//! marker sets. A new convention is one more block in [`CONVENTIONS`].
//!
//! Names are compared after [`normalise`]: the namespace before the last `:` or `|` is
//! dropped (`mixamorig:Hips`, `mixamorig1:Hips`), as is a prefix most names share
//! (`Character1_`, `Bip01 `), and case and separators (`_`, `.`, `-`, spaces) do not count.
//! So `UpperLeg_L`, `thigh.L` and `thigh_l` read as `upperlegl`, `thighl`, `thighl`.
//!
//! Conventions disagree on words: HumanIK's `LeftShoulder` is the clavicle, Biovision's the
//! shoulder joint, SMPL's `left_foot` the toes. So a take is read by one convention whole,
//! the one that places the most roles (then the one that matches the most names), never
//! name by name across conventions.

use super::roles::{Part, Role, RoleMap};

/// A slot of a convention's table: a trunk role, or a limb part on both sides.
#[derive(Debug, Clone, Copy)]
pub enum Slot {
    Trunk(Role),
    Limb(Part),
}

/// How the names listed for a role make its place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A skeleton's joints: the first name listed that the take has (the spine: every
    /// one it has, in order).
    Joints,
    /// A marker set: the centroid of every listed marker the take has.
    Markers,
}

/// One naming convention.
#[derive(Debug)]
pub struct Convention {
    pub name: &'static str,
    /// Who uses it, for people reading `body.convention`.
    pub used_by: &'static str,
    pub kind: Kind,
    /// What `{s}` stands for in a limb's names: left, then right.
    pub sides: [&'static str; 2],
    /// A namespace its names carry (`mixamorig` for `mixamorig:Hips`, `mixamorig7:Hips`), or
    /// none.
    pub namespace: Option<&'static str>,
    pub roles: &'static [(Slot, &'static [&'static str])],
}

use Part::*;
use Slot::{Limb, Trunk};

const PELVIS: Slot = Trunk(Role::Pelvis);
const SPINE: Slot = Trunk(Role::Spine);
const NECK: Slot = Trunk(Role::Neck);
const HEAD: Slot = Trunk(Role::Head);

/// HumanIK's names: Autodesk MotionBuilder, Maya and FBX characters, Mixamo and CMU take
/// them from it.
const HUMANIK: &[(Slot, &[&str])] = &[
    (PELVIS, &["Hips"]),
    (
        SPINE,
        &[
            "Spine", "Spine1", "Spine2", "Spine3", "Spine4", "Spine5", "Spine6", "Spine7",
            "Spine8", "Spine9",
        ],
    ),
    (NECK, &["Neck", "Neck1", "Neck2"]),
    (HEAD, &["Head"]),
    (Limb(Clavicle), &["{s}Shoulder"]),
    (Limb(Shoulder), &["{s}Arm"]),
    (Limb(Elbow), &["{s}ForeArm"]),
    (Limb(Wrist), &["{s}Hand"]),
    (Limb(Hip), &["{s}UpLeg"]),
    (Limb(Knee), &["{s}Leg"]),
    (Limb(Ankle), &["{s}Foot"]),
    (Limb(Toe), &["{s}ToeBase", "{s}Toe"]),
];

/// Every convention known, in the order a tie is settled.
pub static CONVENTIONS: &[Convention] = &[
    Convention {
        name: "mixamo",
        used_by: "Mixamo characters and animations (HumanIK names under mixamorig:)",
        kind: Kind::Joints,
        sides: ["Left", "Right"],
        namespace: Some("mixamorig"),
        roles: HUMANIK,
    },
    Convention {
        name: "cmu",
        used_by:
            "the CMU Graphics Lab database as BVH, and the Xia et al. style set retargeted to it",
        kind: Kind::Joints,
        sides: ["Left", "Right"],
        namespace: None,
        roles: &[
            (PELVIS, &["Hips"]),
            (SPINE, &["LowerBack", "Spine", "Spine1"]),
            (NECK, &["Neck", "Neck1"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["{s}Shoulder"]),
            (Limb(Shoulder), &["{s}Arm"]),
            (Limb(Elbow), &["{s}ForeArm"]),
            (Limb(Wrist), &["{s}Hand"]),
            (Limb(Hip), &["{s}UpLeg"]),
            (Limb(Knee), &["{s}Leg"]),
            (Limb(Ankle), &["{s}Foot"]),
            (Limb(Toe), &["{s}ToeBase"]),
        ],
    },
    Convention {
        name: "humanik",
        used_by: "Autodesk HumanIK: MotionBuilder, Maya, FBX characters, Vicon Blade/Shogun BVH",
        kind: Kind::Joints,
        sides: ["Left", "Right"],
        namespace: None,
        roles: HUMANIK,
    },
    Convention {
        name: "bandai",
        used_by: "Bandai Namco Research Motion datasets 1 and 2",
        kind: Kind::Joints,
        sides: ["_L", "_R"],
        namespace: None,
        roles: &[
            (PELVIS, &["Hips"]),
            (SPINE, &["Spine", "Chest"]),
            (NECK, &["Neck"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["Shoulder{s}"]),
            (Limb(Shoulder), &["UpperArm{s}"]),
            (Limb(Elbow), &["LowerArm{s}"]),
            (Limb(Wrist), &["Hand{s}"]),
            (Limb(Hip), &["UpperLeg{s}"]),
            (Limb(Knee), &["LowerLeg{s}"]),
            (Limb(Ankle), &["Foot{s}"]),
            (Limb(Toe), &["Toes{s}"]),
        ],
    },
    Convention {
        name: "unreal",
        used_by: "the Unreal Engine mannequin (UE4 and UE5)",
        kind: Kind::Joints,
        sides: ["_l", "_r"],
        namespace: None,
        roles: &[
            (PELVIS, &["pelvis"]),
            (
                SPINE,
                &["spine_01", "spine_02", "spine_03", "spine_04", "spine_05"],
            ),
            (NECK, &["neck_01", "neck_02"]),
            (HEAD, &["head"]),
            (Limb(Clavicle), &["clavicle{s}"]),
            (Limb(Shoulder), &["upperarm{s}"]),
            (Limb(Elbow), &["lowerarm{s}"]),
            (Limb(Wrist), &["hand{s}"]),
            (Limb(Hip), &["thigh{s}"]),
            (Limb(Knee), &["calf{s}"]),
            (Limb(Ankle), &["foot{s}"]),
            (Limb(Toe), &["ball{s}"]),
        ],
    },
    Convention {
        name: "smpl",
        used_by: "SMPL, SMPL-H and SMPL-X joint names (AMASS and the datasets fitted with them)",
        kind: Kind::Joints,
        sides: ["left_", "right_"],
        namespace: None,
        roles: &[
            (PELVIS, &["pelvis"]),
            (SPINE, &["spine1", "spine2", "spine3"]),
            (NECK, &["neck"]),
            (HEAD, &["head"]),
            (Limb(Clavicle), &["{s}collar"]),
            (Limb(Shoulder), &["{s}shoulder"]),
            (Limb(Elbow), &["{s}elbow"]),
            (Limb(Wrist), &["{s}wrist"]),
            (Limb(Hip), &["{s}hip"]),
            (Limb(Knee), &["{s}knee"]),
            (Limb(Ankle), &["{s}ankle"]),
            (Limb(Toe), &["{s}foot"]),
        ],
    },
    Convention {
        name: "rokoko",
        used_by: "Rokoko Studio (Smartsuit) BVH and FBX exports",
        kind: Kind::Joints,
        sides: ["Left", "Right"],
        namespace: None,
        roles: &[
            (PELVIS, &["Hips"]),
            (SPINE, &["Spine", "Spine1", "Spine2", "Spine3", "Spine4"]),
            (NECK, &["Neck"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["{s}Shoulder"]),
            (Limb(Shoulder), &["{s}Arm"]),
            (Limb(Elbow), &["{s}ForeArm"]),
            (Limb(Wrist), &["{s}Hand"]),
            (Limb(Hip), &["{s}Thigh"]),
            (Limb(Knee), &["{s}Shin"]),
            (Limb(Ankle), &["{s}Foot"]),
            (Limb(Toe), &["{s}Toe"]),
        ],
    },
    Convention {
        name: "biovision",
        used_by: "Biovision-style BVH: Motion Analysis, Perfume, many older libraries",
        kind: Kind::Joints,
        sides: ["Left", "Right"],
        namespace: None,
        roles: &[
            (PELVIS, &["Hips"]),
            (SPINE, &["Ab", "Chest", "Chest2", "Chest3", "Chest4"]),
            (NECK, &["Neck"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["{s}Collar"]),
            (Limb(Shoulder), &["{s}Shoulder"]),
            (Limb(Elbow), &["{s}Elbow"]),
            (Limb(Wrist), &["{s}Wrist"]),
            (Limb(Hip), &["{s}Hip"]),
            (Limb(Knee), &["{s}Knee"]),
            (Limb(Ankle), &["{s}Ankle"]),
            (Limb(Toe), &["{s}Toe", "{s}Toes"]),
        ],
    },
    Convention {
        name: "blender",
        used_by: "Blender's metarig and Rigify deform bones, as Blender writes BVH",
        kind: Kind::Joints,
        sides: [".L", ".R"],
        namespace: None,
        roles: &[
            (PELVIS, &["pelvis", "hips", "spine"]),
            (
                SPINE,
                &["spine.001", "spine.002", "spine.003", "chest", "spine"],
            ),
            (NECK, &["neck", "spine.004"]),
            (HEAD, &["head", "face", "spine.006"]),
            (Limb(Clavicle), &["shoulder{s}"]),
            (Limb(Shoulder), &["upper_arm{s}"]),
            (Limb(Elbow), &["forearm{s}"]),
            (Limb(Wrist), &["hand{s}"]),
            (Limb(Hip), &["thigh{s}"]),
            (Limb(Knee), &["shin{s}"]),
            (Limb(Ankle), &["foot{s}"]),
            (Limb(Toe), &["toe{s}"]),
        ],
    },
    Convention {
        name: "optitrack",
        used_by: "OptiTrack Motive skeletons",
        kind: Kind::Joints,
        sides: ["L", "R"],
        namespace: None,
        roles: &[
            (PELVIS, &["Hip"]),
            (SPINE, &["Ab", "Chest"]),
            (NECK, &["Neck"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["{s}Shoulder"]),
            (Limb(Shoulder), &["{s}UArm"]),
            (Limb(Elbow), &["{s}FArm"]),
            (Limb(Wrist), &["{s}Hand"]),
            (Limb(Hip), &["{s}Thigh"]),
            (Limb(Knee), &["{s}Shin"]),
            (Limb(Ankle), &["{s}Foot"]),
            (Limb(Toe), &["{s}Toe"]),
        ],
    },
    Convention {
        name: "xsens",
        used_by: "Xsens MVN segments",
        kind: Kind::Joints,
        sides: ["Left", "Right"],
        namespace: None,
        roles: &[
            (PELVIS, &["Pelvis"]),
            (SPINE, &["L5", "L3", "T12", "T8"]),
            (NECK, &["Neck"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["{s}Shoulder"]),
            (Limb(Shoulder), &["{s}UpperArm"]),
            (Limb(Elbow), &["{s}ForeArm"]),
            (Limb(Wrist), &["{s}Hand"]),
            (Limb(Hip), &["{s}UpperLeg"]),
            (Limb(Knee), &["{s}LowerLeg"]),
            (Limb(Ankle), &["{s}Foot"]),
            (Limb(Toe), &["{s}Toe"]),
        ],
    },
    Convention {
        name: "biped",
        used_by: "3ds Max Biped (Bip01 L Thigh, …)",
        kind: Kind::Joints,
        sides: ["L ", "R "],
        namespace: None,
        roles: &[
            (PELVIS, &["Pelvis"]),
            (SPINE, &["Spine", "Spine1", "Spine2", "Spine3"]),
            (NECK, &["Neck", "Neck1"]),
            (HEAD, &["Head"]),
            (Limb(Clavicle), &["{s}Clavicle"]),
            (Limb(Shoulder), &["{s}UpperArm"]),
            (Limb(Elbow), &["{s}Forearm"]),
            (Limb(Wrist), &["{s}Hand"]),
            (Limb(Hip), &["{s}Thigh"]),
            (Limb(Knee), &["{s}Calf"]),
            (Limb(Ankle), &["{s}Foot"]),
            (Limb(Toe), &["{s}Toe0"]),
        ],
    },
    Convention {
        name: "plug-in-gait",
        used_by:
            "Vicon Plug-in Gait full body and lower body (Helen Hayes), MOTEK HBM waist markers",
        kind: Kind::Markers,
        sides: ["L", "R"],
        namespace: None,
        roles: &[
            // VSAC: Motion Analysis's V.Sacral cut to four characters.
            (
                PELVIS,
                &[
                    "LASI", "RASI", "LPSI", "RPSI", "SACR", "LFWT", "RFWT", "LBWT", "RBWT", "VSAC",
                ],
            ),
            (SPINE, &["C7", "T10", "CLAV", "STRN"]),
            (NECK, &["C7", "CLAV"]),
            // THEA, FHEA, RHEA: Motion Analysis's top, front and rear head.
            (
                HEAD,
                &["LFHD", "RFHD", "LBHD", "RBHD", "THEA", "FHEA", "RHEA"],
            ),
            (Limb(Shoulder), &["{s}SHO"]),
            (Limb(Elbow), &["{s}ELB"]),
            // WRI: the Helen Hayes upper-limb wrist (Motion Analysis, OrthoTrak).
            (Limb(Wrist), &["{s}WRA", "{s}WRB", "{s}WRI"]),
            // HIP: Motion Analysis's ASIS; HJC, KJC, AJC: joint centres of Nexus models.
            (
                Limb(Hip),
                &["{s}ASI", "{s}PSI", "{s}FWT", "{s}BWT", "{s}HIP", "{s}HJC"],
            ),
            // Lateral and medial knee (c3d.org's TYPE-3), femoral condyles (MotionMonitor).
            (
                Limb(Knee),
                &[
                    "{s}KNE", "{s}LKN", "{s}MKN", "{s}LFC", "{s}MFC", "{s}KneL", "{s}KneM",
                    "{s}KJC",
                ],
            ),
            // Lateral and medial malleoli.
            (
                Limb(Ankle),
                &["{s}ANK", "{s}LMA", "{s}MMA", "{s}AnkL", "{s}AnkM", "{s}AJC"],
            ),
            // TO: Motion Analysis's R.Toe cut to four characters; MT5: the fifth metatarsal.
            (
                Limb(Toe),
                &["{s}TOE", "{s}TO", "{s}ToeL", "{s}ToeM", "{s}Toe2", "{s}MT5"],
            ),
        ],
    },
    Convention {
        name: "anatomical",
        used_by:
            "anatomical landmark names (ISB, CAST, OpenSim examples): R.ASIS, L.Knee, R.Epi.Lat",
        kind: Kind::Markers,
        sides: ["L.", "R."],
        namespace: None,
        roles: &[
            (
                PELVIS,
                &["L.ASIS", "R.ASIS", "L.PSIS", "R.PSIS", "V.Sacral", "Sacral"],
            ),
            (SPINE, &["C7", "T8", "T10", "T12", "IJ", "PX", "STERN"]),
            (NECK, &["C7", "IJ"]),
            (
                HEAD,
                &[
                    "Top.Head", "Head", "R.TETE", "L.TETE", "Tete.H", "Tete.D", "Tete.G",
                    "R.Temple", "L.Temple", "R.TET", "L.TET",
                ],
            ),
            (
                Limb(Shoulder),
                &[
                    "{s}Shoulder",
                    "{s}Acromion",
                    "{s}Acromium",
                    "{s}Acr",
                    "{s}AC",
                    "{s}AA",
                    "{s}AngulusAcromio",
                ],
            ),
            (
                Limb(Elbow),
                &[
                    "{s}Elbow",
                    "{s}Epi.Lat",
                    "{s}Epi.Med",
                    "{s}COUD",
                    "{s}COUDInt",
                    "{s}COU",
                ],
            ),
            (
                Limb(Wrist),
                &[
                    "{s}Wrist",
                    "{s}Wrist.Rad",
                    "{s}Wrist.Ulna",
                    "{s}Wrist.Uln",
                    "{s}Wrist.Med",
                    "{s}Wrist.Lat",
                    "{s}MAIN",
                    "{s}MAINInt",
                    "{s}MAI",
                ],
            ),
            (
                Limb(Hip),
                &[
                    "{s}ASIS", "{s}PSIS", "{s}EIAS", "{s}EIPS", "{s}EAS", "{s}EPS",
                ],
            ),
            (
                Limb(Knee),
                &[
                    "{s}Knee",
                    "{s}Knee.Medial",
                    "{s}Knee.Lateral",
                    "{s}Knee.Med",
                    "{s}Knee.Lat",
                    "{s}KnJntLn",
                    "{s}CL",
                    "{s}CM",
                ],
            ),
            (
                Limb(Ankle),
                &[
                    "{s}Ankle",
                    "{s}Ankle.Medial",
                    "{s}Ankle.Lateral",
                    "{s}Ankle.Med",
                    "{s}Ankle.Lat",
                    "{s}MM",
                    "{s}ML",
                ],
            ),
            (
                Limb(Toe),
                &["{s}Toe", "{s}MT1", "{s}MT5", "{s}Foot.Med", "{s}Foot.Lat"],
            ),
        ],
    },
    Convention {
        name: "biogesta",
        used_by: "French lab names with a G/D (gauche/droite) suffix, as Biogesta SAGA-3RT \
                  writes them (GD genou droit, CDG coude gauche)",
        kind: Kind::Markers,
        sides: ["G", "D"],
        namespace: None,
        roles: &[
            (PELVIS, &["BG", "BD", "SS"]),
            (SPINE, &["C7"]),
            (NECK, &["C7"]),
            (HEAD, &["TMPG", "TMPD", "MNTN"]),
            (Limb(Shoulder), &["E{s}", "EPL{s}"]),
            (Limb(Elbow), &["CD{s}"]),
            (Limb(Wrist), &["PGT{s}"]),
            (Limb(Hip), &["B{s}", "GT{s}"]),
            (Limb(Knee), &["G{s}", "CDI{s}", "CDE{s}"]),
            (Limb(Ankle), &["C{s}"]),
            (Limb(Toe), &["P{s}", "MT1{s}", "MT5{s}"]),
        ],
    },
    Convention {
        name: "art-dtrack",
        used_by: "A.R.T. DTrack body model segments as C3D points (Human1:PELV, Human1:LUAR, …)",
        kind: Kind::Markers,
        sides: ["L", "R"],
        namespace: None,
        roles: &[
            (PELVIS, &["PELV"]),
            (SPINE, &["LLSP", "ULSP", "LTSP", "UTSP"]),
            (NECK, &["NECK"]),
            (HEAD, &["HEAD"]),
            // A segment's point is its origin, the joint at its near end: the upper arm's
            // is the shoulder, the lower leg's the knee.
            (Limb(Clavicle), &["{s}SHO"]),
            (Limb(Shoulder), &["{s}UAR"]),
            (Limb(Elbow), &["{s}LAR"]),
            (Limb(Wrist), &["{s}HAN"]),
            (Limb(Hip), &["{s}ULE"]),
            (Limb(Knee), &["{s}LLE"]),
            (Limb(Ankle), &["{s}FOO"]),
        ],
    },
];

/// A name as conventions compare it: no namespace, no case, no separators.
pub fn normalise(name: &str) -> String {
    let bare = name.rsplit([':', '|']).next().unwrap_or(name);
    bare.chars()
        .filter(|c| !matches!(c, '_' | '.' | '-' | ' ' | '\t'))
        .flat_map(char::to_lowercase)
        .collect()
}

/// The namespace of a name (`mixamorig1` of `mixamorig1:Hips`), lower case.
fn namespace(name: &str) -> Option<String> {
    let (ns, _) = name.rsplit_once([':', '|'])?;
    Some(ns.trim().to_ascii_lowercase())
}

/// A prefix most names share up to a separator (`Character1_`, `Bip01 `), to be read past.
fn shared_prefix(names: &[String]) -> Option<String> {
    let mut counts: std::collections::HashMap<&str, usize> = Default::default();
    for n in names {
        if let Some(i) = n.find(['_', ' ']) {
            if i > 0 && i + 1 < n.len() {
                *counts.entry(&n[..=i]).or_default() += 1;
            }
        }
    }
    let (prefix, count) = counts
        .into_iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(a.0)))?;
    (count >= 3 && count * 2 > names.len()).then(|| prefix.to_string())
}

/// Roles as point indices.
type Indices = std::collections::BTreeMap<Role, Vec<usize>>;

/// The roles of `names` by the convention that places the most: its name and the roles.
/// `None` when no convention places any.
pub fn resolve(names: &[String]) -> Option<(&'static Convention, RoleMap)> {
    let prefix = shared_prefix(names);
    let keys: Vec<(String, String)> = names
        .iter()
        .map(|n| {
            let stripped = prefix
                .as_deref()
                .and_then(|p| n.strip_prefix(p))
                .map_or_else(|| normalise(n), normalise);
            (normalise(n), stripped)
        })
        .collect();
    let namespaces: Vec<Option<String>> = names.iter().map(|n| namespace(n)).collect();
    CONVENTIONS
        .iter()
        .map(|c| {
            let (roles, matched) = read(c, &keys);
            let ns = c.namespace.is_some_and(|want| {
                namespaces
                    .iter()
                    .flatten()
                    .filter(|n| n.starts_with(want))
                    .count()
                    * 2
                    > names.len()
            });
            let score = (roles.len(), ns || c.namespace.is_none(), ns, matched);
            (score, c, roles)
        })
        // The first of equals wins: the table's order settles ties.
        .fold(None, |best: Option<(_, _, Indices)>, next| match best {
            Some(b) if b.0 >= next.0 => Some(b),
            _ => Some(next),
        })
        .filter(|(_, _, roles)| !roles.is_empty())
        .map(|(_, c, roles)| {
            let placed = roles
                .into_iter()
                .map(|(r, idx): (Role, Vec<usize>)| {
                    (r, idx.into_iter().map(|i| names[i].clone()).collect())
                })
                .collect();
            (c, placed)
        })
}

/// The roles convention `c` places among `keys` (each name normalised, and normalised past
/// a shared prefix), as point indices, and how many names it matched.
fn read(c: &Convention, keys: &[(String, String)]) -> (Indices, usize) {
    let find = |pattern: &str| -> Vec<usize> {
        let want = normalise(pattern);
        keys.iter()
            .enumerate()
            .filter(|(_, (raw, stripped))| *stripped == want || *raw == want)
            .map(|(i, _)| i)
            .collect()
    };
    let mut roles = std::collections::BTreeMap::new();
    let mut matched = std::collections::BTreeSet::new();
    for &(slot, patterns) in c.roles {
        let places: Vec<(Role, Option<&str>)> = match slot {
            Trunk(r) => vec![(r, None)],
            Limb(p) => vec![
                (Role::left(p), Some(c.sides[0])),
                (Role::right(p), Some(c.sides[1])),
            ],
        };
        for (role, side) in places {
            let mut found: Vec<usize> = Vec::new();
            for pattern in patterns {
                let name = match side {
                    Some(s) => pattern.replace("{s}", s),
                    None => pattern.to_string(),
                };
                for i in find(&name) {
                    if !found.contains(&i) {
                        found.push(i);
                    }
                }
                let first_only = c.kind == Kind::Joints && role != Role::Spine;
                if first_only && !found.is_empty() {
                    found.truncate(1);
                    break;
                }
            }
            if role == Role::Spine {
                found.sort_unstable();
            }
            if !found.is_empty() {
                matched.extend(found.iter().copied());
                roles.insert(role, found);
            }
        }
    }
    // A joint plays one role: the spine gives up what a named role took (Blender's
    // `spine` is the pelvis when there is no `pelvis`).
    if c.kind == Kind::Joints {
        let taken: Vec<usize> = roles
            .iter()
            .filter(|(r, _)| **r != Role::Spine)
            .flat_map(|(_, v)| v.iter().copied())
            .collect();
        if let Some(spine) = roles.get_mut(&Role::Spine) {
            spine.retain(|i| !taken.contains(i));
            if spine.is_empty() {
                roles.remove(&Role::Spine);
            }
        }
    }
    (roles, matched.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(s: &str) -> Vec<String> {
        s.split_whitespace().map(str::to_string).collect()
    }

    fn role(m: &RoleMap, r: &str) -> Vec<String> {
        m.get(&r.parse().unwrap()).cloned().unwrap_or_default()
    }

    #[test]
    fn names_normalise() {
        assert_eq!(normalise("mixamorig7:LeftUpLeg"), "leftupleg");
        assert_eq!(normalise("UpperLeg_L"), "upperlegl");
        assert_eq!(normalise("thigh.L"), "thighl");
        assert_eq!(normalise("R.Epi.Lat"), "repilat");
    }

    /// Each convention reads its own names whole, and the same words mean what their own
    /// convention says: HumanIK's LeftShoulder is a clavicle, Biovision's a shoulder.
    #[test]
    fn every_convention_reads_its_own_names() {
        let cmu = names(
            "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg \
             RightFoot RightToeBase LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm \
             LeftForeArm LeftHand RightShoulder RightArm RightForeArm RightHand",
        );
        let (c, m) = resolve(&cmu).unwrap();
        assert_eq!(c.name, "cmu");
        assert!(Role::all().iter().all(|r| m.contains_key(r)), "{m:?}");
        assert_eq!(role(&m, "left_clavicle"), ["LeftShoulder"]);
        assert_eq!(role(&m, "spine"), ["LowerBack", "Spine", "Spine1"]);
        assert_eq!(role(&m, "neck"), ["Neck"]);

        let bio = names(
            "Hips Chest Chest2 LeftCollar LeftShoulder LeftElbow LeftWrist RightCollar \
             RightShoulder RightElbow RightWrist Neck Head LeftHip LeftKnee LeftAnkle RightHip \
             RightKnee RightAnkle",
        );
        let (c, m) = resolve(&bio).unwrap();
        assert_eq!(c.name, "biovision");
        assert_eq!(role(&m, "left_shoulder"), ["LeftShoulder"]);
        assert_eq!(role(&m, "left_clavicle"), ["LeftCollar"]);

        let mixamo: Vec<String> = names(
            "Hips Spine Spine1 Spine2 Neck Head LeftShoulder LeftArm LeftForeArm LeftHand \
             RightShoulder RightArm RightForeArm RightHand LeftUpLeg LeftLeg LeftFoot \
             LeftToeBase RightUpLeg RightLeg RightFoot RightToeBase",
        )
        .into_iter()
        .map(|n| format!("mixamorig:{n}"))
        .collect();
        let (c, m) = resolve(&mixamo).unwrap();
        assert_eq!(c.name, "mixamo");
        assert_eq!(role(&m, "left_toe"), ["mixamorig:LeftToeBase"]);

        let bandai = names(
            "joint_Root Hips Spine Chest Neck Head Shoulder_L UpperArm_L LowerArm_L Hand_L \
             Shoulder_R UpperArm_R LowerArm_R Hand_R UpperLeg_L LowerLeg_L Foot_L Toes_L \
             UpperLeg_R LowerLeg_R Foot_R Toes_R",
        );
        let (c, m) = resolve(&bandai).unwrap();
        assert_eq!(c.name, "bandai");
        assert_eq!(m.len(), 20);
        assert_eq!(role(&m, "pelvis"), ["Hips"]);

        let smpl = names(
            "pelvis left_hip right_hip spine1 left_knee right_knee spine2 left_ankle \
             right_ankle spine3 left_foot right_foot neck left_collar right_collar head \
             left_shoulder right_shoulder left_elbow right_elbow left_wrist right_wrist",
        );
        let (c, m) = resolve(&smpl).unwrap();
        assert_eq!(c.name, "smpl");
        assert_eq!(role(&m, "left_toe"), ["left_foot"]);
        assert_eq!(role(&m, "left_shoulder"), ["left_shoulder"]);

        let unreal = names(
            "root pelvis spine_01 spine_02 spine_03 neck_01 head clavicle_l upperarm_l \
             lowerarm_l hand_l clavicle_r upperarm_r lowerarm_r hand_r thigh_l calf_l foot_l \
             ball_l thigh_r calf_r foot_r ball_r",
        );
        let (c, m) = resolve(&unreal).unwrap();
        assert_eq!(c.name, "unreal");
        assert_eq!(m.len(), 20);

        let biped: Vec<String> = [
            "Bip01",
            "Bip01 Pelvis",
            "Bip01 Spine",
            "Bip01 Neck",
            "Bip01 Head",
            "Bip01 L Clavicle",
            "Bip01 L UpperArm",
            "Bip01 L Forearm",
            "Bip01 L Hand",
            "Bip01 R Clavicle",
            "Bip01 R UpperArm",
            "Bip01 R Forearm",
            "Bip01 R Hand",
            "Bip01 L Thigh",
            "Bip01 L Calf",
            "Bip01 L Foot",
            "Bip01 L Toe0",
            "Bip01 R Thigh",
            "Bip01 R Calf",
            "Bip01 R Foot",
            "Bip01 R Toe0",
        ]
        .map(String::from)
        .into();
        let (c, m) = resolve(&biped).unwrap();
        assert_eq!(c.name, "biped");
        assert_eq!(m.len(), 20);
    }

    #[test]
    fn marker_roles_are_the_markers_around_a_joint() {
        let pig = names(
            "LFHD RFHD LBHD RBHD C7 T10 CLAV STRN RBAK LSHO LELB LWRA LWRB RSHO RELB RWRA RWRB \
             LASI RASI LPSI RPSI LTHI LKNE LTIB LANK LHEE LTOE RTHI RKNE RTIB RANK RHEE RTOE",
        );
        let (c, m) = resolve(&pig).unwrap();
        assert_eq!(c.name, "plug-in-gait");
        assert_eq!(role(&m, "pelvis"), ["LASI", "RASI", "LPSI", "RPSI"]);
        assert_eq!(role(&m, "head").len(), 4);
        assert_eq!(role(&m, "left_wrist"), ["LWRA", "LWRB"]);
        assert!(Role::limbs().iter().all(|r| m.contains_key(r)), "{m:?}");

        let opensim = names(
            "R.Shoulder L.Shoulder R.Elbow L.Elbow R.Wrist L.Wrist R.ASIS L.ASIS V.Sacral \
             R.Knee R.Knee.Medial R.Ankle R.Toe L.Knee L.Ankle L.Toe Top.Head",
        );
        let (c, m) = resolve(&opensim).unwrap();
        assert_eq!(c.name, "anatomical");
        assert_eq!(role(&m, "right_knee"), ["R.Knee", "R.Knee.Medial"]);
        assert_eq!(role(&m, "pelvis"), ["L.ASIS", "R.ASIS", "V.Sacral"]);
        assert!(resolve(&names("Base End")).is_none());
    }
}
