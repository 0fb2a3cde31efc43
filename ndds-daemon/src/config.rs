//! Daemon configuration: defaults, the TOML config file, and their merge.
//!
//! Precedence, highest first: command-line flags (and the environment variables `NDDS_DOMAIN`,
//! `NDDS_SOCKET` that stand for them), the config file, the defaults below.
//!
//! | setting | default |
//! |---|---|
//! | `domain` | 0 |
//! | `socket` | `ndds-<domain>.sock` in `$XDG_RUNTIME_DIR/ndds/`, `/run/ndds/` (root) or `$TMPDIR/ndds-<uid>/` ([`crate::local`]) |
//! | `socket_group` | none: only the daemon's user may connect |
//! | `interface` | `127.0.0.1` (loopback: this host only; name an interface to reach others) |
//! | `multicast` | true |
//! | `multicast_group` | `239.255.76.<domain>` |
//! | `discovery_port` | `7600 + domain` |
//! | `unicast_port` | `7850 + domain`, or any free port if that one is taken |
//! | `peers` | none |
//! | `announce_period_ms` | 1000 |
//! | `lease_ms` | 5000 |
//! | `multicast_ttl` | 1 |
//! | `key_file` | none: the domain is open (`NDDS_KEY_FILE`) |
//! | `integrity_only` | false: sealed datagrams are encrypted |
//! | `permissions` | none: every daemon holding the key may do everything (`NDDS_PERMISSIONS`) |
//! | `admin_key` | none; required with `permissions` (`NDDS_ADMIN_KEY`) |
//! | `identity` | `/var/lib/ndds/identity` (root) or `$XDG_STATE_HOME/ndds/identity`, made on first use |

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::time::Duration;

use ndds_core::discovery::MAX_PEERS;
use ndds_core::domain;
use ndds_core::seal::{Keyring, SealMode};
use serde::Deserialize;

use crate::iface;
use crate::peers::PeerSpec;
use crate::security;

/// Reads a permissions document (the TOML parser comes with the `cli` feature).
fn read_permissions(
    path: &std::path::Path,
    admin: &ndds_core::security::PublicId,
    domain: u16,
) -> Result<ndds_core::security::Permissions, security::SecurityError> {
    #[cfg(feature = "cli")]
    {
        security::load_permissions(path, admin, domain)
    }
    #[cfg(not(feature = "cli"))]
    {
        let _ = (path, admin, domain);
        Err(security::SecurityError::NoParser)
    }
}

/// The daemon's settings as the config file and the command line give them, every one
/// optional. Unknown keys in the file are an error.
#[derive(Clone, Debug, Default, PartialEq, Eq, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(deny_unknown_fields)]
pub struct ConfigFile {
    /// Domain id (0-232) [default: 0].
    #[cfg_attr(feature = "cli", arg(long, env = "NDDS_DOMAIN"))]
    pub domain: Option<u32>,
    /// Unix socket path [default: ndds-DOMAIN.sock in $XDG_RUNTIME_DIR/ndds, /run/ndds as
    /// root, else $TMPDIR/ndds-UID].
    #[cfg_attr(feature = "cli", arg(long, env = "NDDS_SOCKET"))]
    pub socket: Option<PathBuf>,
    /// A group whose members may connect to the socket too (mode 0660) [default: none, only
    /// the daemon's user].
    #[cfg_attr(feature = "cli", arg(long))]
    pub socket_group: Option<String>,
    /// Interface for discovery and data: an IPv4 address or interface name [default: 127.0.0.1].
    #[cfg_attr(feature = "cli", arg(long))]
    pub interface: Option<String>,
    /// Do not use multicast: neither join the discovery group nor send to it; discovery then
    /// relies on --peers and on the daemons that list this one (config file: multicast = false).
    #[cfg_attr(
        feature = "cli",
        arg(long = "no-multicast", num_args = 0, default_missing_value = "false")
    )]
    pub multicast: Option<bool>,
    /// Discovery multicast group [default: 239.255.76.DOMAIN].
    #[cfg_attr(feature = "cli", arg(long))]
    pub multicast_group: Option<Ipv4Addr>,
    /// Discovery multicast port [default: 7600 + DOMAIN].
    #[cfg_attr(feature = "cli", arg(long))]
    pub discovery_port: Option<u16>,
    /// Unicast discovery port; 0 picks any free port. Given explicitly, it must be free
    /// [default: 7850 + DOMAIN, or any free port if that one is taken].
    #[cfg_attr(feature = "cli", arg(long))]
    pub unicast_port: Option<u16>,
    /// Static unicast peers, HOST or HOST:PORT (port default: 7850 + DOMAIN), comma-separated
    /// and repeatable; every discovery datagram is also sent to each, multicast or not
    /// (config file: peers = ["a:7850", "b"]). Flags replace the file's list.
    #[cfg_attr(feature = "cli", arg(long, value_delimiter = ','))]
    pub peers: Option<Vec<PeerSpec>>,
    /// Refresh period in milliseconds [default: 1000].
    #[cfg_attr(feature = "cli", arg(long))]
    pub announce_period_ms: Option<u64>,
    /// Lease in milliseconds: how long others remember this daemon without a refresh
    /// [default: 5000].
    #[cfg_attr(feature = "cli", arg(long))]
    pub lease_ms: Option<u64>,
    /// Multicast TTL [default: 1].
    #[cfg_attr(feature = "cli", arg(long))]
    pub multicast_ttl: Option<u32>,
    /// Random seed of announcement jitter [default: random].
    #[cfg_attr(feature = "cli", arg(long))]
    pub seed: Option<u64>,
    /// The domain's key file (`ndds key new FILE` makes one): every discovery datagram is
    /// then sealed, and only sealed ones are accepted [default: none, an open domain].
    #[cfg_attr(feature = "cli", arg(long, env = "NDDS_KEY_FILE"))]
    pub key_file: Option<PathBuf>,
    /// With a key file: authenticate datagrams without encrypting them, so they stay
    /// readable on the wire (config file: integrity_only = true).
    #[cfg_attr(
        feature = "cli",
        arg(long = "integrity-only", num_args = 0, default_missing_value = "true")
    )]
    pub integrity_only: Option<bool>,
    /// The domain's signed permissions document (`ndds security init`, `add`, `sign`): this
    /// daemon then signs its discovery datagrams with its identity and lets only what the
    /// document allows match. Needs --key-file and --admin-key [default: none].
    #[cfg_attr(feature = "cli", arg(long, env = "NDDS_PERMISSIONS"))]
    pub permissions: Option<PathBuf>,
    /// The administrator's public key that signs the permissions document: `ed25519:...`, or
    /// the path of a file holding it (`admin.pub`).
    #[cfg_attr(feature = "cli", arg(long, env = "NDDS_ADMIN_KEY"))]
    pub admin_key: Option<String>,
    /// This daemon's identity file, made on first use [default: /var/lib/ndds/identity as
    /// root, else $XDG_STATE_HOME/ndds/identity].
    #[cfg_attr(feature = "cli", arg(long))]
    pub identity: Option<PathBuf>,
}

impl ConfigFile {
    /// Reads and parses a config file (with the `cli` feature, on by default: the SDK embeds
    /// daemons without it and never reads TOML).
    #[cfg(feature = "cli")]
    pub fn load(path: &std::path::Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        toml::from_str(&text).map_err(|err| ConfigError::Parse {
            path: path.to_owned(),
            message: err.to_string(),
        })
    }

    /// Fills every field that is `None` here from `lower`.
    pub fn or(self, lower: ConfigFile) -> ConfigFile {
        ConfigFile {
            domain: self.domain.or(lower.domain),
            socket: self.socket.or(lower.socket),
            socket_group: self.socket_group.or(lower.socket_group),
            interface: self.interface.or(lower.interface),
            multicast: self.multicast.or(lower.multicast),
            multicast_group: self.multicast_group.or(lower.multicast_group),
            discovery_port: self.discovery_port.or(lower.discovery_port),
            unicast_port: self.unicast_port.or(lower.unicast_port),
            peers: self.peers.or(lower.peers),
            announce_period_ms: self.announce_period_ms.or(lower.announce_period_ms),
            lease_ms: self.lease_ms.or(lower.lease_ms),
            multicast_ttl: self.multicast_ttl.or(lower.multicast_ttl),
            seed: self.seed.or(lower.seed),
            key_file: self.key_file.or(lower.key_file),
            integrity_only: self.integrity_only.or(lower.integrity_only),
            permissions: self.permissions.or(lower.permissions),
            admin_key: self.admin_key.or(lower.admin_key),
            identity: self.identity.or(lower.identity),
        }
    }

    /// Applies the defaults and resolves the interface. Peers are checked here but resolved
    /// when the daemon starts ([`crate::Daemon::bind`]).
    pub fn resolve(self) -> Result<DaemonConfig, ConfigError> {
        let domain = domain::check(self.domain.unwrap_or(0))?;
        let interface = match self.interface.as_deref() {
            Some(spec) => iface::resolve(spec)?,
            None => Ipv4Addr::LOCALHOST,
        };
        let mut config = DaemonConfig::new(domain, interface);
        if let Some(socket) = self.socket {
            config.socket = socket;
        }
        if let Some(name) = self.socket_group.as_deref() {
            config.socket_group = Some(crate::local::group(name)?);
        }
        if let Some(group) = self.multicast_group {
            if !group.is_multicast() {
                return Err(ConfigError::NotMulticast(group));
            }
            config.group = group;
        }
        config.port = self.discovery_port.unwrap_or(config.port);
        config.unicast_port = self.unicast_port.or(config.unicast_port);
        config.multicast = self.multicast.unwrap_or(config.multicast);
        config.peers = self.peers.unwrap_or_default();
        if config.peers.len() > MAX_PEERS {
            return Err(ConfigError::TooManyPeers(config.peers.len()));
        }
        if let Some(ms) = self.announce_period_ms {
            config.announce_period = Duration::from_millis(ms);
        }
        if let Some(ms) = self.lease_ms {
            config.lease = Duration::from_millis(ms);
        }
        config.ttl = self.multicast_ttl.unwrap_or(config.ttl);
        config.seed = self.seed;
        if let Some(path) = self.key_file {
            config.key = Some(crate::keys::load(&path)?);
            config.key_file = Some(path);
        }
        if self.integrity_only.unwrap_or(false) {
            config.seal_mode = SealMode::IntegrityOnly;
        }
        if let Some(path) = self.permissions {
            let admin = self
                .admin_key
                .as_deref()
                .ok_or(security::SecurityError::NeedsAdmin)?;
            let admin = security::admin_key(admin)?;
            if config.key.is_none() {
                return Err(security::SecurityError::NeedsKey.into());
            }
            let permissions = read_permissions(&path, &admin, domain)?;
            let identity_file = self
                .identity
                .unwrap_or_else(security::default_identity_path);
            let (identity, created) = security::load_or_create_identity(&identity_file)?;
            if created {
                tracing::info!(
                    file = %identity_file.display(),
                    identity = %identity.public(),
                    "made this daemon's identity: add it to the permissions document (`ndds security add`)"
                );
            }
            config.security = Some(security::Security {
                identity,
                identity_file,
                permissions: std::sync::Arc::new(permissions),
                permissions_file: path,
                admin,
            });
        }
        config.discovery().validate()?;
        Ok(config)
    }
}

/// A complete, validated daemon configuration.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DaemonConfig {
    /// Domain id.
    pub domain: u16,
    /// Unix socket path clients connect to.
    pub socket: PathBuf,
    /// Group id whose members may connect too (`None`: only the daemon's user).
    pub socket_group: Option<u32>,
    /// Address of the interface used for discovery and data.
    pub interface: Ipv4Addr,
    /// Discovery multicast group.
    pub group: Ipv4Addr,
    /// Discovery multicast port.
    pub port: u16,
    /// Unicast discovery port: `None` for the domain's default (`7850 + domain`, or any free
    /// port if that one is taken), `Some(0)` for any free port, `Some(port)` for exactly that
    /// port (taken: an error).
    pub unicast_port: Option<u16>,
    /// Whether to join and send to the multicast group.
    pub multicast: bool,
    /// Static unicast peers, resolved when the daemon starts (at most [`MAX_PEERS`]).
    pub peers: Vec<PeerSpec>,
    /// Refresh period.
    pub announce_period: Duration,
    /// Lease announced to other nodes.
    pub lease: Duration,
    /// Multicast time-to-live.
    pub ttl: u32,
    /// Random seed; `None` picks one at start.
    pub seed: Option<u64>,
    /// The domain's keys: every datagram sealed with them, only sealed ones accepted
    /// (`None`: an open domain).
    pub key: Option<Keyring>,
    /// The file `key` was read from: watched, so rotation steps take effect without a restart
    /// ([`crate::keys::KeyWatch`]).
    pub key_file: Option<PathBuf>,
    /// How datagrams are sealed when there is a key.
    pub seal_mode: SealMode,
    /// Identity and permissions document (`None`: no permissions in this domain).
    pub security: Option<security::Security>,
}

impl DaemonConfig {
    /// The defaults for `domain` on `interface`.
    pub fn new(domain: u16, interface: Ipv4Addr) -> Self {
        let defaults = ndds_core::discovery::DiscoveryConfig::new(
            domain,
            ndds_core::wire::Locator::UNSPECIFIED,
        );
        DaemonConfig {
            domain,
            socket: crate::local::default_socket(domain),
            socket_group: None,
            interface,
            group: domain::multicast_group(domain),
            port: domain::discovery_port(domain),
            unicast_port: None,
            multicast: true,
            peers: Vec::new(),
            announce_period: defaults.announce_period,
            lease: defaults.lease,
            ttl: 1,
            seed: None,
            key: None,
            key_file: None,
            seal_mode: SealMode::Encrypt,
            security: None,
        }
    }

    /// The discovery settings implied by this configuration (unicast locator and identity
    /// are filled in when the daemon binds).
    pub fn discovery(&self) -> ndds_core::discovery::DiscoveryConfig {
        let mut config = ndds_core::discovery::DiscoveryConfig::new(
            self.domain,
            ndds_core::wire::Locator::UNSPECIFIED,
        );
        config.announce_period = self.announce_period;
        config.lease = self.lease;
        config.multicast = self.multicast;
        config
    }
}

/// A configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The config file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// The config file is not valid TOML or has unknown or mistyped keys.
    #[error("invalid config file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// toml's message, with line and column.
        message: String,
    },
    /// Domain id out of range.
    #[error(transparent)]
    Domain(#[from] domain::DomainError),
    /// The interface could not be resolved.
    #[error(transparent)]
    Interface(#[from] iface::InterfaceError),
    /// The group is not a multicast address.
    #[error("{0} is not an IPv4 multicast address (224.0.0.0/4)")]
    NotMulticast(Ipv4Addr),
    /// More peers than [`MAX_PEERS`].
    #[error("{0} peers listed (--peers, config key peers); at most {MAX_PEERS} are accepted")]
    TooManyPeers(usize),
    /// Inconsistent discovery settings (timers).
    #[error(transparent)]
    Discovery(#[from] ndds_core::discovery::ConfigError),
    /// The key file cannot be used.
    #[error(transparent)]
    Key(#[from] crate::keys::KeyError),
    /// The identity or the permissions document could not be used.
    #[error(transparent)]
    Security(#[from] security::SecurityError),
    /// The socket group does not exist.
    #[error(transparent)]
    Local(#[from] crate::local::LocalError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(feature = "cli")]
    #[test]
    fn each_run_of_a_daemon_draws_its_own_agreement_key() {
        use ndds_core::security::{Identity, sign};
        let dir = tempfile::tempdir().unwrap();
        let path = |name: &str| dir.path().join(name);
        crate::keys::create(&path("domain.key"), ndds_core::seal::Cipher::default()).unwrap();
        let (identity, created) = security::load_or_create_identity(&path("daemon.id")).unwrap();
        assert!(created);
        let admin = Identity::from_secret([9; 32]);
        let text = format!(
            "serial = 1\ndomain = 0\nnot_before = \"2000-01-01T00:00:00Z\"\n\
             not_after = \"2100-01-01T00:00:00Z\"\n\n[[subject]]\nname = \"a\"\nkey = \"{}\"\n\
             publish = [\"*\"]\nsubscribe = [\"*\"]\n",
            identity.public()
        );
        std::fs::write(path("permissions.toml"), sign(&text, &admin)).unwrap();
        let security = ConfigFile {
            key_file: Some(path("domain.key")),
            permissions: Some(path("permissions.toml")),
            admin_key: Some(admin.public().to_string()),
            identity: Some(path("daemon.id")),
            ..Default::default()
        }
        .resolve()
        .unwrap()
        .security
        .unwrap();
        // What a daemon's engine gets at each start (`Daemon::bind`): a guard of its own.
        let run = || security.guard().unwrap().identity;
        let (first, second) = (run(), run());
        // One identity (the file's), but an agreement key of each run: not the one the file
        // alone gives, so the file opens no data keys of either run.
        assert_eq!(
            (first.public(), second.public()),
            (identity.public(), identity.public())
        );
        assert_ne!(first.agreement_public(), second.agreement_public());
        assert_ne!(first.agreement_public(), identity.agreement_public());
        assert_ne!(second.agreement_public(), identity.agreement_public());
    }

    #[test]
    fn defaults_follow_the_domain() {
        let config = ConfigFile {
            domain: Some(5),
            ..Default::default()
        }
        .resolve()
        .unwrap();
        assert_eq!(config.interface, Ipv4Addr::LOCALHOST);
        assert_eq!(config.port, 7605);
        assert_eq!(config.group, Ipv4Addr::new(239, 255, 76, 5));
        assert_eq!(
            config.socket,
            crate::local::socket_dir().join("ndds-5.sock")
        );
        assert_eq!(
            config.unicast_port, None,
            "the domain's default, with fallback"
        );
        assert!(config.multicast);
        assert!(config.peers.is_empty());
    }

    #[test]
    fn peers_and_multicast_come_from_the_file_and_flags() {
        let file: ConfigFile =
            toml::from_str("peers = [\"10.0.0.2:7900\", \"robot-7\"]\nmulticast = false\n")
                .unwrap();
        let config = file.clone().resolve().unwrap();
        assert!(!config.multicast);
        let written: Vec<String> = config.peers.iter().map(|p| p.to_string()).collect();
        assert_eq!(written, ["10.0.0.2:7900", "robot-7"]);
        // Flags replace the file's list.
        let flags = ConfigFile {
            peers: Some(vec!["10.0.0.9".parse().unwrap()]),
            ..Default::default()
        };
        let config = flags.or(file).resolve().unwrap();
        assert_eq!(config.peers.len(), 1);
        assert!(!config.multicast, "from the file");

        let err = toml::from_str::<ConfigFile>("peers = [\"a:b:c\"]\n").unwrap_err();
        assert!(err.to_string().contains("a:b:c"), "{err}");
    }

    #[test]
    fn too_many_peers_are_refused() {
        let peers = (0..=MAX_PEERS)
            .map(|i| format!("10.1.{}.{}", i / 256, i % 256).parse().unwrap())
            .collect();
        let err = ConfigFile {
            peers: Some(peers),
            ..Default::default()
        }
        .resolve()
        .unwrap_err();
        assert!(matches!(err, ConfigError::TooManyPeers(257)), "{err}");
        assert!(err.to_string().contains("at most 256"), "{err}");
    }

    #[test]
    fn higher_layers_win() {
        let flags = ConfigFile {
            domain: Some(2),
            ..Default::default()
        };
        let file: ConfigFile = toml::from_str("domain = 9\nlease_ms = 9000\n").unwrap();
        let merged = flags.or(file).resolve().unwrap();
        assert_eq!(merged.domain, 2);
        assert_eq!(merged.lease, Duration::from_millis(9000));
    }

    #[test]
    fn bad_files_are_reported_with_their_location() {
        let err = toml::from_str::<ConfigFile>("domian = 3\n").unwrap_err();
        assert!(err.to_string().contains("domian"), "{err}");
        let err = ConfigFile {
            lease_ms: Some(10),
            ..Default::default()
        }
        .resolve()
        .unwrap_err();
        assert!(err.to_string().contains("lease"), "{err}");
        let err = ConfigFile {
            multicast_group: Some(Ipv4Addr::new(10, 0, 0, 1)),
            ..Default::default()
        }
        .resolve()
        .unwrap_err();
        assert!(err.to_string().contains("multicast"), "{err}");
    }
}
