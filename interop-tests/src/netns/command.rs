//! Running `ip` and `nft`: the prerequisites are checked once, with a message that says what
//! is missing, and a failed command reports its arguments and stderr.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

/// Where `program` is: the first match on `PATH`, then the sbin directories (which a user's
/// `PATH` may lack even under sudo).
pub fn locate(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/sbin", "/usr/bin", "/bin"].map(PathBuf::from))
        .map(|dir| dir.join(program))
        .find(|candidate| candidate.is_file())
}

struct Tools {
    ip: PathBuf,
    nft: PathBuf,
}

/// The tools, or a panic that says what is missing. Checked once per process.
fn tools() -> &'static Tools {
    static TOOLS: OnceLock<Result<Tools, String>> = OnceLock::new();
    match TOOLS.get_or_init(check) {
        Ok(tools) => tools,
        Err(message) => panic!("{message}"),
    }
}

fn check() -> Result<Tools, String> {
    let mut missing = Vec::new();
    if !nix::unistd::geteuid().is_root() {
        missing.push(
            "root: the multi-host tests create network namespaces, veth pairs and nft rules \
             (run them as root, as CI does)"
                .to_owned(),
        );
    }
    let ip = locate("ip");
    if ip.is_none() {
        missing.push("`ip` (iproute2): apt-get install -y iproute2".to_owned());
    }
    let nft = locate("nft");
    if nft.is_none() {
        missing.push("`nft` (nftables): apt-get install -y nftables".to_owned());
    }
    match (ip, nft) {
        (Some(ip), Some(nft)) if missing.is_empty() => Ok(Tools { ip, nft }),
        _ => Err(format!(
            "the multi-host (network namespace) tests cannot run; missing: {}",
            missing.join("; ")
        )),
    }
}

/// Panics with a clear message unless this process is root and has `ip` and `nft`.
pub fn require() {
    tools();
}

/// Path of `ip`.
pub(crate) fn ip_path() -> &'static Path {
    &tools().ip
}

/// Path of `nft`.
pub(crate) fn nft_path() -> &'static Path {
    &tools().nft
}

/// Runs `ip ARGS`; returns its stdout, or an error naming the command and its stderr.
pub(crate) fn ip(args: &[&str]) -> Result<String, String> {
    let mut command = Command::new(ip_path());
    command.args(args);
    output(command, None)
}

/// Runs `ip [-n NETNS] -batch -` with `lines` on its stdin.
pub(crate) fn ip_batch(netns: Option<&str>, lines: &[String]) -> Result<String, String> {
    let mut command = Command::new(ip_path());
    if let Some(netns) = netns {
        command.args(["-n", netns]);
    }
    command.args(["-batch", "-"]);
    output(command, Some(&lines.join("\n")))
}

/// Runs `nft -f -` inside the namespace `netns`, with `ruleset` on its stdin.
pub(crate) fn nft_in(netns: &str, ruleset: &str) -> Result<String, String> {
    let mut command = Command::new(ip_path());
    command.args(["netns", "exec", netns]).arg(nft_path());
    command.args(["-f", "-"]);
    output(command, Some(ruleset))
}

fn output(mut command: Command, stdin: Option<&str>) -> Result<String, String> {
    let described = format!("{command:?}");
    let describe = || described.clone();
    let mut child = command
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|err| format!("cannot start {}: {err}", describe()))?;
    if let Some(text) = stdin {
        let mut pipe = child.stdin.take().expect("piped stdin");
        pipe.write_all(text.as_bytes())
            .and_then(|()| pipe.write_all(b"\n"))
            .map_err(|err| format!("{}: writing stdin: {err}", describe()))?;
    }
    let out = child
        .wait_with_output()
        .map_err(|err| format!("{}: {err}", describe()))?;
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    } else {
        Err(format!(
            "{} failed ({}): {}{}",
            describe(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim(),
            stdin.map(|s| format!("\ninput:\n{s}")).unwrap_or_default()
        ))
    }
}
