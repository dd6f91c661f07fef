//! Grasp candidates for one tube, checked against the scene; the best by clearance.
//!
//! Candidates start from the plain grasp from above ([`TubeAxisPose::grasp_frame`]): shifted
//! along the axis within the graspable body section and tilted about the axis within a cone.
//! Each candidate's fingers and palm, swept along the last approach segment, are measured
//! against the scene with parry3d's distance queries; a candidate closer than
//! [`PlannerSettings::min_clearance_mm`] to an obstacle is rejected for that obstacle's kind.

use crate::gripper::{GripperModel, GripperPart};
use crate::solid::TubeSolid;
use crate::terrain::{Terrain, TerrainSettings};
use nalgebra::Point3;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use parry3d_f64::query;
use parry3d_f64::shape::{Cuboid, HalfSpace, Shape};
use serde::{Deserialize, Serialize};
use tubeloc_core::{CoreError, GroundPlane, Pose, TubeAxisPose, TubeModel};

/// How candidates are sampled and ranked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlannerSettings {
    /// Half angle of the cone of approach tilts about the tube axis, degrees (0: from above only).
    pub tilt_cone_deg: f64,
    /// Step between tilts, degrees.
    pub tilt_step_deg: f64,
    /// Step between grasp points along the axis, millimetres.
    pub shift_step_mm: f64,
    /// A candidate closer than this to an obstacle is rejected, millimetres.
    pub min_clearance_mm: f64,
    /// Clearance beyond which more does not rank higher, millimetres: among candidates that
    /// clear the scene by at least this much (or by the best clearance less 0.25 mm), the one
    /// nearest the plain grasp (fewest tilt and shift steps) is chosen.
    pub enough_clearance_mm: f64,
    /// Below this seal-end confidence the graspable section is the part that is body whichever
    /// end is the seal end.
    pub min_end_confidence: f64,
    /// Terrain points are gathered this far (in the ground plane) from the tube centre, beyond
    /// the gripper's reach, millimetres.
    pub terrain_margin_mm: f64,
    /// Two located tubes whose solids interpenetrate by more than this cannot both be right,
    /// millimetres (the weaker one is rejected).
    pub tube_overlap_mm: f64,
    /// How stereo points become terrain columns.
    pub terrain: TerrainSettings,
}

impl Default for PlannerSettings {
    fn default() -> Self {
        PlannerSettings { tilt_cone_deg: 30.0, tilt_step_deg: 10.0, shift_step_mm: 10.0, min_clearance_mm: 1.0, enough_clearance_mm: 10.0, min_end_confidence: 0.6, terrain_margin_mm: 20.0, tube_overlap_mm: 3.0, terrain: TerrainSettings::default() }
    }
}

/// Candidates rejected, by the kind of obstacle found too close first (the kinds are searched
/// in the order ground, tube, terrain); the counts add up to the candidates rejected.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RejectionCounts {
    /// The ground plane.
    pub ground: usize,
    /// Another located tube.
    pub tube: usize,
    /// Terrain columns from the stereo points (rocks, sand).
    pub terrain: usize,
}

/// The outcome of the grasp check of one tube.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GraspCheck {
    /// Whether some candidate clears the scene by at least the minimum clearance.
    pub feasible: bool,
    /// The chosen grasp's smallest distance to the scene (fingers and palm swept along the last
    /// approach segment), millimetres; for an infeasible tube, that of the plain grasp as far
    /// as measured (0 when it touches).
    pub clearance_mm: f64,
    /// The chosen grasp frame, camera frame: origin on the tube axis, +x along the flip-free
    /// axis, +z the approach, +y the closing direction. The plain grasp from above when no
    /// candidate is feasible.
    #[serde(rename = "T_cam_grasp")]
    pub t_cam_grasp: Pose,
    /// Tilt of the chosen approach about the axis from the plain one, degrees.
    pub tilt_deg: f64,
    /// Shift of the chosen grasp point along the flip-free axis from the tube centre, millimetres.
    pub shift_mm: f64,
    /// Whether the chosen grasp differs from the plain grasp from above (tilted, shifted, or
    /// none feasible).
    pub changed: bool,
    /// Number of candidates measured.
    pub candidates_tried: usize,
    /// Rejected candidates by obstacle kind.
    pub rejected: RejectionCounts,
    /// Whether terrain points were checked (stereo); `false`: ground plane and other tubes only.
    pub terrain_checked: bool,
}

impl GraspCheck {
    /// The plain grasp from above, unchecked: not known to be feasible, no candidates tried,
    /// clearance 0. For tubes that were never checked (rejected before the grasp stage).
    pub fn unchecked(t_cam_grasp: Pose) -> Self {
        GraspCheck { feasible: false, clearance_mm: 0.0, t_cam_grasp, tilt_deg: 0.0, shift_mm: 0.0, changed: false, candidates_tried: 0, rejected: RejectionCounts::default(), terrain_checked: false }
    }
}

/// What is known around a tube (camera frame, metres).
#[derive(Clone, Copy, Debug)]
pub struct Scene<'a> {
    /// The ground plane (`n · X = d`, `n` up).
    pub ground: GroundPlane,
    /// The other located tubes (not the target).
    pub tubes: &'a [TubeAxisPose],
    /// Terrain columns from stereo points, if any.
    pub terrain: Option<&'a Terrain>,
}

/// Checks grasps of located tubes with one gripper and tube model.
#[derive(Clone, Debug)]
pub struct GraspPlanner {
    gripper: GripperModel,
    settings: PlannerSettings,
    model: TubeModel,
    /// Fingers and palm swept along the approach, grasp frame.
    swept: [GripperPart; 3],
}

/// The kind of an obstacle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Ground,
    Tube,
    Terrain,
}

impl GraspPlanner {
    /// A planner for `gripper` grasping tubes of `model`. Fails when the open fingers do not
    /// clear the tube's widest section or a setting is out of range (the error names it).
    pub fn new(gripper: GripperModel, settings: PlannerSettings, model: &TubeModel) -> Result<Self, CoreError> {
        gripper.validate()?;
        if gripper.grasp.opening <= 2.0 * model.max_radius() {
            return Err(CoreError::invalid("grasp.opening", format!("{} m does not clear the tube's widest section ({} m across)", gripper.grasp.opening, 2.0 * model.max_radius())));
        }
        let s = &settings;
        for (field, v, ok) in [
            ("tilt_cone_deg", s.tilt_cone_deg, (0.0..90.0).contains(&s.tilt_cone_deg)),
            ("tilt_step_deg", s.tilt_step_deg, s.tilt_step_deg > 0.0),
            ("shift_step_mm", s.shift_step_mm, s.shift_step_mm > 0.0),
            ("min_clearance_mm", s.min_clearance_mm, s.min_clearance_mm >= 0.0),
            ("enough_clearance_mm", s.enough_clearance_mm, s.enough_clearance_mm >= 0.0),
            ("min_end_confidence", s.min_end_confidence, (0.0..=1.0).contains(&s.min_end_confidence)),
            ("terrain_margin_mm", s.terrain_margin_mm, s.terrain_margin_mm >= 0.0),
            ("tube_overlap_mm", s.tube_overlap_mm, s.tube_overlap_mm >= 0.0),
        ] {
            if !(v.is_finite() && ok) {
                return Err(CoreError::invalid(format!("grasp planner {field}"), format!("{v} is out of range")));
            }
        }
        let swept = gripper.parts_swept(gripper.grasp.approach);
        Ok(GraspPlanner { gripper, settings, model: model.clone(), swept })
    }

    /// The gripper.
    pub fn gripper(&self) -> &GripperModel {
        &self.gripper
    }

    /// The settings.
    pub fn settings(&self) -> &PlannerSettings {
        &self.settings
    }

    /// Radius (in the ground plane) about a tube's centre within which terrain matters, metres:
    /// half the tube, the gripper's reach and the terrain margin.
    pub fn terrain_radius(&self) -> f64 {
        self.model.length / 2.0 + self.gripper.reach() + self.settings.terrain_margin_mm * 1e-3
    }

    /// The terrain around `tube` from stereo `points` (camera frame, metres) over `ground`,
    /// within [`GraspPlanner::terrain_radius`], leaving out the points on any of `tubes` (the
    /// located tubes, `tube` included; `metres_per_px`: a pixel's size at the tube's distance)
    /// ([`Terrain::from_points`]).
    pub fn terrain(&self, points: &[Point3<f64>], ground: &GroundPlane, tube: &TubeAxisPose, tubes: &[TubeAxisPose], metres_per_px: f64) -> Terrain {
        Terrain::from_points(points, ground, tube, self.terrain_radius(), tubes, &self.model, &self.settings.terrain, metres_per_px)
    }

    /// The graspable interval of the grasp point along the flip-free axis, metres from the
    /// centre: the body section (the longest) less half a finger width at each end; with a
    /// seal-end confidence below [`PlannerSettings::min_end_confidence`], the part that is body
    /// either way round. `None` when the fingers are wider than that part.
    pub fn graspable_interval(&self, tube: &TubeAxisPose) -> Option<(f64, f64)> {
        let body = self.model.sections.iter().max_by(|a, b| (a.z1 - a.z0).total_cmp(&(b.z1 - b.z0)))?;
        let (z0, z1) = self.model.section_z_in_tube_frame(body);
        // Tube-frame z runs toward the seal end; the grasp frame's x is the flip-free axis.
        let sign = if tube.end_direction.dot(&tube.axis) >= 0.0 { 1.0 } else { -1.0 };
        let (mut lo, mut hi) = if sign > 0.0 { (z0, z1) } else { (-z1, -z0) };
        if tube.end_confidence < self.settings.min_end_confidence {
            (lo, hi) = (lo.max(-hi), hi.min(-lo));
        }
        let half = self.gripper.finger.width / 2.0;
        (hi - lo >= 2.0 * half).then_some((lo + half, hi - half))
    }

    /// Checks the grasps of `tube` against `scene`; `up` is the upward direction (camera frame)
    /// that sets the plain approach from above ([`TubeAxisPose::grasp_frame`]).
    pub fn check(&self, tube: &TubeAxisPose, up: &Vector3<f64>, scene: &Scene) -> GraspCheck {
        let plain = tube.grasp_frame(up);
        let s = &self.settings;
        let (shift_step, tilt_step) = (s.shift_step_mm * 1e-3, s.tilt_step_deg.to_radians());
        let shifts: Vec<f64> = match self.graspable_interval(tube) {
            Some((lo, hi)) => {
                let centre = if (lo..=hi).contains(&0.0) { 0.0 } else { 0.5 * (lo + hi) };
                let mut v = vec![centre];
                for k in 1.. {
                    let (a, b) = (centre - k as f64 * shift_step, centre + k as f64 * shift_step);
                    let (ina, inb) = (a >= lo - 1e-12, b <= hi + 1e-12);
                    if !ina && !inb {
                        break;
                    }
                    v.extend(ina.then_some(a).into_iter().chain(inb.then_some(b)));
                }
                v
            }
            None => Vec::new(),
        };
        let n_tilts = (s.tilt_cone_deg / s.tilt_step_deg + 1e-9).floor() as i64;
        let tilts: Vec<f64> = std::iter::once(0.0).chain((1..=n_tilts).flat_map(|k| [-(k as f64) * tilt_step, k as f64 * tilt_step])).collect();
        let obstacles = self.obstacles(tube, scene);
        let (min_clear, cap) = (s.min_clearance_mm * 1e-3, s.enough_clearance_mm * 1e-3);
        let mut rejected = RejectionCounts::default();
        let mut tried = 0;
        // (clearance, steps from the plain grasp, frame, tilt, shift) of each free candidate.
        let mut free: Vec<(f64, f64, Isometry3<f64>, f64, f64)> = Vec::new();
        let mut plain_clearance = None;
        for (si, &shift) in shifts.iter().enumerate() {
            for (ti, &tilt) in tilts.iter().enumerate() {
                let local = Isometry3::from_parts(Vector3::new(shift, 0.0, 0.0).into(), UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt));
                let frame = plain.0 * local;
                tried += 1;
                let (clearance, hit) = self.clearance(&frame, &obstacles, min_clear, cap);
                if si == 0 && ti == 0 {
                    plain_clearance = Some(clearance);
                }
                match hit {
                    None => free.push((clearance, (tilt / tilt_step).abs().round() + (shift / shift_step).abs().round(), frame, tilt, shift)),
                    Some(Kind::Ground) => rejected.ground += 1,
                    Some(Kind::Tube) => rejected.tube += 1,
                    Some(Kind::Terrain) => rejected.terrain += 1,
                }
            }
        }
        let terrain_checked = scene.terrain.is_some_and(|t| t.measured_cells > 0);
        let best = free.iter().map(|c| c.0).fold(f64::NEG_INFINITY, f64::max);
        let good_enough = cap.min(best - 0.25e-3);
        let chosen = free.iter().filter(|c| c.0 >= good_enough).min_by(|a, b| a.1.total_cmp(&b.1).then(b.0.total_cmp(&a.0)));
        match chosen {
            Some(&(_, _, frame, tilt, shift)) => {
                // Measured again without the cap: the exact clearance of the chosen grasp.
                let clearance = self.clearance(&frame, &obstacles, min_clear, f64::INFINITY).0;
                GraspCheck { feasible: true, clearance_mm: clearance * 1e3, t_cam_grasp: Pose(frame), tilt_deg: tilt.to_degrees(), shift_mm: shift * 1e3, changed: tilt != 0.0 || shift != 0.0, candidates_tried: tried, rejected, terrain_checked }
            }
            None => GraspCheck { clearance_mm: plain_clearance.unwrap_or(0.0).max(0.0) * 1e3, changed: true, candidates_tried: tried, rejected, terrain_checked, ..GraspCheck::unchecked(plain) },
        }
    }

    /// The obstacles near `tube`: the ground as a half-space, the other tubes' sections, the
    /// terrain columns; each with its kind, placement, shape and bounding sphere (centre,
    /// radius) for pruning.
    fn obstacles<'a>(&self, tube: &TubeAxisPose, scene: &'a Scene) -> Vec<Obstacle<'a>> {
        let mut out = Vec::new();
        let g = &scene.ground;
        let ground_pose = Isometry3::translation(g.normal.x * g.offset, g.normal.y * g.offset, g.normal.z * g.offset);
        out.push(Obstacle { kind: Kind::Ground, pose: ground_pose, shape: ObstacleShape::Ground(HalfSpace::new(nalgebra::Unit::new_normalize(g.normal))), sphere: None });
        let near = self.model.length / 2.0 + self.gripper.reach() + self.gripper.grasp.approach + 0.05;
        for other in scene.tubes {
            let solid = TubeSolid::new(&self.model, other);
            if (solid.centre - tube.centre).norm() > near + solid.bounding_radius {
                continue;
            }
            for (pose, cyl) in solid.sections {
                let r = (cyl.half_height).hypot(cyl.radius);
                out.push(Obstacle { kind: Kind::Tube, pose, shape: ObstacleShape::Tube(cyl), sphere: Some((pose.translation.vector, r)) });
            }
        }
        if let Some(t) = scene.terrain {
            if let Some(c) = &t.columns {
                out.push(Obstacle { kind: Kind::Terrain, pose: t.pose, shape: ObstacleShape::Terrain(c, t.top), sphere: None });
            }
        }
        out
    }

    /// The smallest distance (metres, 0 when touching) of the swept gripper at `frame` to the
    /// obstacles, exact below `cap` (at least `cap` otherwise), and the kind of the first
    /// obstacle (ground, tube, terrain order) closer than `min_clear`, where the search stops.
    /// An obstacle is measured only when a lower bound on its distance (bounding spheres for
    /// tubes; for terrain, the part's lowest point above the highest column) is below what
    /// could change the answer.
    fn clearance(&self, frame: &Isometry3<f64>, obstacles: &[Obstacle], min_clear: f64, cap: f64) -> (f64, Option<Kind>) {
        let mut best = f64::INFINITY;
        let parts: [(Isometry3<f64>, &Cuboid, f64); 3] = self.swept.each_ref().map(|p| (frame * p.pose, &p.shape, p.shape.half_extents.norm()));
        for o in obstacles {
            let shape: &dyn Shape = match &o.shape {
                ObstacleShape::Ground(h) => h,
                ObstacleShape::Tube(c) => c,
                ObstacleShape::Terrain(c, _) => *c,
            };
            for (pose, cuboid, radius) in &parts {
                let needed = best.min(cap).max(min_clear);
                let bound = match (&o.shape, o.sphere) {
                    (_, Some((c, r))) => (c - pose.translation.vector).norm() - r - radius,
                    (ObstacleShape::Terrain(_, top), None) => {
                        // Lowest point of the box in the height-map frame, above the highest column.
                        let local = o.pose.inverse() * pose;
                        let r = local.rotation.to_rotation_matrix();
                        let reach: f64 = (0..3).map(|i| r[(2, i)].abs() * cuboid.half_extents[i]).sum();
                        local.translation.z - reach - top
                    }
                    _ => f64::NEG_INFINITY,
                };
                if bound >= needed {
                    continue;
                }
                let d = query::distance(pose, *cuboid, &o.pose, shape).unwrap_or(0.0).max(0.0);
                best = best.min(d);
                if d < min_clear {
                    return (best, Some(o.kind));
                }
            }
        }
        (best, None)
    }
}

enum ObstacleShape<'a> {
    Ground(HalfSpace),
    Tube(parry3d_f64::shape::Cylinder),
    /// Columns and their top height above the ground (height-map frame), metres.
    Terrain(&'a parry3d_f64::shape::Compound, f64),
}

struct Obstacle<'a> {
    kind: Kind,
    pose: Isometry3<f64>,
    shape: ObstacleShape<'a>,
    sphere: Option<(Vector3<f64>, f64)>,
}
