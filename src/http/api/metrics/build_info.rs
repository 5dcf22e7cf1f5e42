//! `jointd_build_info`: what this binary is. The features are read with
//! `cfg!` here, in the crate they switch, so the label cannot disagree with
//! the code that was compiled; the revision and the compiler's version come
//! from `build.rs` ("unknown" for a build without `.git`).

use super::exposition::{label, Exposition};

/// Every feature of Cargo.toml's `[features]`, and whether this build has
/// it. A test holds this list to Cargo.toml.
const FEATURES: [(&str, bool); 2] = [
    ("bench", cfg!(feature = "bench")),
    ("ros2", cfg!(feature = "ros2")),
];

/// The features compiled in, comma-separated, in Cargo.toml's order.
fn features() -> String {
    let on: Vec<&str> = FEATURES
        .iter()
        .filter(|(_, on)| *on)
        .map(|(name, _)| *name)
        .collect();
    on.join(",")
}

pub(super) fn family(m: &mut Exposition) {
    let labels = format!(
        "version=\"{}\",features=\"{}\",revision=\"{}\",rustc_version=\"{}\"",
        label(env!("CARGO_PKG_VERSION")),
        label(&features()),
        label(env!("JOINTD_GIT_REVISION")),
        label(env!("JOINTD_RUSTC_VERSION")),
    );
    m.gauge(
        "jointd_build_info",
        "The daemon's version, cargo features, git revision and compiler (always 1).",
        &labels,
        1.0,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `features` label of a rendered exposition.
    fn features_label(text: &str) -> String {
        let line = text
            .lines()
            .find(|l| l.starts_with("jointd_build_info{"))
            .expect("a build_info line");
        let rest = line.split_once("features=\"").expect("a features label").1;
        rest.split_once('"').expect("closing quote").0.to_owned()
    }

    #[test]
    fn the_features_label_is_what_cargo_compiled_in() {
        let mut m = Exposition::default();
        family(&mut m);
        // build.rs lists the features cargo enabled for this very build.
        assert_eq!(
            features_label(&m.render()),
            env!("JOINTD_CARGO_FEATURES"),
            "features label vs cargo's CARGO_FEATURE_* for this build"
        );
    }

    #[test]
    fn every_cargo_feature_is_in_the_list() {
        let manifest = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml"));
        let manifest: toml::Table = toml::from_str(manifest).expect("Cargo.toml parses");
        let declared: std::collections::BTreeSet<&str> = manifest["features"]
            .as_table()
            .expect("[features]")
            .keys()
            .map(String::as_str)
            .collect();
        let listed: std::collections::BTreeSet<&str> =
            FEATURES.iter().map(|(name, _)| *name).collect();
        assert_eq!(listed, declared, "FEATURES vs Cargo.toml's [features]");
    }

    #[test]
    fn the_revision_is_a_short_hash_or_unknown() {
        let rev = env!("JOINTD_GIT_REVISION");
        assert!(
            rev == "unknown" || (rev.len() >= 7 && rev.chars().all(|c| c.is_ascii_hexdigit())),
            "{rev}"
        );
    }
}
