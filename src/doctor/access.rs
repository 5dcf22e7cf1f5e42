//! Whether this user may open the port, and whether another process has
//! it: the device node's group and mode against this process's groups
//! (`/proc/self/status`, `/etc/group`), the processes holding it open
//! (`/proc/*/fd`), and what an open that failed means, with the fix.
//!
//! A port another process holds is left untouched: the holders are looked
//! up before the doctor opens anything, and a running jointd's lock
//! ([`crate::transport::tty::PortHeld`]) refuses the open before termios,
//! RS-485 mode or the latency timer are set.

use std::fs;
use std::io;
use std::os::unix::fs::MetadataExt;
use std::path::Path;

use serde::Serialize;

use super::check::{Check, CheckId};
use super::port::{udev_rule, PortFacts, PortKind, Roots};

/// A process that has the port open.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Holder {
    pub pid: u32,
    /// Its `comm`: `jointd`, `minicom`, `ModemManager`.
    pub command: String,
}

/// Who may open the port, and who has it.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
pub struct AccessFacts {
    /// The device node's group and mode (`dialout`, `0660`).
    pub group: Option<String>,
    pub mode: Option<String>,
    pub user: Option<String>,
    /// This process is in the node's group now.
    pub in_group_now: bool,
    /// `/etc/group` lists the user in it (a login since would have it).
    pub in_group_file: bool,
    /// Other processes with the port open (only those this user may see).
    pub holders: Vec<Holder>,
}

/// Reads who may open `device` and who has it open.
pub fn inspect(device: &Path, roots: &Roots) -> AccessFacts {
    let meta = fs::metadata(device).ok();
    let status = fs::read_to_string(roots.proc_root.join("self/status")).unwrap_or_default();
    let (uid, groups) = parse_status(&status);
    let etc = |f: &str| fs::read_to_string(roots.etc.join(f)).unwrap_or_default();
    let user = uid.and_then(|uid| user_name(&etc("passwd"), uid));
    let gid = meta.as_ref().map(|m| m.gid());
    let entry = gid.and_then(|gid| group_entry(&etc("group"), gid));
    AccessFacts {
        mode: meta.as_ref().map(|m| format!("{:04o}", m.mode() & 0o7777)),
        in_group_now: gid.is_some_and(|g| groups.contains(&g)),
        in_group_file: match (&entry, &user) {
            (Some((_, members)), Some(user)) => members.contains(user),
            _ => false,
        },
        group: entry.map(|(name, _)| name),
        user,
        holders: holders(&roots.proc_root, device, std::process::id()),
    }
}

/// This process's real uid and supplementary groups, from `/proc/self/status`.
pub(crate) fn parse_status(text: &str) -> (Option<u32>, Vec<u32>) {
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name))
            .map(str::split_whitespace)
    };
    let uid = field("Uid:").and_then(|mut w| w.next()?.parse().ok());
    let groups =
        field("Groups:").map_or_else(Vec::new, |w| w.filter_map(|g| g.parse().ok()).collect());
    (uid, groups)
}

/// The group with `gid` in an `/etc/group` text: its name and members.
pub(crate) fn group_entry(text: &str, gid: u32) -> Option<(String, Vec<String>)> {
    text.lines().find_map(|line| {
        let mut f = line.split(':');
        let (name, _, id, members) = (f.next()?, f.next()?, f.next()?, f.next().unwrap_or(""));
        (id.parse::<u32>().ok() == Some(gid)).then(|| {
            let members = members
                .split(',')
                .filter(|m| !m.is_empty())
                .map(String::from)
                .collect();
            (name.to_string(), members)
        })
    })
}

/// The name of `uid` in an `/etc/passwd` text.
pub(crate) fn user_name(text: &str, uid: u32) -> Option<String> {
    text.lines().find_map(|line| {
        let mut f = line.split(':');
        let (name, _, id) = (f.next()?, f.next()?, f.next()?);
        (id.parse::<u32>().ok() == Some(uid)).then(|| name.to_string())
    })
}

/// The processes other than `own_pid` with a descriptor on `device`.
pub(crate) fn holders(proc_root: &Path, device: &Path, own_pid: u32) -> Vec<Holder> {
    let Ok(entries) = fs::read_dir(proc_root) else {
        return Vec::new();
    };
    let mut found: Vec<Holder> = entries
        .filter_map(Result::ok)
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&pid| pid != own_pid && holds(&proc_root.join(pid.to_string()), device))
        .map(|pid| Holder {
            pid,
            command: fs::read_to_string(proc_root.join(format!("{pid}/comm")))
                .map(|c| c.trim().to_string())
                .unwrap_or_default(),
        })
        .collect();
    found.sort_by_key(|h| h.pid);
    found
}

/// True when one of the process's descriptors (`PROC/PID/fd/*`) is `device`.
fn holds(process: &Path, device: &Path) -> bool {
    let Ok(fds) = fs::read_dir(process.join("fd")) else {
        return false;
    };
    fds.filter_map(Result::ok)
        .any(|fd| fs::read_link(fd.path()).is_ok_and(|target| target == device))
}

/// `pid 812 (jointd), pid 90 (minicom)`.
fn named(holders: &[Holder]) -> String {
    let names: Vec<String> = holders
        .iter()
        .map(|h| format!("pid {} ({})", h.pid, h.command))
        .collect();
    names.join(", ")
}

/// Whether another process has the port, judged before it is opened: on a
/// pty its creator always has (only a lock says it is taken); on anything
/// else another holder would read the replies or write over the doctor's
/// frames, and the port is left alone.
pub(crate) fn holders_check(facts: &PortFacts, access: &AccessFacts) -> Check {
    let id = CheckId::Held;
    if access.holders.is_empty() {
        return Check::ok(id, "no other process has it open (that this user can see)");
    }
    if facts.kind == PortKind::Pty {
        return Check::ok(
            id,
            format!(
                "open in {} (a pty's creator holds it); not locked",
                named(&access.holders)
            ),
        );
    }
    let mut fix = String::from("close it first (a running jointd: stop it, e.g. `systemctl stop jointd`); the doctor left the port untouched");
    if access.holders.iter().any(|h| h.command == "ModemManager") {
        fix.push_str(
            "; ModemManager probes new serial ports: keep it off this adapter with a udev rule \
             adding ENV{ID_MM_DEVICE_IGNORE}=\"1\"",
        );
    }
    Check::fail(id, format!("open in {}", named(&access.holders)), fix)
}

/// The open was refused because the port's lock is held: a running jointd.
pub(crate) fn held_by_lock(facts: &PortFacts, access: &AccessFacts) -> Check {
    let who = if access.holders.is_empty() {
        "a running jointd (or another program that locked it)".to_string()
    } else {
        named(&access.holders)
    };
    Check::fail(
        CheckId::Held,
        format!(
            "{} is held by {who}: its lock is taken",
            facts.path.display()
        ),
        "stop the daemon holding it, or ask that daemon instead (`GET /api/v1/buses/{bus}`); \
         the doctor left the port untouched",
    )
}

/// What an open that failed (other than a held lock) means, and the fix.
pub(crate) fn open_failed(e: &io::Error, facts: &PortFacts, access: &AccessFacts) -> Check {
    let path = facts.path.display();
    match e.raw_os_error() {
        Some(libc::EACCES | libc::EPERM) => permission_denied(facts, access),
        Some(libc::EBUSY) => Check::fail(
            CheckId::Held,
            format!("{path} is busy: another program opened it exclusive (TIOCEXCL)"),
            "close the program that has it (`fuser -v` names it)",
        ),
        Some(libc::ENOENT) => Check::fail(
            CheckId::Open,
            format!("{path} does not exist"),
            "is the adapter plugged in? `ls -l /dev/serial/by-id/` lists USB adapters, \
             `dmesg | tail` shows one arriving",
        ),
        Some(libc::ENXIO | libc::ENODEV | libc::EIO) => Check::fail(
            CheckId::Open,
            format!("no device behind {path} ({e})"),
            "replug the adapter; `dmesg | tail` says what the kernel saw",
        ),
        _ => Check::fail(
            CheckId::Open,
            format!("{path} could not be opened raw: {e}"),
            "check that it is a serial tty (`stty -F PATH` should answer)",
        ),
    }
}

/// EACCES: the group to join, or the login to renew, or a udev rule.
fn permission_denied(facts: &PortFacts, access: &AccessFacts) -> Check {
    let group = access.group.clone().unwrap_or_else(|| "dialout".into());
    let found = format!(
        "permission denied: {} is {} group {group}, and this user ({}) is not in it",
        facts
            .device
            .as_deref()
            .unwrap_or(facts.path.as_path())
            .display(),
        access.mode.as_deref().unwrap_or("?"),
        access.user.as_deref().unwrap_or("?"),
    );
    let mut fix = if access.in_group_file {
        format!("you were added to {group} after this login: log out and in again (or run `newgrp {group}`)")
    } else if group == "root" {
        "the node belongs to root: give it to the dialout group with a udev rule (below), then join dialout"
            .to_string()
    } else {
        format!("`sudo usermod -aG {group} $USER`, then log out and in again")
    };
    if let PortKind::Usb(u) = &facts.kind {
        fix.push_str(&format!(
            "; or a udev rule for this adapter (/etc/udev/rules.d/99-jointd.rules):\n{}",
            udev_rule(u)
        ));
    }
    Check::fail(CheckId::Permission, found, fix)
}

/// The open worked: say what made it allowed.
pub(crate) fn permission_ok(access: &AccessFacts) -> Check {
    Check::ok(
        CheckId::Permission,
        format!(
            "mode {} group {}: this user may read and write it",
            access.mode.as_deref().unwrap_or("?"),
            access.group.as_deref().unwrap_or("?")
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::check::Verdict;
    use std::path::PathBuf;

    #[test]
    fn status_group_and_passwd_parse() {
        let status = "Name:\tbash\nUid:\t1000\t1000\t1000\t1000\nGid:\t1000\t1000\t1000\t1000\nGroups:\t4 24 27 1000 \n";
        assert_eq!(parse_status(status), (Some(1000), vec![4, 24, 27, 1000]));
        let group = "root:x:0:\ndialout:x:20:alice,bob\n";
        assert_eq!(
            group_entry(group, 20),
            Some(("dialout".into(), vec!["alice".into(), "bob".into()]))
        );
        assert_eq!(group_entry(group, 0), Some(("root".into(), vec![])));
        assert_eq!(group_entry(group, 99), None);
        assert_eq!(
            user_name(
                "root:x:0:0::/root:/bin/sh\nalice:x:1000:1000::/home/alice:/bin/bash\n",
                1000
            )
            .as_deref(),
            Some("alice")
        );
    }

    #[test]
    fn holders_are_found_by_their_descriptors_and_named() {
        let root = std::env::temp_dir().join(format!("jointd-doctor-proc-{}", std::process::id()));
        let _ = fs::remove_dir_all(&root);
        let device = PathBuf::from("/dev/ttyUSB0");
        for (pid, comm, fd_target) in [
            (812, "jointd", "/dev/ttyUSB0"),
            (90, "bash", "/dev/pts/1"),
            (7, "self", "/dev/ttyUSB0"),
        ] {
            let fd = root.join(format!("{pid}/fd"));
            fs::create_dir_all(&fd).unwrap();
            std::os::unix::fs::symlink(fd_target, fd.join("3")).unwrap();
            fs::write(root.join(format!("{pid}/comm")), format!("{comm}\n")).unwrap();
        }
        fs::create_dir_all(root.join("self")).unwrap();
        let found = holders(&root, &device, 7);
        assert_eq!(
            found,
            vec![Holder {
                pid: 812,
                command: "jointd".into()
            }]
        );
        let facts = PortFacts {
            device: Some(device.clone()),
            tty: Some("ttyUSB0".into()),
            ..PortFacts::unknown(device)
        };
        let access = AccessFacts {
            holders: found,
            ..AccessFacts::default()
        };
        let c = holders_check(&facts, &access);
        assert_eq!(c.verdict, Verdict::Fail);
        assert!(c.found.contains("pid 812 (jointd)"), "{}", c.found);
        let pty = PortFacts {
            kind: PortKind::Pty,
            ..facts
        };
        assert_eq!(
            holders_check(&pty, &access).verdict,
            Verdict::Ok,
            "a pty's creator holds it"
        );
        let _ = fs::remove_dir_all(root);
    }

    #[test]
    fn a_refused_open_names_the_group_or_the_login_to_renew() {
        let facts = PortFacts {
            device: Some("/dev/ttyUSB0".into()),
            tty: Some("ttyUSB0".into()),
            ..PortFacts::unknown("/dev/ttyUSB0")
        };
        let mut access = AccessFacts {
            group: Some("dialout".into()),
            mode: Some("0660".into()),
            user: Some("alice".into()),
            ..AccessFacts::default()
        };
        let denied = io::Error::from_raw_os_error(libc::EACCES);
        let c = open_failed(&denied, &facts, &access);
        assert_eq!((c.id, c.verdict), (CheckId::Permission, Verdict::Fail));
        assert!(
            c.fix
                .as_deref()
                .unwrap_or_default()
                .contains("usermod -aG dialout"),
            "{c:?}"
        );
        access.in_group_file = true;
        let c = open_failed(&denied, &facts, &access);
        assert!(
            c.fix
                .as_deref()
                .unwrap_or_default()
                .contains("log out and in again"),
            "{c:?}"
        );
        let gone = open_failed(&io::Error::from_raw_os_error(libc::ENOENT), &facts, &access);
        assert_eq!((gone.id, gone.verdict), (CheckId::Open, Verdict::Fail));
    }
}
