//! The shipped Foxglove layout (config/foxglove/thrusterd-live.json) names only what exists:
//! every plotted or shown path is a field of the message its topic carries (checked on the
//! messages' recorded JSON form, as the bridge sends them), every service button one of the
//! bridge's services. A renamed field then fails here, not silently in the app. Every panel
//! has its own title (`foxglovePanelTitle`, what Foxglove and Lichtblick show), and every
//! service has its button.

use serde_json::Value;

fn layout() -> Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/foxglove/thrusterd-live.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The JSON form of a message of `topic`, as the bridge sends it (matrices as row objects).
fn message(topic: &str) -> Value {
    thruster_recorder::source::every_default_message()
        .into_iter()
        .find(|(t, _, _)| *t == topic)
        .unwrap_or_else(|| panic!("the layout names topic {topic}, which the bridge has not"))
        .1
}

/// Resolves `field[i].sub` in `value`; a slice `field[a:b]` (inclusive, as in the apps'
/// message paths) resolves to its last element after checking that every one exists.
fn resolve<'a>(value: &'a Value, path: &str) -> Option<&'a Value> {
    let mut v = value;
    for part in path.split('.') {
        let (name, index) = match part.split_once('[') {
            Some((n, i)) => (n, Some(i.trim_end_matches(']'))),
            None => (part, None),
        };
        v = v.get(name)?;
        if let Some(i) = index {
            match i.split_once(':') {
                Some((a, b)) => {
                    let (a, b) = (a.parse::<usize>().ok()?, b.parse::<usize>().ok()?);
                    if a > b || (a..=b).any(|k| v.get(k).is_none()) {
                        return None;
                    }
                    v = v.get(b)?;
                }
                None => v = v.get(i.parse::<usize>().ok()?)?,
            }
        }
    }
    Some(v)
}

/// `topic` or `topic.field...`, resolved in the topic's message.
fn check_path(id: &str, p: &str) -> Value {
    match p.split_once('.') {
        None => message(p),
        Some((topic, field)) => resolve(&message(topic), field)
            .unwrap_or_else(|| panic!("{id}: {p} is not a field of {topic}"))
            .clone(),
    }
}

#[test]
fn every_path_and_service_of_the_layout_exists() {
    let layout = layout();
    let panels = layout["configById"].as_object().unwrap();
    let mut checked = 0;
    let mut buttons = Vec::new();
    for (id, config) in panels {
        // Titled for both apps: Lichtblick reads only its own key.
        let title = config["foxglovePanelTitle"].as_str().unwrap_or_default();
        assert!(!title.is_empty(), "{id}: no foxglovePanelTitle");
        assert_eq!(config["lichtblickPanelTitle"], title, "{id}");
        let mut paths: Vec<String> = Vec::new();
        if id.starts_with("Plot!") {
            for p in config["paths"].as_array().unwrap() {
                paths.push(p["value"].as_str().unwrap().to_string());
            }
        } else if id.starts_with("RawMessages!") {
            check_path(id, config["topicPath"].as_str().unwrap());
            checked += 1;
        } else if id.starts_with("Indicator!") {
            // A number, and a rule for every value the daemon sends.
            let path = config["path"].as_str().unwrap();
            assert!(check_path(id, path).is_number(), "{id}: {path}");
            let values: Vec<String> = config["rules"]
                .as_array()
                .unwrap()
                .iter()
                .map(|r| r["rawValue"].as_str().unwrap().to_string())
                .collect();
            for state in thruster_protocol::DaemonState::ALL {
                assert!(
                    values.contains(&state.as_u32().to_string()),
                    "{id}: {state:?}"
                );
            }
            checked += 1;
        } else if id.starts_with("CallService!") {
            let name = config["serviceName"].as_str().unwrap();
            let leaf = name
                .strip_prefix(thruster_bridge::services::PREFIX)
                .unwrap_or_else(|| panic!("{id}: {name}"));
            assert!(
                thruster_bridge::services::NAMES.contains(&leaf),
                "{id}: {name}"
            );
            let payload = config["requestPayload"].as_str().unwrap();
            thruster_bridge::services::parse(leaf, payload.as_bytes())
                .unwrap_or_else(|e| panic!("{id}: the button's request is refused: {e}"));
            // The tooltip says what the button does, starting with the service it calls.
            let tooltip = config["buttonTooltip"].as_str().unwrap_or_default();
            assert!(tooltip.starts_with(&format!("{name}: ")), "{id}: {tooltip}");
            buttons.push(leaf.to_string());
            checked += 1;
        } else {
            panic!("panel {id}: not checked by this test");
        }
        for p in paths {
            assert!(p.contains('.'), "{id}: {p}");
            let v = check_path(id, &p);
            assert!(v.is_number(), "{id}: {p} is not a number: {v}");
            checked += 1;
        }
    }
    assert!(checked >= 20, "{checked} items checked");
    buttons.sort();
    let mut services = thruster_bridge::services::NAMES.map(String::from).to_vec();
    services.sort();
    assert_eq!(buttons, services, "one button per service");
    // The emergency stop is red and says so.
    let stop = &panels["CallService!stop"];
    assert_eq!(stop["buttonText"], "EMERGENCY STOP");
    assert_eq!(stop["buttonColor"], "#d1242f");
    // Every panel of the tree is configured.
    let tree = layout["layout"].to_string();
    for id in panels.keys() {
        assert!(
            tree.contains(&format!("\"{id}\"")),
            "{id} not placed in the layout"
        );
    }
}
