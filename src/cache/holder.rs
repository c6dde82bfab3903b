//! Who holds a tile lock. A lock's token names the machine it was taken on
//! (its host name, boot and PID namespace), the process and the call:
//! `HOST:BOOT:PIDNS:PID:NANOS:N`. A lock whose holder died on this machine
//! (the same host, boot and PID namespace, and no process `PID` any more)
//! is known to be abandoned; a token of another machine, or any token on a
//! machine whose `/proc` cannot say, proves nothing, and its lock only
//! expires.
//!
//! Invariant: a live holder is never declared dead. Only locks of this
//! process's own user are judged (`/proc` may hide other users' processes:
//! `hidepid`), the boot's id tells apart machines that share a host name
//! (the first PID namespace is the same number everywhere), and `/proc`
//! must be this PID namespace's own. A reused PID only makes a dead holder
//! look alive (its lock then expires as any other).

use std::path::Path;
use std::sync::OnceLock;
use std::time::SystemTime;

/// A token unique to this process and call, naming this machine and process.
pub(crate) fn token() -> String {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let nanos = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    format!("{}:{}:{nanos}:{n}", machine().unwrap_or(UNKNOWN), std::process::id())
}

/// True if `token`, of a lock owned by user `owner`, names a process of
/// this machine and user that no longer runs.
pub(crate) fn died(token: &str, owner: u32) -> bool {
    let Some(here) = machine() else { return false };
    if own_uid() != Some(owner) {
        return false;
    }
    let Some(rest) = token.strip_prefix(here).and_then(|r| r.strip_prefix(':')) else { return false };
    let pid = rest.split(':').next().and_then(|p| p.parse::<u32>().ok()).filter(|&pid| pid > 0);
    pid.is_some_and(|pid| !Path::new(&format!("/proc/{pid}")).exists())
}

/// `c`, or `_` where it has no place in a token or a file name (a host
/// name, or a token read back from a damaged lock file, may hold anything).
pub(crate) fn file_safe(c: char) -> char {
    if c.is_ascii_alphanumeric() || c == '.' || c == '-' { c } else { '_' }
}

/// The user this process runs as (who owns its `/proc` entry).
fn own_uid() -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    static UID: OnceLock<Option<u32>> = OnceLock::new();
    *UID.get_or_init(|| std::fs::metadata("/proc/self").ok().map(|m| m.uid()))
}

/// This machine as tokens name it, `HOST:BOOT:PIDNS`: the host alone would
/// take two containers that share a host name (`--network host`) but not
/// their PIDs for one machine, and two hosts of one name for one. `None`
/// where `/proc` does not say, or is another PID namespace's.
pub(crate) fn machine() -> Option<&'static str> {
    static MACHINE: OnceLock<Option<String>> = OnceLock::new();
    MACHINE.get_or_init(read_machine).as_deref()
}

/// What a token names as its machine where this one's is not known; no
/// boot id is `0` (12 hex digits), so it never names a known machine.
const UNKNOWN: &str = "unknown:0:0";

fn read_machine() -> Option<String> {
    let ours = std::fs::read_link("/proc/self").ok()?.to_string_lossy() == std::process::id().to_string();
    if !ours {
        return None;
    }
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").ok()?;
    // 48 bits of the boot's random id tell machines apart.
    let boot = std::fs::read_to_string("/proc/sys/kernel/random/boot_id").ok()?;
    let boot: String = boot.chars().filter(char::is_ascii_hexdigit).take(12).collect();
    // `pid:[4026531836]`.
    let namespace = std::fs::read_link("/proc/self/ns/pid").ok()?;
    let namespace: String = namespace.to_string_lossy().chars().filter(char::is_ascii_digit).collect();
    let host: String = host.trim().chars().map(file_safe).collect();
    (!host.is_empty() && boot.len() == 12 && !namespace.is_empty()).then(|| format!("{host}:{boot}:{namespace}"))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A PID that ran on this machine and has ended (a child, reaped).
    pub(crate) fn dead_pid() -> u32 {
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        pid
    }

    #[test]
    fn tokens_differ_and_name_a_dead_holder_only_on_this_machine() {
        assert_ne!(token(), token());
        let here = machine().expect("Linux says its host name, boot and PID namespace");
        assert!(token().starts_with(&format!("{here}:{}:", std::process::id())));
        let me = own_uid().expect("this process's user");
        assert!(!died(&token(), me), "this process runs");
        let dead = dead_pid();
        assert!(died(&format!("{here}:{dead}:0:0"), me));
        // Another user's processes may be hidden from /proc: not judged.
        assert!(!died(&format!("{here}:{dead}:0:0"), me + 1));
        let (host, rest) = here.split_once(':').unwrap();
        let (_, namespace) = rest.split_once(':').unwrap();
        for alive_or_unknown in [
            format!("other-host:{rest}:{dead}:0:0"),
            // A host of the same name, booted apart.
            format!("{host}:000000000000:{namespace}:{dead}:0:0"),
            format!("{here}0:{dead}:0:0"),
            format!("{UNKNOWN}:{dead}:0:0"),
            format!("{here}:0:0:0"),
            "killed-seeder".to_string(),
            String::new(),
        ] {
            assert!(!died(&alive_or_unknown, me), "{alive_or_unknown}");
        }
    }
}
