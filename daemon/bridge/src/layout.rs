//! The Foxglove layout for a vehicle: the shipped layout (config/foxglove/thrusterd-live.json,
//! made for AMOUR-5) with its thrust plot rewritten to show exactly the vehicle's thrusters,
//! each labelled with its name from the vehicle file (`thruster-bridge --layout-for FILE`).
//! A static layout cannot know the thruster count; the daemon's messages carry 16 entries
//! whatever the vehicle has, so without this the plot shows unused thrusters at zero.
//!
//! Two more things are written here rather than by hand, because the apps read them from
//! different places (seen in Lichtblick 1.18, docs/recording.md "Screenshots"): every panel's
//! title goes under both apps' keys (`foxglovePanelTitle` for Foxglove, `lichtblickPanelTitle`
//! for Lichtblick, which ignores the other and showed "Plot" on every plot), and the state
//! indicator gets one rule per [`DaemonState`], so it names the state in words and colours
//! a fault red instead of showing a number.

use anyhow::{anyhow, Result};
use serde_json::{json, Map, Value};
use thruster_protocol::DaemonState;

/// The shipped layout's text.
pub const SHIPPED: &str = include_str!("../../../config/foxglove/thrusterd-live.json");

/// The panel the thrust plot is in.
pub const THRUST_PANEL: &str = "Plot!thrust";

/// The panel showing the daemon's state in words (`status.state`).
pub const STATE_PANEL: &str = "Indicator!state";

/// The key of a panel's title in the Foxglove app's layouts, and in Lichtblick's.
pub const TITLE_KEYS: [&str; 2] = ["foxglovePanelTitle", "lichtblickPanelTitle"];

/// What the state indicator shows for `state`: its colour and its words.
pub fn state_label(state: DaemonState) -> (&'static str, &'static str) {
    match state {
        DaemonState::Idle => ("#6e7781", "IDLE: thrusters neutral, no control"),
        DaemonState::MeasureNoise => ("#1f6feb", "ESTIMATING: measuring the noise at rest"),
        DaemonState::Pulse => ("#1f6feb", "ESTIMATING: pulsing the thrusters"),
        DaemonState::Settle => ("#1f6feb", "ESTIMATING: settling after a pulse"),
        DaemonState::Solve => ("#1f6feb", "ESTIMATING: solving the model"),
        DaemonState::Active => ("#2da44e", "HOLDING with the model in force"),
        DaemonState::Fault => ("#d1242f", "FAULT: thrusters neutral (reason below)"),
        DaemonState::Identify => ("#1a7f37", "HOLDING and identifying (dither)"),
    }
}

/// The shipped layout with the thrust plot showing `names` (one per thruster, in the
/// protocol's order) of the vehicle `vehicle`, the state indicator's rules, and every panel's
/// title under both apps' keys.
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
    let indicator = layout["configById"]
        .get_mut(STATE_PANEL)
        .ok_or_else(|| anyhow!("the shipped layout has no {STATE_PANEL}"))?;
    indicator["rules"] = DaemonState::ALL
        .iter()
        .map(|&state| {
            let (color, label) = state_label(state);
            json!({
                "operator": "=",
                "rawValue": state.as_u32().to_string(),
                "color": color,
                "label": label,
            })
        })
        .collect();
    let panels = layout["configById"]
        .as_object_mut()
        .ok_or_else(|| anyhow!("the shipped layout has no configById"))?;
    for (id, config) in panels.iter_mut() {
        let config: &mut Map<String, Value> = config
            .as_object_mut()
            .ok_or_else(|| anyhow!("{id}: not an object"))?;
        let title = config
            .get(TITLE_KEYS[0])
            .cloned()
            .ok_or_else(|| anyhow!("{id}: no {}", TITLE_KEYS[0]))?;
        config.insert(TITLE_KEYS[1].to_string(), title);
    }
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

    #[test]
    fn every_state_has_words_and_every_panel_a_title_for_both_apps() {
        let l = for_vehicle("eight", &["A".to_string()]).unwrap();
        let rules = l["configById"][STATE_PANEL]["rules"].as_array().unwrap();
        assert_eq!(rules.len(), DaemonState::ALL.len());
        for (rule, state) in rules.iter().zip(DaemonState::ALL) {
            assert_eq!(rule["rawValue"], state.as_u32().to_string());
            assert_eq!(rule["operator"], "=");
        }
        assert_eq!(
            rules[DaemonState::Fault.as_u32() as usize]["color"],
            "#d1242f"
        );
        for (id, config) in l["configById"].as_object().unwrap() {
            let title = &config[TITLE_KEYS[0]];
            assert!(title.as_str().is_some_and(|t| !t.is_empty()), "{id}");
            assert_eq!(&config[TITLE_KEYS[1]], title, "{id}");
        }
    }
}
