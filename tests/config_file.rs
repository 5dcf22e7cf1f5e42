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
        p.control
            .joint_names
            .get(&(Some("right_hand".into()), 1))
            .map(String::as_str),
        Some("index_mcp")
    );
    assert_eq!(p.control.watchdog.hold_timeout_ms, 300);
    assert_eq!(p.buses[0].firmware.name(), "auto");
    assert_eq!(p.buses[0].adapter, jointd::bus::AdapterSetting::Auto);
}

#[test]
fn firmware_is_read_per_bus_and_per_device() {
    let (_f, args) = config(
        "[[bus]]\nname = \"b\"\npath = \"/dev/null\"\nbaud = 500000\nfirmware = \"2.0.8\"\n\
         firmware_by_id = { \"9-16\" = \"2.0.1\", \"3\" = \"auto\" }\n",
    );
    let p = plan(&args).expect("plan");
    let policy = p.buses[0].firmware_policy().expect("valid");
    let names: Vec<&str> = [1, 3, 9, 16]
        .iter()
        .map(|id| policy.for_id(*id).name())
        .collect();
    assert_eq!(names, ["2.0.8", "auto", "2.0.1", "2.0.1"]);
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
        (format!("{bus}firmware = \"2.0.2\"\n"), "\"auto\", \"2.0.1\", \"2.0.8\""),
        (format!("{bus}firmware_by_id = {{ \"1-3\" = \"2.0.8\", \"3\" = \"2.0.1\" }}\n"), "device 3 twice"),
        (format!("{bus}firmware_by_id = {{ \"0\" = \"2.0.8\" }}\n"), "not a device id"),
        (format!("{bus}adapter = \"pl2303\"\n"), "not one of native, ftdi[:MS]"),
        (format!("{bus}adapter = \"ftdi:0\"\n"), "1..=255"),
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
fn a_bad_baud_in_the_file_is_refused_at_load_with_its_line() {
    // Values a bus checks itself (baud, ranges) are refused when the file is
    // read, with the line of the key, not later by the bus.
    let (_f, args) = config("[[bus]]\nname = \"b\"\npath = \"/dev/null\"\nbaud = 9600\n");
    let err = plan(&args)
        .expect_err("9600 is not a module baud")
        .to_string();
    assert!(
        err.contains("line 4, column 1") && err.contains("`baud`"),
        "{err}"
    );
    assert!(err.contains("9600"), "{err}");
}

/// A file of this test's own (the name says which), removed at the end.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str, text: &str) -> Self {
        let path = std::env::temp_dir().join(format!("jointd-{}-{name}", std::process::id()));
        std::fs::write(&path, text).expect("write scratch file");
        Self(path)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn sim_args() -> RunArgs {
    RunArgs {
        sim: Some(1),
        ..Default::default()
    }
}

#[test]
fn an_empty_or_blank_token_stops_the_start() {
    for (token, why) in [
        ("", "empty"),
        (" ", "only whitespace"),
        ("\t\n", "only whitespace"),
        (" s3cret", "whitespace"),
        ("s3\u{7}cret", "control character"),
    ] {
        let args = RunArgs {
            token: Some(token.into()),
            ..sim_args()
        };
        let err = plan(&args).expect_err(token).to_string();
        assert!(
            err.contains("token") && err.contains(why),
            "{token:?}: {err}"
        );
    }
    let err =
        error_of("token = \"\"\n[[bus]]\nname = \"a\"\npath = \"/dev/null\"\nbaud = 500000\n");
    assert!(err.contains("empty"), "{err}");
}

#[test]
fn a_token_file_is_read_once_trimmed_of_its_newline() {
    let secret = Scratch::new("token-ok", "a/b+= c\n");
    let args = RunArgs {
        token_file: Some(secret.0.clone()),
        ..sim_args()
    };
    assert_eq!(plan(&args).unwrap().token.as_deref(), Some("a/b+= c"));
    let crlf = Scratch::new("token-crlf", "s3cret\r\n");
    let args = RunArgs {
        token_file: Some(crlf.0.clone()),
        ..sim_args()
    };
    assert_eq!(plan(&args).unwrap().token.as_deref(), Some("s3cret"));
    for (name, text, why) in [
        ("token-empty", "", "empty"),
        ("token-nl", "\n", "empty"),
        ("token-blank", "  \n", "whitespace"),
    ] {
        let f = Scratch::new(name, text);
        let args = RunArgs {
            token_file: Some(f.0.clone()),
            ..sim_args()
        };
        let err = plan(&args).expect_err(name).to_string();
        assert!(
            err.contains(&f.0.display().to_string()) && err.contains(why),
            "{err}"
        );
    }
    let missing = RunArgs {
        token_file: Some("/nonexistent/jointd-token".into()),
        ..sim_args()
    };
    assert!(plan(&missing)
        .unwrap_err()
        .to_string()
        .contains("cannot read"));
    // In the config file: token_file, not both.
    let path = secret.0.display();
    let (_f, args) = config(&format!("token_file = \"{path}\"\n"));
    let args = RunArgs {
        sim: Some(1),
        ..args
    };
    assert_eq!(plan(&args).unwrap().token.as_deref(), Some("a/b+= c"));
    let (_f, args) = config(&format!("token = \"x\"\ntoken_file = \"{path}\"\n"));
    let args = RunArgs {
        sim: Some(1),
        ..args
    };
    assert!(plan(&args).unwrap_err().to_string().contains("not both"));
}

#[test]
fn allow_lists_and_body_limit_from_file_and_flags() {
    let (_f, args) = config(
        "allowed_hosts = [\"Robot-PC\", \"192.168.1.5\"]\n\
         allowed_origins = [\"http://robot-pc:3000/\"]\nmax_body_bytes = 4096\n",
    );
    let args = RunArgs {
        sim: Some(1),
        ..args
    };
    let p = plan(&args).unwrap().http.policy;
    assert_eq!(p.allowed_hosts, ["robot-pc", "192.168.1.5"]);
    assert_eq!(p.allowed_origins, ["http://robot-pc:3000"]);
    assert_eq!(p.max_body_bytes, 4096);
    let flags = RunArgs {
        allowed_hosts: vec!["arm.lan".into()],
        allowed_origins: vec!["https://ops.example".into()],
        max_body_bytes: Some(100),
        ..args
    };
    let p = plan(&flags).unwrap().http.policy;
    assert_eq!(p.allowed_hosts, ["arm.lan"]);
    assert_eq!(p.allowed_origins, ["https://ops.example"]);
    assert_eq!(p.max_body_bytes, 100);
    let p = plan(&sim_args()).unwrap().http.policy;
    assert_eq!(p.max_body_bytes, 1024 * 1024);
    assert!(p.allowed_hosts.is_empty() && p.allowed_origins.is_empty());
    let err = error_of("allowed_origins = [\"robot-pc:3000\"]\n[[bus]]\nname = \"a\"\npath = \"/dev/null\"\nbaud = 500000\n");
    assert!(
        err.contains("allowed_origins") && err.contains("scheme://"),
        "{err}"
    );
    let err = error_of("allowed_hosts = [\"http://robot-pc\"]\n[[bus]]\nname = \"a\"\npath = \"/dev/null\"\nbaud = 500000\n");
    assert!(err.contains("allowed_hosts"), "{err}");
    let err = error_of(
        "max_body_bytes = 0\n[[bus]]\nname = \"a\"\npath = \"/dev/null\"\nbaud = 500000\n",
    );
    assert!(err.contains("max_body_bytes"), "{err}");
}
