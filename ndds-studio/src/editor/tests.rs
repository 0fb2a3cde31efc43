use super::*;

/// A copy of `examples/` in a temporary directory, and an editor of it (no daemon: network
/// bindings are left unbuilt, as the loader does without a participant).
fn examples() -> (tempfile::TempDir, Editor) {
    let dir = tempfile::tempdir().unwrap();
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    copy_dir(&source, dir.path());
    let editor = Editor::new(dir.path(), ndds_components::library(), None).unwrap();
    (dir, editor)
}

/// The same with `arm.toml` open.
fn arm() -> (tempfile::TempDir, Editor) {
    let (dir, mut editor) = examples();
    editor
        .apply(&EditOp::Open {
            path: "arm.toml".into(),
            discard: false,
        })
        .unwrap();
    (dir, editor)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap().flatten() {
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

fn key(k: &str) -> Step {
    Step::Key(k.to_owned())
}

/// A path written with dots: `"component.0.kp"`.
fn path(dotted: &str) -> Vec<Step> {
    dotted
        .split('.')
        .map(|part| part.parse().map_or_else(|_| key(part), Step::Index))
        .collect()
}

fn set_op(file: &str, path: Vec<Step>, value: Option<&str>) -> EditOp {
    EditOp::Set {
        file: file.into(),
        path,
        value: value.map(str::to_owned),
    }
}

/// Lines of `a` and `b` that differ (both have the same number of lines).
fn changed_lines(a: &str, b: &str) -> Vec<(String, String)> {
    assert_eq!(a.lines().count(), b.lines().count(), "{b}");
    a.lines()
        .zip(b.lines())
        .filter(|(x, y)| x != y)
        .map(|(x, y)| (x.to_owned(), y.to_owned()))
        .collect()
}

#[test]
fn opening_the_arm_reads_its_includes_and_machine_and_it_verifies() {
    let (_dir, editor) = arm();
    let state = editor.state();
    let files: Vec<(&str, &str)> = state["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f["path"].as_str().unwrap(), f["kind"].as_str().unwrap()))
        .collect();
    assert_eq!(
        files,
        [
            ("arm.toml", "description"),
            ("arm/plant.toml", "description"),
            ("arm/controller.toml", "description"),
            ("arm/supervisor.toml", "machine"),
        ]
    );
    assert!(editor.verifies(), "{:?}", editor.problems());
    assert!(
        state["summary"]
            .as_str()
            .unwrap()
            .contains("without a daemon"),
        "{state}"
    );
    assert_eq!(state["diff"], "");
    // The page's field texts: a component's gain as written.
    let controller = &state["files"][2]["values"]["component"][0];
    assert_eq!(controller["name"], "\"joint_pd\"");
    assert_eq!(controller["kp"], "40.0");
    let listed = editor.list();
    assert!(
        listed.contains(&"arm/controller.toml".to_owned()),
        "{listed:?}"
    );
}

#[test]
fn changing_a_gain_changes_that_one_line_and_keeps_comments() {
    let (dir, mut editor) = arm();
    let before = editor.text("arm/controller.toml").unwrap().to_owned();
    editor
        .apply(&set_op(
            "arm/controller.toml",
            path("component.0.kp"),
            Some("55.0"),
        ))
        .unwrap();
    let after = editor.text("arm/controller.toml").unwrap().to_owned();
    assert_eq!(
        changed_lines(&before, &after),
        [("kp = 40.0".to_owned(), "kp = 55.0".to_owned())]
    );
    let diff = editor.diff();
    assert_eq!(
        diff.lines()
            .filter(|l| (l.starts_with('+') || l.starts_with('-'))
                && !l.starts_with("+++")
                && !l.starts_with("---"))
            .collect::<Vec<_>>(),
        ["-kp = 40.0", "+kp = 55.0"],
        "{diff}"
    );
    assert!(editor.verifies(), "{:?}", editor.problems());
    // Nothing on disk yet; saving writes exactly the changed file.
    let on_disk = |f: &str| std::fs::read_to_string(dir.path().join(f)).unwrap();
    assert_eq!(on_disk("arm/controller.toml"), before);
    let plant = on_disk("arm/plant.toml");
    assert_eq!(
        editor.apply(&EditOp::Save { force: false }).unwrap(),
        "saved arm/controller.toml"
    );
    assert_eq!(on_disk("arm/controller.toml"), after);
    assert_eq!(on_disk("arm/plant.toml"), plant);
    assert_eq!(editor.diff(), "");
    assert_eq!(
        editor.apply(&EditOp::Save { force: false }).unwrap(),
        "nothing to save"
    );
}

#[test]
fn a_value_of_the_wrong_type_is_shown_at_that_key_and_saving_is_refused() {
    let (dir, mut editor) = arm();
    editor
        .apply(&set_op(
            "arm/controller.toml",
            path("component.1.r"),
            Some("\"small\""),
        ))
        .unwrap();
    assert!(!editor.verifies());
    let problems = editor.problems();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert_eq!(problems[0].file.as_deref(), Some("arm/controller.toml"));
    assert_eq!(
        problems[0].path,
        [key("component"), Step::Index(1), key("r")],
        "{problems:?}"
    );
    assert!(problems[0].message.contains("`r`"), "{problems:?}");
    let before = std::fs::read_to_string(dir.path().join("arm/controller.toml")).unwrap();
    let refused = editor.apply(&EditOp::Save { force: false }).unwrap_err();
    assert!(
        refused.to_string().contains("does not verify (1 problem)"),
        "{refused}"
    );
    assert_eq!(
        std::fs::read_to_string(dir.path().join("arm/controller.toml")).unwrap(),
        before
    );
    // Forced, it is written as it is.
    editor.apply(&EditOp::Save { force: true }).unwrap();
    assert!(
        std::fs::read_to_string(dir.path().join("arm/controller.toml"))
            .unwrap()
            .contains("r = \"small\"")
    );
}

#[test]
fn text_that_is_not_toml_is_refused_and_changes_nothing() {
    let (_dir, mut editor) = arm();
    let before = editor.text("arm/controller.toml").unwrap().to_owned();
    let err = editor
        .apply(&set_op(
            "arm/controller.toml",
            path("component.0.kp"),
            Some("4 0"),
        ))
        .unwrap_err();
    assert!(err.to_string().contains("is not a TOML value"), "{err}");
    let err = editor
        .apply(&set_op(
            "arm/controller.toml",
            path("component.9.kp"),
            Some("1.0"),
        ))
        .unwrap_err();
    assert!(err.to_string().contains("only 4 `[[component]]`"), "{err}");
    let err = editor
        .apply(&set_op("arm/elsewhere.toml", path("x"), Some("1")))
        .unwrap_err();
    assert!(
        err.to_string().contains("not one of this system's files"),
        "{err}"
    );
    assert_eq!(editor.text("arm/controller.toml").unwrap(), before);
}

#[test]
fn paths_outside_the_root_are_refused() {
    let (_dir, mut editor) = examples();
    for path in [
        "../outside.toml",
        "/etc/ssl/openssl.cnf.toml",
        "arm/../../x.toml",
        "arm.txt",
    ] {
        let err = editor
            .apply(&EditOp::Open {
                path: path.into(),
                discard: false,
            })
            .unwrap_err();
        assert!(matches!(err, EditError::Path(..)), "{path}: {err}");
    }
    let err = editor
        .apply(&EditOp::New {
            path: "arm.toml".into(),
            discard: false,
        })
        .unwrap_err();
    assert!(err.to_string().contains("exists already"), "{err}");
}

#[test]
fn a_component_added_from_the_palette_is_checked_where_it_was_added() {
    let (_dir, mut editor) = arm();
    let before = editor.text("arm/controller.toml").unwrap().to_owned();
    editor
        .apply(&EditOp::Push {
            file: "arm/controller.toml".into(),
            path: path("component"),
            fields: vec![
                ("name".into(), "\"scaled\"".into()),
                ("type".into(), "\"gain\"".into()),
                ("habitat".into(), "\"control\"".into()),
            ],
        })
        .unwrap();
    let text = editor.text("arm/controller.toml").unwrap().to_owned();
    // After the last component, before the configurations' section that follows it? No:
    // arrays of tables keep their own order; the new table follows the last `[[component]]`.
    let added = text.find("name = \"scaled\"").unwrap();
    let tip_error = text.find("name = \"tip_error\"").unwrap();
    let machine = text.find("[[state_machine]]").unwrap();
    assert!(tip_error < added && added < machine, "{text}");
    assert!(text[..added].ends_with("\n\n[[component]]\n"), "{text}");
    // `gain` needs its input, output and k: each missing one said at the new component.
    let problems = editor.problems();
    assert!(!problems.is_empty());
    for p in problems {
        assert_eq!(p.file.as_deref(), Some("arm/controller.toml"), "{p:?}");
        assert_eq!(p.path[..2], [key("component"), Step::Index(4)], "{p:?}");
    }
    let said: Vec<&str> = problems.iter().map(|p| p.message.as_str()).collect();
    assert!(said.iter().any(|m| m.contains("`input`")), "{said:?}");
    // Connected and given its gain, it verifies.
    for (k, v) in [
        ("input", "\"tip_error\""),
        ("output", "\"scaled_error\""),
        ("k", "2.0"),
    ] {
        editor
            .apply(&set_op(
                "arm/controller.toml",
                vec![key("component"), Step::Index(4), key(k)],
                Some(v),
            ))
            .unwrap();
    }
    assert!(editor.verifies(), "{:?}", editor.problems());
    // Removed again, the file is as it was.
    editor
        .apply(&EditOp::Remove {
            file: "arm/controller.toml".into(),
            path: path("component.4"),
        })
        .unwrap();
    assert_eq!(editor.text("arm/controller.toml").unwrap(), before);
    assert_eq!(editor.diff(), "");
}

#[test]
fn transitions_and_states_are_edited_in_the_machine_file() {
    let (_dir, mut editor) = arm();
    let file = "arm/supervisor.toml";
    editor
        .apply(&set_op(
            file,
            path("machine.0.states"),
            Some("[\"Joint\", \"Endpoint\", \"Held\", \"Safe\", \"Parked\"]"),
        ))
        .unwrap();
    editor
        .apply(&EditOp::Push {
            file: file.into(),
            path: path("machine.0.transition"),
            fields: vec![
                ("from".into(), "\"Held\"".into()),
                ("when".into(), "\"Coarse\"".into()),
                ("next".into(), "{ 0 = \"Parked\" }".into()),
            ],
        })
        .unwrap();
    assert!(editor.verifies(), "{:?}", editor.problems());
    let text = editor.text(file).unwrap();
    assert!(
        text.ends_with("\n[[machine.transition]]\nfrom = \"Held\"\nwhen = \"Coarse\"\nnext = { 0 = \"Parked\" }\n"),
        "{text}"
    );
    // A condition the FSM parser refuses: reported at that transition of the machine file.
    editor
        .apply(&set_op(
            file,
            vec![
                key("machine"),
                Step::Index(0),
                key("transition"),
                Step::Index(3),
                key("when"),
            ],
            Some("\"Coarse and\""),
        ))
        .unwrap();
    // (Then the trigger naming the machine finds none: the second problem.)
    let problems = editor.problems();
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert_eq!(problems[0].file.as_deref(), Some(file));
    assert!(
        problems[0]
            .message
            .starts_with("state machine `arm/supervisor.toml`: machine `arm`, transition 3"),
        "{problems:?}"
    );
    assert_eq!(
        problems[0].path,
        [
            key("machine"),
            Step::Index(0),
            key("transition"),
            Step::Index(3)
        ],
        "{problems:?}"
    );
    // Broken TOML in the machine file: reported at its line there.
    let broken = editor
        .text(file)
        .unwrap()
        .replace("states = [", "states = [[");
    editor
        .apply(&EditOp::Text {
            file: file.into(),
            text: broken,
        })
        .unwrap();
    let problems = editor.problems();
    assert_eq!(problems[0].file.as_deref(), Some(file), "{problems:?}");
    assert!(problems[0].line > 1, "{problems:?}");
    assert!(
        problems[0].message.contains("TOML parse error"),
        "{problems:?}"
    );
    let err = editor
        .apply(&set_op(file, path("main"), Some("\"arm\"")))
        .unwrap_err();
    assert!(matches!(err, EditError::Unparsed(..)), "{err}");
    editor.apply(&EditOp::Revert).unwrap();
    assert!(editor.verifies(), "{:?}", editor.problems());
    assert_eq!(editor.diff(), "");
}

#[test]
fn a_new_system_with_a_new_machine_is_saved_and_loads_from_disk() {
    let (dir, mut editor) = examples();
    editor
        .apply(&EditOp::New {
            path: "lab/new.toml".into(),
            discard: false,
        })
        .unwrap();
    assert!(editor.verifies(), "{:?}", editor.problems());
    editor
        .apply(&EditOp::Push {
            file: "lab/new.toml".into(),
            path: path("component"),
            fields: vec![
                ("name".into(), "\"source\"".into()),
                ("type".into(), "\"constant\"".into()),
                ("habitat".into(), "\"control\"".into()),
                ("value".into(), "[1.5]".into()),
                ("output".into(), "\"setpoint\"".into()),
            ],
        })
        .unwrap();
    editor
        .apply(&EditOp::NewMachine {
            name: "mode".into(),
        })
        .unwrap();
    assert!(editor.verifies(), "{:?}", editor.problems());
    assert_eq!(
        editor.apply(&EditOp::Save { force: false }).unwrap(),
        "saved lab/new.toml, lab/mode.toml"
    );
    let system = System::load(
        dir.path().join("lab/new.toml"),
        None,
        ndds_components::library(),
    )
    .expect("the saved system loads");
    assert_eq!(system.machine_names(), ["mode"]);
    assert_eq!(system.runtime().habitats().len(), 1);
}

#[test]
fn opening_another_system_does_not_forget_unsaved_changes_unless_told() {
    let (_dir, mut editor) = arm();
    editor
        .apply(&set_op(
            "arm/controller.toml",
            path("component.0.kp"),
            Some("41.0"),
        ))
        .unwrap();
    let open = |discard| EditOp::Open {
        path: "multirate.toml".into(),
        discard,
    };
    let err = editor.apply(&open(false)).unwrap_err();
    assert!(
        err.to_string()
            .contains("unsaved changes in arm/controller.toml"),
        "{err}"
    );
    assert!(editor.diff().contains("+kp = 41.0"));
    editor.apply(&open(true)).unwrap();
    assert_eq!(editor.diff(), "");
    assert_eq!(editor.state()["top"], "multirate.toml");
}

#[test]
fn a_file_changed_on_disk_since_it_was_opened_is_not_overwritten() {
    let (dir, mut editor) = arm();
    editor
        .apply(&set_op(
            "arm/controller.toml",
            path("component.0.kd"),
            Some("11.0"),
        ))
        .unwrap();
    let path = dir.path().join("arm/controller.toml");
    let theirs = std::fs::read_to_string(&path).unwrap() + "\n# someone else's line\n";
    std::fs::write(&path, &theirs).unwrap();
    let err = editor.apply(&EditOp::Save { force: true }).unwrap_err();
    assert!(err.to_string().contains("was changed on disk"), "{err}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), theirs);
}

#[test]
fn a_malformed_file_is_shown_with_the_loaders_error_and_can_be_corrected() {
    let (dir, mut editor) = examples();
    std::fs::write(
        dir.path().join("broken.toml"),
        "[[habitat]]\nname = \"h\"\nrate = [1, 2\n",
    )
    .unwrap();
    editor
        .apply(&EditOp::Open {
            path: "broken.toml".into(),
            discard: false,
        })
        .unwrap();
    let state = editor.state();
    assert!(state["files"][0]["error"].as_str().is_some(), "{state}");
    let problems = editor.problems();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].message.starts_with("not valid TOML"),
        "{problems:?}"
    );
    assert_eq!(problems[0].file.as_deref(), Some("broken.toml"));
    editor
        .apply(&EditOp::Text {
            file: "broken.toml".into(),
            text: "[[habitat]]\nname = \"h\"\nrate = 100.0\n".into(),
        })
        .unwrap();
    assert!(editor.verifies(), "{:?}", editor.problems());
}

#[test]
fn the_palette_lists_the_library_with_inputs_outputs_and_parameters() {
    let palette = palette(&ndds_components::library());
    let pd = palette["components"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "pd")
        .expect("pd");
    let kinds: BTreeMap<&str, &str> = pd["params"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["name"].as_str().unwrap(), p["kind"].as_str().unwrap()))
        .collect();
    assert_eq!(kinds["measured"], "input");
    assert_eq!(kinds["output"], "output");
    assert_eq!(kinds["kp"], "number");
    // A parameter's line carries its unit (and range) as the reference does.
    let kd = pd["params"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "kd")
        .expect("kd");
    assert_eq!(kd["unit"], "s");
    assert!(kd["doc"].as_str().unwrap().ends_with(" [s]"), "{kd}");
    assert!(
        palette["sections"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["name"] == "habitat")
    );
}
