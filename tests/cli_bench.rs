//! `jointd bench` in a build without the `bench` feature: it says how to
//! get the bench and exits 2, whatever arguments follow.

#[cfg(not(feature = "bench"))]
#[test]
fn bench_without_the_feature_says_how_to_build_it() {
    for args in [&["bench"][..], &["bench", "--ws", "--seconds", "3"][..]] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_jointd"))
            .args(args)
            .output()
            .expect("run jointd");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("--features bench")
                && err.contains("cargo run --release --features bench -- bench"),
            "{args:?}: {err}"
        );
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}

/// `jointd --help` does not offer a subcommand this build lacks.
#[cfg(not(feature = "bench"))]
#[test]
fn help_does_not_list_the_missing_bench() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_jointd"))
        .arg("--help")
        .output()
        .expect("run jointd");
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("frame") && !help.contains("bench"), "{help}");
}
