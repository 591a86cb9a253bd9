//! 2-D rigid transforms and oriented rectangles (vehicle footprints, obstacles).

use nalgebra::Vector2;

/// A 2-D vector in SI units.
pub type Vec2 = Vector2<f64>;

/// Counter-clockwise rotation of `v` by angle `a`: `R(a) v`.
#[inline]
#[must_use]
pub fn rotate(a: f64, v: Vec2) -> Vec2 {
    let (s, c) = a.sin_cos();
    Vec2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

/// 2-D cross product (z component of `a × b`).
#[inline]
#[must_use]
pub fn cross(a: Vec2, b: Vec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// A planar pose: the transform `world_from_body`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose2 {
    /// Origin of the body frame in the world.
    pub p_in_world: Vec2,
    /// Heading ψ of the body x axis, counter-clockwise from world X.
    pub yaw: f64,
}

impl Pose2 {
    #[must_use]
    pub fn new(x: f64, y: f64, yaw: f64) -> Self {
        Self {
            p_in_world: Vec2::new(x, y),
            yaw,
        }
    }

    /// Map a point given in the body frame into the world frame.
    #[inline]
    #[must_use]
    pub fn world_from_body(&self, p_in_body: Vec2) -> Vec2 {
        self.p_in_world + rotate(self.yaw, p_in_body)
    }

    /// Map a world point into the body frame.
    #[inline]
    #[must_use]
    pub fn body_from_world(&self, p_in_world: Vec2) -> Vec2 {
        rotate(-self.yaw, p_in_world - self.p_in_world)
    }
}

/// An oriented rectangle: centre, heading and half extents along its own x and y axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obb {
    pub center: Vec2,
    pub yaw: f64,
    /// Half length (along the rectangle's x axis) and half width.
    pub half: Vec2,
}

impl Obb {
    #[must_use]
    pub fn new(center: Vec2, yaw: f64, length: f64, width: f64) -> Self {
        Self {
            center,
            yaw,
            half: Vec2::new(0.5 * length, 0.5 * width),
        }
    }

    /// Footprint of a vehicle whose reference point (c.g.) is at `pose`, with the body
    /// rectangle spanning `[−(length − cg_to_front), cg_to_front]` along body x.
    #[must_use]
    pub fn vehicle_footprint(pose: &Pose2, length: f64, width: f64, cg_to_front: f64) -> Self {
        let center_in_body = Vec2::new(cg_to_front - 0.5 * length, 0.0);
        Self::new(
            pose.world_from_body(center_in_body),
            pose.yaw,
            length,
            width,
        )
    }

    /// Unit axes (x, y) of the rectangle in the world.
    #[inline]
    #[must_use]
    pub fn axes(&self) -> (Vec2, Vec2) {
        let (s, c) = self.yaw.sin_cos();
        (Vec2::new(c, s), Vec2::new(-s, c))
    }

    /// The four corners, counter-clockwise starting at front-left (+x, +y).
    #[must_use]
    pub fn corners(&self) -> [Vec2; 4] {
        let (ax, ay) = self.axes();
        let ex = ax * self.half.x;
        let ey = ay * self.half.y;
        [
            self.center + ex + ey,
            self.center - ex + ey,
            self.center - ex - ey,
            self.center + ex - ey,
        ]
    }

    /// Whether a world point lies inside (or on) the rectangle.
    #[must_use]
    pub fn contains(&self, p: Vec2) -> bool {
        let (ax, ay) = self.axes();
        let d = p - self.center;
        d.dot(&ax).abs() <= self.half.x && d.dot(&ay).abs() <= self.half.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_roundtrip() {
        let pose = Pose2::new(3.0, -2.0, 0.7);
        let p = Vec2::new(1.5, -0.4);
        let back = pose.body_from_world(pose.world_from_body(p));
        assert!((back - p).norm() < 1e-12);
    }

    #[test]
    fn footprint_corners() {
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let fp = Obb::vehicle_footprint(&pose, 4.0, 2.0, 3.0);
        let c = fp.corners();
        assert!((c[0] - Vec2::new(3.0, 1.0)).norm() < 1e-12);
        assert!((c[2] - Vec2::new(-1.0, -1.0)).norm() < 1e-12);
        assert!(fp.contains(Vec2::new(2.9, 0.9)));
        assert!(!fp.contains(Vec2::new(3.1, 0.0)));
    }
}
