//! The Foxglove messages derived from each state: the 3D scene, the frame transforms and the
//! poses, built from the Foxglove SDK's own message types (`foxglove::messages`, protobuf).
//!
//! Frame `world` is the plant's: x east, y north, z up. A pose is planar: the yaw ψ as a
//! quaternion about +z, `(0, 0, sin ψ/2, cos ψ/2)`; roll and pitch are not drawn.

use super::{RecordMeta, VehicleBox, WORLD_FRAME};
use crate::msg::StateEstimate;
use dynamics::road::Obstacle;
use foxglove::messages::{
    line_primitive, ArrowPrimitive, Color, CubePrimitive, Duration, FrameTransform,
    FrameTransforms, KeyValuePair, LinePrimitive, Point3, Pose, PoseInFrame, Quaternion,
    SceneEntity, SceneUpdate, TextPrimitive, Timestamp, Vector3,
};

/// The child frame of the bullet's transform on `/tf` (and the frame to follow it in a viewer).
pub const BULLET_FRAME: &str = "bullet";
/// The child frame of the target's transform on `/tf`.
pub const TARGET_FRAME: &str = "target";
/// The entity ids on `/scene` (an obstacle's is `obstacle/<index>`).
pub mod entity {
    pub const BULLET: &str = "bullet";
    pub const TARGET: &str = "target";
    pub const CONTACT: &str = "contact";
    pub const ROAD: &str = "road";
    pub const OBSTACLE_PREFIX: &str = "obstacle/";
}
/// Obstacles are drawn this tall (m); the scenario gives only their footprint.
pub const OBSTACLE_HEIGHT: f64 = 1.5;

const BULLET_COLOR: Color = rgba(0.15, 0.45, 0.95, 0.9);
const TARGET_COLOR: Color = rgba(0.95, 0.3, 0.15, 0.9);
const OBSTACLE_COLOR: Color = rgba(0.45, 0.45, 0.45, 0.9);
const CONTACT_COLOR: Color = rgba(0.6, 0.2, 0.85, 1.0);
const EDGE_COLOR: Color = rgba(0.85, 0.85, 0.85, 1.0);
const CENTRE_COLOR: Color = rgba(1.0, 0.85, 0.1, 1.0);
const LABEL_COLOR: Color = rgba(1.0, 1.0, 1.0, 1.0);

const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// A vehicle-clock time in ns as a Foxglove timestamp (seconds saturate at `u32::MAX`).
#[must_use]
pub fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

/// The rotation by `yaw` (rad) about +z.
#[must_use]
pub fn yaw_quaternion(yaw: f64) -> Quaternion {
    let (s, c) = (0.5 * yaw).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

/// A planar pose: position `(x, y, z)`, heading `yaw` about +z.
#[must_use]
pub fn planar_pose(x: f64, y: f64, z: f64, yaw: f64) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(yaw_quaternion(yaw)),
    }
}

/// The point `(dx, dy)` of a body with c.g. `(x, y)` and heading `yaw`, in the world.
fn body_to_world(x: f64, y: f64, yaw: f64, dx: f64, dy: f64) -> (f64, f64) {
    let (s, c) = yaw.sin_cos();
    (x + c * dx - s * dy, y + s * dx + c * dy)
}

/// The planar poses `(x, y, ψ)` of both vehicles in a state, or `None` when one is not finite.
#[must_use]
pub fn vehicle_poses(s: &StateEstimate) -> Option<([f64; 3], [f64; 3])> {
    let bullet = [s.bullet[0], s.bullet[1], s.bullet[2]];
    let target = [s.target[6], s.target[7], s.target[2]];
    bullet
        .iter()
        .chain(&target)
        .all(|v| v.is_finite())
        .then_some((bullet, target))
}

fn text(pose: Pose, label: &str) -> TextPrimitive {
    TextPrimitive {
        pose: Some(pose),
        billboard: true,
        font_size: 14.0,
        scale_invariant: true,
        color: Some(LABEL_COLOR),
        text: label.to_owned(),
    }
}

fn entity(id: &str, stamp: Timestamp) -> SceneEntity {
    SceneEntity {
        timestamp: Some(stamp),
        frame_id: WORLD_FRAME.to_owned(),
        id: id.to_owned(),
        // Zero: shown until replaced (every state replaces the moving entities).
        lifetime: Some(Duration::new(0, 0)),
        ..SceneEntity::default()
    }
}

/// A vehicle: a cube of its size over its footprint (`cg_to_front` ahead of the c.g. is the
/// front) at half its height, and a label over the c.g.
fn vehicle_entity(
    id: &str,
    stamp: Timestamp,
    pose: [f64; 3],
    size: VehicleBox,
    color: Color,
) -> SceneEntity {
    let [x, y, yaw] = pose;
    let (cx, cy) = body_to_world(x, y, yaw, size.cg_to_front - 0.5 * size.length, 0.0);
    SceneEntity {
        metadata: vec![KeyValuePair {
            key: "vehicle".to_owned(),
            value: id.to_owned(),
        }],
        cubes: vec![CubePrimitive {
            pose: Some(planar_pose(cx, cy, 0.5 * size.height, yaw)),
            size: Some(Vector3 {
                x: size.length,
                y: size.width,
                z: size.height,
            }),
            color: Some(color),
        }],
        texts: vec![text(planar_pose(x, y, size.height + 0.6, yaw), id)],
        ..entity(id, stamp)
    }
}

/// An obstacle at scenario time `t` (s): a grey box on its footprint, moving with its velocity.
fn obstacle_entity(index: usize, stamp: Timestamp, ob: &Obstacle, t: f64) -> SceneEntity {
    let id = format!("{}{index}", entity::OBSTACLE_PREFIX);
    SceneEntity {
        cubes: vec![CubePrimitive {
            pose: Some(planar_pose(
                ob.x + ob.vx * t,
                ob.y + ob.vy * t,
                0.5 * OBSTACLE_HEIGHT,
                ob.heading,
            )),
            size: Some(Vector3 {
                x: ob.length,
                y: ob.width,
                z: OBSTACLE_HEIGHT,
            }),
            color: Some(OBSTACLE_COLOR),
        }],
        ..entity(&id, stamp)
    }
}

/// The contact force on the target as an arrow whose head touches the contact point, drawn
/// at half the target's height, `scale` m per N long (at least 0.3 m). `None` apart or when
/// a number is not finite.
fn contact_arrow(
    s: &StateEstimate,
    target_pose: [f64; 3],
    target: VehicleBox,
    scale: f64,
) -> Option<ArrowPrimitive> {
    let [fn_, ft] = s.contact_force;
    let [px, py] = s.contact_point;
    let numbers = [fn_, ft, s.contact_gamma, px, py];
    if !(numbers.iter().all(|v| v.is_finite()) && fn_ > 0.0) {
        return None;
    }
    // f_world = R(γ) f_c; the arrow points along it and ends at the contact point.
    let heading = s.contact_gamma + ft.atan2(fn_);
    let length = (fn_.hypot(ft) * scale).max(0.3);
    let [x, y, yaw] = target_pose;
    let (cx, cy) = body_to_world(x, y, yaw, px, py);
    let (dx, dy) = (heading.cos(), heading.sin());
    let shaft = 0.05 * target.width;
    Some(ArrowPrimitive {
        pose: Some(planar_pose(
            cx - dx * length,
            cy - dy * length,
            0.5 * target.height,
            heading,
        )),
        shaft_length: 0.75 * length,
        shaft_diameter: shaft,
        head_length: 0.25 * length,
        head_diameter: 3.0 * shaft,
        color: Some(CONTACT_COLOR),
    })
}

/// The road's polylines (left and right edge, centre line), `None` without a road.
#[must_use]
pub fn road_lines(meta: &RecordMeta) -> Option<Vec<LinePrimitive>> {
    let r = meta.road.as_ref()?;
    Some(
        [
            (&r.left, EDGE_COLOR),
            (&r.right, EDGE_COLOR),
            (&r.centre, CENTRE_COLOR),
        ]
        .into_iter()
        .filter(|(pts, _)| pts.len() >= 2)
        .map(|(pts, color)| LinePrimitive {
            r#type: line_primitive::Type::LineStrip as i32,
            pose: Some(planar_pose(0.0, 0.0, 0.0, 0.0)),
            thickness: 0.15,
            scale_invariant: false,
            points: pts
                .iter()
                .map(|p| Point3 {
                    x: p[0],
                    y: p[1],
                    z: 0.01,
                })
                .collect(),
            color: Some(color),
            colors: Vec::new(),
            indices: Vec::new(),
        })
        .collect(),
    )
}

/// The scene of one state with finite poses: the vehicles, the contact (an arrow in contact,
/// empty apart, so the previous arrow goes), every obstacle, and the road when `road` is
/// given (its lines never expire).
#[must_use]
pub fn scene_update(
    s: &StateEstimate,
    poses: ([f64; 3], [f64; 3]),
    meta: &RecordMeta,
    road: Option<&[LinePrimitive]>,
) -> SceneUpdate {
    let stamp = timestamp(s.stamp_ns);
    let (bullet, target) = poses;
    let mut entities = Vec::with_capacity(4 + meta.obstacles.len());
    entities.push(vehicle_entity(
        entity::BULLET,
        stamp,
        bullet,
        meta.bullet,
        BULLET_COLOR,
    ));
    entities.push(vehicle_entity(
        entity::TARGET,
        stamp,
        target,
        meta.target,
        TARGET_COLOR,
    ));
    entities.push(SceneEntity {
        arrows: contact_arrow(s, target, meta.target, meta.contact_arrow_scale)
            .into_iter()
            .collect(),
        ..entity(entity::CONTACT, stamp)
    });
    let t = s.stamp_ns.saturating_sub(s.run_start_ns) as f64 * 1e-9;
    for (i, ob) in meta.obstacles.iter().enumerate() {
        entities.push(obstacle_entity(i, stamp, ob, t));
    }
    if let Some(lines) = road {
        entities.push(SceneEntity {
            frame_locked: true,
            lines: lines.to_vec(),
            ..entity(entity::ROAD, stamp)
        });
    }
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// `world` → `bullet` and `world` → `target` at the state's measurement time.
#[must_use]
pub fn frame_transforms(s: &StateEstimate, poses: ([f64; 3], [f64; 3])) -> FrameTransforms {
    let stamp = timestamp(s.stamp_ns);
    let tf = |child: &str, [x, y, yaw]: [f64; 3]| FrameTransform {
        timestamp: Some(stamp),
        parent_frame_id: WORLD_FRAME.to_owned(),
        child_frame_id: child.to_owned(),
        translation: Some(Vector3 { x, y, z: 0.0 }),
        rotation: Some(yaw_quaternion(yaw)),
    };
    FrameTransforms {
        transforms: vec![tf(BULLET_FRAME, poses.0), tf(TARGET_FRAME, poses.1)],
    }
}

/// A vehicle's pose (its c.g. on the ground) in frame `world` at the state's measurement time.
#[must_use]
pub fn pose_in_frame(s: &StateEstimate, [x, y, yaw]: [f64; 3]) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(s.stamp_ns)),
        frame_id: WORLD_FRAME.to_owned(),
        pose: Some(planar_pose(x, y, 0.0, yaw)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_quaternion_round_trips() {
        for psi in [-3.0, -0.4, 0.0, 0.7, 3.1] {
            let q = yaw_quaternion(psi);
            assert!((2.0 * q.z.atan2(q.w) - psi).abs() < 1e-12);
            assert!((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn body_points_rotate_with_the_heading() {
        let (x, y) = body_to_world(1.0, 2.0, std::f64::consts::FRAC_PI_2, 1.0, 0.0);
        assert!((x - 1.0).abs() < 1e-12 && (y - 3.0).abs() < 1e-12);
    }

    #[test]
    fn timestamp_splits_nanoseconds() {
        let t = timestamp(3_250_000_001);
        assert_eq!((t.sec(), t.nsec()), (3, 250_000_001));
    }

    /// The arrow points along `R(γ) f_c` and its head ends at the contact point.
    #[test]
    fn the_contact_arrow_ends_at_the_contact_point_along_the_force() {
        let s = StateEstimate {
            contact_force: [3000.0, 1000.0],
            contact_gamma: 0.4,
            contact_point: [-1.5, 0.8],
            ..StateEstimate::default()
        };
        let target = [10.0, 2.0, 0.3];
        let size = VehicleBox::default();
        let a = contact_arrow(&s, target, size, 1e-3).expect("in contact");
        let p = a.pose.unwrap();
        let q = p.orientation.unwrap();
        let heading = 2.0 * q.z.atan2(q.w);
        let f = [
            3000.0 * 0.4f64.cos() - 1000.0 * 0.4f64.sin(),
            3000.0 * 0.4f64.sin() + 1000.0 * 0.4f64.cos(),
        ];
        assert!((heading - f[1].atan2(f[0])).abs() < 1e-12);
        let len = a.shaft_length + a.head_length;
        assert!((len - 3000f64.hypot(1000.0) * 1e-3).abs() < 1e-12);
        let pos = p.position.unwrap();
        let tip = (pos.x + len * heading.cos(), pos.y + len * heading.sin());
        let c = body_to_world(10.0, 2.0, 0.3, -1.5, 0.8);
        assert!((tip.0 - c.0).abs() < 1e-12 && (tip.1 - c.1).abs() < 1e-12);
        let apart = StateEstimate::default();
        assert!(contact_arrow(&apart, target, size, 1e-3).is_none());
    }
}
