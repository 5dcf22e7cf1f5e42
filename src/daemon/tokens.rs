//! The scoped tokens of `[[tokens]]`: each a name, a scope (`read`,
//! `operate`, `admin`) and a secret read from a file or an environment
//! variable, never written in the config file itself and never logged.
//! The single token of `--token` is the admin token named `token`.

use std::path::PathBuf;

use serde::Deserialize;

use super::error::DaemonError;
use crate::http::scope::Scope;
use crate::http::tokens::{NamedToken, SINGLE_TOKEN_NAME};

/// Longest token name.
const MAX_NAME: usize = 64;

/// One `[[tokens]]` entry.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenConfig {
    /// Who holds it: shown in the log and the events beside what it did.
    pub name: String,
    /// `read`, `operate` or `admin`.
    pub scope: String,
    /// A file holding the secret (a container secret); trailing newlines
    /// are ignored.
    pub file: Option<PathBuf>,
    /// An environment variable holding the secret.
    pub env: Option<String>,
}

/// Every `[[tokens]]` entry checked, its secret read. `single`: the secret
/// of `--token`, which no scoped token may share.
pub(super) fn scoped_tokens(
    configs: &[TokenConfig],
    single: Option<&str>,
) -> Result<Vec<NamedToken>, DaemonError> {
    let mut out: Vec<NamedToken> = Vec::with_capacity(configs.len());
    let mut secrets: Vec<String> = single.map(str::to_owned).into_iter().collect();
    for (i, c) in configs.iter().enumerate() {
        let at = format!("[[tokens]] #{} (`{}`)", i + 1, c.name);
        let bad = |why: String| DaemonError::Token {
            from: at.clone(),
            why,
        };
        check_name(&c.name).map_err(|why| bad(why.into()))?;
        if out.iter().any(|t| t.name == c.name) {
            return Err(bad("a second token of this name".into()));
        }
        let scope = Scope::parse(&c.scope).ok_or_else(|| {
            bad(format!(
                "scope `{}` is none of read, operate, admin",
                c.scope
            ))
        })?;
        let secret = match (&c.file, &c.env) {
            (Some(path), None) => std::fs::read_to_string(path)
                .map(|t| t.trim_end_matches(['\n', '\r']).to_owned())
                .map_err(|e| bad(format!("cannot read {}: {e}", path.display())))?,
            (None, Some(var)) => {
                std::env::var(var).map_err(|_| bad(format!("the environment has no `{var}`")))?
            }
            _ => return Err(bad("give its secret's `file` or `env`, one of them".into())),
        };
        if let Some(why) = token_problem(&secret) {
            return Err(bad(format!("its secret: {why}")));
        }
        if secrets.contains(&secret) {
            return Err(bad(
                "its secret is another token's: a request could not say which it is".into(),
            ));
        }
        secrets.push(secret.clone());
        out.push(NamedToken::new(c.name.clone(), scope, secret));
    }
    Ok(out)
}

/// A name for the log and the events: printable, short, and not the
/// single token's.
fn check_name(name: &str) -> Result<(), &'static str> {
    if name.is_empty() || name.len() > MAX_NAME {
        return Err("its name must be 1..=64 characters");
    }
    if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
    {
        return Err("its name may hold letters, digits, `-`, `_` and `.` only");
    }
    if name == SINGLE_TOKEN_NAME {
        return Err("the name `token` is the single token's (`--token`)");
    }
    Ok(())
}

/// Why a token cannot be used: an `Authorization` header cannot carry
/// blanks at its ends or control characters, and an empty token would
/// silently turn auth off.
pub(super) fn token_problem(token: &str) -> Option<&'static str> {
    if token.is_empty() {
        Some("it is empty; give a token, or leave the option out to run without one")
    } else if token.trim().is_empty() {
        Some("it is only whitespace")
    } else if token.trim() != token {
        Some("it starts or ends with whitespace, which an Authorization header cannot carry")
    } else if token.chars().any(char::is_control) {
        Some("it contains a control character")
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(name: &str, scope: &str, env: &str) -> TokenConfig {
        TokenConfig {
            name: name.into(),
            scope: scope.into(),
            file: None,
            env: Some(env.into()),
        }
    }

    #[test]
    fn tokens_come_from_the_environment_with_their_scope() {
        std::env::set_var("JOINTD_TEST_TOKEN_DASH", "dash-secret");
        std::env::set_var("JOINTD_TEST_TOKEN_POLICY", "policy-secret");
        let tokens = scoped_tokens(
            &[
                entry("dashboard", "read", "JOINTD_TEST_TOKEN_DASH"),
                entry("policy", "operate", "JOINTD_TEST_TOKEN_POLICY"),
            ],
            None,
        )
        .expect("two good tokens");
        assert_eq!(tokens.len(), 2);
        assert_eq!(
            (tokens[0].name.as_str(), tokens[0].scope),
            ("dashboard", Scope::Read)
        );
        assert_eq!(tokens[1].scope, Scope::Operate);
    }

    #[test]
    fn a_bad_entry_is_refused_saying_which_and_why() {
        std::env::set_var("JOINTD_TEST_TOKEN_A", "same");
        std::env::set_var("JOINTD_TEST_TOKEN_B", "same");
        let refused = |configs: &[TokenConfig], single: Option<&str>| {
            scoped_tokens(configs, single)
                .expect_err("refused")
                .to_string()
        };
        let e = refused(&[entry("x", "root", "JOINTD_TEST_TOKEN_A")], None);
        assert!(e.contains("scope `root`"), "{e}");
        let e = refused(&[entry("token", "read", "JOINTD_TEST_TOKEN_A")], None);
        assert!(e.contains("single token"), "{e}");
        let e = refused(
            &[
                entry("a", "read", "JOINTD_TEST_TOKEN_A"),
                entry("b", "admin", "JOINTD_TEST_TOKEN_B"),
            ],
            None,
        );
        assert!(e.contains("another token's"), "{e}");
        let e = refused(&[entry("a", "read", "JOINTD_TEST_TOKEN_A")], Some("same"));
        assert!(e.contains("another token's"), "{e}");
        let e = refused(&[entry("a", "read", "JOINTD_TEST_NO_SUCH_VAR")], None);
        assert!(e.contains("JOINTD_TEST_NO_SUCH_VAR"), "{e}");
        let e = refused(&[entry("a b", "read", "JOINTD_TEST_TOKEN_A")], None);
        assert!(e.contains("letters, digits"), "{e}");
        assert!(!e.contains("same"), "a secret never in an error: {e}");
    }
}
