//! Connecting to the local daemon as a tool.

use std::path::PathBuf;

use ndds_client::{ConnectError, EmbeddedPolicy, Participant, ParticipantBuilder};

/// Where the daemon is: flags first, then `NDDS_DOMAIN` / `NDDS_SOCKET` (read by the SDK).
#[derive(Clone, Debug, Default, clap::Args)]
#[command(next_help_heading = "Daemon")]
pub struct DaemonArgs {
    /// Domain id (0-232) [env: NDDS_DOMAIN] [default: 0].
    #[arg(long, global = true, value_parser = clap::value_parser!(u16).range(0..=232))]
    pub domain: Option<u16>,
    /// Daemon socket path [env: NDDS_SOCKET] [default: ndds-DOMAIN.sock in $XDG_RUNTIME_DIR/ndds,
    /// else /run/ndds, else $TMPDIR/ndds-UID].
    #[arg(long, global = true)]
    pub socket: Option<PathBuf>,
    /// The domain's key file, in a sealed domain [env: NDDS_KEY_FILE].
    #[arg(long, global = true)]
    pub key_file: Option<PathBuf>,
}

/// Opens a tool session with the local daemon; never starts an embedded daemon.
pub fn connect(args: &DaemonArgs) -> anyhow::Result<Participant> {
    connect_with(args, |builder| builder)
}

/// As [`connect`], with `options` applied to the participant's builder.
pub fn connect_with(
    args: &DaemonArgs,
    options: impl FnOnce(ParticipantBuilder) -> ParticipantBuilder,
) -> anyhow::Result<Participant> {
    let mut builder = options(
        Participant::builder()
            .embedded(EmbeddedPolicy::Never)
            .name("ndds")
            .tool(),
    );
    if let Some(domain) = args.domain {
        builder = builder.domain(domain);
    }
    if let Some(socket) = &args.socket {
        builder = builder.socket(socket);
    }
    if let Some(key_file) = &args.key_file {
        builder = builder.key_file(key_file);
    }
    let participant = builder.connect().map_err(|err| match err {
        ConnectError::NoDaemon { path, reason } => anyhow::anyhow!(
            "no ndds daemon is running at {} ({reason}); start `ndds-daemon` (or a program \
             that embeds one), or name the daemon's socket with --socket or NDDS_SOCKET",
            path.display()
        ),
        other => other.into(),
    })?;
    check_domain(args, &participant)?;
    Ok(participant)
}

/// A `--domain` that the daemon reached (through `--socket` or `NDDS_SOCKET`) does not serve
/// is an error: the command would act on another domain than the one asked for.
pub fn check_domain(args: &DaemonArgs, participant: &Participant) -> anyhow::Result<()> {
    let serves = participant.daemon().domain;
    match args.domain {
        Some(asked) if asked != serves => anyhow::bail!(
            "--domain {asked} was asked for, but the daemon at the socket given by {} serves \
             domain {serves}; name domain {asked}'s socket (or unset NDDS_SOCKET, so --domain \
             picks it)",
            if args.socket.is_some() {
                "--socket"
            } else {
                "NDDS_SOCKET"
            }
        ),
        _ => Ok(()),
    }
}
