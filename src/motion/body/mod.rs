//! A take's body: which of its points play which anatomical role ([`Roles`]), and what
//! the body says of the coordinates ([`Axes`]: up, forward, the floor). Everything that
//! turns, moves or maps a take reads these instead of guessing from the figure's extent.
//!
//! Roles are a function of names (and a skeleton's shape), so they are read again from a
//! take's point names or stored skeleton whenever needed; axes need the frames, so they are
//! derived once (at ingest, or at the first read of a take stored before) and stored.
//!
//! Up is anatomy's call: the head above the pelvis above the ankles, frame after frame. A
//! file format's convention (BVH is Y-up, lab C3D Z-up) is only the prior used when
//! anatomy cannot decide, and what a user states wins over both.

pub mod axis;
pub mod names;
pub mod roles;
mod topology;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

pub use axis::Axis;
pub use roles::{Part, Role, RoleMap, Side};

use crate::motion::skeleton::Joint;
use crate::motion::Motion;

/// Which points play which role, and by what convention they were read.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Roles {
    /// The naming convention that placed the roles (`cmu`, `mixamo`, `plug-in-gait`, …);
    /// `topology` when only the hierarchy's shape did; absent when nothing did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub convention: Option<String>,
    pub roles: RoleMap,
    /// Roles no point plays, in [`Role::all`]'s order.
    pub unplaced: Vec<Role>,
    /// Roles a user set (by PATCH), which no convention or shape overrides.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub given: Vec<Role>,
}

impl Roles {
    fn finish(convention: Option<String>, roles: RoleMap) -> Roles {
        let unplaced = Role::all()
            .into_iter()
            .filter(|r| !roles.contains_key(r))
            .collect();
        Roles {
            convention,
            roles,
            unplaced,
            given: Vec::new(),
        }
    }

    /// These roles with `given` ones in their place: a role listed with points is played
    /// by them, one listed with none is played by nothing.
    pub fn with_given(self, given: &RoleMap) -> Roles {
        if given.is_empty() {
            return self;
        }
        let mut roles = self.roles;
        for (role, names) in given {
            if names.is_empty() {
                roles.remove(role);
            } else {
                roles.insert(*role, names.clone());
            }
        }
        Roles {
            given: given.keys().copied().collect(),
            ..Roles::finish(self.convention, roles)
        }
    }

    /// The roles of a marker take: its point names read by the convention that places the
    /// most.
    pub fn of_markers(names: &[String]) -> Roles {
        match names::resolve(names) {
            Some((c, roles)) => Roles::finish(Some(c.name.to_string()), roles),
            None => Roles::finish(None, RoleMap::new()),
        }
    }

    /// The roles of a skeleton: its joints' names read by the convention that places the
    /// most; roles still unplaced are taken from the hierarchy's shape where it places them
    /// on joints no role has yet.
    pub fn of_skeleton(joints: &[Joint]) -> Roles {
        let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
        let (convention, mut roles) = match names::resolve(&names) {
            Some((c, roles)) => (Some(c.name.to_string()), roles),
            None => (None, RoleMap::new()),
        };
        if roles.len() < Role::all().len() {
            let shaped = topology::roles(joints);
            let mut used: Vec<String> = roles.values().flatten().cloned().collect();
            let mut added = false;
            for (role, idx) in shaped {
                let names: Vec<String> = idx.iter().map(|&i| joints[i].name.clone()).collect();
                if roles.contains_key(&role) || names.iter().any(|n| used.contains(n)) {
                    continue;
                }
                used.extend(names.iter().cloned());
                roles.insert(role, names);
                added = true;
            }
            if added && convention.is_none() {
                return Roles::finish(Some("topology".into()), roles);
            }
        }
        Roles::finish(convention, roles)
    }

    /// The points that play `role` (indices into `names`).
    pub fn points(&self, role: Role, names: &[String]) -> Vec<usize> {
        self.roles.get(&role).map_or_else(Vec::new, |want| {
            want.iter()
                .filter_map(|w| names.iter().position(|n| n == w))
                .collect()
        })
    }

    /// For each role of [`Role::all`], the points among `names` that play it (indices),
    /// empty where none does: what [`centroids`] takes.
    pub fn placed_in(&self, names: &[String]) -> Vec<Vec<usize>> {
        Role::all()
            .into_iter()
            .map(|r| self.points(r, names))
            .collect()
    }

    /// The limb roles ([`Role::limbs`]) not placed.
    pub fn missing_limbs(&self) -> Vec<Role> {
        Role::limbs()
            .into_iter()
            .filter(|r| !self.roles.contains_key(r))
            .collect()
    }
}

/// A take's body: its axes and its roles, as the API shows them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Body {
    #[serde(flatten)]
    pub axes: Axes,
    #[serde(flatten)]
    pub roles: Roles,
}

impl Body {
    /// The roles of take `m` (its skeleton's, or its point names'), and its axes by them.
    pub fn of(m: &Motion, given: Given, prior: Option<&Prior>) -> crate::motion::Result<Body> {
        let roles = roles_of(m);
        let joints = m.skeleton.as_ref().map(|s| s.joints.as_slice());
        let axes = derive(m, joints, &roles, given, prior)?;
        Ok(Body { axes, roles })
    }
}

/// The roles of take `m`: its skeleton's, or its point names'.
pub fn roles_of(m: &Motion) -> Roles {
    match &m.skeleton {
        Some(s) => Roles::of_skeleton(&s.joints),
        None => Roles::of_markers(&m.point_names),
    }
}

/// What settled an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// The body's own posture across the take.
    Anatomy,
    /// Points no role names, standing on the lab's floor: their lowest ones steady at the
    /// origin's height, the cloud a person's height above it.
    Floor,
    /// The file format's convention (BVH Y-up, C3D Z-up or its `POINT:Y_SCREEN`).
    Format,
    /// The user, at ingest or by a correction.
    Given,
}

/// What a file format says of up, before anatomy is looked at.
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    pub up: Axis,
    /// Why, for the record: "BVH is Y-up by convention".
    pub says: String,
}

/// What a user states: it wins over anatomy and format.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Given {
    pub up: Option<Axis>,
    pub forward: Option<Axis>,
}

impl Given {
    /// Up and forward must lie across each other.
    pub fn check(&self) -> Result<(), String> {
        match (self.up, self.forward) {
            (Some(u), Some(f)) if u.index() == f.index() => Err(format!(
                "forward={f} lies along up={u}: forward must be horizontal"
            )),
            _ => Ok(()),
        }
    }
}

/// A take's axes in its own coordinates, and how each was settled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axes {
    /// The axis pointing up; `None` when nothing decided (see `reason`).
    pub up: Option<Axis>,
    /// The horizontal axis the body faces along over the take (or at its start).
    pub forward: Option<Axis>,
    /// The floor's height along `up` (the coordinate along it, signed as it is), in metres:
    /// where the lowest foot points stand.
    pub floor_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up_from: Option<Source>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub forward_from: Option<Source>,
    /// What settled up, or why nothing did; and what was not settled.
    pub reason: String,
}

/// Frames looked at when deriving axes: evenly spread, the ends included.
const SAMPLED_FRAMES: usize = 600;
/// The share of looked-at frames that must agree on up for anatomy to decide it.
const UP_AGREEMENT: f64 = 0.6;
/// How near an axis the body's top-to-bottom line must point in a frame to stand along it
/// (cos 60°): a sprinter leaning 45° stands along two axes, and the floor decides.
const UPRIGHT_COS: f64 = 0.5;
/// How far (metres, 10th to 90th percentile) the lowest foot points of a take wander along
/// an axis they keep a floor along.
const FLOOR_WANDER_M: f64 = 0.1;
/// How far they wander along an axis the body travels along rather than stands on (a
/// jump lifts them less, and comes back down).
const TRAVEL_M: f64 = 0.5;
/// Points with no roles stand on the floor along an axis when their lowest point keeps
/// within this band (metres, 10th to 90th percentile over the take) near the origin's
/// height ([`FLOOR_AT_ORIGIN_M`]) and the cloud stands [`FLOOR_HEIGHT_M`] above it: labs
/// calibrate with the origin on the floor.
const FLOOR_BAND_M: f64 = 0.08;
const FLOOR_AT_ORIGIN_M: f64 = 0.15;
const FLOOR_HEIGHT_M: std::ops::RangeInclusive<f64> = 1.0..=2.3;
/// How consistently the body must face one way over the take for that to be its forward
/// (the length of the mean facing direction); else its first second decides.
const FACING_AGREEMENT: f64 = 0.5;

/// The axes of take `m` by its `roles`. `joints`, a skeleton take's (whether `m` carries
/// its animation or only its points), let the floor be found under the ankles' children
/// too: the end sites of toes and heels. `given` wins, then anatomy, then `prior`.
/// `Invalid`: what was given contradicts itself.
pub fn derive(
    m: &Motion,
    joints: Option<&[Joint]>,
    roles: &Roles,
    given: Given,
    prior: Option<&Prior>,
) -> crate::motion::Result<Axes> {
    given.check().map_err(crate::motion::Error::Invalid)?;
    let figure = Figure::new(m.positions(), &m.point_names, roles, joints);
    let (metres_per_unit, fps) = (m.unit.metres_per_unit, m.fps);
    let mut notes = Vec::new();
    let (up, up_from) = match (given.up, figure.up(metres_per_unit)) {
        (Some(u), _) => {
            notes.push(format!("up {u} as given"));
            (Some(u), Some(Source::Given))
        }
        (
            None,
            Ok(Upright::Anatomy {
                up,
                over,
                share,
                note,
            }),
        ) => {
            notes.push(format!(
                "up {up}: the {over} along {up} in {:.0}% of frames{note}",
                share * 100.0
            ));
            (Some(up), Some(Source::Anatomy))
        }
        (None, Ok(Upright::Floor { up, height_m })) => {
            notes.push(format!(
                "up {up}: no roles, but the points stand on the floor at the origin along \
                 {up}, {height_m:.2} m tall"
            ));
            (Some(up), Some(Source::Floor))
        }
        (None, Err(why)) => match prior {
            Some(p) => {
                notes.push(format!("up {} because {}: {why}", p.up, p.says));
                (Some(p.up), Some(Source::Format))
            }
            None => {
                notes.push(format!("up unknown: {why}, and the format has no convention; give up= at ingest or by PATCH"));
                (None, None)
            }
        },
    };
    let (forward, forward_from) = match (given.forward, up) {
        (Some(f), _) => (Some(f), Some(Source::Given)),
        (None, Some(u)) => match figure.forward(u, fps) {
            Ok(f) => (Some(f), Some(Source::Anatomy)),
            Err(why) => {
                notes.push(format!("forward unknown: {why}"));
                (None, None)
            }
        },
        (None, None) => (None, None),
    };
    let floor_m = up
        .and_then(|u| figure.floor(u))
        .map(|h| h * metres_per_unit);
    Ok(Axes {
        up,
        forward,
        floor_m,
        up_from,
        forward_from,
        reason: notes.join("; "),
    })
}

/// The frames of a take as its roles' places.
struct Figure<'a> {
    positions: &'a [f32],
    points: usize,
    /// The body's parts from the top down, as a standing body holds them: the top and
    /// the bottom ones present tell up.
    levels: Vec<Layer>,
    pelvis: Vec<usize>,
    /// Left then right of a pair of the same part, for telling the body's sides apart.
    sides: Vec<(Vec<usize>, Vec<usize>)>,
    /// Toes and the ankles they belong to, for the way the feet point.
    toes: Vec<(Vec<usize>, Vec<usize>)>,
    /// Points at the bottom of the legs: the floor is under them.
    feet: Vec<usize>,
}

impl<'a> Figure<'a> {
    fn new(
        positions: &'a [f32],
        names: &[String],
        roles: &Roles,
        joints: Option<&[Joint]>,
    ) -> Figure<'a> {
        let at = |r: Role| roles.points(r, names);
        let limb = |p: Part| -> Vec<usize> {
            let mut v = at(Role::left(p));
            v.extend(at(Role::right(p)));
            v
        };
        let mut shoulders = limb(Part::Shoulder);
        shoulders.extend(limb(Part::Clavicle));
        let mut pelvis = at(Role::Pelvis);
        pelvis.extend(limb(Part::Hip));
        let mut levels = vec![
            (Level::Head, at(Role::Head)),
            (Level::Neck, at(Role::Neck)),
            (Level::Shoulders, shoulders),
            (Level::Spine, at(Role::Spine)),
            (Level::Pelvis, pelvis),
            (Level::Knees, limb(Part::Knee)),
            (Level::Ankles, limb(Part::Ankle)),
            (Level::Toes, limb(Part::Toe)),
        ];
        // A point plays its highest part (a marker set's C7 is neck and spine).
        let mut seen: Vec<usize> = Vec::new();
        for (_, v) in levels.iter_mut() {
            v.retain(|p| !seen.contains(p));
            seen.extend(v.iter().copied());
        }
        levels.retain(|(_, v)| !v.is_empty());
        let sides = [Part::Hip, Part::Shoulder]
            .into_iter()
            .map(|p| (at(Role::left(p)), at(Role::right(p))))
            .filter(|(l, r)| !l.is_empty() && !r.is_empty())
            .collect();
        let toes = Side::BOTH
            .into_iter()
            .map(|s| (at(Role::Limb(s, Part::Ankle)), at(Role::Limb(s, Part::Toe))))
            .filter(|(a, t)| !a.is_empty() && !t.is_empty())
            .collect();
        let mut feet = limb(Part::Ankle);
        feet.extend(limb(Part::Toe));
        if let Some(joints) = joints {
            // The end sites and joints below an ankle: a toe's tip, a heel.
            for (i, j) in joints.iter().enumerate() {
                if let Some(p) = j.parent {
                    if feet.contains(&p) && !feet.contains(&i) {
                        feet.push(i);
                    }
                }
            }
        }
        Figure {
            positions,
            points: names.len(),
            levels,
            pelvis: at(Role::Pelvis),
            sides,
            toes,
            feet,
        }
    }

    fn frames(&self) -> usize {
        match self.points {
            0 => 0,
            n => self.positions.len() / (n * 3),
        }
    }

    /// Up to [`SAMPLED_FRAMES`] frames, evenly spread over `range`.
    fn sampled(range: std::ops::Range<usize>) -> impl Iterator<Item = usize> {
        let n = range.len();
        let k = n.min(SAMPLED_FRAMES);
        (0..k).map(move |i| range.start + if k > 1 { i * (n - 1) / (k - 1) } else { 0 })
    }

    /// Point `p` in frame `f`, unless it is missing there: not finite, or at exactly the
    /// origin (how many C3D writers leave a marker never seen: valid residual, 0, 0, 0).
    fn at(&self, f: usize, p: usize) -> Option<Vector3<f64>> {
        let i = (f * self.points + p) * 3;
        let v = &self.positions[i..i + 3];
        let all_zero = v.iter().all(|x| *x == 0.0);
        (v.iter().all(|x| x.is_finite()) && !all_zero)
            .then(|| Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])))
    }

    /// The centroid of the points of `set` present in frame `f`.
    fn centroid(&self, f: usize, set: &[usize]) -> Option<Vector3<f64>> {
        let mut sum = Vector3::zeros();
        let mut k = 0;
        for v in set.iter().filter_map(|&p| self.at(f, p)) {
            sum += v;
            k += 1;
        }
        (k > 0).then(|| sum / k as f64)
    }

    /// The lowest of `set` along `a` in each looked-at frame that has one.
    fn lows(&self, set: &[usize], a: Axis) -> Vec<f64> {
        Self::sampled(0..self.frames())
            .filter_map(|f| {
                set.iter()
                    .filter_map(|&p| self.at(f, p))
                    .map(|v| a.vector().dot(&v))
                    .min_by(f64::total_cmp)
            })
            .collect()
    }

    /// The part to read up from, top down, and the one to read it against: the highest
    /// of head, neck, shoulders and pelvis present, and the lowest of ankles, toes,
    /// knees, pelvis and spine below it (the ankles before the toes, which reach ahead).
    fn top_and_bottom(&self) -> Option<(&Layer, &Layer)> {
        let present = |set: &[usize]| {
            Self::sampled(0..self.frames()).any(|f| self.centroid(f, set).is_some())
        };
        let levels: Vec<&Layer> = self.levels.iter().filter(|(_, v)| present(v)).collect();
        let top = *levels.iter().find(|(l, _)| {
            matches!(
                l,
                Level::Head | Level::Neck | Level::Shoulders | Level::Pelvis
            )
        })?;
        let bottom = [
            Level::Ankles,
            Level::Toes,
            Level::Knees,
            Level::Pelvis,
            Level::Spine,
        ]
        .into_iter()
        .filter(|b| *b > top.0)
        .find_map(|b| levels.iter().find(|(l, _)| *l == b))?;
        Some((top, bottom))
    }

    /// Up from anatomy (the top part over the bottom one, the pelvis between them, frame
    /// after frame), or for points no role names from the floor they stand on; or why
    /// neither can say. `metres_per_unit` scales the floor's tolerances.
    fn up(&self, metres_per_unit: f64) -> Result<Upright, String> {
        let Some(((top, tops), (bottom, bottoms))) = self.top_and_bottom() else {
            return match self.standing(metres_per_unit) {
                Some((up, height_m)) => Ok(Upright::Floor { up, height_m }),
                None => Err(
                    "no head over feet (or shoulders or pelvis over what is below \
                             them) to tell up by, and the points stand on no floor"
                        .into(),
                ),
            };
        };
        let pelvis = (*top < Level::Pelvis && Level::Pelvis < *bottom)
            .then_some(self.pelvis.as_slice())
            .filter(|p| !p.is_empty());
        // Per axis: frames where the top is above the bottom along it, and of those, where
        // the body stands within 60° of it with the pelvis between them (a sprinter in the
        // blocks has the head over the feet, but the hips above the head).
        let (mut over, mut upright) = ([0usize; 6], [0usize; 6]);
        let mut looked = 0;
        for f in Self::sampled(0..self.frames()) {
            let (Some(t), Some(b)) = (self.centroid(f, tops), self.centroid(f, bottoms)) else {
                continue;
            };
            let d = t - b;
            if d.norm() == 0.0 {
                continue;
            }
            looked += 1;
            let p = pelvis.and_then(|set| self.centroid(f, set));
            for (k, a) in Axis::all().into_iter().enumerate() {
                let along = |v: Vector3<f64>| a.vector().dot(&v);
                let between = p.is_none_or(|p| along(t - p) > 0.0 && along(p - b) > 0.0);
                if along(d) > 0.0 {
                    over[k] += 1;
                    if between && along(d) / d.norm() >= UPRIGHT_COS {
                        upright[k] += 1;
                    }
                }
            }
        }
        let parts = format!("{} above the {}", top.name(), bottom.name());
        if looked == 0 {
            return Err(format!(
                "no frame has both the {} and the {}",
                top.name(),
                bottom.name()
            ));
        }
        let share = |counts: &[usize; 6], k: usize| counts[k] as f64 / looked as f64;
        // How far the lowest foot points wander along an axis (metres): a floor keeps them
        // within centimetres; an axis the body travels along spreads them over metres.
        let feet = if self.feet.is_empty() {
            bottoms
        } else {
            &self.feet
        };
        let wander = |k: usize| band(self.lows(feet, Axis::all()[k])) * metres_per_unit;
        let steadiest = (0..6)
            .filter(|&k| share(&over, k) >= UP_AGREEMENT)
            .min_by(|&x, &y| wander(x).total_cmp(&wander(y)));
        let most_upright = (0..6)
            .max_by(|&x, &y| share(&upright, x).total_cmp(&share(&upright, y)))
            .filter(|&k| share(&upright, k) >= UP_AGREEMENT);
        let (best, how) = match (most_upright, steadiest) {
            (Some(u), Some(s)) if s != u && wander(u) > TRAVEL_M && wander(s) <= FLOOR_WANDER_M => {
                (
                    s,
                    format!(
                        "; it leans along {} more than it stands, but its feet keep a floor \
                     along {} ({:.0} mm, against {:.0} mm)",
                        Axis::all()[u],
                        Axis::all()[s],
                        wander(s) * 1000.0,
                        wander(u) * 1000.0
                    ),
                )
            }
            (Some(u), _) => (u, String::new()),
            (None, Some(s)) if wander(s) <= FLOOR_WANDER_M => (
                s,
                format!(
                    "; it seldom stands upright, but its feet keep a floor along {} ({:.0} mm)",
                    Axis::all()[s],
                    wander(s) * 1000.0
                ),
            ),
            _ => {
                let most = (0..6).map(|k| share(&upright, k)).fold(0.0, f64::max);
                return Err(format!(
                    "the {parts} within 60° of one axis in only {:.0}% of frames, and its \
                     feet keep no floor",
                    most * 100.0
                ));
            }
        };
        Ok(Upright::Anatomy {
            up: Axis::all()[best],
            over: parts,
            share: share(&over, best),
            note: how,
        })
    }

    /// The axis the points stand along on the lab's floor, and how tall they stand
    /// (metres), when exactly one axis fits: see [`FLOOR_BAND_M`].
    fn standing(&self, metres_per_unit: f64) -> Option<(Axis, f64)> {
        let all: Vec<usize> = (0..self.points).collect();
        let fits: Vec<(Axis, f64)> = Axis::all()
            .into_iter()
            .filter_map(|a| {
                let lows = self.lows(&all, a);
                let highs = self.lows(&all, a.flipped());
                if lows.is_empty() || lows.len() != highs.len() {
                    return None;
                }
                let mut heights: Vec<f64> =
                    lows.iter().zip(&highs).map(|(lo, hi)| -hi - lo).collect();
                let height = median(&mut heights) * metres_per_unit;
                let at = median(&mut lows.clone()) * metres_per_unit;
                let steady = band(lows) * metres_per_unit <= FLOOR_BAND_M;
                (steady && at.abs() <= FLOOR_AT_ORIGIN_M && FLOOR_HEIGHT_M.contains(&height))
                    .then_some((a, height))
            })
            .collect();
        match fits.as_slice() {
            [one] => Some(*one),
            _ => None,
        }
    }

    /// The way the body faces in frame `f` across `up` (unit), from its left-right pairs
    /// (forward = up × (right − left)), or from the feet.
    fn facing(&self, f: usize, up: &Vector3<f64>) -> Option<Vector3<f64>> {
        let flat = |v: Vector3<f64>| v - up * v.dot(up);
        let mut across = Vector3::zeros();
        for (l, r) in &self.sides {
            if let (Some(a), Some(b)) = (self.centroid(f, l), self.centroid(f, r)) {
                let d = flat(b - a);
                if d.norm() > 0.0 {
                    across += d.normalize();
                }
            }
        }
        let dir = if across.norm() > 0.0 {
            up.cross(&across)
        } else {
            let mut ahead = Vector3::zeros();
            for (a, t) in &self.toes {
                if let (Some(a), Some(t)) = (self.centroid(f, a), self.centroid(f, t)) {
                    ahead += flat(t - a);
                }
            }
            ahead
        };
        (dir.norm() > 0.0).then(|| dir.normalize())
    }

    /// Forward from the way the body faces: over the take when it keeps to one way, else
    /// over its first second.
    fn forward(&self, up: Axis, fps: f64) -> Result<Axis, String> {
        if self.sides.is_empty() && self.toes.is_empty() {
            return Err("no hips, shoulders or feet to tell it by".into());
        }
        let u = up.vector();
        let mean = |range: std::ops::Range<usize>| {
            let (mut sum, mut k) = (Vector3::zeros(), 0usize);
            for f in Self::sampled(range) {
                if let Some(d) = self.facing(f, &u) {
                    sum += d;
                    k += 1;
                }
            }
            (k > 0).then(|| sum / k as f64)
        };
        let frames = self.frames();
        let first_second = 0..frames.min((fps.round() as usize).max(1));
        let dir = match mean(0..frames) {
            Some(m) if m.norm() >= FACING_AGREEMENT => m,
            Some(_) => match mean(first_second) {
                Some(m) if m.norm() >= FACING_AGREEMENT => m,
                _ => return Err("the body faces no one way, even in its first second".into()),
            },
            None => return Err("no frame has both sides of the body".into()),
        };
        let mut flat = dir;
        flat[up.index()] = 0.0;
        Axis::nearest(&flat).ok_or_else(|| "the body faces straight up".into())
    }

    /// The floor's height along `up` (file units): a low percentile of each looked-at
    /// frame's lowest foot point (all points when no feet are known), so that a glitch
    /// does not sink it and a jump does not lift it.
    fn floor(&self, up: Axis) -> Option<f64> {
        let all: Vec<usize>;
        let feet = if self.feet.is_empty() {
            all = (0..self.points).collect();
            &all
        } else {
            &self.feet
        };
        let mut lows = self.lows(feet, up);
        if lows.is_empty() {
            return None;
        }
        lows.sort_by(f64::total_cmp);
        Some(lows[lows.len() / 50])
    }
}

/// A level of the body and its points.
type Layer = (Level, Vec<usize>);

/// A part of a standing body, from the top down.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Level {
    Head,
    Neck,
    Shoulders,
    Spine,
    Pelvis,
    Knees,
    Ankles,
    Toes,
}

impl Level {
    fn name(self) -> &'static str {
        match self {
            Level::Head => "head",
            Level::Neck => "neck",
            Level::Shoulders => "shoulders",
            Level::Spine => "spine",
            Level::Pelvis => "pelvis",
            Level::Knees => "knees",
            Level::Ankles => "ankles",
            Level::Toes => "toes",
        }
    }
}

/// What settled up without a user or a format.
enum Upright {
    /// The parts `over` each other along `up` in a `share` of frames; `note`: why this
    /// axis when the body leans along another.
    Anatomy {
        up: Axis,
        over: String,
        share: f64,
        note: String,
    },
    /// Points no role names, on the floor along `up`, `height_m` tall.
    Floor { up: Axis, height_m: f64 },
}

/// The spread of `v` from its 10th to its 90th percentile (∞ when empty).
fn band(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::INFINITY;
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    at(0.9) - at(0.1)
}

/// The median of `v` (sorted in place; non-empty).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One point per group of `groups` (indices into a frame's `points` points): the centroid
/// of the group's points present in each frame, NaN where none is or the group is empty.
/// What a take's body roles make of its points ([`Roles::placed_in`]): one point per role.
pub fn centroids(positions: &[f32], points: usize, groups: &[Vec<usize>]) -> Vec<f32> {
    let width = points * 3;
    if width == 0 {
        return Vec::new();
    }
    let frames = positions.len() / width;
    let mut out = vec![f32::NAN; frames * groups.len() * 3];
    for (f, frame) in positions.chunks_exact(width).enumerate() {
        for (g, idx) in groups.iter().enumerate() {
            let mut sum = [0f64; 3];
            let mut n = 0usize;
            for &p in idx {
                let v = &frame[p * 3..p * 3 + 3];
                if v.iter().any(|x| x.is_nan()) {
                    continue;
                }
                for k in 0..3 {
                    sum[k] += f64::from(v[k]);
                }
                n += 1;
            }
            if n > 0 {
                let o = (f * groups.len() + g) * 3;
                for k in 0..3 {
                    out[o + k] = (sum[k] / n as f64) as f32;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests;
