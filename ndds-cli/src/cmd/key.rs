//! `ndds key`: domain key files — a new one, and the steps of a rotation.

use std::path::PathBuf;

use ndds_core::seal::Cipher;
use ndds_daemon::keys;

use crate::outln;

/// Options of `ndds key`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    action: Action,
}

#[derive(Debug, clap::Subcommand)]
enum Action {
    /// Write a new domain key file (mode 0600; never over an existing file). Copy it to
    /// every host of the domain and give it to daemons and programs with --key-file or
    /// NDDS_KEY_FILE.
    New {
        /// Where to write it.
        file: PathBuf,
        /// The domain's cipher: auto (aegis-128l if this processor has the instructions it
        /// needs, else aes-128-gcm if it has those, else chacha20-poly1305),
        /// chacha20-poly1305 (fast on any processor), aegis-128l, aes-128-gcm or aes-256-gcm
        /// (several times faster where every host has AES instructions; aes-*-gcm where NIST
        /// algorithms are required; see docs/security.md).
        #[arg(long, default_value = "auto", value_parser = parse_cipher)]
        cipher: CipherChoice,
    },
    /// Show a key file's epochs and which one is sealed with (never the keys).
    Show {
        /// The key file.
        file: PathBuf,
    },
    /// Rotation, step 1: add a new key (accepted, not yet sealed with). Copy the file to
    /// every host: daemons and programs put it in force within a second, no restart.
    Rotate {
        /// The key file.
        file: PathBuf,
    },
    /// Rotation, step 2: seal with EPOCH from now on (once every host accepts it).
    Use {
        /// The key file.
        file: PathBuf,
        /// The epoch to seal with.
        epoch: u32,
    },
    /// Rotation, step 3: stop accepting EPOCH (once no host seals with it).
    Retire {
        /// The key file.
        file: PathBuf,
        /// The epoch to refuse from now on.
        epoch: u32,
    },
}

/// Runs `ndds key`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    match &args.action {
        Action::New { file, cipher } => {
            let chosen = match cipher {
                CipherChoice::Auto => keys::suggested_cipher(),
                CipherChoice::Named(cipher) => *cipher,
            };
            keys::create(file, chosen)?;
            let why = match cipher {
                CipherChoice::Named(_) => "as asked".to_owned(),
                CipherChoice::Auto if chosen == Cipher::ChaCha20Poly1305 => {
                    "this processor has no AES instructions".to_owned()
                }
                CipherChoice::Auto => format!(
                    "this processor has the instructions it needs; if a host of the domain \
                     lacks them (many ARM boards), make the key with --cipher {} instead",
                    Cipher::ChaCha20Poly1305.name()
                ),
            };
            outln!("cipher {} ({why})", chosen.name())?;
            if let Some(warning) = keys::slow_cipher_warning(chosen) {
                outln!("note: {warning}")?;
            }
            outln!(
                "wrote a new domain key to {} (mode 0600): copy it to every host of the domain, \
                 then start daemons with --key-file {0} and programs with NDDS_KEY_FILE={0}",
                file.display()
            )?;
        }
        Action::Show { file } => {
            let keyring = keys::load(file)?;
            let epochs: Vec<String> = keyring.epochs().map(|e| e.to_string()).collect();
            outln!(
                "{}: cipher {}, epochs accepted {}, sealing with epoch {}",
                file.display(),
                keyring.cipher().name(),
                epochs.join(", "),
                keyring.send_epoch()
            )?;
        }
        Action::Rotate { file } => {
            let epoch = edit(file, |keyring| {
                let epoch = keyring
                    .epochs()
                    .max()
                    .unwrap_or(0)
                    .checked_add(1)
                    .ok_or_else(|| {
                        anyhow::anyhow!("{}: no epoch after {}", file.display(), u32::MAX)
                    })?;
                keyring.add(epoch, keys::random_key()?);
                Ok(epoch)
            })?;
            outln!(
                "added epoch {epoch} to {} (accepted, not yet sealed with): copy the file to \
                 every host (daemons and programs pick it up within a second), then run `ndds \
                 key use {0} {epoch}`",
                file.display()
            )?;
        }
        Action::Use { file, epoch } => {
            edit(file, |keyring| {
                anyhow::ensure!(
                    keyring.set_send(*epoch),
                    "{} holds no key of epoch {epoch}",
                    file.display()
                );
                Ok(())
            })?;
            outln!(
                "{} now seals with epoch {epoch}: copy it to every host (picked up within a \
                 second), then retire the old epoch with `ndds key retire`",
                file.display()
            )?;
        }
        Action::Retire { file, epoch } => {
            edit(file, |keyring| {
                anyhow::ensure!(
                    keyring.retire(*epoch),
                    "{} cannot retire epoch {epoch}: it is not there, or it is the one sealed \
                     with (run `ndds key use` with another epoch first)",
                    file.display()
                );
                Ok(())
            })?;
            outln!(
                "{} no longer accepts epoch {epoch}: copy it to every host (picked up within a \
                 second)",
                file.display()
            )?;
        }
    }
    Ok(())
}

/// Reads the key file, applies `change`, and writes the file back (only if `change` succeeded).
fn edit<T>(
    file: &std::path::Path,
    change: impl FnOnce(&mut ndds_core::seal::Keyring) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let mut keyring = keys::load(file)?;
    let done = change(&mut keyring)?;
    keys::save(file, &keyring)?;
    Ok(done)
}

/// `--cipher`: a cipher by name, or `auto`.
#[derive(Clone, Copy, Debug)]
enum CipherChoice {
    /// Chosen for this processor ([`keys::suggested_cipher`]).
    Auto,
    /// The one named.
    Named(Cipher),
}

fn parse_cipher(text: &str) -> Result<CipherChoice, String> {
    if text == "auto" {
        return Ok(CipherChoice::Auto);
    }
    Cipher::from_name(text)
        .map(CipherChoice::Named)
        .ok_or_else(|| {
            let names: Vec<&str> = Cipher::ALL.iter().map(|c| c.name()).collect();
            format!(
                "unknown cipher `{text}` (one of: auto, {})",
                names.join(", ")
            )
        })
}
