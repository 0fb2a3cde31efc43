//! What no single section can tell: names used twice, and references to habitats, CSMats,
//! groups, configurations and state machines that nothing declares. Each concern is one
//! check; [`cross_check`] runs them in the order their messages have always come.

use std::collections::{BTreeMap, BTreeSet};

use super::port::Serves;
use super::provided::Provided;
use super::trigger::TriggerDecl;
use super::{Description, Named, list, suggest};
use crate::system::source::{Diagnostics, Location};

/// Every check across sections.
pub(super) fn cross_check(d: &Description, p: &mut Diagnostics) {
    unique_names(d, p);
    habitat_references(d, p);
    let provided = Provided::of(d);
    provided.check_reads(d, p);
    group_references(d, p);
    start_configuration(d, p);
    machine_references(d, p);
    provided.check_set_actions(d, p);
    rate_actions(d, p);
    configuration_rates(d, p);
}

/// `rate HABITAT HZ` actions name a habitat of the system and a usable rate.
fn rate_actions(d: &Description, p: &mut Diagnostics) {
    let habitats: Vec<&str> = d.habitats.iter().map(|h| h.name.name.as_str()).collect();
    for m in &d.machines {
        for (machine, def) in &m.program.machines {
            for t in &def.transitions {
                let crate::fsm::ActionRef::Named { name, argument } = &t.action else {
                    continue;
                };
                if name != "rate" {
                    continue;
                }
                // Read as the action itself reads it when it runs.
                let usable =
                    crate::fsm::task::rate_argument(argument.as_deref()).is_ok_and(|(h, hz)| {
                        habitats.contains(&h) && crate::habitat::period_of(hz).is_some()
                    });
                if usable {
                    continue;
                }
                let argument = argument.as_deref().unwrap_or("");
                let habitat = argument.split_whitespace().next().unwrap_or("");
                p.expected(
                    &m.at,
                    format!(
                        "state machine `{machine}` ({}): action `rate {argument}`",
                        m.file.display()
                    ),
                    format!(
                        "`rate HABITAT HZ` with a habitat of this system{} and a rate from \
                         {:.6} to {} Hz",
                        suggest(habitat, &habitats),
                        crate::MIN_RATE_HZ,
                        crate::MAX_RATE_HZ
                    ),
                );
            }
        }
    }
}

/// A configuration's `rates` name habitats of the system.
fn configuration_rates(d: &Description, p: &mut Diagnostics) {
    let habitats: Vec<&str> = d.habitats.iter().map(|h| h.name.name.as_str()).collect();
    for conf in &d.configurations {
        for (habitat, _, at) in &conf.rates {
            if !habitats.contains(&habitat.as_str()) {
                p.push(
                    at,
                    format!(
                        "configuration `{}` sets the rate of habitat `{habitat}`, which this \
                         system does not declare{}; habitats: {}",
                        conf.name.name,
                        suggest(habitat, &habitats),
                        list(&habitats)
                    ),
                );
            }
        }
    }
}

/// Habitats, CSMats, components, configurations, rate transitions, ports and state machines
/// each have a name of their own.
fn unique_names(d: &Description, p: &mut Diagnostics) {
    unique("habitat", d.habitats.iter().map(|h| &h.name), p);
    unique("CSMat", d.mats.iter().map(|m| &m.name), p);
    unique("component", d.components.iter().map(|c| &c.name), p);
    unique("configuration", d.configurations.iter().map(|c| &c.name), p);
    unique("rate transition", d.rates.iter().map(|c| &c.name), p);
    unique("port", d.ports.iter().map(|c| &c.name), p);
    let machines: Vec<Named> = d
        .machines
        .iter()
        .map(|m| Named {
            name: m.program.main.clone(),
            at: m.at.clone(),
        })
        .collect();
    unique("state machine", machines.iter(), p);
}

/// Reports each name of `names` declared before, with where it was first declared.
fn unique<'a>(kind: &str, names: impl Iterator<Item = &'a Named>, p: &mut Diagnostics) {
    let mut seen: BTreeMap<&str, &Location> = BTreeMap::new();
    for n in names {
        match seen.get(n.name.as_str()) {
            Some(first) => p.push(
                &n.at,
                format!("duplicate {kind} `{}` (first declared at {first})", n.name),
            ),
            None => {
                seen.insert(&n.name, &n.at);
            }
        }
    }
}

/// Components, bindings, rate transitions and triggers name declared habitats (one
/// declared with a problem, reported already, is not reported again).
fn habitat_references(d: &Description, p: &mut Diagnostics) {
    let habitats: Vec<&str> = d.habitats.iter().map(|h| h.name.name.as_str()).collect();
    let used = (d.components.iter().map(|c| &c.habitat))
        .chain(d.subscribes.iter().map(|s| &s.habitat))
        .chain(d.publishes.iter().map(|s| &s.habitat))
        .chain(d.rates.iter().flat_map(|r| [&r.from.0, &r.to.0]))
        .chain(d.triggers.iter().map(|t| &t.habitat));
    for h in used {
        if habitats.contains(&h.name.as_str()) || d.broken_habitats.contains(&h.name) {
            continue;
        }
        p.expected(
            &h.at,
            format!("unknown habitat `{}`", h.name),
            format!(
                "a habitat declared with [[habitat]]{}: {}",
                suggest(&h.name, &habitats),
                list(&habitats)
            ),
        );
    }
}

/// Configurations name groups some component is in.
fn group_references(d: &Description, p: &mut Diagnostics) {
    let groups: BTreeSet<String> = d
        .components
        .iter()
        .filter_map(|c| c.group.as_ref().map(|(c, g, _)| format!("{c}/{g}")))
        .collect();
    let known: Vec<&String> = groups.iter().collect();
    for conf in &d.configurations {
        for (c, g, at) in &conf.groups {
            let full = format!("{c}/{g}");
            if groups.contains(&full) {
                continue;
            }
            p.expected(
                at,
                format!(
                    "configuration `{}` names group `{full}`, which no component is in",
                    conf.name.name
                ),
                format!("one of {}{}", list(&known), suggest(&full, &known)),
            );
        }
    }
}

/// `[system] configuration` is declared.
fn start_configuration(d: &Description, p: &mut Diagnostics) {
    let Some(conf) = &d.configuration else {
        return;
    };
    let names: Vec<&str> = d
        .configurations
        .iter()
        .map(|c| c.name.name.as_str())
        .collect();
    if names.contains(&conf.name.as_str()) {
        return;
    }
    p.expected(
        &conf.at,
        format!("unknown configuration `{}`", conf.name),
        format!(
            "one declared with [[configuration]]{}: {}",
            suggest(&conf.name, &names),
            list(&names)
        ),
    );
}

/// Triggers and ports serving stimuli name declared state machines; a trigger's stimulus is
/// one its machine declares.
fn machine_references(d: &Description, p: &mut Diagnostics) {
    let machines: Vec<&str> = d.machines.iter().map(|m| m.program.main.as_str()).collect();
    for t in &d.triggers {
        known_machine(&machines, &t.machine.name, &t.machine.at, p);
        declared_stimulus(d, t, p);
    }
    for port in &d.ports {
        if let (Serves::Stimuli(m), Some(at)) = (&port.serves, &port.machine_at) {
            known_machine(&machines, m, at, p);
        }
    }
}

fn known_machine(machines: &[&str], name: &str, at: &Location, p: &mut Diagnostics) {
    if machines.contains(&name) {
        return;
    }
    p.expected(
        at,
        format!("unknown state machine `{name}`"),
        format!(
            "the main machine of a [[state_machine]] file{}: {}",
            suggest(name, machines),
            list(machines)
        ),
    );
}

fn declared_stimulus(d: &Description, t: &TriggerDecl, p: &mut Diagnostics) {
    let machine = d.machines.iter().find(|m| m.program.main == t.machine.name);
    if machine.is_some_and(|m| !m.program.stimuli.contains_key(&t.stimulus.name)) {
        p.push(
            &t.at,
            format!(
                "state machine `{}` declares no stimulus `{}`",
                t.machine.name, t.stimulus.name
            ),
        );
    }
}
