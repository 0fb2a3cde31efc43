//! What the shell knows of the live system: its description (the `Describe` answer) and the
//! ports its process owns. Lookups by name answer with what exists when the name is not
//! there (`system `arm` has no configuration `endptlqg` (did you mean `endptLQG`?);
//! configurations: JointPD, endptLQG`). No IO here: the session fetches, this only reads.

use ndds_core::suggest;
use ndds_runtime::describe::{
    ConfigurationDescription, HabitatDescription, MachineDescription, MatDescription,
    ModuleDescription, SystemDescription,
};
use ndds_runtime::fsm::StimulusKind;

/// The live system as last fetched.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SystemView {
    /// Its description.
    pub description: SystemDescription,
    /// The ports its process owns, by name (its command port `cs.NAME`, its machines'
    /// `fsm.MACHINE`, and those declared in its description files).
    pub ports: Vec<String>,
}

/// What a port of the system is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortRole {
    /// The system's command port (`cs.NAME`): what the shell itself talks to.
    Command,
    /// A state machine's command port (`fsm.MACHINE`): `send MACHINE ...`.
    Machine,
    /// A port declared in a description file: takes text (`query PORT TEXT`).
    Declared,
}

impl SystemView {
    /// The system's name.
    pub fn name(&self) -> &str {
        &self.description.runtime
    }

    /// Habitat names.
    pub fn habitats(&self) -> Vec<&str> {
        self.description
            .habitats
            .iter()
            .map(|h| h.name.as_str())
            .collect()
    }

    /// Module names.
    pub fn modules(&self) -> Vec<&str> {
        (self.description.modules.iter())
            .map(|m| m.name.as_str())
            .collect()
    }

    /// CSMat names.
    pub fn mats(&self) -> Vec<&str> {
        (self.description.mats.iter())
            .map(|m| m.name.as_str())
            .collect()
    }

    /// The CSMats `set` takes: those no module writes (parameters and reference inputs).
    pub fn settable_mats(&self) -> Vec<&str> {
        (self.description.mats.iter())
            .filter(|m| self.writer_of(&m.name).is_none())
            .map(|m| m.name.as_str())
            .collect()
    }

    /// The module that writes CSMat `mat` every sample, if one does.
    pub fn writer_of(&self, mat: &str) -> Option<&str> {
        (self.description.modules.iter())
            .find(|m| m.outputs.iter().any(|o| o.mat == mat))
            .map(|m| m.name.as_str())
    }

    /// Configuration names.
    pub fn configurations(&self) -> Vec<&str> {
        (self.description.configurations.iter())
            .map(|c| c.name.as_str())
            .collect()
    }

    /// State machine names.
    pub fn machines(&self) -> Vec<&str> {
        (self.description.machines.iter())
            .map(|m| m.name.as_str())
            .collect()
    }

    /// What port `port` is for.
    pub fn port_role(&self, port: &str) -> PortRole {
        if port == ndds_runtime::command_port(self.name()) {
            return PortRole::Command;
        }
        let machine = port.strip_prefix("fsm.");
        if machine.is_some_and(|m| self.machines().contains(&m)) {
            return PortRole::Machine;
        }
        PortRole::Declared
    }

    /// The ports `query` takes: those declared in the description files.
    pub fn declared_ports(&self) -> Vec<&str> {
        (self.ports.iter())
            .filter(|p| self.port_role(p) == PortRole::Declared)
            .map(String::as_str)
            .collect()
    }

    /// CSMat `name`.
    pub fn mat(&self, name: &str) -> Result<&MatDescription, String> {
        let found = self.description.mats.iter().find(|m| m.name == name);
        found.ok_or_else(|| self.missing("CSMat", "CSMats", name, &self.mats()))
    }

    /// CSMat `name`, if `set` takes it: no module writes it.
    pub fn settable_mat(&self, name: &str) -> Result<&MatDescription, String> {
        let settable = self.settable_mats();
        let Ok(mat) = self.mat(name) else {
            return Err(self.missing("CSMat", "settable CSMats", name, &settable));
        };
        match self.writer_of(name) {
            Some(writer) => Err(format!(
                "CSMat `{name}` is written by module `{writer}` every sample; only parameters \
                 and reference inputs (CSMats no module writes) can be set: {}",
                listed(&settable)
            )),
            None => Ok(mat),
        }
    }

    /// Module `name`.
    pub fn module(&self, name: &str) -> Result<&ModuleDescription, String> {
        let found = self.description.modules.iter().find(|m| m.name == name);
        found.ok_or_else(|| self.missing("module", "modules", name, &self.modules()))
    }

    /// Habitat `name`.
    pub fn habitat(&self, name: &str) -> Result<&HabitatDescription, String> {
        let found = self.description.habitats.iter().find(|h| h.name == name);
        found.ok_or_else(|| self.missing("habitat", "habitats", name, &self.habitats()))
    }

    /// Configuration `name`.
    pub fn configuration(&self, name: &str) -> Result<&ConfigurationDescription, String> {
        let found = (self.description.configurations.iter()).find(|c| c.name == name);
        found.ok_or_else(|| {
            self.missing(
                "configuration",
                "configurations",
                name,
                &self.configurations(),
            )
        })
    }

    /// State machine `name`.
    pub fn machine(&self, name: &str) -> Result<&MachineDescription, String> {
        let found = self.description.machines.iter().find(|m| m.name == name);
        found.ok_or_else(|| self.missing("state machine", "state machines", name, &self.machines()))
    }

    /// Stimulus `name` of `machine`, with its kind.
    pub fn stimulus(
        &self,
        machine: &MachineDescription,
        name: &str,
    ) -> Result<StimulusKind, String> {
        let found = machine.stimuli.iter().find(|(n, _)| n == name);
        found.map(|(_, kind)| *kind).ok_or_else(|| {
            let known: Vec<&str> = machine.stimuli.iter().map(|(n, _)| n.as_str()).collect();
            format!(
                "state machine `{}` has no stimulus `{name}`{}; stimuli: {}",
                machine.name,
                hint(name, &known),
                listed(&known)
            )
        })
    }

    /// Port `name`, if `query` takes it (declared in a description file).
    pub fn declared_port(&self, name: &str) -> Result<&str, String> {
        let declared = self.declared_ports();
        match self.ports.iter().find(|p| *p == name) {
            Some(port) if self.port_role(port) == PortRole::Declared => Ok(port),
            Some(_) => Err(format!(
                "port `{name}` is not one declared in a description file (it does not take \
                 text; `send` talks to state machines); ports that take text: {}",
                listed(&declared)
            )),
            None => Err(self.missing("port", "ports that take text", name, &declared)),
        }
    }

    fn missing(&self, kind: &str, plural: &str, name: &str, known: &[&str]) -> String {
        format!(
            "system `{}` has no {kind} `{name}`{}; {plural}: {}",
            self.name(),
            hint(name, known),
            listed(known)
        )
    }
}

/// ` (did you mean `x`?)`, or nothing when no known name is close.
pub fn hint(name: &str, known: &[&str]) -> String {
    suggest::did_you_mean(&suggest::suggest(name, known))
        .map(|s| format!(" ({s})"))
        .unwrap_or_default()
}

/// `a, b, c`, or `none`.
pub fn listed(known: &[&str]) -> String {
    if known.is_empty() {
        "none".to_owned()
    } else {
        known.join(", ")
    }
}

/// The words for a stimulus kind.
pub fn kind_word(kind: StimulusKind) -> &'static str {
    match kind {
        StimulusKind::Transient => "transient",
        StimulusKind::Latched => "latched",
        StimulusKind::Condition => "condition",
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use ndds_runtime::describe::PortDescription;

    use super::*;

    /// The arm example, as its `Describe` answers (abridged).
    pub(crate) fn arm() -> SystemView {
        let mat = |name: &str, rows: u32, fields: &[(&str, &str)]| MatDescription {
            name: name.into(),
            rows,
            cols: 1,
            row_fields: (fields.iter())
                .map(|(n, u)| ((*n).to_owned(), (*u).to_owned()))
                .collect(),
            col_fields: Vec::new(),
        };
        let module = |name: &str, habitat: &str, reads: &str, writes: &str| ModuleDescription {
            name: name.into(),
            habitat: habitat.into(),
            active: true,
            inputs: vec![PortDescription {
                role: "input".into(),
                mat: reads.into(),
                usage: "input".into(),
            }],
            outputs: vec![PortDescription {
                role: "output".into(),
                mat: writes.into(),
                usage: "output".into(),
            }],
            ..ModuleDescription::default()
        };
        SystemView {
            description: SystemDescription {
                runtime: "arm".into(),
                configuration: Some("JointPD".into()),
                habitats: vec![
                    HabitatDescription {
                        name: "control".into(),
                        rate_hz: 200.0,
                        running: true,
                        order: vec!["joint_pd".into(), "joint_error".into()],
                        clock: "timer".into(),
                    },
                    HabitatDescription {
                        name: "plant".into(),
                        rate_hz: 500.0,
                        running: true,
                        order: vec!["arm".into()],
                        clock: "timer".into(),
                    },
                ],
                modules: vec![
                    module("joint_pd", "control", "joints", "command"),
                    module("joint_error", "control", "joint_goal", "joint_error"),
                    module("arm", "plant", "command", "joints"),
                ],
                mats: vec![
                    mat("command", 2, &[]),
                    mat("endpoint_goal", 2, &[("x", "m"), ("y", "m")]),
                    mat("joint_error", 2, &[]),
                    mat("joint_goal", 2, &[("q1", "rad"), ("q2", "rad")]),
                    mat("joints", 2, &[("q1", "rad"), ("q2", "rad")]),
                ],
                configurations: vec![
                    ConfigurationDescription {
                        name: "JointPD".into(),
                        groups: vec![("controllers".into(), "PD".into())],
                    },
                    ConfigurationDescription {
                        name: "endptLQG".into(),
                        groups: vec![("controllers".into(), "LQG".into())],
                    },
                ],
                machines: vec![MachineDescription {
                    name: "arm".into(),
                    error_state: "Safe".into(),
                    stimuli: vec![
                        ("Coarse".into(), StimulusKind::Transient),
                        ("Object".into(), StimulusKind::Condition),
                        ("Precise".into(), StimulusKind::Transient),
                        ("Settled".into(), StimulusKind::Transient),
                    ],
                    graphs: Vec::new(),
                }],
                ..SystemDescription::default()
            },
            ports: vec!["arm-configure".into(), "cs.arm".into(), "fsm.arm".into()],
        }
    }

    #[test]
    fn a_missing_name_gets_the_close_one_and_every_one() {
        let view = arm();
        assert_eq!(
            view.configuration("endptlqg").unwrap_err(),
            "system `arm` has no configuration `endptlqg` (did you mean `endptLQG`?); \
             configurations: JointPD, endptLQG"
        );
        assert_eq!(
            view.habitat("nowhere").unwrap_err(),
            "system `arm` has no habitat `nowhere`; habitats: control, plant"
        );
        let machine = view.machine("arm").unwrap();
        assert_eq!(
            view.stimulus(machine, "Precice").unwrap_err(),
            "state machine `arm` has no stimulus `Precice` (did you mean `Precise`?); \
             stimuli: Coarse, Object, Precise, Settled"
        );
        assert!(
            view.machine("amr")
                .unwrap_err()
                .contains("state machines: arm")
        );
    }

    #[test]
    fn only_mats_no_module_writes_can_be_set() {
        let view = arm();
        assert_eq!(view.settable_mats(), ["endpoint_goal", "joint_goal"]);
        assert!(view.settable_mat("joint_goal").is_ok());
        let written = view.settable_mat("joints").unwrap_err();
        assert!(written.contains("written by module `arm`"), "{written}");
        assert!(written.contains("endpoint_goal, joint_goal"), "{written}");
        let unknown = view.settable_mat("joint_gaol").unwrap_err();
        assert!(unknown.contains("did you mean `joint_goal`?"), "{unknown}");
    }

    #[test]
    fn ports_are_told_apart_by_what_they_take() {
        let view = arm();
        assert_eq!(view.port_role("cs.arm"), PortRole::Command);
        assert_eq!(view.port_role("fsm.arm"), PortRole::Machine);
        assert_eq!(view.declared_ports(), ["arm-configure"]);
        assert!(view.declared_port("arm-configure").is_ok());
        let command = view.declared_port("cs.arm").unwrap_err();
        assert!(
            command.contains("ports that take text: arm-configure"),
            "{command}"
        );
    }
}
