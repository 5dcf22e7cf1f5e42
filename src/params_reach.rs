//! Test builds only: the fictitious parameter row (`protocol::params::tests::
//! FICTITIOUS`, added to the table by one `#[cfg(test)]` line) reaches every
//! user of the table above `protocol`: the REST surface and its OpenAPI
//! schema, the bus's write verification and the simulator. Adding an index
//! touches the table and its tests only; these tests fail if a user keeps a
//! list of its own. They live at the crate root so that `protocol` imports
//! nothing from the rooms that use it, not even in tests.

use crate::protocol::values::{BaudLevel, InfoBlock};

#[test]
fn fictitious_row_is_offered_by_the_rest_surface_and_its_schema() {
    use crate::http::api::config_params::{api_keys, to_config, ConfigPatch};
    use crate::http::api::config_schema::{ConfigView, ParamTable};
    use utoipa::PartialSchema;
    assert!(api_keys().contains(&"test_level"));
    let patch: ConfigPatch = serde_json::from_str(r#"{"test_level": 4}"#).expect("accepted");
    let (row, value) = patch.entries()[0];
    let write = to_config(row, value).expect("in range");
    assert_eq!(write.index_value(), (40, 4));
    assert_eq!(to_config(row, 12.0).map_err(|e| e.problem.status), Err(422));
    let schema = serde_json::to_value(ConfigPatch::schema()).expect("schema");
    assert_eq!(schema["properties"]["test_level"]["maximum"], 9.0);
    let view = serde_json::to_value(ConfigView::schema()).expect("schema");
    assert!(view["required"]
        .as_array()
        .is_some_and(|r| r.contains(&"test_level".into())));
    assert!(ParamTable::new()
        .params
        .iter()
        .any(|p| p.name == "TEST_LEVEL"));
}

#[test]
fn fictitious_row_is_stored_and_reported_by_the_simulator() {
    use crate::bus::verify::{confirmation, Confirm};
    use crate::protocol::ConfigParam;
    use crate::sim::Params;
    let write = ConfigParam::from_index_value(40, 6).expect("valid");
    let mut p = Params::factory(BaudLevel::B500000);
    assert!(p.apply(&write), "a RAM setting is stored");
    let data = p.block(InfoBlock::Info04);
    assert_eq!(data[3], 6, "reported at its read-back field");
    let Ok(Confirm::ReadBack { block, field }) = confirmation(&write) else {
        panic!("the bus verifies it by read-back");
    };
    assert_eq!((block, field.read(&data)), (InfoBlock::Info04, 6));
}
