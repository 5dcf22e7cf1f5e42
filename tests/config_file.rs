//! The config file: the annotated example in the repository plans cleanly,
//! flags override it, and a bad key or value stops the daemon at start with a
//! message naming it.

use std::io::Write;
use std::path::PathBuf;

use jointd::daemon::{plan, RunArgs};

fn example() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("jointd.example.toml")
}

fn args_with(path: PathBuf) -> RunArgs {
    RunArgs {
        config: Some(path),
        ..Default::default()
    }
}

fn config(text: &str) -> (tempfile_like::TempFile, RunArgs) {
    let f = tempfile_like::TempFile::new(text);
    let args = args_with(f.path.clone());
    (f, args)
}

/// A file removed when the test ends (no extra crate for one temp file).
mod tempfile_like {
    use super::*;

    pub struct TempFile {
        pub path: PathBuf,
    }

    impl TempFile {
        pub fn new(text: &str) -> Self {
            let path = std::env::temp_dir().join(format!(
                "jointd-config-{}-{:?}.toml",
                std::process::id(),
                std::thread::current().id()
            ));
            let mut f = std::fs::File::create(&path).expect("temp file");
            f.write_all(text.as_bytes()).expect("write");
            Self { path }
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

fn error_of(text: &str) -> String {
    let (_f, args) = config(text);
    match plan(&args) {
        Ok(_) => panic!("config was accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_annotated_example_plans() {
    let p = plan(&args_with(example())).expect("jointd.example.toml is valid");
    assert_eq!(p.buses.len(), 1);
    assert_eq!(p.buses[0].name, "right_hand");
    assert_eq!(p.buses[0].baud, 500_000);
    assert_eq!(p.buses[0].ids.len(), 16);
    assert_eq!(p.listen.to_string(), "127.0.0.1:8080");
    assert_eq!(
        p.options
            .joint_names
            .get(&(Some("right_hand".into()), 1))
            .map(String::as_str),
        Some("index_mcp")
    );
    assert_eq!(p.options.watchdog.hold_timeout_ms, 300);
}

#[test]
fn flags_override_the_file() {
    let mut args = args_with(example());
    args.listen = Some("127.0.0.1:9999".parse().expect("addr"));
    args.token = Some("from-flag".into());
    let p = plan(&args).expect("plan");
    assert_eq!(p.listen.to_string(), "127.0.0.1:9999");
    assert_eq!(p.token.as_deref(), Some("from-flag"));
}

#[test]
fn bad_keys_and_values_are_named() {
    let bus = "[[bus]]\nname = \"b\"\npath = \"/dev/null\"\nbaud = 500000\n";
    let cases = [
        (format!("{bus}bauds = 1\n"), "bauds"),
        (format!("{bus}[bus.poll]\ncontrol_shar = 0.5\n"), "control_shar"),
        (format!("{bus}[bus.timing]\nretry = 1\n"), "retry"),
        ("listen = \"not an address\"\n".to_string(), "listen"),
        ("lisen = \"127.0.0.1:1\"\n".to_string(), "lisen"),
        (format!("{bus}[[joint]]\nid = 200\nname = \"x\"\n"), "joint[0].id = 200"),
        (format!("{bus}[[joint]]\nid = 1\nname = \"a\"\n[[joint]]\nid = 1\nname = \"b\"\n"), "named twice"),
        (format!("{bus}[watchdog]\nhold_timeout_ms = 5\n"), "watchdog.hold_timeout_ms = 5"),
        (format!("{bus}[watchdog]\npolicy = \"drop\"\n"), "drop"),
        (format!("{bus}[[limit]]\nmin_deg = -300.0\n"), "-300"),
        ("listen = \"0.0.0.0:8080\"\n[[bus]]\nname = \"b\"\npath = \"/dev/null\"\nbaud = 500000\n".to_string(), "without a token"),
    ];
    for (text, needle) in cases {
        let msg = error_of(&text);
        assert!(
            msg.contains(needle),
            "error for\n{text}\nwas: {msg}\n(expected it to name `{needle}`)"
        );
    }
}

#[test]
fn a_bad_baud_in_the_file_is_refused_when_the_bus_starts() {
    // Values a bus checks itself (baud, ranges) are refused by spawn_bus with
    // the bus's name; plan() only reads the file.
    let (_f, args) = config("[[bus]]\nname = \"b\"\npath = \"/dev/null\"\nbaud = 9600\n");
    let p = plan(&args).expect("plan");
    let err = p.buses[0]
        .validate()
        .expect_err("9600 is not a module baud");
    assert!(err.to_string().contains("9600"), "{err}");
}
