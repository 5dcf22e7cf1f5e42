//! `jointd frame decode|encode` through the real binary: output, and exit
//! status 2 with a message on stderr for bad input.

use std::process::{Command, Output};

fn jointd(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_jointd"))
        .args(args)
        .output()
        .expect("jointd runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn decode_prints_one_json_object_per_frame_and_skips_garbage() {
    let hex = "ff 00 55AA00140002010000 00754F0000FA05AC950000 \
               55 AB 00 2D 00 2D 00 2D 00 2D 00 2D 00 2D 00 2D 00 2D B6 67";
    let o = jointd(&["frame", "decode", hex]);
    assert!(o.status.success(), "{o:?}");
    let lines: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is JSON"))
        .collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["kind"], "reply");
    assert_eq!(lines[0]["vbus_v"], 11.953125);
    assert_eq!(lines[1]["group"], "pos 1-8");
    assert!(String::from_utf8_lossy(&o.stderr).contains("2 bytes skipped"));
}

#[test]
fn encode_prints_the_twenty_bytes() {
    let o = jointd(&["frame", "encode", r#"{"kind":"jog","dev_id":2,"dir":"cw"}"#]);
    assert!(o.status.success(), "{o:?}");
    assert_eq!(
        stdout(&o).trim(),
        "55 AA 00 14 F0 00 00 00 02 00 01 00 00 00 00 00 EE 60 00 00"
    );
}

#[test]
fn bad_input_exits_2_with_a_reason() {
    let cases: [(&[&str], &str); 6] = [
        (&["frame", "decode", "55 A"], "odd number of hex digits"),
        (&["frame", "decode", "zz"], "not a hex digit"),
        (
            &[
                "frame",
                "decode",
                "55 B1 00 14 B1 00 00 00 FF 01 00 00 00 00 00 00 F3 58 00 00",
            ],
            "no valid frame",
        ),
        (&["frame", "encode", "{"], "not valid JSON"),
        (
            &[
                "frame",
                "encode",
                r#"{"kind":"control","dev_id":1,"en":3,"pos_deg":300,"spd_rpm":10}"#,
            ],
            "out of range",
        ),
        (
            &[
                "frame",
                "encode",
                r#"{"kind":"config","dev_id":2,"index":18,"amps":-1}"#,
            ],
            "out of range",
        ),
    ];
    for (args, why) in cases {
        let o = jointd(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(why), "{args:?}: stderr {err:?} lacks {why:?}");
        assert!(o.stdout.is_empty(), "{args:?} printed to stdout");
    }
}

#[test]
fn encode_refuses_set_ref_without_a_target_and_unknown_fields() {
    let o = jointd(&[
        "frame",
        "encode",
        r#"{"kind":"control","dev_id":1,"en":"set_ref"}"#,
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = jointd(&[
        "frame",
        "encode",
        r#"{"kind":"jog","dev_id":1,"dir":"cw","speed":3}"#,
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown field `speed`"));
}

#[test]
fn decode_names_every_index_of_the_table() {
    // Every index gets its name from the parameter table, INFO_07_R (rev
    // 2.0.8) included, never "UNKNOWN".
    let hex = "55 AA 00 14 A0 00 00 00 02 20 00 00 00 00 00 00 A8 A1 00 00";
    let o = jointd(&["frame", "decode", hex]);
    assert!(o.status.success(), "{o:?}");
    let json: serde_json::Value = serde_json::from_str(stdout(&o).trim()).expect("JSON");
    assert_eq!(json["name"], "INFO_07_R");
    assert_eq!(json["index"], 32);
}
