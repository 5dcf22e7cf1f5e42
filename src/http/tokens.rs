//! The daemon's tokens, each a name, a scope and a secret. A request's
//! bearer token is compared with every one, each in constant time; the
//! match's name and scope go with the request ([`Caller`]), its secret
//! nowhere: no log, no event, no answer carries it.

use std::fmt;

use super::scope::Scope;

/// One token: who holds it (its name) and what it may do.
#[derive(Clone)]
pub struct NamedToken {
    pub name: String,
    pub scope: Scope,
    secret: String,
}

impl NamedToken {
    pub fn new(name: impl Into<String>, scope: Scope, secret: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            scope,
            secret: secret.into(),
        }
    }
}

/// Names the token, never its secret.
impl fmt::Debug for NamedToken {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("NamedToken")
            .field("name", &self.name)
            .field("scope", &self.scope)
            .finish_non_exhaustive()
    }
}

/// The name `--token` (and `token` in the config file) goes by.
pub const SINGLE_TOKEN_NAME: &str = "token";

/// Every token the daemon takes; none: the API is open.
#[derive(Debug, Clone, Default)]
pub struct Tokens(Vec<NamedToken>);

impl Tokens {
    pub fn new(tokens: Vec<NamedToken>) -> Self {
        Self(tokens)
    }

    /// The one token of `--token`, with every scope (admin); an empty one
    /// counts as none.
    pub fn single(secret: Option<String>) -> Self {
        Self(
            secret
                .filter(|s| !s.is_empty())
                .map(|s| NamedToken::new(SINGLE_TOKEN_NAME, Scope::Admin, s))
                .into_iter()
                .collect(),
        )
    }

    /// These and `more`.
    pub fn and(mut self, more: Vec<NamedToken>) -> Self {
        self.0.extend(more);
        self
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The tokens' names and scopes (for the log at start: no secret).
    pub fn names(&self) -> Vec<(String, Scope)> {
        self.0.iter().map(|t| (t.name.clone(), t.scope)).collect()
    }

    /// The token `presented` is. Every token is compared, each in constant
    /// time, so how long it takes says nothing of which one (nearly)
    /// matched.
    pub fn find(&self, presented: &str) -> Option<&NamedToken> {
        let mut found = None;
        for t in &self.0 {
            if constant_time_eq(presented.as_bytes(), t.secret.as_bytes()) && found.is_none() {
                found = Some(t);
            }
        }
        found
    }
}

/// Who made a request: its token's name and scope.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    pub name: String,
    pub scope: Scope,
}

impl Caller {
    /// A caller the auth layer did not name: it may look (and stop), nothing more.
    pub fn unknown() -> Self {
        Self {
            name: "unknown".into(),
            scope: Scope::Read,
        }
    }

    /// With no token configured the API is open: every caller may do all.
    pub fn open() -> Self {
        Self {
            name: "open".into(),
            scope: Scope::Admin,
        }
    }
}

impl From<&NamedToken> for Caller {
    fn from(t: &NamedToken) -> Self {
        Self {
            name: t.name.clone(),
            scope: t.scope,
        }
    }
}

/// Compares without an early exit, so response time does not reveal how
/// much of a guessed token was right: every byte of the longer input is
/// visited and folded into one accumulator, whatever differs. (The time
/// depends on the lengths only; the presented one is the caller's own.)
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let len_diff = a.len() ^ b.len();
    let longest = a.len().max(b.len());
    let mut diff = 0u8;
    for i in 0..longest {
        diff |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0xFF);
    }
    diff == 0 && len_diff == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn token_comparison() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secret2"));
        assert!(!constant_time_eq(b"", b"x"));
    }

    #[test]
    fn each_token_is_found_by_its_secret_and_prints_without_it() {
        let tokens = Tokens::new(vec![
            NamedToken::new("dash", Scope::Read, "r-secret"),
            NamedToken::new("policy", Scope::Operate, "o-secret"),
        ]);
        assert_eq!(
            tokens.find("o-secret").map(|t| t.scope),
            Some(Scope::Operate)
        );
        assert_eq!(
            tokens.find("r-secret").map(|t| t.name.as_str()),
            Some("dash")
        );
        assert!(tokens.find("o-secre").is_none());
        assert!(!format!("{tokens:?}").contains("secret"));
    }

    #[test]
    fn the_single_token_is_admin_and_an_empty_one_is_none() {
        let one = Tokens::single(Some("x".into()));
        assert_eq!(one.find("x").map(|t| t.scope), Some(Scope::Admin));
        assert!(Tokens::single(Some(String::new())).is_empty());
        assert!(Tokens::single(None).is_empty());
    }
}
