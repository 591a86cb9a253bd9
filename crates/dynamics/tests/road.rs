//! Road geometry: hand-worked Frenet projections on straights and arcs, round trips on
//! roads with clothoids, continuity at the joints, clothoid accuracy against a fine-step
//! reference integration, the sharpest curvature of a stretch, edge distances of
//! footprints, the specification format and its errors, and obstacles.

use dynamics::geometry::{Obb, Vec2};
use dynamics::road::{Frenet, Obstacle, Road, RoadError, RoadSpec, SegmentSpec};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_3, FRAC_PI_4, FRAC_PI_6, PI};

fn spec(segments: Vec<SegmentSpec>, origin: [f64; 3]) -> RoadSpec {
    RoadSpec {
        segments,
        lanes: 2,
        lane_width: 3.5,
        shoulder: 0.5,
        origin,
    }
}

fn polar(center: Vec2, radius: f64, angle: f64) -> Vec2 {
    center + radius * Vec2::new(angle.cos(), angle.sin())
}

#[track_caller]
fn assert_frenet(f: Frenet, s: f64, d: f64, heading: f64, curvature: f64) {
    assert!((f.s - s).abs() < 1e-9, "s = {} (expected {s})", f.s);
    assert!((f.d - d).abs() < 1e-9, "d = {} (expected {d})", f.d);
    assert!(
        (f.heading - heading).abs() < 1e-12,
        "heading = {} (expected {heading})",
        f.heading
    );
    assert!(
        (f.curvature - curvature).abs() < 1e-12,
        "curvature = {} (expected {curvature})",
        f.curvature
    );
}

/// Projection, the same from a hint a little off, and the round trip back to the point.
#[track_caller]
fn assert_projects(road: &Road, p: Vec2, s: f64, d: f64, heading: f64, curvature: f64) {
    let f = road.project(p);
    assert_frenet(f, s, d, heading, curvature);
    for offset in [-3.0, 0.0, 4.0] {
        assert_frenet(
            road.project_with_hint(p, s + offset),
            s,
            d,
            heading,
            curvature,
        );
    }
    assert!((road.to_world(f.s, f.d) - p).norm() < 1e-9);
}

#[test]
fn straight_projection_by_hand() {
    let road = Road::straight(100.0, 2, 3.5, 0.5);
    assert_eq!(road.length(), 100.0);
    assert_eq!(road.half_width(), 4.0);
    assert_projects(&road, Vec2::new(30.0, 2.0), 30.0, 2.0, 0.0, 0.0);
    assert_projects(&road, Vec2::new(70.0, -3.0), 70.0, -3.0, 0.0, 0.0);
    // Off the ends: the road continues along its end tangents.
    assert_projects(&road, Vec2::new(-5.0, -1.0), -5.0, -1.0, 0.0, 0.0);
    assert_projects(&road, Vec2::new(120.0, 3.0), 120.0, 3.0, 0.0, 0.0);

    // Start at (10, 5) heading north: left is west.
    let north = Road::new(spec(
        vec![SegmentSpec::Straight { length: 50.0 }],
        [10.0, 5.0, FRAC_PI_2],
    ))
    .unwrap();
    assert_projects(&north, Vec2::new(8.0, 25.0), 20.0, 2.0, FRAC_PI_2, 0.0);
    assert_projects(&north, Vec2::new(11.0, 60.0), 55.0, -1.0, FRAC_PI_2, 0.0);
    let p = north.to_world(20.0, 2.0);
    assert!((p - Vec2::new(8.0, 25.0)).norm() < 1e-12);
}

#[test]
fn arc_projection_by_hand() {
    // A left quarter circle of radius 50 from the origin: centre (0, 50), ends at (50, 50)
    // heading north.
    let r = 50.0;
    let road = Road::new(spec(
        vec![SegmentSpec::Arc {
            length: r * FRAC_PI_2,
            curvature: 1.0 / r,
        }],
        [0.0, 0.0, 0.0],
    ))
    .unwrap();
    let c = Vec2::new(0.0, r);
    let end = road.pose_at(road.length());
    assert!((end.point - Vec2::new(r, r)).norm() < 1e-12);
    assert!((end.heading - FRAC_PI_2).abs() < 1e-15);

    // The arc point at turn angle φ is c + r (sin φ, −cos φ), i.e. at polar angle φ − π/2.
    // Inside the curve (towards the centre) is to the left: d > 0.
    assert_projects(
        &road,
        polar(c, 45.0, FRAC_PI_4 - FRAC_PI_2),
        r * FRAC_PI_4,
        5.0,
        FRAC_PI_4,
        0.02,
    );
    // Outside: d < 0.
    assert_projects(
        &road,
        polar(c, 53.0, FRAC_PI_3 - FRAC_PI_2),
        r * FRAC_PI_3,
        -3.0,
        FRAC_PI_3,
        0.02,
    );
    // Beyond the end, along the northbound tangent: east is right.
    assert_projects(
        &road,
        Vec2::new(52.0, 60.0),
        r * FRAC_PI_2 + 10.0,
        -2.0,
        FRAC_PI_2,
        0.0,
    );
    // Before the start.
    assert_projects(&road, Vec2::new(-4.0, 1.0), -4.0, 1.0, 0.0, 0.0);

    // A right turn: centre (0, −50); inside is to the right (d < 0).
    let right = Road::new(spec(
        vec![SegmentSpec::Arc {
            length: 40.0,
            curvature: -1.0 / r,
        }],
        [0.0, 0.0, 0.0],
    ))
    .unwrap();
    let phi: f64 = 0.3;
    let p = Vec2::new(0.0, -r) + 47.0 * Vec2::new(phi.sin(), phi.cos());
    assert_projects(&right, p, r * phi, -3.0, -phi, -0.02);
}

#[test]
fn curved_road_projection_by_hand() {
    // Entry straight of 20 m, quarter circle of radius 50, exit straight of 20 m.
    let road = Road::curved(20.0, 50.0, 50.0 * FRAC_PI_2, 0.0, 2, 3.5, 0.5);
    assert_eq!(road.spec().segments.len(), 3);
    let arc_end = 20.0 + 25.0 * PI;
    assert!((road.length() - (arc_end + 20.0)).abs() < 1e-12);
    let c = Vec2::new(20.0, 50.0);
    // On the inside of the curve and on the outside.
    assert_projects(
        &road,
        polar(c, 45.0, -FRAC_PI_4),
        20.0 + 50.0 * FRAC_PI_4,
        5.0,
        FRAC_PI_4,
        0.02,
    );
    assert_projects(
        &road,
        polar(c, 54.0, -FRAC_PI_6),
        20.0 + 50.0 * FRAC_PI_3,
        -4.0,
        FRAC_PI_3,
        0.02,
    );
    // On the entry and exit straights (exit starts at (70, 50) heading north).
    assert_projects(&road, Vec2::new(12.0, -1.5), 12.0, -1.5, 0.0, 0.0);
    assert_projects(
        &road,
        Vec2::new(68.0, 60.0),
        arc_end + 10.0,
        2.0,
        FRAC_PI_2,
        0.0,
    );
    // Past the exit.
    assert_projects(
        &road,
        Vec2::new(71.0, 100.0),
        arc_end + 50.0,
        -1.0,
        FRAC_PI_2,
        0.0,
    );
}

/// Roads with clothoids (left and right curves, an S-bend with a curvature reversal inside
/// a clothoid, a rotated and shifted origin).
fn clothoid_roads() -> Vec<Road> {
    let s_bend = RoadSpec {
        segments: vec![
            SegmentSpec::Straight { length: 20.0 },
            SegmentSpec::Clothoid {
                length: 30.0,
                curvature_start: 0.0,
                curvature_end: 0.03,
            },
            SegmentSpec::Clothoid {
                length: 50.0,
                curvature_start: 0.03,
                curvature_end: -0.025,
            },
            SegmentSpec::Arc {
                length: 20.0,
                curvature: -0.025,
            },
            SegmentSpec::Clothoid {
                length: 40.0,
                curvature_start: -0.025,
                curvature_end: 0.01,
            },
        ],
        lanes: 2,
        lane_width: 3.75,
        shoulder: 1.0,
        origin: [100.0, -20.0, 0.7],
    };
    vec![
        Road::curved(30.0, 60.0, 40.0, 25.0, 2, 3.5, 0.5),
        Road::curved(10.0, -35.0, 20.0, 15.0, 3, 3.5, 1.0),
        Road::new(s_bend).unwrap(),
    ]
}

#[test]
fn clothoid_roads_round_trip() {
    let mut rng = ChaCha8Rng::seed_from_u64(20_240_611);
    for road in clothoid_roads() {
        let w = road.half_width() + 2.0;
        for _ in 0..2000 {
            // Points near the road (inside and beyond the edges, before and after it).
            let s = rng.random_range(-15.0..road.length() + 15.0);
            let d = rng.random_range(-w..w);
            let p = road.to_world(s, d);
            let f = road.project(p);
            assert!((f.s - s).abs() < 1e-8, "s = {} (expected {s})", f.s);
            assert!((f.d - d).abs() < 1e-9, "d = {} (expected {d})", f.d);
            assert!((road.to_world(f.s, f.d) - p).norm() < 1e-9);
            // Orthogonality: p − foot is along the normal.
            let foot = road.pose_at(f.s);
            assert!((p - foot.point).dot(&foot.tangent()).abs() < 1e-9);
            assert!((foot.heading - f.heading).abs() < 1e-12);
            assert!((foot.curvature - f.curvature).abs() < 1e-12);
            // A hint a few metres off finds the same foot point.
            let hinted = road.project_with_hint(p, s + rng.random_range(-6.0..6.0));
            assert!((hinted.s - f.s).abs() < 1e-8 && (hinted.d - f.d).abs() < 1e-9);
        }
    }
}

#[test]
fn points_anywhere_round_trip() {
    // Points in the road's bounding box, some far from it: the projection is still a foot
    // point (orthogonal, and to_world gives the point back).
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for road in clothoid_roads() {
        let (mut lo, mut hi) = (Vec2::repeat(f64::INFINITY), Vec2::repeat(f64::NEG_INFINITY));
        for i in 0..=100 {
            let p = road.pose_at(road.length() * f64::from(i) / 100.0).point;
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
        for _ in 0..500 {
            let p = Vec2::new(
                rng.random_range(lo.x - 10.0..hi.x + 10.0),
                rng.random_range(lo.y - 10.0..hi.y + 10.0),
            );
            let f = road.project(p);
            assert!(
                (road.to_world(f.s, f.d) - p).norm() < 1e-9,
                "p = {p:?}, f = {f:?}"
            );
            let foot = road.pose_at(f.s);
            assert!((p - foot.point).dot(&foot.tangent()).abs() < 1e-9);
            // No point of a fine sampling of the road is nearer than the foot point.
            let dist = f.d.abs();
            for i in -20..=520 {
                let q = road.pose_at(road.length() * f64::from(i) / 500.0).point;
                assert!(
                    (p - q).norm() >= dist - 1e-9,
                    "p = {p:?}: foot at s = {} not nearest",
                    f.s
                );
            }
        }
    }
}

#[test]
fn joints_are_continuous_in_heading_and_curvature() {
    let eps = 1e-7;
    for road in clothoid_roads() {
        let mut joint = 0.0;
        for segment in &road.spec().segments[..road.spec().segments.len() - 1] {
            joint += segment.length();
            let (a, b) = (road.pose_at(joint - eps), road.pose_at(joint + eps));
            assert!(
                (a.point - b.point).norm() < 2.0 * eps + 1e-12,
                "position jump at s = {joint}"
            );
            assert!(
                (a.heading - b.heading).abs() < 1e-8,
                "heading jump at s = {joint}"
            );
            assert!(
                (a.curvature - b.curvature).abs() < 1e-8,
                "curvature jump at s = {joint}"
            );
            // The positions follow the heading across the joint (G1 of the curve itself).
            let h = 1e-4;
            let chord = road.pose_at(joint + h).point - road.pose_at(joint - h).point;
            let mid = road.pose_at(joint);
            assert!(
                (chord.y.atan2(chord.x) - mid.heading).abs() < 1e-6,
                "tangent and chord differ at s = {joint}"
            );
        }
    }
}

#[test]
fn curve_turns_by_arc_plus_transition_over_radius() {
    let (entry, radius, arc, transition) = (30.0, 60.0, 40.0, 25.0);
    let road = Road::curved(entry, radius, arc, transition, 2, 3.5, 0.5);
    assert!((road.length() - (2.0 * entry + arc + 2.0 * transition)).abs() < 1e-12);
    let exit = road.pose_at(road.length());
    assert!((exit.heading - (arc + transition) / radius).abs() < 1e-14);
    assert_eq!(exit.curvature, 0.0);
    // Curvature ramps linearly through the transitions and is 1/R on the arc.
    let k = road.pose_at(entry + 0.4 * transition).curvature;
    assert!((k - 0.4 / radius).abs() < 1e-15);
    assert!((road.pose_at(entry + transition + 0.5 * arc).curvature - 1.0 / radius).abs() < 1e-15);
    // The curve is symmetric about its middle normal: the exit mirrors the entry.
    let mid = road.pose_at(0.5 * road.length());
    let n = mid.normal();
    let (p0, p1) = (road.pose_at(0.0).point, exit.point);
    let mirrored = p0 - 2.0 * (p0 - mid.point).dot(&mid.tangent()) * mid.tangent();
    assert!((mirrored - p1).norm() < 1e-9, "{mirrored:?} vs {p1:?}");
    assert!(((p0 - mid.point).dot(&n) - (p1 - mid.point).dot(&n)).abs() < 1e-9);
}

#[test]
fn the_sharpest_curvature_of_a_stretch_is_sampled_at_its_stations() {
    // Straight 0–100 m, a right-hand clothoid to 1/80 over 20 m, the arc 120–150 m, the
    // clothoid back over 150–170 m, straight 170–270 m.
    let road = Road::curved(100.0, -80.0, 30.0, 20.0, 3, 3.5, 2.0);
    let k = -1.0 / 80.0;
    // Stations 5, 15, …, 95 lie on the entry: straight.
    assert_eq!(road.sharpest_curvature(5.0, 10.0, 0..=9), 0.0);
    // One more station (105 m) reaches a quarter into the clothoid: signed as the road.
    let ramp = road.sharpest_curvature(5.0, 10.0, 0..=10);
    assert!((ramp - 0.25 * k).abs() < 1e-12, "{ramp}");
    // From beyond the curve, looking back over it: the arc's curvature.
    let back = road.sharpest_curvature(260.0, 10.0, -14..=0);
    assert!((back - k).abs() < 1e-12, "{back}");
    // Beyond the ends the line runs straight, and an empty stretch has no curvature.
    assert_eq!(road.sharpest_curvature(300.0, 10.0, 0..=20), 0.0);
    assert_eq!(
        road.sharpest_curvature(130.0, 10.0, std::ops::RangeInclusive::new(1, 0)),
        0.0
    );
    // A left-hand curve is positive.
    let left = Road::curved(100.0, 80.0, 30.0, 20.0, 3, 3.5, 2.0);
    assert!((left.sharpest_curvature(0.0, 5.0, 0..=60) + k).abs() < 1e-12);
}

/// `∫_0^s (cos θ, sin θ)` by composite Simpson with `n` steps and compensated summation.
fn reference_clothoid(theta: impl Fn(f64) -> f64, s: f64, n: usize) -> Vec2 {
    let h = s / n as f64;
    let (mut sum, mut comp) = (Vec2::zeros(), Vec2::zeros());
    for i in 0..=n {
        let w = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let th = theta(i as f64 * h);
        let term = w * Vec2::new(th.cos(), th.sin()) - comp;
        let next = sum + term;
        comp = (next - sum) - term;
        sum = next;
    }
    sum * h / 3.0
}

#[test]
fn clothoid_pose_matches_fine_step_integration() {
    for (length, k0, k1, origin) in [
        (200.0, 0.001, 0.02, [3.0, -2.0, 0.4]),
        (60.0, -0.05, 0.15, [-7.0, 12.0, -2.0]),
        (150.0, 0.0, -0.04, [0.0, 0.0, 0.0]),
    ] {
        let road = Road::new(RoadSpec {
            segments: vec![SegmentSpec::Clothoid {
                length,
                curvature_start: k0,
                curvature_end: k1,
            }],
            lanes: 1,
            lane_width: 3.0,
            shoulder: 0.0,
            origin,
        })
        .unwrap();
        let p0 = Vec2::new(origin[0], origin[1]);
        let theta = |s: f64| origin[2] + k0 * s + (k1 - k0) * s * s / (2.0 * length);
        for s in [0.37 * length, length] {
            let reference = p0 + reference_clothoid(theta, s, 400_000);
            let pose = road.pose_at(s);
            assert!(
                (pose.point - reference).norm() < 1e-9,
                "L = {length}, s = {s}: {:?} vs {reference:?} (error {:e})",
                pose.point,
                (pose.point - reference).norm()
            );
            assert!((pose.heading - theta(s)).abs() < 1e-13);
            assert!((pose.curvature - (k0 + (k1 - k0) * s / length)).abs() < 1e-15);
        }
    }
}

#[test]
fn clothoid_with_constant_curvature_is_an_arc() {
    let k = 0.035;
    let as_clothoid = Road::new(spec(
        vec![SegmentSpec::Clothoid {
            length: 80.0,
            curvature_start: k,
            curvature_end: k,
        }],
        [1.0, 2.0, 0.3],
    ))
    .unwrap();
    let as_arc = Road::new(spec(
        vec![SegmentSpec::Arc {
            length: 80.0,
            curvature: k,
        }],
        [1.0, 2.0, 0.3],
    ))
    .unwrap();
    for i in 0..=40 {
        let s = 2.0 * f64::from(i);
        let (a, b) = (as_clothoid.pose_at(s), as_arc.pose_at(s));
        assert!((a.point - b.point).norm() < 1e-11, "s = {s}");
        assert!((a.heading - b.heading).abs() < 1e-14);
    }
}

#[test]
fn lane_centres() {
    let three = Road::straight(50.0, 3, 3.5, 1.0);
    assert_eq!(three.half_width(), 6.25);
    assert_eq!(three.lane_center_offset(0), -3.5);
    assert_eq!(three.lane_center_offset(1), 0.0);
    assert_eq!(three.lane_center_offset(2), 3.5);
    let two = Road::straight(50.0, 2, 3.5, 0.5);
    assert_eq!(two.lane_center_offset(0), -1.75);
    assert_eq!(two.lane_center_offset(1), 1.75);
}

#[test]
#[should_panic(expected = "lane 2 does not exist")]
fn lane_beyond_the_road_panics() {
    let _ = Road::straight(50.0, 2, 3.5, 0.5).lane_center_offset(2);
}

#[test]
fn edge_distance_on_a_straight() {
    // Two lanes of 3.5 m and 0.5 m shoulders: edges at d = ±4.
    let road = Road::straight(100.0, 2, 3.5, 0.5);
    let (length, width) = (4.5, 1.8);
    // Centred: half width minus half the car's width.
    let car = Obb::new(Vec2::new(50.0, 0.0), 0.0, length, width);
    assert!((road.edge_distance(&car) - (4.0 - 0.9)).abs() < 1e-12);
    // In the right lane.
    let car = Obb::new(
        Vec2::new(50.0, road.lane_center_offset(0)),
        0.0,
        length,
        width,
    );
    assert!((road.edge_distance(&car) - (4.0 - 1.75 - 0.9)).abs() < 1e-12);
    // Straddling the left edge: its left side at d = 5.1 is 1.1 m beyond it.
    let car = Obb::new(Vec2::new(50.0, 4.2), 0.0, length, width);
    assert!((road.edge_distance(&car) + 1.1).abs() < 1e-12);
    // Rotated by 30°: the front-left corner is the furthest left.
    let car = Obb::new(Vec2::new(50.0, 1.0), FRAC_PI_6, 4.0, 2.0);
    let reach = 2.0 * FRAC_PI_6.sin() + 1.0 * FRAC_PI_6.cos();
    assert!((road.edge_distance(&car) - (4.0 - 1.0 - reach)).abs() < 1e-12);
    // Rotated by −20° near the right edge: the front-right corner crosses it.
    let yaw = -20f64.to_radians();
    let car = Obb::new(Vec2::new(50.0, -2.5), yaw, length, width);
    let reach = 0.5 * length * yaw.sin().abs() + 0.5 * width * yaw.cos();
    let expected = 4.0 - (2.5 + reach);
    assert!(expected < 0.0);
    assert!((road.edge_distance(&car) - expected).abs() < 1e-12);
    // The point version.
    assert!((road.edge_distance_point(Vec2::new(10.0, -3.0)) - 1.0).abs() < 1e-12);
    assert!((road.edge_distance_point(Vec2::new(10.0, 4.5)) + 0.5).abs() < 1e-12);
    // Beyond the end the edges continue straight.
    assert!((road.edge_distance_point(Vec2::new(130.0, 3.5)) - 0.5).abs() < 1e-12);
}

#[test]
fn edge_distance_on_a_curve() {
    // Quarter circle of radius 50 (centre (30, 50)) between two 30 m straights; edges at
    // radius 46 (inside) and 54 (outside).
    let r = 50.0;
    let road = Road::curved(30.0, r, r * FRAC_PI_2, 0.0, 2, 3.5, 0.5);
    let c = Vec2::new(30.0, r);
    let (length, width) = (4.5, 1.8);
    let phi = FRAC_PI_4; // road heading at the car
    let car_at = |d: f64| {
        let center = c + (r - d) * Vec2::new(phi.sin(), -phi.cos());
        Obb::new(center, phi, length, width)
    };
    let corner_margin = |car: &Obb| {
        car.corners()
            .iter()
            .map(|&p| road.edge_distance_point(p))
            .fold(f64::INFINITY, f64::min)
    };

    // Outside of the curve (d = −2): the outer corners are the furthest out, at radius
    // √((52.9)² + 2.25²).
    let car = car_at(-2.0);
    let r_corner = ((r + 2.0 + 0.5 * width).powi(2) + (0.5 * length).powi(2)).sqrt();
    let expected = 4.0 - (r_corner - r);
    assert!((road.edge_distance(&car) - expected).abs() < 1e-9);
    assert!((corner_margin(&car) - expected).abs() < 1e-9);

    // Inside of the curve (d = 2.8): the middle of the inner side is the furthest in, at
    // radius 50 − 2.8 − 0.9 = 46.3, nearer the edge than the corners.
    let car = car_at(2.8);
    let expected = 4.0 - (2.8 + 0.5 * width);
    assert!(
        (road.edge_distance(&car) - expected).abs() < 1e-9,
        "{}",
        road.edge_distance(&car)
    );
    let r_corner = ((r - 2.8 - 0.5 * width).powi(2) + (0.5 * length).powi(2)).sqrt();
    assert!((corner_margin(&car) - (4.0 - (r - r_corner))).abs() < 1e-9);
    assert!(corner_margin(&car) > expected + 0.05);

    // Every corner inside, yet the inner side crosses the edge by 5 cm.
    let car = car_at(3.15);
    assert!(corner_margin(&car) > 0.0);
    assert!((road.edge_distance(&car) + 0.05).abs() < 1e-9);
}

const TOML_TABLES: &str = r#"
lanes = 2
lane_width = 3.5
shoulder = 0.5
origin = [0.0, 0.0, 0.0]

[[segments]]
kind = "straight"
length = 40.0

[[segments]]
kind = "clothoid"
length = 20.0
curvature_start = 0.0
curvature_end = 0.02

[[segments]]
kind = "arc"
length = 30
curvature = 0.02
"#;

const TOML_INLINE: &str = r#"
segments = [
    { kind = "straight", length = 40.0 },
    { kind = "clothoid", length = 20.0, curvature_start = 0.0, curvature_end = 0.02 },
    { kind = "arc", length = 30.0, curvature = 0.02 },
]
lanes = 2
lane_width = 3.5
shoulder = 0.5
origin = [0.0, 0.0, 0.0]
"#;

fn expected_spec() -> RoadSpec {
    spec(
        vec![
            SegmentSpec::Straight { length: 40.0 },
            SegmentSpec::Clothoid {
                length: 20.0,
                curvature_start: 0.0,
                curvature_end: 0.02,
            },
            SegmentSpec::Arc {
                length: 30.0,
                curvature: 0.02,
            },
        ],
        [0.0, 0.0, 0.0],
    )
}

#[test]
fn spec_round_trips_through_toml() {
    for text in [TOML_TABLES, TOML_INLINE] {
        let parsed = RoadSpec::from_toml_str(text, "road.toml").unwrap();
        assert_eq!(parsed, expected_spec());
        let again = RoadSpec::from_toml_str(&parsed.to_toml_string(), "again").unwrap();
        assert_eq!(again, parsed);
        // Plain serde works as well.
        let direct: RoadSpec = toml::from_str(text).unwrap();
        assert_eq!(direct, parsed);
    }
    let road = Road::try_from(expected_spec()).unwrap();
    assert_eq!(road.spec(), &expected_spec());
    assert!((road.length() - 90.0).abs() < 1e-12);
}

fn error_of(text: &str) -> RoadError {
    RoadSpec::from_toml_str(text, "road.toml").unwrap_err()
}

fn replaced(from: &str, to: &str) -> String {
    assert!(TOML_INLINE.contains(from), "{from} not in the template");
    TOML_INLINE.replacen(from, to, 1)
}

#[test]
fn bad_specs_name_the_field() {
    let cases = [
        (
            replaced("length = 30.0", "length = -5"),
            "segments[2].length = -5: must be positive",
        ),
        (
            replaced("length = 40.0", "length = 0.0"),
            "segments[0].length = 0: must be positive",
        ),
        (
            replaced("length = 20.0", "length = nan"),
            "segments[1].length = NaN: must be finite",
        ),
        (
            replaced("lanes = 2", "lanes = 0"),
            "lanes = 0: must be at least 1",
        ),
        (
            replaced("lane_width = 3.5", "lane_width = -3.5"),
            "lane_width = -3.5: must be positive",
        ),
        (
            replaced("shoulder = 0.5", "shoulder = -0.1"),
            "shoulder = -0.1: must not be negative",
        ),
        (
            replaced("0.0, 0.0, 0.0]", "0.0, 0.0, inf]"),
            "origin[2] = inf: must be finite",
        ),
        (
            replaced("curvature = 0.02", "curvature = 0.3"),
            "segments[2].curvature = 0.3: |curvature| × half_width must be below 1",
        ),
        (
            replaced("curvature_end = 0.02", "curvature_end = -0.26"),
            "segments[1].curvature_end = -0.26: |curvature| × half_width must be below 1",
        ),
    ];
    for (text, message) in cases {
        let e = error_of(&text);
        assert!(matches!(e, RoadError::Invalid { .. }), "{e:?}");
        assert!(
            e.to_string().starts_with(message),
            "`{e}` does not start with `{message}`"
        );
        // Road::new refuses the same specification with the same error.
        let spec: RoadSpec = toml::from_str(&text).unwrap();
        assert_eq!(Road::new(spec).unwrap_err().to_string(), e.to_string());
    }
    // Nesting adds the path of the enclosing object.
    let e = error_of(&replaced("length = 30.0", "length = -5")).within("road");
    assert_eq!(
        e.to_string(),
        "road.segments[2].length = -5: must be positive"
    );

    // No segments at all.
    let empty = RoadSpec {
        segments: Vec::new(),
        ..expected_spec()
    };
    assert_eq!(Road::new(empty).unwrap_err(), RoadError::NoSegments);
}

#[test]
fn schema_errors_name_the_field() {
    for (text, word) in [
        (
            replaced("curvature = 0.02 }", "curvature = 0.02, radius = 50.0 }"),
            "radius",
        ),
        (replaced(r#"kind = "arc""#, r#"kind = "spiral""#), "spiral"),
        (
            replaced("lanes = 2", "lanes = 2\nlane_count = 2"),
            "lane_count",
        ),
        (replaced("lanes = 2", ""), "lanes"),
        (
            replaced("lane_width = 3.5", "lane_width = \"wide\""),
            "lane_width",
        ),
    ] {
        let e = error_of(&text);
        let RoadError::Parse {
            source_name,
            message,
        } = &e
        else {
            panic!("expected a parse error, got {e:?}");
        };
        assert_eq!(source_name, "road.toml");
        assert!(
            message.contains(word),
            "`{message}` does not mention `{word}`"
        );
    }
}

#[test]
fn obstacles_move_at_constant_velocity() {
    let moving = Obstacle {
        x: 10.0,
        y: 1.0,
        heading: 0.3,
        vx: 2.0,
        vy: -0.5,
        length: 4.0,
        width: 2.0,
    };
    moving.validate().unwrap();
    assert!(!moving.is_static());
    let start = moving.footprint_at(0.0);
    assert_eq!(start, Obb::new(Vec2::new(10.0, 1.0), 0.3, 4.0, 2.0));
    for t in [0.5, 3.0, 10.0] {
        let fp = moving.footprint_at(t);
        assert!((fp.center - Vec2::new(10.0 + 2.0 * t, 1.0 - 0.5 * t)).norm() < 1e-12);
        assert_eq!(fp.yaw, 0.3);
        assert_eq!(fp.half, Vec2::new(2.0, 1.0));
        // Every corner moves by v t.
        for (a, b) in start.corners().iter().zip(fp.corners()) {
            assert!((b - a - t * Vec2::new(2.0, -0.5)).norm() < 1e-12);
        }
    }

    let parked: Obstacle = toml::from_str(
        "x = 40.0\ny = -3.3\nheading = 0.0\nvx = 0.0\nvy = 0.0\nlength = 4.5\nwidth = 1.8\n",
    )
    .unwrap();
    assert!(parked.is_static());
    assert_eq!(parked.footprint_at(0.0), parked.footprint_at(12.0));
    // Parked on the right shoulder of a 2-lane road, 0.2 m of it beyond the edge.
    let road = Road::straight(100.0, 2, 3.5, 0.5);
    assert!((road.edge_distance(&parked.footprint_at(5.0)) + 0.2).abs() < 1e-12);

    let bad = Obstacle {
        width: 0.0,
        ..moving.clone()
    };
    let e = bad.validate().unwrap_err();
    assert_eq!(e.to_string(), "width = 0: must be positive");
    assert_eq!(
        e.within("obstacles[3]").to_string(),
        "obstacles[3].width = 0: must be positive"
    );
    let bad = Obstacle {
        vy: f64::NAN,
        ..moving
    };
    assert_eq!(
        bad.validate().unwrap_err().to_string(),
        "vy = NaN: must be finite"
    );
    assert!(toml::from_str::<Obstacle>("x = 1.0\ny = 0.0\nheading = 0.0\nvx = 0.0\nvy = 0.0\nlength = 4.5\nwidth = 1.8\nmass = 3.0\n").is_err());
}

#[test]
#[should_panic(expected = "radius")]
fn curved_refuses_zero_radius() {
    let _ = Road::curved(10.0, 0.0, 10.0, 0.0, 2, 3.5, 0.5);
}
