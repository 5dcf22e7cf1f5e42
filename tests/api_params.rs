//! `GET /api/v1/params` serves the parameter table the dashboard builds its
//! configuration form from, and it agrees with the config surface.

mod support;

use jointd::protocol::params::PARAMS;
use support::http::serve;

#[tokio::test]
async fn the_table_is_served_row_by_row() {
    let server = serve(jointd::http::AppState::new(
        std::sync::Arc::new(jointd::control::Control::new(
            Vec::new(),
            Default::default(),
        )),
        None,
    ))
    .await;
    let r = server.get("/api/v1/params").await;
    assert!(r.status.is_success(), "{}", r.status);
    let rows = r.body["params"].as_array().expect("params array");
    assert_eq!(rows.len(), PARAMS.len());
    let max_cur = rows.iter().find(|r| r["index"] == 18).expect("MAX_CUR");
    assert_eq!(max_cur["name"], "MAX_CUR");
    assert_eq!(max_cur["key"], "max_current_a");
    assert_eq!(max_cur["unit"], "A");
    assert_eq!(max_cur["max"], 5.625);
    assert_eq!(max_cur["read_back"]["block"], "INFO_04_R");
    assert_eq!(max_cur["read_back"]["offset"], 4);
    assert_eq!(max_cur["api"], true);
    let info07 = rows.iter().find(|r| r["index"] == 32).expect("INFO_07_R");
    assert_eq!(
        (info07["name"].as_str(), info07["since"].as_str()),
        (Some("INFO_07_R"), Some("2.0.8"))
    );
    let offered: Vec<_> = rows.iter().filter(|r| r["api"] == true).collect();
    assert_eq!(offered.len(), 16, "the keys PATCH …/config accepts");
    // Three of them only on rev 2.0.8 devices, and write-only there.
    let rev_2_0_8: Vec<_> = offered
        .iter()
        .filter(|r| r["since"] == "2.0.8")
        .map(|r| (r["key"].as_str().unwrap_or(""), r["read_back"].is_null()))
        .collect();
    assert_eq!(
        rev_2_0_8,
        [("drv_ot_c", true), ("spd_limit_rpm", true), ("sn", true)]
    );
}
