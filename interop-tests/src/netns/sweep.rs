//! Names of the namespaces a test run creates, and the sweep that removes the ones a killed
//! earlier run left behind.
//!
//! Every name is `nddst-<pid>-<tag>-<role>`: the pid of the test process that owns it, a
//! random tag per network, and `s` (the switch) or `h<i>` (host i). A namespace whose owner
//! is no longer alive is stale; a live owner's namespaces are never touched, so parallel runs
//! (and parallel tests of one run) cannot remove each other's.

use std::sync::Once;

use nix::errno::Errno;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use super::command::ip;

/// First part of every namespace name this harness creates.
pub const PREFIX: &str = "nddst-";

/// The owning pid written in a namespace name of ours, if it is one.
pub fn owner(name: &str) -> Option<i32> {
    let rest = name.strip_prefix(PREFIX)?;
    let (pid, _) = rest.split_once('-')?;
    pid.parse().ok().filter(|pid| *pid > 0)
}

/// True while a process `pid` exists.
fn alive(pid: i32) -> bool {
    !matches!(kill(Pid::from_raw(pid), None), Err(Errno::ESRCH))
}

/// Every network namespace name of this machine.
pub fn list() -> Vec<String> {
    ip(&["netns", "list"])
        .unwrap_or_default()
        .lines()
        .filter_map(|line| line.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

/// Kills every process in `name` and deletes the namespace. Errors are reported on stderr,
/// never panicked on: this also runs while a failed test unwinds.
pub fn remove(name: &str) {
    for pid in ip(&["netns", "pids", name]).unwrap_or_default().lines() {
        if let Ok(pid) = pid.trim().parse::<i32>() {
            let pid = Pid::from_raw(pid);
            let _ = kill(pid, Signal::SIGKILL);
        }
    }
    if let Err(err) = ip(&["netns", "delete", name]) {
        eprintln!("interop-tests: cannot delete network namespace {name}: {err}");
    }
}

/// Removes the namespaces of ours whose owning process is dead; returns their names.
pub fn sweep_stale() -> Vec<String> {
    let stale: Vec<String> = list()
        .into_iter()
        .filter(|name| owner(name).is_some_and(|pid| !alive(pid)))
        .collect();
    for name in &stale {
        eprintln!("interop-tests: removing stale network namespace {name}");
        remove(name);
    }
    stale
}

/// Runs [`sweep_stale`] once per test process.
pub(crate) fn sweep_once() {
    static SWEPT: Once = Once::new();
    SWEPT.call_once(|| {
        sweep_stale();
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn owner_is_read_from_our_names_only() {
        assert_eq!(owner("nddst-4242-beef-h3"), Some(4242));
        assert_eq!(owner("nddst-4242-beef-s"), Some(4242));
        assert_eq!(owner("nddst-x-beef-s"), None);
        assert_eq!(owner("nddst-0-beef-s"), None);
        assert_eq!(owner("other-4242-beef-s"), None);
        assert_eq!(owner("nddst-4242"), None);
    }
}
