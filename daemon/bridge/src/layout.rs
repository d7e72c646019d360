//! The Foxglove layout for a vehicle: the shipped layout (config/foxglove/thrusterd-live.json,
//! made for AMOUR-5) with its thrust plot rewritten to show exactly the vehicle's thrusters,
//! each labelled with its name from the vehicle file (`thruster-bridge --layout-for FILE`).
//! A static layout cannot know the thruster count; the daemon's messages carry 16 entries
//! whatever the vehicle has, so without this the plot shows unused thrusters at zero.

use anyhow::{anyhow, Result};
use serde_json::{json, Value};

/// The shipped layout's text.
pub const SHIPPED: &str = include_str!("../../../config/foxglove/thrusterd-live.json");

/// The panel the thrust plot is in.
pub const THRUST_PANEL: &str = "Plot!thrust";

/// The shipped layout with the thrust plot showing `names` (one per thruster, in the
/// protocol's order) of the vehicle `vehicle`.
pub fn for_vehicle(vehicle: &str, names: &[String]) -> Result<Value> {
    let mut layout: Value = serde_json::from_str(SHIPPED)
        .map_err(|e| anyhow!("config/foxglove/thrusterd-live.json: {e}"))?;
    let plot = layout["configById"]
        .get_mut(THRUST_PANEL)
        .ok_or_else(|| anyhow!("the shipped layout has no {THRUST_PANEL}"))?;
    plot["paths"] = names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            json!({
                "value": format!("thrust.thrust[{i}]"),
                "enabled": true,
                "timestampMethod": "receiveTime",
                "label": format!("{name} (thruster {i})"),
            })
        })
        .collect();
    plot["title"] = json!(format!("thrust per thruster (-1..1), vehicle {vehicle}"));
    Ok(layout)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_layout_is_the_one_for_amour5() {
        let names = thrusterctl_operator::geometry::load_names(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/vehicles/amour5.toml"
        )))
        .unwrap();
        assert_eq!(names, ["T", "LB", "RB", "L", "R"]);
        let shipped: Value = serde_json::from_str(SHIPPED).unwrap();
        assert_eq!(for_vehicle("amour5", &names).unwrap(), shipped);
    }

    #[test]
    fn a_vehicle_gets_exactly_its_thrusters() {
        let names: Vec<String> = (0..8).map(|i| format!("M{i}")).collect();
        let l = for_vehicle("eight", &names).unwrap();
        let paths = l["configById"][THRUST_PANEL]["paths"].as_array().unwrap();
        assert_eq!(paths.len(), 8);
        assert_eq!(paths[7]["value"], "thrust.thrust[7]");
        assert_eq!(paths[7]["label"], "M7 (thruster 7)");
    }
}
