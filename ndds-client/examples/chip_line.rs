//! The appendix of Shin's paper, whole, on simulated devices: a line that releases pallets
//! (GATE, with BOUNDED_BUFFER as a filter on FREQUENCY, and RELEASE on LET_1_GO with one user
//! and a 2 s timeout), loads a card on each (LOAD_IT, which starts LOAD_CARD and
//! SCREW_IN_CARD with `costart` and queries them every second), and inserts chips into it
//! (CHIP_IT and CHIP_IT2, one station each, sharing a rack of chip feeders through
//! SHARE_FEEDER queries under their `order`, and a work schedule of chips).
//!
//! ```text
//! cargo run -p ndds-client --features module-files --example chip_line    # every module, 6 pallets
//! cargo run -p ndds-client --features module-files --example chip_line -- --pallets 20 --feeder4 5
//! cargo run -p ndds-client --features module-files --example chip_line -- --spec my_line.toml
//! ```
//!
//! The modules' specifications — tasks, ports and their restrictions, handlers, subprograms,
//! orders, work schedules, children — are a description file, `chip_line.toml` beside this
//! one (built in; `--spec FILE` reads another, so that moving a chip is an edit of that file).
//! This code binds what the file declares: each port's message types, and the bodies.
//!
//! Every event is one JSON line on stdout (`{"t_us":..,"module":..,"event":..}`); a summary
//! goes to stderr at the end. Ctrl-C stops the modules cleanly. `--modules` runs some of the
//! modules only (`GATE`, `RELEASE`, `LOAD_IT`, `CHIP_IT`, `CHIP_IT2`), so that the line can be
//! spread over hosts: the interop test runs GATE and RELEASE on one host, LOAD_IT (and its
//! children) on a second and the two chip robots on a third. `--release-name RELEASE2` runs a
//! replacement RELEASE, for when the first was killed.
//!
//! The devices are simulated: the conveyor is three reliable topics (`line/load`,
//! `line/chip/0` and `line/chip/1`, `line/done`), the feeder rack a shared structure of the
//! process that runs the chip robots, with a count of chips per feeder (feeder 4 holds
//! `--feeder4` chips; an operator refills an empty feeder after half a second).
//!
//! Two departures from the paper, both named in docs/ports.md: a robot waits for its next
//! card, and backs off after a refused or timed-out SHARE_FEEDER query, in sections of their
//! own that its order does not name (so they rank below the critical-section handler): an idle
//! robot gives permission instead of letting the other's query time out.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use ndds_client::ports::{
    Call, ModuleBuilder, ModuleContext, ModuleError, ModuleFile, Performed, PortError, PortUser,
    RequestFilter, RunningModule, Usage, Verdict,
};
use ndds_client::{ConsumerQos, Participant, ProducerQos, Reliability};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// The modules' specifications (`--spec` reads another file).
const SPEC: &str = include_str!("chip_line.toml");

/// The feeders of the rack.
const FEEDERS: [u32; 3] = [1, 4, 12];

/// How long a grasp and an insertion take.
const MOTION: Duration = Duration::from_millis(40);

/// A pallet that left the line.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Done {
    pallet: u32,
    robot: String,
}

/// One JSON line on stdout.
fn event(module: &str, what: &str, fields: Value) {
    let t_us = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64);
    let mut line = json!({ "t_us": t_us, "module": module, "event": what });
    if let (Some(line), Value::Object(fields)) = (line.as_object_mut(), fields) {
        line.extend(fields);
    }
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

struct Args {
    modules: BTreeSet<String>,
    pallets: u32,
    seconds: Option<f64>,
    release_name: String,
    feeder4: u32,
    spec: Option<std::path::PathBuf>,
}

fn args() -> Result<Args, String> {
    let mut args = Args {
        modules: ["GATE", "RELEASE", "LOAD_IT", "CHIP_IT", "CHIP_IT2"]
            .map(str::to_owned)
            .into(),
        pallets: 6,
        seconds: None,
        release_name: "RELEASE".into(),
        feeder4: 4,
        spec: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--modules" => {
                args.modules = value()?.split(',').map(str::to_owned).collect();
            }
            "--pallets" => {
                args.pallets = value()?.parse().map_err(|e| format!("--pallets: {e}"))?
            }
            "--seconds" => {
                args.seconds = Some(value()?.parse().map_err(|e| format!("--seconds: {e}"))?);
            }
            "--release-name" => args.release_name = value()?,
            "--spec" => args.spec = Some(value()?.into()),
            "--feeder4" => {
                args.feeder4 = value()?.parse().map_err(|e| format!("--feeder4: {e}"))?
            }
            other => {
                return Err(format!(
                    "unknown argument `{other}`; use --modules, --pallets, --seconds, --release-name, --feeder4, --spec"
                ));
            }
        }
    }
    for module in &args.modules {
        if !["GATE", "RELEASE", "LOAD_IT", "CHIP_IT", "CHIP_IT2"].contains(&module.as_str()) {
            return Err(format!(
                "unknown module `{module}`: GATE, RELEASE, LOAD_IT, CHIP_IT or CHIP_IT2"
            ));
        }
    }
    Ok(args)
}

fn reliable() -> (ProducerQos, ConsumerQos) {
    let reliability = Reliability::Reliable { depth: 64 };
    (
        ProducerQos {
            reliability,
            ..ProducerQos::default()
        },
        ConsumerQos {
            reliability,
            depth: 64,
            ..ConsumerQos::default()
        },
    )
}

/// BOUNDED_BUFFER, the paper's filter on FREQUENCY: it holds up to 20 cycle-time messages
/// from LOAD_IT and CHIP_IT, answers each sender at once, and gives GATE the oldest one when
/// GATE asks through the port FILTER (`(-1, -1.0)` when it holds none).
struct BoundedBuffer {
    buffer: VecDeque<(i32, f64)>,
}

impl RequestFilter<(i32, f64), (i32, f64)> for BoundedBuffer {
    type Message = mpsc::SyncSender<(i32, f64)>;

    fn request(&mut self, _sender: &str, message: (i32, f64)) -> Verdict<(i32, f64), (i32, f64)> {
        if self.buffer.len() >= 20 {
            return Verdict::Refuse("the buffer holds 20 messages already".into());
        }
        self.buffer.push_back(message);
        Verdict::Answer((0, 0.0))
    }

    fn message(&mut self, gate: mpsc::SyncSender<(i32, f64)>) {
        let _ = gate.send(self.buffer.pop_front().unwrap_or((-1, -1.0)));
    }

    /// `USAGE=RECEIVE`: it receives the users' messages (GATE asks it through FILTER).
    fn usages(&self) -> Vec<Usage> {
        vec![Usage::Receive]
    }
}

/// GATE: releases a pallet every CYCLE_TIME through RELEASE, and adjusts CYCLE_TIME to the
/// faster of the two cells, from what BOUNDED_BUFFER holds.
fn gate(
    participant: &Participant,
    spec: &ModuleFile,
    pallets: u32,
) -> Result<ModuleBuilder, ModuleError> {
    Ok(ModuleBuilder::from_file(participant, spec, "GATE")?
        .port_filtered::<(i32, f64), (i32, f64), _>(
            "FREQUENCY",
            BoundedBuffer {
                buffer: VecDeque::new(),
            },
        )
        .port::<u32, i32>("LET_1_GO")
        .exception("LET_1_GO.TIMEOUT", |ctx| {
            event(
                ctx.name(),
                "release_timeout",
                json!({ "help": "RELEASE does not answer: restart it" }),
            );
        })
        .body(move |ctx| {
            let mut cycle = Duration::from_millis(400);
            let mut speeds = [0.8_f64, 1.6];
            let mut pallet = 0;
            while pallet < pallets {
                if ctx.delay(cycle).is_err() {
                    return;
                }
                match ctx.send::<u32, i32>("LET_1_GO", &pallet) {
                    Ok(0) => {
                        event("GATE", "let_go", json!({ "pallet": pallet }));
                        pallet += 1;
                    }
                    Ok(rc) => event("GATE", "release_failed", json!({ "rc": rc })),
                    Err(ModuleError::Stopping(_)) => return,
                    Err(err) => event("GATE", "release_error", json!({ "error": err.to_string() })),
                }
                // Ask BOUNDED_BUFFER for the next queued cycle time.
                let Ok(filter) = ctx.filter::<mpsc::SyncSender<(i32, f64)>>("FREQUENCY") else {
                    continue;
                };
                let (asked, answer) = mpsc::sync_channel(1);
                if filter.send(asked)
                    && let Ok((task, time)) = answer.recv_timeout(Duration::from_secs(1))
                    && (0..=1).contains(&task)
                {
                    speeds[task as usize] = time;
                    let fastest = speeds[0].min(speeds[1]).max(0.1);
                    cycle = Duration::from_secs_f64(fastest / 2.0);
                    event(
                        "GATE",
                        "cycle",
                        json!({ "from": task, "seconds": cycle.as_secs_f64() }),
                    );
                }
            }
            event("GATE", "all_released", json!({ "pallets": pallets }));
        }))
}

/// RELEASE (under `name`): the one user of LET_1_GO; puts each pallet GATE lets go on the
/// conveyor to the loading station.
fn release(
    participant: &Participant,
    spec: &ModuleFile,
    name: &str,
) -> Result<ModuleBuilder, ModuleError> {
    let (producer_qos, _) = reliable();
    let conveyor = participant
        .producer::<u32>("line/load", producer_qos)
        .map_err(|e| ModuleError::Port(PortError::BadName(e.to_string())))?;
    let me = name.to_owned();
    Ok(ModuleBuilder::from_file(participant, spec, name)?
        .port::<u32, i32>("LET_1_GO")
        .body(move |ctx| {
            loop {
                let released = ctx.receive_from_owner::<u32, i32>(
                    "LET_1_GO",
                    Duration::from_millis(500),
                    |pallet| match conveyor.write(pallet) {
                        Ok(()) => 0,
                        Err(_) => 1,
                    },
                );
                match released {
                    Ok(pallet) => event(&me, "released", json!({ "pallet": pallet })),
                    Err(ModuleError::Stopping(_)) => return,
                    Err(_) => {} // nothing to release yet
                }
            }
        }))
}

/// LOAD_IT, with its children LOAD_CARD (and its task FREEZE_PALLET) and SCREW_IN_CARD.
fn load_it(participant: &Participant, spec: &ModuleFile) -> Result<ModuleBuilder, ModuleError> {
    let (producer_qos, consumer_qos) = reliable();
    let state = Arc::new(Mutex::new((0_u32, 0.0_f64))); // cards loaded, last cycle time
    let status = Arc::clone(&state);
    let stations =
        [0, 1].map(|s| participant.producer::<u32>(&format!("line/chip/{s}"), producer_qos));
    let [Ok(station0), Ok(station1)] = stations else {
        return Err(ModuleError::Port(PortError::BadName("line/chip".into())));
    };
    let arrivals = participant
        .consumer::<u32>("line/load", consumer_qos)
        .map_err(|e| ModuleError::Port(PortError::BadName(e.to_string())))?;
    let load_card = ModuleBuilder::from_file(participant, spec, "LOAD_CARD")?
        .task("FREEZE_PALLET", move |task| {
            // Stops each pallet at the station, signals LOAD_CARD, and lets it go on when
            // LOAD_CARD replies (the card is on and screwed).
            let signal = PortUser::<u32, ()>::declare(
                task.participant(),
                "PALLET_IN_PLACE",
                "FREEZE_PALLET",
            );
            let Ok(signal) = signal else { return };
            while !task.stopping() {
                let Ok(sample) = arrivals.recv_timeout(Duration::from_millis(100)) else {
                    continue;
                };
                let pallet = sample.value;
                event("FREEZE_PALLET", "frozen", json!({ "pallet": pallet }));
                match task.send(&signal, &pallet, Duration::from_secs(30)) {
                    Ok(()) => {
                        let station = if pallet % 2 == 0 {
                            &station0
                        } else {
                            &station1
                        };
                        let _ = station.write(&pallet);
                        event(
                            "FREEZE_PALLET",
                            "to_chip",
                            json!({ "pallet": pallet, "station": pallet % 2 }),
                        );
                    }
                    Err(ModuleError::Stopping(_)) => return,
                    Err(err) => event(
                        "FREEZE_PALLET",
                        "not_loaded",
                        json!({ "pallet": pallet, "error": err.to_string() }),
                    ),
                }
            }
        })
        .port::<(), (i32, u32, f64)>("ASK_CHILD1")
        .response("ASK_CHILD1.STATUS", move |()| {
            let (loaded, cycle) = *status.lock().unwrap_or_else(|p| p.into_inner());
            (0, loaded, cycle)
        })
        .port::<u32, ()>("PALLET_IN_PLACE")
        .port::<u32, i32>("CARD_IN_PLACE")
        .exception("PALLET_IN_PLACE.TIMEOUT", |ctx| {
            event(ctx.name(), "no_pallet", json!({ "for_seconds": 30 }));
        })
        .exception("CARD_IN_PLACE.TIMEOUT", |ctx| {
            event(
                ctx.name(),
                "card_not_anchored",
                json!({ "help": "signal for help" }),
            );
        })
        .body(move |ctx| {
            loop {
                let started = Instant::now();
                let (pallet, handle) =
                    match ctx.receive::<u32, ()>("PALLET_IN_PLACE", Duration::from_secs(30)) {
                        Ok(taken) => taken,
                        Err(ModuleError::Stopping(_)) => return,
                        Err(_) => continue,
                    };
                // Move the card to the pallet.
                if ctx.delay(Duration::from_millis(60)).is_err() {
                    return;
                }
                match ctx.send::<u32, i32>("CARD_IN_PLACE", &pallet) {
                    Ok(0) => {
                        let _ = handle.reply(&()); // release the pallet
                        let mut state = state.lock().unwrap_or_else(|p| p.into_inner());
                        state.0 += 1;
                        state.1 = started.elapsed().as_secs_f64();
                        event(
                            "LOAD_CARD",
                            "loaded",
                            json!({ "pallet": pallet, "loaded": state.0 }),
                        );
                    }
                    Ok(rc) => event(
                        "LOAD_CARD",
                        "not_anchored",
                        json!({ "pallet": pallet, "rc": rc }),
                    ),
                    Err(ModuleError::Stopping(_)) => return,
                    Err(err) => event(
                        "LOAD_CARD",
                        "not_anchored",
                        json!({ "pallet": pallet, "error": err.to_string() }),
                    ),
                }
            }
        });
    let screw_in_card = ModuleBuilder::from_file(participant, spec, "SCREW_IN_CARD")?
        .port::<(), i32>("ASK_CHILD2")
        .response("ASK_CHILD2.STATUS", |()| 0)
        .port::<u32, i32>("CARD_IN_PLACE")
        .exception("CARD_IN_PLACE.TIMEOUT", |ctx| {
            event(ctx.name(), "no_card", json!({ "for_seconds": 30 }));
        })
        .body(|ctx| {
            loop {
                let screwed = ctx.receive_from_owner::<u32, i32>(
                    "CARD_IN_PLACE",
                    Duration::from_secs(30),
                    |_| 0,
                );
                match screwed {
                    Ok(pallet) => event("SCREW_IN_CARD", "screwed", json!({ "pallet": pallet })),
                    Err(ModuleError::Stopping(_)) => return,
                    Err(_) => {}
                }
            }
        });
    Ok(ModuleBuilder::from_file(participant, spec, "LOAD_IT")?
        .port::<(i32, f64), (i32, f64)>("FREQUENCY")
        .port::<(), (i32, u32, f64)>("ASK_CHILD1")
        .port::<(), i32>("ASK_CHILD2")
        .exception("ASK_CHILD1.TIMEOUT", |ctx| {
            event(ctx.name(), "child_silent", json!({ "child": "LOAD_CARD" }));
        })
        .exception("ASK_CHILD2.TIMEOUT", |ctx| {
            event(
                ctx.name(),
                "child_silent",
                json!({ "child": "SCREW_IN_CARD" }),
            );
        })
        .child(load_card)
        .child(screw_in_card)
        .body(|ctx| {
            if let Err(err) = ctx.costart(&["LOAD_CARD", "SCREW_IN_CARD"]) {
                event(
                    "LOAD_IT",
                    "costart_failed",
                    json!({ "error": err.to_string() }),
                );
                return;
            }
            event(
                "LOAD_IT",
                "costarted",
                json!({ "children": ["LOAD_CARD", "SCREW_IN_CARD"] }),
            );
            loop {
                if ctx.delay(Duration::from_secs(1)).is_err() {
                    return;
                }
                let card = ctx.query::<(), (i32, u32, f64)>("ASK_CHILD1", &());
                let screw = ctx.query::<(), i32>("ASK_CHILD2", &());
                match (card, screw) {
                    (Err(ModuleError::Stopping(_)), _) | (_, Err(ModuleError::Stopping(_))) => {
                        return;
                    }
                    (Ok((rc, loaded, cycle)), Ok(screw_rc)) => {
                        event(
                            "LOAD_IT",
                            "status",
                            json!({ "rc": rc, "loaded": loaded, "screw_rc": screw_rc }),
                        );
                        if cycle > 0.0 {
                            let _ = ctx.send::<(i32, f64), (i32, f64)>("FREQUENCY", &(0, cycle));
                        }
                    }
                    _ => {} // a timeout: its handler signalled for help
                }
            }
        }))
}

/// The rack of chip feeders both robots reach into.
struct Rack {
    counts: BTreeMap<u32, u32>,
    refill_at: BTreeMap<u32, Instant>,
    holder: Option<String>,
}

impl Rack {
    /// `robot` takes a chip from `feeder`: `Err` when it is empty (an operator refills it
    /// half a second after it ran empty).
    fn grasp(&mut self, robot: &str, feeder: u32) -> Result<(), ()> {
        let count = self.counts.entry(feeder).or_insert(0);
        if *count == 0 {
            match self.refill_at.get(&feeder) {
                Some(at) if Instant::now() >= *at => {
                    *count = 10;
                    self.refill_at.remove(&feeder);
                    event("RACK", "refilled", json!({ "feeder": feeder, "chips": 10 }));
                }
                _ => return Err(()),
            }
        }
        if let Some(other) = &self.holder {
            event(
                "RACK",
                "violation",
                json!({ "feeder": feeder, "robot": robot, "holder": other }),
            );
        }
        self.holder = Some(robot.to_owned());
        *count -= 1;
        if *count == 0 {
            self.refill_at
                .insert(feeder, Instant::now() + Duration::from_millis(500));
            event("RACK", "feeder_emptied", json!({ "feeder": feeder }));
        }
        Ok(())
    }

    fn let_go(&mut self) {
        self.holder = None;
    }
}

/// CHIP_IT (`second`: CHIP_IT2, with the ports' roles and its timeout mirrored).
fn chip_it(
    participant: &Participant,
    spec: &ModuleFile,
    second: bool,
    rack: Arc<Mutex<Rack>>,
) -> Result<ModuleBuilder, ModuleError> {
    let (me, other, ready, own_share, peer_share, station) = if second {
        (
            "CHIP_IT2",
            "CHIP_IT",
            "READY_TO_CHIP2",
            "SHARE_FEEDER1",
            "SHARE_FEEDER",
            1,
        )
    } else {
        (
            "CHIP_IT",
            "CHIP_IT2",
            "READY_TO_CHIP",
            "SHARE_FEEDER",
            "SHARE_FEEDER1",
            0,
        )
    };
    let (producer_qos, consumer_qos) = reliable();
    let done = participant
        .producer::<Done>("line/done", producer_qos)
        .map_err(|e| ModuleError::Port(PortError::BadName(e.to_string())))?;
    let cards = participant
        .consumer::<u32>(&format!("line/chip/{station}"), consumer_qos)
        .map_err(|e| ModuleError::Port(PortError::BadName(e.to_string())))?;
    let crit = format!("{peer_share}.CRIT_SECTION");
    let mut builder = ModuleBuilder::from_file(participant, spec, me)?
        .task("FREEZE_CARD", move |task| {
            let signal = PortUser::<u32, ()>::declare(task.participant(), ready, "FREEZE_CARD");
            let Ok(signal) = signal else { return };
            while !task.stopping() {
                let Ok(sample) = cards.recv_timeout(Duration::from_millis(100)) else {
                    continue;
                };
                let pallet = sample.value;
                if task.send(&signal, &pallet, Duration::from_secs(60)).is_ok() {
                    let _ = done.write(&Done {
                        pallet,
                        robot: me.to_owned(),
                    });
                    event(me, "done", json!({ "pallet": pallet }));
                }
            }
        })
        .port::<u32, ()>(ready)
        // Its timeout is not only for a failed peer: both querying at once is a deadlock,
        // and the shorter timeout of CHIP_IT2 breaks it.
        .port::<(), i32>(own_share)
        .port::<(), i32>(peer_share)
        // Because of the order, permission is always given: the handler runs only when
        // this robot is not in the feeder area.
        .response(&crit, |()| 1)
        .exception(&format!("{ready}.TIMEOUT"), move |ctx| {
            event(ctx.name(), "no_card", json!({ "for_seconds": 60 }));
        })
        .exception(&format!("{own_share}.TIMEOUT"), move |ctx| {
            event(ctx.name(), "share_timeout", json!({ "peer": other }));
        });
    if !second {
        builder = builder.port::<(i32, f64), (i32, f64)>("FREQUENCY");
    }
    Ok(builder.body(move |ctx| robot(ctx, me, ready, own_share, !second, &rack)))
}

/// A chip robot's background code: for each card, the work schedule under SHARE_FEEDER's
/// permission.
fn robot(
    ctx: &ModuleContext,
    me: &str,
    ready: &str,
    own_share: &str,
    reports: bool,
    rack: &Mutex<Rack>,
) {
    let backoff = |ctx: &ModuleContext| {
        let jitter = Duration::from_millis(20 + u64::from(fastrand_u8()) % 60);
        ctx.section("BACKOFF", || ctx.delay(jitter)).is_err()
    };
    loop {
        let started = Instant::now();
        // Waiting for a card: a section below the critical section, so an idle robot answers.
        let taken = ctx.section("AWAIT_CARD", || {
            ctx.receive::<u32, ()>(ready, Duration::from_secs(60))
        });
        let (pallet, handle) = match taken {
            Ok(taken) => taken,
            Err(ModuleError::Stopping(_)) => return,
            Err(_) => continue,
        };
        ctx.reinstate();
        let mut feeder = 0;
        loop {
            while ctx.more() > 0 {
                match ctx.query::<(), i32>(own_share, &()) {
                    Ok(1) => {}
                    Err(ModuleError::Stopping(_)) => return,
                    _ => {
                        if backoff(ctx) {
                            return;
                        }
                        continue;
                    }
                }
                let performed = ctx.perform(|call: &Call| {
                    let number = |i: usize| match call.args.get(i) {
                        Some(ndds_client::ports::Arg::Number(n)) => *n,
                        _ => 0.0,
                    };
                    match call.name.as_str() {
                        "GRASP" => {
                            feeder = number(0) as u32;
                            let grasped = rack
                                .lock()
                                .unwrap_or_else(|p| p.into_inner())
                                .grasp(me, feeder);
                            if grasped.is_err() {
                                return 1;
                            }
                            event(
                                me,
                                "grasp_begin",
                                json!({ "feeder": feeder, "pallet": pallet }),
                            );
                            let stopped = ctx.delay(MOTION).is_err();
                            event(
                                me,
                                "grasp_end",
                                json!({ "feeder": feeder, "pallet": pallet }),
                            );
                            rack.lock().unwrap_or_else(|p| p.into_inner()).let_go();
                            i32::from(stopped)
                        }
                        "INSERT" => {
                            if ctx.delay(MOTION).is_err() {
                                return 1;
                            }
                            event(
                                me,
                                "inserted",
                                json!({
                                    "pallet": pallet, "feeder": feeder,
                                    "at": [number(0), number(1), number(2)],
                                }),
                            );
                            0
                        }
                        _ => 1,
                    }
                });
                if let Performed::Failed { step, code, .. } = performed {
                    if ctx.stopping() {
                        return;
                    }
                    event(
                        me,
                        "feeder_empty",
                        json!({ "step": step, "code": code, "feeder": feeder, "operator": "told" }),
                    );
                }
            }
            // Failed steps wait for the operator; the others are done.
            if ctx.retry_failed() == 0 {
                break;
            }
            if backoff(ctx)
                || ctx
                    .section("BACKOFF", || ctx.delay(Duration::from_millis(200)))
                    .is_err()
            {
                return;
            }
        }
        let _ = handle.reply(&());
        let cycle = started.elapsed().as_secs_f64();
        event(
            me,
            "card_done",
            json!({ "pallet": pallet, "seconds": cycle }),
        );
        if reports {
            let _ = ctx.send::<(i32, f64), (i32, f64)>("FREQUENCY", &(1, cycle));
        }
    }
}

/// A small random number without a crate: the low bits of the clock.
fn fastrand_u8() -> u8 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| (d.subsec_nanos() >> 10) as u8)
}

fn main() {
    let args = match args() {
        Ok(args) => args,
        Err(err) => {
            eprintln!("chip_line: {err}");
            std::process::exit(2);
        }
    };
    if let Err(err) = run(&args) {
        eprintln!("chip_line: {err}");
        std::process::exit(1);
    }
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let spec = match &args.spec {
        Some(path) => ModuleFile::read(path)?,
        None => ModuleFile::parse("chip_line.toml (built in)", SPEC)?,
    };
    let participant = Participant::connect()?;
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))?;
    }
    let rack = Arc::new(Mutex::new(Rack {
        counts: FEEDERS
            .iter()
            .map(|&f| (f, if f == 4 { args.feeder4 } else { 100 }))
            .collect(),
        refill_at: BTreeMap::new(),
        holder: None,
    }));
    let has = |m: &str| args.modules.contains(m);
    // Every module is loaded (checked, its ports declared) before any starts, so that a
    // problem starts nothing.
    let mut loaded = Vec::new();
    // Downstream first, so that nothing waits for a station that is not there yet.
    for second in [false, true] {
        if has(if second { "CHIP_IT2" } else { "CHIP_IT" }) {
            loaded.push(chip_it(&participant, &spec, second, Arc::clone(&rack))?.load()?);
        }
    }
    if has("LOAD_IT") {
        loaded.push(load_it(&participant, &spec)?.load()?);
    }
    if has("RELEASE") {
        loaded.push(release(&participant, &spec, &args.release_name)?.load()?);
    }
    if has("GATE") {
        loaded.push(gate(&participant, &spec, args.pallets)?.load()?);
    }
    let mut running: Vec<RunningModule> = Vec::new();
    for module in loaded {
        running.push(module.start()?);
    }
    event(
        "chip_line",
        "started",
        json!({ "modules": args.modules, "pid": std::process::id() }),
    );
    // With the chip robots here: until every pallet left the line. Otherwise until stopped.
    let (_, consumer_qos) = reliable();
    let finished = participant.consumer::<Done>("line/done", consumer_qos)?;
    let mut done = BTreeSet::new();
    let until = args
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s));
    let counting = has("CHIP_IT") && has("CHIP_IT2") && has("GATE");
    while !stop.load(Ordering::Relaxed) && until.is_none_or(|at| Instant::now() < at) {
        if let Ok(sample) = finished.recv_timeout(Duration::from_millis(100)) {
            done.insert(sample.value.pallet);
        }
        if counting && done.len() as u32 >= args.pallets {
            break;
        }
    }
    event(
        "chip_line",
        "stopping",
        json!({ "pallets_done": done.len() }),
    );
    // Upstream first: GATE stops releasing, then the stations.
    while let Some(module) = running.pop() {
        module.stop();
    }
    eprintln!(
        "chip_line: {} pallet(s) left the line; modules stopped",
        done.len()
    );
    Ok(())
}
