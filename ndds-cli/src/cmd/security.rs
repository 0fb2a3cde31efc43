//! `ndds security`: the administrator key, the permissions document, daemon identities.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use anyhow::Context as _;
use ndds_core::security::{self as core, Identity, Pattern, PublicId};
use ndds_daemon::security::{self, document};

use crate::outln;

/// Options of `ndds security`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    action: Action,
}

#[derive(Debug, clap::Subcommand)]
enum Action {
    /// Make an administrator key (DIR/admin.secret, mode 0600: keep it offline), its public
    /// half (DIR/admin.pub, for every daemon's --admin-key) and an empty permissions document
    /// (DIR/permissions.toml). Nothing is overwritten.
    Init {
        /// The directory (made if missing).
        dir: PathBuf,
        /// The domain the document is for (any domain if not given).
        #[arg(long)]
        domain: Option<u16>,
        /// How long the document stays valid, in days.
        #[arg(long, default_value_t = 365)]
        days: u64,
    },
    /// Print this host's daemon identity (made on first use), to add it to the document.
    Id {
        /// The daemon's identity file [default: the daemon's default].
        #[arg(long)]
        identity: Option<PathBuf>,
    },
    /// Add a subject (a daemon's identity, with a name) and its rules to the document; the
    /// document must then be signed again (`ndds security sign`).
    Add {
        /// The permissions document.
        document: PathBuf,
        /// A name for the subject (a host, a role).
        name: String,
        /// Its daemon's identity (`ndds security id` on that host).
        key: PublicId,
        /// Topics it may publish (patterns, `*` for any run of characters); repeatable.
        #[arg(long)]
        publish: Vec<String>,
        /// Topics it may subscribe to; repeatable.
        #[arg(long)]
        subscribe: Vec<String>,
        /// Ports it may own; repeatable.
        #[arg(long)]
        own: Vec<String>,
        /// Ports it may use; repeatable.
        #[arg(long = "use")]
        use_: Vec<String>,
    },
    /// Sign the document with the administrator key, in place (its serial grows by one).
    Sign {
        /// The permissions document.
        document: PathBuf,
        /// The administrator key (admin.secret).
        #[arg(long)]
        admin: PathBuf,
    },
    /// Show the document: validity, subjects and rules, and whether its signature verifies.
    Show {
        /// The permissions document.
        document: PathBuf,
        /// The administrator key to check the signature with: `ed25519:...` or admin.pub
        /// [default: the key the document names].
        #[arg(long)]
        admin_key: Option<String>,
    },
}

/// Runs `ndds security`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    match &args.action {
        Action::Init { dir, domain, days } => init(dir, *domain, *days),
        Action::Id { identity } => {
            let path = identity
                .clone()
                .unwrap_or_else(security::default_identity_path);
            let (identity, created) = security::load_or_create_identity(&path)?;
            if created {
                eprintln!("made a new identity in {} (mode 0600)", path.display());
            }
            outln!("{}", identity.public())?;
            Ok(())
        }
        Action::Add {
            document,
            name,
            key,
            publish,
            subscribe,
            own,
            use_,
        } => add(document, name, key, [publish, subscribe, own, use_]),
        Action::Sign { document, admin } => sign(document, admin),
        Action::Show {
            document,
            admin_key,
        } => show(document, admin_key.as_deref()),
    }
}

fn init(dir: &Path, domain: Option<u16>, days: u64) -> anyhow::Result<()> {
    use std::os::unix::fs::DirBuilderExt as _;
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
        .with_context(|| format!("cannot make {}", dir.display()))?;
    let (secret, public, doc) = (
        dir.join("admin.secret"),
        dir.join("admin.pub"),
        dir.join("permissions.toml"),
    );
    for path in [&secret, &public, &doc] {
        anyhow::ensure!(
            !path.exists(),
            "{} exists already: nothing was written",
            path.display()
        );
    }
    let admin = Identity::from_secret(ndds_daemon::keys::random_bytes()?);
    // Valid from an hour ago: hosts whose clocks run a little behind accept it too.
    let now = SystemTime::now() - Duration::from_secs(3600);
    let until = now + Duration::from_secs(days.saturating_mul(86_400));
    let text = format!(
        "# ndds permissions document (docs/security.md). Edit it, or use `ndds security add`;\n\
         # then sign it with `ndds security sign`. Patterns: `*` matches any run of characters.\n\
         serial = 1\n\
         {}\
         not_before = \"{}\"\n\
         not_after = \"{}\"\n\
         admin = \"{}\"\n",
        domain.map_or(String::new(), |d| format!("domain = {d}\n")),
        humantime::format_rfc3339_seconds(now),
        humantime::format_rfc3339_seconds(until),
        admin.public(),
    );
    security::write_text(&secret, &admin.to_file_text(), 0o600, false)
        .with_context(|| format!("cannot write {}", secret.display()))?;
    security::write_text(&public, &format!("{}\n", admin.public()), 0o644, false)
        .with_context(|| format!("cannot write {}", public.display()))?;
    security::write_text(&doc, &text, 0o644, false)
        .with_context(|| format!("cannot write {}", doc.display()))?;
    outln!(
        "administrator key {} in {} (keep it offline), its public half in {}, an empty \
         document in {3}.\nNext: `ndds security id` on each host, `ndds security add {3} NAME \
         KEY --publish ... --subscribe ...` for each, `ndds security sign {3} --admin {1}`, then \
         start the daemons with --key-file, --permissions {3} and --admin-key {2}.",
        admin.public(),
        secret.display(),
        public.display(),
        doc.display(),
    )?;
    Ok(())
}

fn read(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
}

fn add(
    path: &Path,
    name: &str,
    key: &PublicId,
    [publish, subscribe, own, use_]: [&Vec<String>; 4],
) -> anyhow::Result<()> {
    let text = read(path)?;
    let body = core::unsigned_text(&text);
    let current = document::parse(body).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if let Some(existing) = current.subjects.iter().find(|s| s.key == *key) {
        anyhow::bail!(
            "{}: key {key} is subject `{}` already (edit its rules in the file)",
            path.display(),
            existing.name
        );
    }
    anyhow::ensure!(
        current.subjects.iter().all(|s| s.name != name),
        "{}: a subject is named `{name}` already",
        path.display()
    );
    let mut block = format!("\n[[subject]]\nname = {}\nkey = \"{key}\"\n", quoted(name));
    for (field, patterns) in [
        ("publish", publish),
        ("subscribe", subscribe),
        ("own", own),
        ("use", use_),
    ] {
        for pattern in patterns {
            Pattern::new(pattern)?;
        }
        if !patterns.is_empty() {
            let list: Vec<String> = patterns.iter().map(|p| quoted(p)).collect();
            block.push_str(&format!("{field} = [{}]\n", list.join(", ")));
        }
    }
    let mut new_text = body.to_owned();
    if !new_text.ends_with('\n') {
        new_text.push('\n');
    }
    new_text.push_str(&block);
    document::parse(&new_text).map_err(|e| anyhow::anyhow!("the new subject: {e}"))?;
    security::write_text(path, &new_text, 0o644, true)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let none = patterns_or_none([publish, subscribe, own, use_]);
    outln!(
        "added subject `{name}` ({key}){none} to {}: sign it again (`ndds security sign`) and \
         copy it to every host",
        path.display()
    )?;
    Ok(())
}

fn patterns_or_none(lists: [&Vec<String>; 4]) -> &'static str {
    if lists.iter().all(|l| l.is_empty()) {
        " with no rules (it may do nothing yet)"
    } else {
        ""
    }
}

/// A TOML basic string.
fn quoted(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn sign(path: &Path, admin: &Path) -> anyhow::Result<()> {
    let admin_text = read(admin)?;
    let admin =
        Identity::parse(&admin_text).map_err(|e| anyhow::anyhow!("{}: {e}", admin.display()))?;
    let text = read(path)?;
    let mut body = core::unsigned_text(&text).to_owned();
    let current = document::parse(&body).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if let Some(named) = document::admin_of(&body) {
        anyhow::ensure!(
            named == admin.public(),
            "{} names administrator {named}, not {} (the key given)",
            path.display(),
            admin.public()
        );
    }
    // A signed version is a new version: its serial grows (said in every refusal).
    let serial = current.serial + 1;
    body = bump_serial(&body, serial)
        .with_context(|| format!("{}: no `serial = N` line", path.display()))?;
    let signed = core::sign(&body, &admin);
    security::write_text(path, &signed, 0o644, true)
        .with_context(|| format!("cannot write {}", path.display()))?;
    outln!(
        "signed {} (serial {serial}, {} subjects, valid until {}): copy it to every host",
        path.display(),
        current.subjects.len(),
        document::time_text(current.not_after)
    )?;
    Ok(())
}

fn bump_serial(body: &str, serial: u64) -> Option<String> {
    let mut done = false;
    let lines: Vec<String> = body
        .lines()
        .map(|line| {
            let is_serial = line
                .split_once('=')
                .is_some_and(|(key, _)| key.trim() == "serial");
            if is_serial && !done {
                done = true;
                format!("serial = {serial}")
            } else {
                line.to_owned()
            }
        })
        .collect();
    done.then(|| lines.join("\n") + "\n")
}

fn show(path: &Path, admin_key: Option<&str>) -> anyhow::Result<()> {
    let text = read(path)?;
    let body = core::unsigned_text(&text);
    let permissions =
        document::parse(body).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let admin = match admin_key {
        Some(spec) => Some(security::admin_key(spec)?),
        None => document::admin_of(body),
    };
    let signature = match (core::split_signed(&text), admin) {
        (Err(err), _) => format!("not signed ({err})"),
        (Ok(_), None) => "signed; no administrator key to check it with".to_owned(),
        (Ok(_), Some(admin)) => match core::verify_signed(&text, &admin) {
            Ok(_) => format!("signed by {admin}: verifies"),
            Err(err) => format!("DOES NOT VERIFY: {err}"),
        },
    };
    let valid = if permissions.valid_at(security::unix_now()) {
        "valid now"
    } else {
        "NOT valid now"
    };
    outln!(
        "{}: serial {}, {}, from {} until {} ({valid})\n{signature}",
        path.display(),
        permissions.serial,
        permissions
            .domain
            .map_or("any domain".to_owned(), |d| format!("domain {d}")),
        document::time_text(permissions.not_before),
        document::time_text(permissions.not_after),
    )?;
    for subject in &permissions.subjects {
        outln!("subject `{}` {}", subject.name, subject.key)?;
        for action in [
            core::Action::Publish,
            core::Action::Subscribe,
            core::Action::Own,
            core::Action::Use,
        ] {
            let rules: Vec<&str> = subject.rules(action).iter().map(Pattern::as_str).collect();
            if !rules.is_empty() {
                outln!("    {:<9} {}", action.name(), rules.join(", "))?;
            }
        }
    }
    Ok(())
}
