//! A running system described for tools: what `ndds studio` draws (the data-flow diagram, the
//! state-machine graphs) and what a late joiner needs to make sense of the system's topics.
//!
//! A runtime with services publishes its [`SystemDescription`] on `cs/<runtime>/description`
//! (reliable, kept for late joiners) when it starts and again whenever it changes: a
//! configuration switch (the active modules and execution order change), a rate change, a
//! habitat started or stopped. Everything in it is also available in the process through
//! [`Runtime::describe`]; nothing in it is needed to run the system.

use serde::{Deserialize, Serialize};

use super::fsm::{Program, StimulusKind};
use super::module::Use;
use super::runtime::Runtime;

/// The topic a runtime's description is published on.
pub fn description_topic(runtime: &str) -> String {
    format!("cs/{runtime}/description")
}

/// The type announced on a description topic (`ndds::SystemDescription`), with its layout
/// (so `ndds echo` decodes it too).
pub fn description_type() -> ndds_client::TypeDescription {
    let named = |desc: ndds_client::TypeDescription| {
        desc.with_name(ndds_core::types::builtin::SYSTEM_DESCRIPTION)
    };
    match ndds_client::TypeDescription::describer()
        .with::<StimulusKind>()
        .describe::<SystemDescription>()
    {
        Ok(desc) => named(desc),
        // Only a change to the types above could make it fail; a test keeps it working.
        Err(_) => named(ndds_client::TypeDescription::opaque("SystemDescription")),
    }
}

/// A running system, as tools draw it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SystemDescription {
    /// The runtime's name (the system's).
    pub runtime: String,
    /// The description file's prose (`[system] description`), empty without one.
    pub description: String,
    /// The files it was loaded from, the top one first.
    pub files: Vec<String>,
    /// The active configuration, if one was switched to.
    pub configuration: Option<String>,
    /// The habitats, by name.
    pub habitats: Vec<HabitatDescription>,
    /// The modules, by name.
    pub modules: Vec<ModuleDescription>,
    /// The CSMats, by name.
    pub mats: Vec<MatDescription>,
    /// Module groups, by category and name.
    pub groups: Vec<GroupDescription>,
    /// Configurations, by name.
    pub configurations: Vec<ConfigurationDescription>,
    /// CSMats published or subscribed on the network.
    pub bindings: Vec<BindingDescription>,
    /// State machines (their programs), by main machine.
    pub machines: Vec<MachineDescription>,
}

/// One habitat.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HabitatDescription {
    /// Its name.
    pub name: String,
    /// Samples per second (0 for a habitat without a clock yet).
    pub rate_hz: f64,
    /// Whether it samples now.
    pub running: bool,
    /// Its active modules, in execution order.
    pub order: Vec<String>,
    /// What clocks it: `timer`, `topic NAME` or `manual` (empty when not created).
    pub clock: String,
}

/// One module: a component instance, or one the runtime made (`publish:TOPIC`,
/// `subscribe:TOPIC`, rate transitions, triggers).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModuleDescription {
    /// Its name.
    pub name: String,
    /// The habitat it runs in.
    pub habitat: String,
    /// The component type of a description file's `[[component]]` (empty for the others).
    pub component: String,
    /// Its groups, as `category/group`.
    pub groups: Vec<String>,
    /// Whether it is in its habitat's active set now.
    pub active: bool,
    /// What it reads.
    pub inputs: Vec<PortDescription>,
    /// What it writes.
    pub outputs: Vec<PortDescription>,
}

/// One CSMat a module reads or writes.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortDescription {
    /// The module's own name for it.
    pub role: String,
    /// The CSMat.
    pub mat: String,
    /// `input` (read in `execute`), `state` (read in `state_update`), `parameter`, or
    /// `output`.
    pub usage: String,
}

/// One CSMat.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MatDescription {
    /// Its name.
    pub name: String,
    /// Rows.
    pub rows: u32,
    /// Columns.
    pub cols: u32,
    /// Row fields (name, unit), empty or one per row.
    pub row_fields: Vec<(String, String)>,
    /// Column fields (name, unit), empty or one per column.
    pub col_fields: Vec<(String, String)>,
}

/// One module group.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GroupDescription {
    /// Its category.
    pub category: String,
    /// Its name.
    pub name: String,
    /// Its modules.
    pub modules: Vec<String>,
    /// Whether it is its category's active group.
    pub active: bool,
}

/// One configuration: a group per category.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConfigurationDescription {
    /// Its name.
    pub name: String,
    /// `(category, group)`.
    pub groups: Vec<(String, String)>,
}

/// A CSMat bound to a topic.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BindingDescription {
    /// The topic.
    pub topic: String,
    /// The CSMat.
    pub mat: String,
    /// The habitat whose samples publish or take it.
    pub habitat: String,
    /// `publish` or `subscribe`.
    pub direction: String,
}

/// A state machine's program.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MachineDescription {
    /// The main machine (which names the program on the network: `fsm/<name>/state`).
    pub name: String,
    /// The state entered when something goes wrong.
    pub error_state: String,
    /// Declared stimuli and their kinds.
    pub stimuli: Vec<(String, StimulusKind)>,
    /// The main machine and its sub-machines.
    pub graphs: Vec<MachineGraph>,
}

/// One machine's states and transitions.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MachineGraph {
    /// Its name.
    pub name: String,
    /// The state it starts in.
    pub start: String,
    /// Its states.
    pub states: Vec<String>,
    /// Return states (of a sub-machine) and their codes.
    pub returns: Vec<(String, i32)>,
    /// Transitions, in priority order.
    pub transitions: Vec<TransitionDescription>,
}

/// One transition.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransitionDescription {
    /// The state it leaves; `None` for a global one (from every state).
    pub from: Option<String>,
    /// Its condition, as written.
    pub when: String,
    /// Its action, as written (`none`, `switch endptLQG`, `call Sub`).
    pub action: String,
    /// Return code and the next state.
    pub next: Vec<(i32, String)>,
}

impl MachineDescription {
    /// The description of `program`.
    pub fn of(program: &Program) -> Self {
        let mut graphs: Vec<MachineGraph> = program
            .machines
            .values()
            .map(|m| MachineGraph {
                name: m.name.clone(),
                start: m.start.clone(),
                states: m.states.clone(),
                returns: m.returns.iter().map(|(s, c)| (s.clone(), *c)).collect(),
                transitions: m
                    .transitions
                    .iter()
                    .map(|t| TransitionDescription {
                        from: t.from.clone(),
                        when: t.when.to_string(),
                        action: t.action.to_string(),
                        next: t.next.iter().map(|(c, s)| (*c, s.clone())).collect(),
                    })
                    .collect(),
            })
            .collect();
        // The main machine first.
        graphs.sort_by_key(|g| g.name != program.main);
        MachineDescription {
            name: program.main.clone(),
            error_state: program.error_state.clone(),
            stimuli: program
                .stimuli
                .iter()
                .map(|(n, k)| (n.clone(), *k))
                .collect(),
            graphs,
        }
    }
}

/// What only a loaded system knows (a runtime built in code has none of it).
#[derive(Clone, Debug, Default)]
pub(crate) struct Extras {
    pub(crate) description: String,
    pub(crate) files: Vec<String>,
    /// Module → component type.
    pub(crate) components: std::collections::BTreeMap<String, String>,
    pub(crate) bindings: Vec<BindingDescription>,
    pub(crate) machines: Vec<MachineDescription>,
}

fn usage(u: Use) -> &'static str {
    match u {
        Use::Feedthrough => "input",
        Use::State => "state",
        Use::Parameter => "parameter",
    }
}

impl Runtime {
    /// This runtime as tools draw it (see the module's documentation). Takes the database's
    /// lock, then each habitat's list lock in turn for its execution order (as
    /// [`Habitat::order`](super::Habitat::order) does), never both at once.
    pub fn describe(&self) -> SystemDescription {
        let extras = self.extras();
        let mut d = SystemDescription {
            runtime: self.name().to_owned(),
            description: extras.description.clone(),
            files: extras.files.clone(),
            bindings: extras.bindings.clone(),
            machines: extras.machines.clone(),
            ..SystemDescription::default()
        };
        let habitats = {
            let db = self.db();
            d.configuration = db.current.clone();
            for (name, module) in &db.modules {
                let port = |p: &super::module::Port, u: &str| PortDescription {
                    role: p.role.clone(),
                    mat: p.mat.name().to_owned(),
                    usage: u.to_owned(),
                };
                d.modules.push(ModuleDescription {
                    name: name.clone(),
                    habitat: module.habitat.clone(),
                    component: extras.components.get(name).cloned().unwrap_or_default(),
                    groups: db
                        .groups_of(name)
                        .map(|g| {
                            let category = db.groups.get(g).map(|e| e.category.as_str());
                            format!("{}/{g}", category.unwrap_or(""))
                        })
                        .collect(),
                    active: module.active,
                    inputs: (module.interface.inputs.iter())
                        .map(|(p, u)| port(p, usage(*u)))
                        .collect(),
                    outputs: (module.interface.outputs.iter())
                        .map(|p| port(p, "output"))
                        .collect(),
                });
            }
            for (name, entry) in &db.mats {
                if !entry.mat.is_bound() {
                    continue;
                }
                let value = entry.mat.snapshot();
                let fields = |f: &[super::csmat::Field]| {
                    f.iter()
                        .map(|f| (f.name.clone(), f.unit.clone()))
                        .collect::<Vec<_>>()
                };
                let (rows, cols) = value.shape();
                d.mats.push(MatDescription {
                    name: name.clone(),
                    rows: u32::try_from(rows).unwrap_or(u32::MAX),
                    cols: u32::try_from(cols).unwrap_or(u32::MAX),
                    row_fields: fields(value.row_fields()),
                    col_fields: fields(value.col_fields()),
                });
            }
            for (name, group) in &db.groups {
                let active = db
                    .categories
                    .get(&group.category)
                    .is_some_and(|c| c.active.as_deref() == Some(name));
                d.groups.push(GroupDescription {
                    category: group.category.clone(),
                    name: name.clone(),
                    modules: group.modules.clone(),
                    active,
                });
            }
            for (name, groups) in &db.configurations {
                d.configurations.push(ConfigurationDescription {
                    name: name.clone(),
                    groups: groups.iter().map(|(c, g)| (c.clone(), g.clone())).collect(),
                });
            }
            db.habitats.values().cloned().collect::<Vec<_>>()
        };
        for habitat in habitats {
            if !habitat.is_created() {
                continue;
            }
            let period = habitat.period().as_secs_f64();
            d.habitats.push(HabitatDescription {
                name: habitat.name().to_owned(),
                rate_hz: if period > 0.0 { 1.0 / period } else { 0.0 },
                running: habitat.is_running(),
                order: habitat.order(),
                clock: match habitat.clock() {
                    Some(crate::Clock::Timer) => "timer".to_owned(),
                    Some(crate::Clock::Topic(topic)) => format!("topic {topic}"),
                    Some(crate::Clock::Manual) => "manual".to_owned(),
                    None => String::new(),
                },
            });
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_description_type_has_a_layout_tools_can_decode() {
        let desc = description_type();
        assert_eq!(desc.name, "ndds::SystemDescription");
        let layout = desc.layout.as_ref().expect("a layout");
        let d = SystemDescription {
            runtime: "arm".into(),
            machines: vec![MachineDescription {
                name: "arm".into(),
                stimuli: vec![("Go".into(), StimulusKind::Latched)],
                ..MachineDescription::default()
            }],
            ..SystemDescription::default()
        };
        let bytes = postcard::to_allocvec(&d).unwrap();
        let json = ndds_core::dynamic::decode_json(layout, &bytes).unwrap();
        assert_eq!(json["runtime"], "arm");
        assert_eq!(json["machines"][0]["stimuli"][0][0], "Go");
    }
}
