//! Glue between the binaries and the MCAP recorder ([`crate::record`]): the scene metadata
//! (vehicle boxes, the road's edges and centre line, the obstacles, the contact arrow's scale)
//! from the scenario.

use crate::ports::ServiceNames;
use crate::record::{RecordMeta, Recorder, RoadLines, VehicleBox};
use dynamics::params::{ParamSet, VehicleParams};
use dynamics::road::Road;
use sim::Scenario;
use std::path::Path;

fn vehicle_box(p: &VehicleParams) -> VehicleBox {
    VehicleBox {
        length: p.length,
        width: p.width,
        height: p.height,
        cg_to_front: p.cg_to_front,
    }
}

/// The road's left edge, right edge and reference line, sampled every 2 m.
#[must_use]
pub fn road_lines(road: &Road) -> RoadLines {
    let n = (road.length() / 2.0).ceil().max(1.0) as usize;
    let w = road.half_width();
    let mut lines = RoadLines {
        left: Vec::with_capacity(n + 1),
        right: Vec::with_capacity(n + 1),
        centre: Vec::with_capacity(n + 1),
    };
    for i in 0..=n {
        let s = road.length() * i as f64 / n as f64;
        for (d, line) in [
            (w, &mut lines.left),
            (-w, &mut lines.right),
            (0.0, &mut lines.centre),
        ] {
            let p = road.to_world(s, d);
            line.push([p.x, p.y]);
        }
    }
    lines
}

/// Start recording every topic under `names` to `path`, with the scenario's scene.
///
/// # Errors
/// A message naming the file or the service.
pub fn start(
    names: &ServiceNames,
    path: &Path,
    sc: &Scenario,
    params: &ParamSet,
    process: &str,
) -> Result<Recorder, String> {
    // A contact force equal to the target's weight draws as long as the target.
    let weight = params.target.mass * dynamics::GRAVITY;
    let mut meta = RecordMeta::new(vehicle_box(&params.bullet), vehicle_box(&params.target))
        .with_obstacles(sc.obstacles())
        .with_contact_arrow_scale(params.target.length / weight)
        .with_entry("process", process)
        .with_entry("scenario", sc.id.as_str())
        .with_entry("params", sc.params.name())
        .with_entry(
            "command_line",
            std::env::args().collect::<Vec<_>>().join(" ").as_str(),
        )
        .with_entry("version", env!("CARGO_PKG_VERSION"));
    if let Ok(road) = sc.build_road() {
        meta = meta.with_road(road_lines(&road));
    }
    Recorder::spawn(names, path, meta).map_err(|e| e.to_string())
}

/// Finish the recording and report what it holds.
///
/// # Errors
/// A message naming the file when writing it failed.
pub fn stop(r: Recorder) -> Result<(), String> {
    let stats = r.stop().map_err(|e| e.to_string())?;
    let gaps: u64 = stats.seq_gaps.values().sum();
    let errors: u64 = stats.receive_errors.values().sum();
    if gaps > 0 || errors > 0 {
        eprintln!(
            "warning: {}: {gaps} sequence gaps, {errors} receive errors",
            stats.path.display()
        );
    }
    Ok(())
}
