//! A shell session on one running system: the requests each command makes of it (through its
//! command port, its machines' ports and its declared ports) and what is printed of the
//! answers. Names are checked against the system's description first, so a mistyped one is
//! answered with what exists; what the system itself refuses is printed as it says it.
//!
//! Single-threaded: the line editor's completion and the commands share one session
//! (`Rc`), which keeps the description it last fetched for [`FRESH`].

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::rc::Rc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};
use ndds_client::Participant;
use ndds_client::ports::{CommandReply, PortError, PortUser};
use ndds_runtime::fsm::Stimulus;
use ndds_runtime::{HabitatStats, Pace, RuntimeCommand};
use serde::Deserialize;

use super::commands::ShellCommand;
use super::help;
use super::table::{self, MatValues};
use super::view::SystemView;
use crate::systems::{self, SystemLink};
use crate::{out, outln};

/// A fetched description is used for this long; then it is fetched again.
pub const FRESH: Duration = Duration::from_secs(2);

/// How long a TAB waits for the system's description.
pub const COMPLETION_WAIT: Duration = Duration::from_millis(500);

/// `stats` measures the achieved rates over this span.
const PACE_SPAN: Duration = Duration::from_millis(500);

/// What to do after a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Read the next command.
    Continue,
    /// Leave the shell.
    Quit,
}

/// One running system, as the shell talks to it.
pub struct Session {
    participant: Participant,
    link: SystemLink,
    wait: Duration,
    /// The view last fetched, and when (`None` once a command changed the system).
    view: RefCell<Option<(Option<Instant>, Rc<SystemView>)>>,
    /// Users of the declared ports `query` has talked to, kept so the next query needs no
    /// new declaration (and no new match).
    query_users: RefCell<BTreeMap<String, Rc<PortUser<String, CommandReply>>>>,
}

impl Session {
    /// A session on the system `link` reaches; fetches its description (failing if the
    /// system does not answer).
    pub fn open(
        participant: Participant,
        link: SystemLink,
        wait: Duration,
    ) -> anyhow::Result<Self> {
        let session = Session {
            participant,
            link,
            wait,
            view: RefCell::new(None),
            query_users: RefCell::new(BTreeMap::new()),
        };
        session.fetch()?;
        Ok(session)
    }

    /// The system's name.
    pub fn name(&self) -> &str {
        self.link.name()
    }

    /// The description (and ports) now, fetched again when older than [`FRESH`].
    pub fn view(&self) -> anyhow::Result<Rc<SystemView>> {
        let cached = self.view.borrow().clone();
        match cached {
            Some((Some(at), view)) if at.elapsed() < FRESH => Ok(view),
            _ => self.fetch(),
        }
    }

    /// For completion: the view now, or the last one when the system does not answer within
    /// [`COMPLETION_WAIT`] (a TAB must neither fail nor hang; the next try is [`FRESH`] later).
    pub fn completion_view(&self) -> Rc<SystemView> {
        let cached = self.view.borrow().clone();
        match cached {
            Some((Some(at), view)) if at.elapsed() < FRESH => view,
            _ => self.fetch_within(COMPLETION_WAIT).unwrap_or_else(|_| {
                let mut cached = self.view.borrow_mut();
                let (fetched, view) = cached.get_or_insert_with(Default::default);
                *fetched = Some(Instant::now());
                Rc::clone(view)
            }),
        }
    }

    fn fetch(&self) -> anyhow::Result<Rc<SystemView>> {
        self.fetch_within(self.wait)
    }

    fn fetch_within(&self, wait: Duration) -> anyhow::Result<Rc<SystemView>> {
        let description = self.link.describe_within(wait)?;
        let ports = systems::ports_of(&self.participant, self.name())?;
        let view = Rc::new(SystemView { description, ports });
        *self.view.borrow_mut() = Some((Some(Instant::now()), Rc::clone(&view)));
        Ok(view)
    }

    /// Fetches the view again before its next use (a command changed the system).
    fn forget(&self) {
        if let Some((fetched, _)) = self.view.borrow_mut().as_mut() {
            *fetched = None;
        }
    }

    /// `find` on the view; when it finds nothing on a view fetched earlier, once more on a
    /// fresh one (the name may be new), and then its answer (what exists) is the error.
    pub fn check<T>(&self, find: impl Fn(&SystemView) -> Result<T, String>) -> anyhow::Result<T> {
        let view = self.view()?;
        match find(&view) {
            Ok(found) => Ok(found),
            Err(_) => find(&*self.fetch()?).map_err(anyhow::Error::msg),
        }
    }

    /// Runs `command`, printing its output to stdout; its error says what went wrong and
    /// what exists.
    pub fn execute(&self, command: &ShellCommand) -> anyhow::Result<Flow> {
        let outcome = self.carry_out(command);
        if command.changes_the_system() {
            // Refused or not, the system may have changed (a machine's action ran).
            self.forget();
        }
        outcome
    }

    fn carry_out(&self, command: &ShellCommand) -> anyhow::Result<Flow> {
        match command {
            ShellCommand::Ls(which) => out!("{}", table::listing(&*self.view()?, *which))?,
            ShellCommand::Show(mat) => self.show(mat)?,
            ShellCommand::Module(name) => {
                let module = self.check(|v| v.module(name).cloned())?;
                out!("{}", table::module_text(&module))?;
            }
            ShellCommand::Watch { mat, seconds } => super::watch::run(self, mat, *seconds)?,
            ShellCommand::Stats => self.stats()?,
            ShellCommand::Set { mat, values } => self.set(mat, values)?,
            ShellCommand::Switch(configuration) => {
                self.check(|v| v.configuration(configuration).map(|_| ()))?;
                self.ask(&RuntimeCommand::Configure(configuration.clone()))?;
            }
            ShellCommand::Habitat { habitat, action } => {
                self.check(|v| v.habitat(habitat).map(|_| ()))?;
                self.ask(&RuntimeCommand::habitat(habitat, *action))?;
            }
            ShellCommand::Send { machine, stimuli } => self.send(machine, stimuli)?,
            ShellCommand::Query { port, text } => self.query(port, text)?,
            ShellCommand::Help(None) => out!("{}", help::help_text())?,
            ShellCommand::Help(Some(name)) => {
                out!(
                    "{}",
                    help::command_help_text(name).map_err(anyhow::Error::msg)?
                )?;
            }
            ShellCommand::Quit => return Ok(Flow::Quit),
        }
        Ok(Flow::Continue)
    }

    /// Sends `command` to the system and prints its answer; its refusal is the error.
    fn ask(&self, command: &RuntimeCommand) -> anyhow::Result<()> {
        match self.link.ask(command)? {
            Ok(done) => Ok(outln!("{done}")?),
            Err(refused) => Err(anyhow!("{refused}")),
        }
    }

    /// The answer of a request that answers with JSON text.
    fn ask_json<T: for<'de> Deserialize<'de>>(
        &self,
        command: &RuntimeCommand,
    ) -> anyhow::Result<T> {
        let text = (self.link.ask(command)?).map_err(|refused| anyhow!("{refused}"))?;
        serde_json::from_str(&text)
            .with_context(|| format!("system `{}`'s answer to {command:?}", self.name()))
    }

    /// The values of CSMat `name` now.
    pub fn read_mat(&self, name: &str) -> anyhow::Result<MatValues> {
        /// One entry of the `ReadMats` answer (a NaN comes as `null`).
        #[derive(Deserialize)]
        struct Entry {
            rows: Option<usize>,
            cols: Option<usize>,
            #[serde(default)]
            data: Vec<Option<f64>>,
            error: Option<String>,
        }
        let mut answer: BTreeMap<String, Entry> =
            self.ask_json(&RuntimeCommand::ReadMats(vec![name.to_owned()]))?;
        let entry = answer
            .remove(name)
            .ok_or_else(|| anyhow!("system `{}` did not answer for CSMat `{name}`", self.name()))?;
        match entry {
            Entry {
                rows: Some(rows),
                cols: Some(cols),
                data,
                error: None,
            } => Ok(MatValues {
                rows,
                cols,
                data: data.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect(),
            }),
            Entry { error, .. } => bail!(
                "system `{}`: {}",
                self.name(),
                error.unwrap_or_else(|| format!("no values for CSMat `{name}`"))
            ),
        }
    }

    fn show(&self, mat: &str) -> anyhow::Result<()> {
        let description = self.check(|v| v.mat(mat).cloned())?;
        let values = self.read_mat(mat)?;
        out!("{}", table::mat_table(mat, Some(&description), &values))?;
        Ok(())
    }

    fn stats(&self) -> anyhow::Result<()> {
        let earlier: Vec<HabitatStats> = self.ask_json(&RuntimeCommand::Stats)?;
        let started = Instant::now();
        std::thread::sleep(PACE_SPAN);
        let later: Vec<HabitatStats> = self.ask_json(&RuntimeCommand::Stats)?;
        let elapsed = started.elapsed();
        let paces: Vec<Option<Pace>> = (later.iter())
            .map(|l| {
                let e = earlier.iter().find(|e| e.habitat == l.habitat)?;
                Pace::between(e, l, elapsed)
            })
            .collect();
        out!("{}", table::stats_table(&later, &paces))?;
        Ok(())
    }

    fn set(&self, mat: &str, values: &[f64]) -> anyhow::Result<()> {
        let description = self.check(|v| v.settable_mat(mat).cloned())?;
        let (rows, cols) = (description.rows, description.cols);
        let wanted = rows as usize * cols as usize;
        if values.len() != wanted {
            bail!(
                "CSMat `{mat}` is {rows}x{cols}: give {wanted} value{}, row-major; {} given",
                if wanted == 1 { "" } else { "s" },
                values.len()
            );
        }
        self.ask(&RuntimeCommand::SetMat {
            name: mat.to_owned(),
            values: values.to_vec(),
        })
    }

    fn send(&self, machine: &str, stimuli: &[String]) -> anyhow::Result<()> {
        let parsed: Vec<Stimulus> = stimuli.iter().map(|s| Stimulus::parse(s)).collect();
        self.check(|v| {
            let described = v.machine(machine)?;
            parsed
                .iter()
                .try_for_each(|s| v.stimulus(described, &s.name).map(|_| ()))
        })?;
        match super::super::fsm::command(&self.participant, machine, &parsed, self.wait)? {
            Ok(report) => {
                for line in report.lines() {
                    outln!("{machine}: {line}")?;
                }
                Ok(())
            }
            Err(refused) => bail!("{refused}"),
        }
    }

    fn query(&self, port: &str, text: &str) -> anyhow::Result<()> {
        self.check(|v| v.declared_port(port).map(|_| ()))?;
        let user = self.query_user(port)?;
        match user.send(&text.to_owned(), self.wait) {
            Ok(Ok(reply)) => Ok(outln!("{reply}")?),
            Ok(Err(refused)) => bail!("port `{port}`: {refused}"),
            Err(PortError::Timeout { owner: None, .. }) => bail!(
                "port `{port}` has no owner now (system `{}` may have stopped)",
                self.name()
            ),
            Err(err) => Err(err.into()),
        }
    }

    fn query_user(&self, port: &str) -> anyhow::Result<Rc<PortUser<String, CommandReply>>> {
        if let Some(user) = self.query_users.borrow().get(port) {
            return Ok(Rc::clone(user));
        }
        let user = Rc::new(PortUser::declare(&self.participant, port, "ndds shell")?);
        (self.query_users.borrow_mut()).insert(port.to_owned(), Rc::clone(&user));
        Ok(user)
    }
}
