//! `ndds studio` in a real browser: headless Chromium (Debian's `chromium` and
//! `chromium-driver`, which `.ci/run` installs) driven over WebDriver, against
//! `examples/arm.toml` running under a test daemon. Each check of the page is also checked
//! through the system itself (its statistics, its state machine's state, its command port), so
//! a page that only claims a change does not pass. Screenshots of each view go to
//! `target/studio-screenshots/` (docs/studio.md shows them).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::actions::{InputSource as _, MOUSE_BUTTON_LEFT, MouseActions, PointerAction};
use fantoccini::{Client, ClientBuilder, Locator};
use interop_tests::{ClientProcess, TestDomain, participant};
use ndds_client::ConsumerQos;
use ndds_client::ports::{CommandReply, PortUser};
use ndds_core::types::builtin;
use ndds_runtime::fsm::{MachineState, Stimulus};
use ndds_runtime::{HabitatStats, RuntimeCommand};

const WAIT: Duration = Duration::from_secs(30);
const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// Chromium and its driver, or a skip (a failure under CI, which installs them).
fn browser_available() -> bool {
    let present = Path::new(CHROMIUM).exists() && Path::new(CHROMEDRIVER).exists();
    if !present {
        assert!(
            std::env::var_os("CI").is_none(),
            "{CHROMIUM} and {CHROMEDRIVER} are missing (apt-get install chromium chromium-driver)"
        );
        eprintln!(
            "skipped: {CHROMIUM} or {CHROMEDRIVER} missing (apt-get install chromium chromium-driver)"
        );
    }
    present
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port on loopback")
}

/// chromedriver on loopback, killed on drop.
struct Driver {
    child: Child,
    url: String,
}

impl Driver {
    fn start() -> Self {
        let port = free_port();
        let child = Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .arg("--allowed-ips=127.0.0.1")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start chromedriver");
        let started = interop_tests::wait_until(WAIT, || {
            std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
        });
        assert!(started.is_some(), "chromedriver listens on {port}");
        Driver {
            child,
            url: format!("http://127.0.0.1:{port}"),
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

async fn browser(driver: &Driver, profile: &Path) -> Client {
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        serde_json::json!({
            "binary": CHROMIUM,
            "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     "--disable-quic", "--no-first-run", "--disable-background-networking",
                     "--disable-component-update", "--disable-sync", "--window-size=1500,1100",
                     format!("--user-data-dir={}", profile.display())]
        }),
    );
    ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&driver.url)
        .await
        .expect("a Chromium session through chromedriver")
}

/// Opens `url` in a fresh headless Chromium, runs `test` on the page, and closes it.
fn in_browser(url: &str, test: impl AsyncFnOnce(&Client)) {
    let driver = Driver::start();
    let profile = tempfile::tempdir().unwrap();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let page = browser(&driver, profile.path()).await;
        page.goto(url).await.unwrap();
        test(&page).await;
        page.close().await.unwrap();
    });
}

/// Polls `script` (a JS expression) in the page until it is truthy; its last value.
async fn until(page: &Client, what: &str, script: &str) -> serde_json::Value {
    let deadline = Instant::now() + WAIT;
    loop {
        let value = page
            .execute(&format!("return ({script});"), vec![])
            .await
            .unwrap_or(serde_json::Value::Null);
        let truthy = match &value {
            serde_json::Value::Null | serde_json::Value::Bool(false) => false,
            serde_json::Value::String(s) => !s.is_empty(),
            serde_json::Value::Number(n) => n.as_f64().is_some_and(|n| n != 0.0),
            _ => true,
        };
        if truthy {
            return value;
        }
        if Instant::now() >= deadline {
            let errors = page
                .execute("return {editor: (typeof ed !== 'undefined' && ed.state) ? {problems: ed.state.problems, selected: ed.selected, adding: ed.adding, reply: document.getElementById('ed-reply').textContent} : null, errors: window.studioErrors, systems: Object.keys(state.systems), machines: Object.keys(state.machines), topics: state.network ? state.network.topics.map(t => t.name).filter(n => n.startsWith('cs/')) : null}", vec![])
                .await
                .unwrap_or_default();
            panic!("the page never showed {what} ({script}): {value}; page errors: {errors}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

async fn click(page: &Client, css: &str) {
    page.find(Locator::Css(css))
        .await
        .unwrap_or_else(|e| panic!("no {css} on the page: {e}"))
        .click()
        .await
        .unwrap_or_else(|e| panic!("cannot click {css}: {e}"));
}

async fn screenshot(page: &Client, name: &str) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/studio-screenshots");
    std::fs::create_dir_all(&dir).unwrap();
    let png = page.screenshot().await.expect("a screenshot");
    std::fs::write(dir.join(format!("{name}.png")), png).unwrap();
}

/// Waits until `check` holds for a sample of `T` on `topic` (as the system reports it).
fn system_reports<T: serde::de::DeserializeOwned + serde::Serialize + Send + 'static>(
    socket: &Path,
    topic: &str,
    type_name: &str,
    check: impl Fn(&T) -> bool,
) -> Option<T> {
    let watcher = participant(socket, "verifier");
    let consumer = watcher
        .consumer_with_type::<T>(
            topic,
            ndds_client::TypeDescription::named::<T>(type_name),
            ConsumerQos::default(),
        )
        .unwrap();
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        if let Ok(sample) = consumer.recv_timeout(Duration::from_millis(200))
            && check(&sample.value)
        {
            return Some(sample.value);
        }
    }
    None
}

/// `ndds run examples/arm.toml` with the daemon at `socket`.
fn arm_system(socket: &Path) -> ClientProcess {
    let arm = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/arm.toml");
    ClientProcess::program(
        "ndds",
        socket,
        &["run", &arm.display().to_string(), "--plain"],
    )
}

/// `ndds studio` on any free port with the daemon at `socket`, and the URL it prints.
fn studio(socket: &Path) -> (ClientProcess, String) {
    studio_with(socket, &[])
}

fn studio_with(socket: &Path, extra: &[&str]) -> (ClientProcess, String) {
    let mut args = vec!["studio", "--port", "0"];
    args.extend_from_slice(extra);
    let studio = ClientProcess::program("ndds", socket, &args);
    let url = studio
        .line(WAIT)
        .and_then(|l| l.strip_prefix("ndds studio: ").map(str::to_owned))
        .expect("the studio prints its URL");
    (studio, url)
}

#[test]
fn the_studio_shows_and_drives_the_arm_example_in_a_real_browser() {
    if !browser_available() {
        return;
    }
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let _system = arm_system(&socket);
    // The arm settles in Joint and its supervisor switches to endptLQG by itself; `Coarse`
    // takes it to Held in JointPD, where it stays until told otherwise.
    let tool = participant(&socket, "setup");
    let machine =
        PortUser::<Vec<Stimulus>, CommandReply>::declare(&tool, "fsm.arm", "test").unwrap();
    let held = interop_tests::wait_until(WAIT, || {
        machine
            .send(&vec![Stimulus::parse("Coarse")], Duration::from_secs(2))
            .is_ok_and(|r| r.is_ok_and(|text| text.contains("Held")))
    });
    assert!(held.is_some(), "the arm's machine took Coarse");
    let (_studio, url) = studio(&socket);
    assert!(
        url.starts_with("http://127.0.0.1:") && url.contains("#token="),
        "{url}"
    );
    in_browser(&url, async |page: &Client| {
        // Network: the arm's topics, with the processes on them.
        until(
            page,
            "arm/endpoint in the topic list",
            "document.querySelector('#net-topics tr[data-topic=\"arm/endpoint\"]')",
        )
        .await;
        until(page, "a rate for arm/endpoint", "document.querySelector('#net-topics tr[data-topic=\"arm/endpoint\"] td:nth-child(5)').textContent.includes('Hz')").await;
        let nodes = until(page, "the topic in the graph", "graphs.net.nodes('[kind = \"topic\"]').map(n => n.data('name')).filter(n => n === 'arm/endpoint').length").await;
        assert_eq!(nodes, 1);
        until(
            page,
            "write access",
            "document.getElementById('access').textContent === 'may change the system'",
        )
        .await;
        screenshot(page, "network").await;

        // System: the components in their habitats; the configuration switched from the page.
        click(page, "#tab-system").await;
        until(
            page,
            "the endptLQG button",
            "document.querySelector('button[data-configuration=\"endptLQG\"]')",
        )
        .await;
        let modules = until(
            page,
            "the arm's modules",
            "graphs.sys.nodes().map(n => n.data('module')).filter(Boolean)",
        )
        .await;
        for module in [
            "arm",
            "joint_pd",
            "endpoint_lqg",
            "joint_error",
            "tip_error",
        ] {
            assert!(
                modules.as_array().unwrap().iter().any(|m| m == module),
                "{module} in {modules}"
            );
        }
        // The description the page got first may be from before `Coarse` switched to JointPD;
        // the runtime writes the new one within a second.
        until(
            page,
            "JointPD as the configuration",
            "document.getElementById('sys-config').textContent === 'JointPD'",
        )
        .await;
        screenshot(page, "system").await;

        click(page, "button[data-configuration=\"endptLQG\"]").await;
        let reply = until(
            page,
            "the switch's reply",
            "document.getElementById('sys-reply').textContent",
        )
        .await;
        assert!(
            reply
                .as_str()
                .unwrap()
                .contains("switched to configuration `endptLQG`"),
            "{reply}"
        );
        let stats = system_reports::<HabitatStats>(
            &socket,
            "cs/arm/control/stats",
            builtin::HABITAT_STATS,
            |s| s.configuration == "endptLQG",
        );
        assert!(
            stats.is_some(),
            "the runtime reports endptLQG after the page's button"
        );
        until(
            page,
            "the new configuration on the page",
            "document.getElementById('sys-config').textContent === 'endptLQG'",
        )
        .await;

        // A parameter set in place, read back through the runtime's command port.
        until(
            page,
            "joint_pd.kp among the parameters",
            "document.querySelector('input[data-mat=\"joint_pd.kp\"]')",
        )
        .await;
        page.execute("const i = document.querySelector('input[data-mat=\"joint_pd.kp\"]'); i.value = '41.5'; i.closest('tr').querySelector('button').click(); return true;", vec![]).await.unwrap();
        let reply = until(page, "the set's reply", "document.getElementById('sys-reply').textContent.includes('joint_pd.kp') && document.getElementById('sys-reply').textContent").await;
        assert!(reply.as_str().unwrap().contains("set to [41.5]"), "{reply}");
        let tool = participant(&socket, "reader");
        let port =
            PortUser::<RuntimeCommand, CommandReply>::declare(&tool, "cs.arm", "test").unwrap();
        let read = port
            .send(&RuntimeCommand::ReadMats(vec!["joint_pd.kp".into()]), WAIT)
            .unwrap()
            .unwrap();
        let read: serde_json::Value = serde_json::from_str(&read).unwrap();
        assert_eq!(
            read["joint_pd.kp"]["data"],
            serde_json::json!([41.5]),
            "{read}"
        );
        until(page, "the new value in the table", "document.querySelector('#sys-params tr[data-mat=\"joint_pd.kp\"] .value').textContent === '41.5'").await;
        // A parameter of the wrong shape gets the runtime's own refusal.
        page.execute("const i = document.querySelector('input[data-mat=\"joint_pd.kp\"]'); i.value = '1, 2'; i.closest('tr').querySelector('button').click(); return true;", vec![]).await.unwrap();
        let refusal = until(page, "the refusal", "document.getElementById('sys-reply').className.includes('bad') && document.getElementById('sys-reply').textContent").await;
        assert!(
            refusal
                .as_str()
                .unwrap()
                .contains("is 1x1 (1 values); 2 given"),
            "{refusal}"
        );

        // State machines: the state the machine reports, and a stimulus sent from the page.
        click(page, "#tab-fsm").await;
        until(
            page,
            "the arm machine",
            "document.getElementById('fsm-select').value === 'arm'",
        )
        .await;
        let reported =
            system_reports::<MachineState>(&socket, "fsm/arm/state", builtin::FSM_STATE, |_| true)
                .expect("the machine reports its state");
        until(
            page,
            "the reported state",
            &format!(
                "document.getElementById('fsm-state').textContent === {:?}",
                reported.state
            ),
        )
        .await;
        assert_eq!(reported.state, "Held");
        click(page, "button[data-stimulus=\"Precise\"]").await;
        let reply = until(
            page,
            "the stimulus's reply",
            "document.getElementById('fsm-reply').textContent",
        )
        .await;
        assert!(
            reply
                .as_str()
                .unwrap()
                .contains("Precise: Held -> Endpoint"),
            "{reply}"
        );
        let endpoint =
            system_reports::<MachineState>(&socket, "fsm/arm/state", builtin::FSM_STATE, |s| {
                s.state == "Endpoint"
            });
        assert!(
            endpoint.is_some(),
            "the machine went to Endpoint on the page's Precise"
        );
        until(
            page,
            "Endpoint on the page",
            "document.getElementById('fsm-state').textContent === 'Endpoint'",
        )
        .await;
        let highlighted = until(
            page,
            "the current state highlighted",
            "graphs.fsm.nodes('.current').map(n => n.id()).join(',')",
        )
        .await;
        assert_eq!(highlighted, "s:arm:Endpoint");
        let fired = until(
            page,
            "the last transition highlighted",
            "graphs.fsm.edges('.fired').map(e => e.data('from') + '>' + e.data('to')).join(',')",
        )
        .await;
        assert_eq!(fired, "Held>Endpoint");
        screenshot(page, "fsm").await;

        // Plots: arm/endpoint's x, decimated on the server, points arriving.
        click(page, "#tab-plots").await;
        until(page, "arm/endpoint among the plot topics", "[...document.getElementById('plot-topic').options].some(o => o.value === 'arm/endpoint')").await;
        page.execute("const s = document.getElementById('plot-topic'); s.value = 'arm/endpoint'; s.dispatchEvent(new Event('input')); return true;", vec![]).await.unwrap();
        let field = until(page, "arm/endpoint's fields", "[...document.getElementById('plot-field').options].map(o => o.value).find(v => v.startsWith('x'))").await;
        assert_eq!(field, "x (m)");
        page.execute(
            "document.getElementById('plot-field').value = 'x (m)'; return true;",
            vec![],
        )
        .await
        .unwrap();
        click(page, "#plot-add").await;
        let points = until(page, "points in the plot", "Number(document.querySelector('.plot').dataset.points) > 100 && Number(document.querySelector('.plot').dataset.points)").await;
        assert!(points.as_f64().unwrap() > 100.0);
        tokio::time::sleep(Duration::from_secs(2)).await;
        screenshot(page, "plots").await;

        // Without the token the page may look but not change anything.
        let base = url.split('#').next().unwrap().to_owned();
        page.goto(&base).await.unwrap();
        until(
            page,
            "view-only access",
            "document.getElementById('access').textContent.startsWith('view only')",
        )
        .await;
        click(page, "#tab-system").await;
        until(
            page,
            "the JointPD button",
            "document.querySelector('button[data-configuration=\"JointPD\"]')",
        )
        .await;
        click(page, "button[data-configuration=\"JointPD\"]").await;
        let refused = until(
            page,
            "the refusal",
            "document.getElementById('sys-reply').textContent",
        )
        .await;
        assert!(
            refused.as_str().unwrap().contains("may only look"),
            "{refused}"
        );
        let still = system_reports::<HabitatStats>(
            &socket,
            "cs/arm/control/stats",
            builtin::HABITAT_STATS,
            |_| true,
        )
        .unwrap();
        assert_eq!(
            still.configuration, "endptLQG",
            "a page without the token changed nothing"
        );
    });
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

/// Sets a text field the way a person does: all selected (Ctrl+A), typed over, Enter.
async fn type_into(page: &Client, css: &str, text: &str) {
    let field = page
        .find(Locator::Css(css))
        .await
        .unwrap_or_else(|e| panic!("no {css} on the page: {e}"));
    field
        .send_keys(&format!("\u{E009}a\u{E000}{text}\u{E007}"))
        .await
        .unwrap();
}

/// Clicks the editor's diagram where a component's node is drawn (a real mouse click on the
/// canvas).
async fn click_node(page: &Client, component: &str) {
    let at = page
        .execute(
            &format!(
                "const n = graphs.ed.nodes().filter(n => n.data('label').startsWith({component:?} + '\\n'))[0];
                 document.getElementById('ed-graph').scrollIntoView();
                 const box = document.getElementById('ed-graph').getBoundingClientRect();
                 const p = n.renderedPosition();
                 return [box.left + p.x, box.top + p.y];"
            ),
            vec![],
        )
        .await
        .unwrap();
    let (x, y) = (at[0].as_f64().unwrap(), at[1].as_f64().unwrap());
    let mouse = MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo {
            duration: None,
            x,
            y,
        })
        .then(PointerAction::Down {
            button: MOUSE_BUTTON_LEFT,
        })
        .then(PointerAction::Up {
            button: MOUSE_BUTTON_LEFT,
        });
    page.perform_actions(mouse).await.unwrap();
}

/// The description-file editor (issue 19, item 5): `examples/` copied to a directory the
/// studio edits; the arm opened, a gain given a wrong value (the loader's problem shown at
/// that key and on the diagram, saving refused) and then a new one, saved; the file on disk
/// differs from the example in exactly that line and `ndds run --check` accepts it. The state
/// machine gets a state and a transition; a file that is not TOML gets the loader's error; a
/// page without the token cannot open anything.
#[test]
fn the_editor_changes_one_gain_of_the_arm_and_ndds_run_accepts_the_file() {
    if !browser_available() {
        return;
    }
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let files = tempfile::tempdir().unwrap();
    let examples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples");
    copy_dir(&examples, files.path());
    std::fs::write(
        files.path().join("broken.toml"),
        "[[habitat]]\nname = \"h\"\nrate = [1, 2\n",
    )
    .unwrap();
    let root = files.path().display().to_string();
    let (_studio, url) = studio_with(&socket, &["--files", &root]);
    in_browser(&url, async |page: &Client| {
        until(
            page,
            "write access",
            "document.getElementById('access').textContent === 'may change the system'",
        )
        .await;
        click(page, "#tab-editor").await;
        until(
            page,
            "arm.toml among the files",
            "[...document.getElementById('ed-files').options].some(o => o.value === 'arm.toml')",
        )
        .await;
        page.execute(
            "document.getElementById('ed-files').value = 'arm.toml'; return true;",
            vec![],
        )
        .await
        .unwrap();
        click(page, "#ed-open").await;
        let verdict = until(page, "the arm verifying", "document.getElementById('ed-verdict').textContent.startsWith('✓') && document.getElementById('ed-verdict').textContent").await;
        assert!(
            verdict
                .as_str()
                .unwrap()
                .contains("verifies: 2 habitats, 5 components, 2 configurations, 1 state machine"),
            "{verdict}"
        );
        let nodes = until(
            page,
            "the components on the diagram",
            "graphs.ed.nodes().map(n => n.data('label')).filter(l => l.includes('\\n'))",
        )
        .await;
        for component in ["joint_pd\npd", "endpoint_lqg\nlqg", "arm\ntwo_link_arm"] {
            assert!(
                nodes.as_array().unwrap().iter().any(|n| n == component),
                "{component} in {nodes}"
            );
        }

        click(page, "#ed-components tr[data-component=\"joint_pd\"]").await;
        let kp = until(page, "joint_pd's kp in the inspector", "document.querySelector('#ed-inspector input[data-key=\"kp\"]') && document.querySelector('#ed-inspector input[data-key=\"kp\"]').value").await;
        assert_eq!(kp, "40.0");
        // Not TOML: refused, nothing changes.
        type_into(page, "#ed-inspector input[data-key=\"kp\"]", "fast").await;
        let refused = until(page, "the refusal", "document.getElementById('ed-reply').className.includes('bad') && document.getElementById('ed-reply').textContent").await;
        assert!(
            refused.as_str().unwrap().contains("is not a TOML value"),
            "{refused}"
        );
        // The wrong type: the loader's problem at that key, on the diagram, and no save.
        type_into(page, "#ed-inspector input[data-key=\"kp\"]", "\"fast\"").await;
        let problem = until(page, "the problem at kp", "document.querySelector('#ed-inspector tr[data-key=\"kp\"] .field-problem') && document.querySelector('#ed-inspector tr[data-key=\"kp\"] .field-problem').textContent").await;
        assert!(problem.as_str().unwrap().contains("`kp`"), "{problem}");
        until(
            page,
            "one problem in the verdict",
            "document.getElementById('ed-verdict').textContent === '✗ 1 problem'",
        )
        .await;
        let marked = until(
            page,
            "the component marked",
            "graphs.ed.nodes('.problem').map(n => n.data('label')).join(',')",
        )
        .await;
        assert_eq!(marked, "joint_pd\npd");
        click(page, "#ed-save").await;
        let refused = until(page, "saving refused", "!document.getElementById('ed-save-anyway').hidden && document.getElementById('ed-reply').textContent").await;
        assert!(
            refused.as_str().unwrap().contains("does not verify"),
            "{refused}"
        );
        // The new gain: verifies, the diff is that one line, saved.
        type_into(page, "#ed-inspector input[data-key=\"kp\"]", "55.0").await;
        until(
            page,
            "the system verifying again",
            "document.getElementById('ed-verdict').textContent.startsWith('✓')",
        )
        .await;
        let diff = until(
            page,
            "the diff",
            "document.getElementById('ed-diff').textContent",
        )
        .await;
        let changed: Vec<&str> = diff
            .as_str()
            .unwrap()
            .lines()
            .filter(|l| {
                (l.starts_with('+') || l.starts_with('-'))
                    && !l.starts_with("+++")
                    && !l.starts_with("---")
            })
            .collect();
        assert_eq!(changed, ["-kp = 40.0", "+kp = 55.0"], "{diff}");
        screenshot(page, "editor").await;
        click(page, "#ed-save").await;
        let saved = until(page, "saved", "document.getElementById('ed-reply').textContent.startsWith('saved') && document.getElementById('ed-reply').textContent").await;
        assert_eq!(saved, "saved arm/controller.toml");

        // A component from the library, connected on the diagram: the loader first says what it
        // lacks, at the new component; connected and given its gain, the system verifies.
        click(page, "#ed-palette-list li[data-type=\"gain\"]").await;
        type_into(page, "#ed-add-name", "scaled").await;
        page.execute("document.getElementById('ed-add-habitat').value = 'control'; document.getElementById('ed-add-file').value = 'arm/controller.toml'; return true;", vec![]).await.unwrap();
        click(page, "#ed-add").await;
        let lacks = until(page, "what the new component lacks", "document.querySelector('#ed-inspector tr[data-key=\"input\"] .field-problem') && document.querySelector('#ed-inspector tr[data-key=\"input\"] .field-problem').textContent").await;
        assert!(lacks.as_str().unwrap().contains("`input`"), "{lacks}");
        click(page, "#ed-connect").await;
        click_node(page, "tip_error").await;
        click_node(page, "scaled").await;
        until(
            page,
            "the connection form",
            "document.getElementById('ed-connect-apply')",
        )
        .await;
        let offered = page.execute("return [document.getElementById('ed-connect-mat').value, document.getElementById('ed-connect-key').value]", vec![]).await.unwrap();
        assert_eq!(offered, serde_json::json!(["tip_error", "input"]));
        click(page, "#ed-connect-apply").await;
        until(page, "the connection drawn", "graphs.ed.edges().some(e => e.source().data('label').startsWith('tip_error') && e.target().data('label').startsWith('scaled') && e.data('label') === 'tip_error')").await;
        type_into(
            page,
            "#ed-inspector input[data-key=\"output\"]",
            "scaled_error",
        )
        .await;
        until(
            page,
            "the output set",
            "document.getElementById('ed-diff').textContent.includes('+output = \"scaled_error\"')",
        )
        .await;
        type_into(page, "#ed-inspector input[data-key=\"k\"]", "0.5").await;
        let diff = until(page, "the new component's diff", "document.getElementById('ed-diff').textContent.includes('+k = 0.5') && document.getElementById('ed-diff').textContent").await;
        until(
            page,
            "the system verifying with the new component",
            "document.getElementById('ed-verdict').textContent.includes('6 components')",
        )
        .await;
        assert!(diff.as_str().unwrap().contains("+[[component]]\n+name = \"scaled\"\n+type = \"gain\"\n+habitat = \"control\"\n+input = \"tip_error\"\n+output = \"scaled_error\"\n+k = 0.5"), "{diff}");
        click(page, "#ed-revert").await;
        until(
            page,
            "no unsaved changes",
            "document.getElementById('ed-diff').textContent.trim() === 'no unsaved changes'",
        )
        .await;

        // The state machine: a state and a transition drawn and written, then forgotten.
        until(
            page,
            "the arm's machine",
            "document.getElementById('ed-machine').value === 'arm/supervisor.toml#0'",
        )
        .await;
        type_into(page, "#ed-state-name", "Parked").await;
        click(page, "#ed-state-add").await;
        until(
            page,
            "the new state drawn",
            "graphs.edFsm.getElementById('s:Parked').length === 1",
        )
        .await;
        for (field, text) in [
            ("#ed-t-from", "Held"),
            ("#ed-t-when", "Coarse"),
            ("#ed-t-next", "Parked"),
        ] {
            let f = page.find(Locator::Css(field)).await.unwrap();
            f.send_keys(text).await.unwrap();
        }
        click(page, "#ed-t-add").await;
        until(
            page,
            "the new transition drawn",
            "graphs.edFsm.edges().filter(e => e.target().id() === 's:Parked').length === 1",
        )
        .await;
        let diff = until(page, "the machine's diff", "document.getElementById('ed-diff').textContent.includes('+[[machine.transition]]') && document.getElementById('ed-diff').textContent").await;
        assert!(
            diff.as_str()
                .unwrap()
                .contains("+next = { 0 = \"Parked\" }"),
            "{diff}"
        );
        until(
            page,
            "the machine verifying",
            "document.getElementById('ed-verdict').textContent.startsWith('✓')",
        )
        .await;
        page.execute("document.getElementById('ed-fsm-panel').scrollLeft = 0; document.getElementById('ed-machine').scrollIntoView(); return true;", vec![]).await.unwrap();
        screenshot(page, "editor-fsm").await;
        click(page, "#ed-revert").await;
        until(
            page,
            "no unsaved changes",
            "document.getElementById('ed-diff').textContent.trim() === 'no unsaved changes'",
        )
        .await;

        // A file that is not TOML: the loader's error on the page, nothing breaks.
        page.execute(
            "document.getElementById('ed-files').value = 'broken.toml'; return true;",
            vec![],
        )
        .await
        .unwrap();
        click(page, "#ed-open").await;
        let problem = until(page, "the loader's error", "document.getElementById('ed-problems').textContent.includes('not valid TOML') && document.getElementById('ed-problems').textContent").await;
        assert!(
            problem.as_str().unwrap().starts_with("broken.toml:3:"),
            "{problem}"
        );
        let errors = page
            .execute("return window.studioErrors", vec![])
            .await
            .unwrap();
        assert_eq!(errors, serde_json::json!([]), "page errors");

        // Without the token the editor opens nothing.
        let base = url.split('#').next().unwrap().to_owned();
        page.goto(&base).await.unwrap();
        until(
            page,
            "view-only access",
            "document.getElementById('access').textContent.startsWith('view only')",
        )
        .await;
        click(page, "#tab-editor").await;
        let refused = until(
            page,
            "the editor refused",
            "document.getElementById('ed-reply').textContent",
        )
        .await;
        assert!(
            refused
                .as_str()
                .unwrap()
                .contains("open the URL with the token"),
            "{refused}"
        );
    });

    // On disk: the example with exactly that line changed, and `ndds run --check` accepts it.
    let original = std::fs::read_to_string(examples.join("arm/controller.toml")).unwrap();
    let saved = std::fs::read_to_string(files.path().join("arm/controller.toml")).unwrap();
    let changed: Vec<(&str, &str)> = original
        .lines()
        .zip(saved.lines())
        .filter(|(a, b)| a != b)
        .collect();
    assert_eq!(original.lines().count(), saved.lines().count());
    assert_eq!(changed, [("kp = 40.0", "kp = 55.0")]);
    for other in ["arm.toml", "arm/plant.toml", "arm/supervisor.toml"] {
        assert_eq!(
            std::fs::read_to_string(examples.join(other)).unwrap(),
            std::fs::read_to_string(files.path().join(other)).unwrap(),
            "{other} unchanged"
        );
    }
    let top = files.path().join("arm.toml").display().to_string();
    let check = domain.ndds("a", &["run", &top, "--check"], WAIT);
    assert!(
        check.code == Some(0),
        "ndds run --check refused the saved file: {}{}",
        check.stdout,
        check.stderr
    );
    assert!(
        check.stdout.contains("verified, nothing started"),
        "{}",
        check.stdout
    );
}

/// The p99 period jitter (µs) of the arm's two habitats (control, plant) over `window`, from
/// the system's own statistics: the median of the per-interval p99s each reports (one per
/// second), both measured at once.
fn jitter_p99(socket: &Path, window: Duration) -> (f64, f64) {
    let watcher = participant(socket, "jitter");
    let consumers: Vec<_> = ["control", "plant"]
        .iter()
        .map(|habitat| {
            watcher
                .consumer_with_type::<HabitatStats>(
                    &format!("cs/arm/{habitat}/stats"),
                    ndds_client::TypeDescription::named::<HabitatStats>(builtin::HABITAT_STATS),
                    ConsumerQos::default(),
                )
                .unwrap()
        })
        .collect();
    let end = Instant::now() + window;
    let mut p99s = vec![Vec::new(), Vec::new()];
    while Instant::now() < end {
        for (i, consumer) in consumers.iter().enumerate() {
            while let Ok(sample) = consumer.try_recv() {
                p99s[i].push(sample.value.period_jitter.p99_us);
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let median = |mut v: Vec<f64>| {
        assert!(v.len() >= 3, "statistics: {v:?}");
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let plant = p99s.pop().unwrap();
    let control = p99s.pop().unwrap();
    (median(control), median(plant))
}

/// A page's WebSocket without the page: plots `topic` (token, watch) and counts the points.
struct SocketViewer {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<usize>,
}

impl SocketViewer {
    /// Stops it; the points it received.
    fn finish(self) -> usize {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

fn plot_over_websocket(url: &str, topic: &str) -> SocketViewer {
    let (base, token) = url.split_once("#token=").expect("a URL with its token");
    let address = base
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();
    let token = token.to_owned();
    let topic = topic.to_owned();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stopping = std::sync::Arc::clone(&stop);
    let thread = std::thread::spawn(move || {
        let stream = std::net::TcpStream::connect(&address).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let (mut ws, _) =
            tungstenite::client::client(format!("ws://{address}/ws"), stream).unwrap();
        for message in [
            serde_json::json!({"type": "auth", "token": token}),
            serde_json::json!({"type": "watch", "topic": topic}),
        ] {
            ws.send(tungstenite::Message::text(message.to_string()))
                .unwrap();
        }
        let mut points = 0;
        while !stopping.load(std::sync::atomic::Ordering::Relaxed) {
            match ws.read() {
                Ok(tungstenite::Message::Text(text)) => {
                    let m: serde_json::Value = serde_json::from_str(text.as_str()).unwrap();
                    if m["type"] == "points" {
                        points += m["data"]["points"].as_array().map_or(0, |fields| {
                            fields
                                .iter()
                                .map(|f| f.as_array().map_or(0, Vec::len))
                                .sum()
                        });
                    }
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => panic!("the studio's WebSocket: {e}"),
            }
        }
        points
    });
    SocketViewer { stop, thread }
}

/// CPU seconds of every Chromium process (the browser showing the page; not its driver).
fn browser_cpu_seconds() -> f64 {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return 0.0;
    };
    entries
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            std::fs::read_to_string(format!("/proc/{pid}/comm"))
                .is_ok_and(|c| c.trim() == "chromium" || c.starts_with("chrome"))
        })
        // A process that ended meanwhile counts nothing.
        .filter_map(cpu_seconds_of)
        .sum()
}

fn cpu_seconds(pid: u32) -> f64 {
    cpu_seconds_of(pid).unwrap_or_else(|| panic!("no CPU times for process {pid}"))
}

/// User and system CPU seconds of `pid` (from `/proc/PID/stat`, in 1/100 s ticks).
fn cpu_seconds_of(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// The studio's cost (issue 19, "Performance"), not a pass/fail test: the arm example plus 50
/// topics at 100 Hz; its habitats' jitter alternately without a studio and with a studio and a
/// page plotting `arm/endpoint` (alone, watched, alone, watched: the machine's drift falls on
/// both), and the studio's CPU while watched. Twice: the example as it is (habitats at normal
/// priority) and with its habitats at `SCHED_FIFO` priority 80 (as a control system would run;
/// needs root), and that again with `ndds studio --no-rates`; and at normal priority with the
/// page elsewhere (a WebSocket client of this process asks for the same plot and takes its
/// points, so the studio works as for a browser but nothing draws on this machine, as when the
/// browser runs on the operator's computer). `ROUNDS=N` alternates N times
/// (default 2); `CONFIGS=1,3` runs only those. Run with a release build, nothing else running:
/// `cargo test --release -p interop-tests --test studio_browser -- --ignored --nocapture`.
#[test]
#[ignore = "a benchmark: run it alone (docs/benchmarks.md, \"The studio's cost\")"]
fn the_cost_of_watching_a_system_with_the_studio() {
    if !browser_available() {
        return;
    }
    let examples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let prioritised = tempfile::tempdir().unwrap();
    copy_dir(&examples, prioritised.path());
    for (file, rate) in [
        ("arm/controller.toml", "rate = 200.0\n"),
        ("arm/plant.toml", "rate = 500.0\n"),
    ] {
        let path = prioritised.path().join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains(rate));
        std::fs::write(
            &path,
            text.replacen(rate, &format!("{rate}priority = 80\n"), 1),
        )
        .unwrap();
    }
    println!(
        "| habitats | phase | control (200 Hz) p99, µs | plant (500 Hz) p99, µs | studio CPU |"
    );
    println!("|---|---|---|---|---|");
    let rounds: usize = std::env::var("ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(2);
    for (label, top, studio_args, in_browser) in [
        ("normal priority", examples.join("arm.toml"), &[][..], true),
        (
            "SCHED_FIFO 80",
            prioritised.path().join("arm.toml"),
            &[][..],
            true,
        ),
        (
            "SCHED_FIFO 80, studio --no-rates",
            prioritised.path().join("arm.toml"),
            &["--no-rates"][..],
            true,
        ),
        (
            "normal priority, page elsewhere",
            examples.join("arm.toml"),
            &[][..],
            false,
        ),
    ]
    .into_iter()
    .enumerate()
    .filter(|(i, _)| {
        std::env::var("CONFIGS").map_or(true, |c| {
            c.split(',').any(|n| n.trim() == (i + 1).to_string())
        })
    })
    .map(|(_, config)| config)
    {
        cost_of_watching(label, &top, studio_args, in_browser, rounds);
    }
}

fn cost_of_watching(
    label: &str,
    top: &Path,
    studio_args: &[&str],
    in_browser: bool,
    rounds: usize,
) {
    const WINDOW: Duration = Duration::from_secs(20);
    let domain = TestDomain::new();
    let _daemon = domain.daemon("a");
    let socket = domain.socket("a");
    let _system = ClientProcess::program(
        "ndds",
        &socket,
        &["run", &top.display().to_string(), "--plain"],
    );
    // 50 topics at 100 Hz, from this process.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let publisher = {
        let socket = socket.clone();
        let stop = std::sync::Arc::clone(&stop);
        std::thread::spawn(move || {
            let source = participant(&socket, "fifty");
            let producers: Vec<_> = (0..50)
                .map(|i| {
                    source
                        .producer::<(u64, f64)>(
                            &format!("load/{i}"),
                            ndds_client::ProducerQos::default(),
                        )
                        .unwrap()
                })
                .collect();
            let started = Instant::now();
            let mut tick = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                for (i, p) in producers.iter().enumerate() {
                    let _ = p.write(&(tick, (tick as f64 / 100.0 + i as f64).sin()));
                }
                tick += 1;
                let due = started + Duration::from_millis(10 * tick);
                if let Some(wait) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(wait);
                }
            }
        })
    };
    std::thread::sleep(Duration::from_secs(5));
    let driver = Driver::start();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let mut alone = Vec::new();
    let mut watched = Vec::new();
    for round in 0..rounds {
        let quiet = jitter_p99(&socket, WINDOW);
        println!(
            "| {label} | alone {} | {:.0} | {:.0} | |",
            round + 1,
            quiet.0,
            quiet.1
        );
        alone.push(quiet);

        let (studio, url) = studio_with(&socket, studio_args);
        let profile = tempfile::tempdir().unwrap();
        let rates = !studio_args.contains(&"--no-rates");
        if !in_browser {
            // The page elsewhere: what the studio does for it is done (the plot's points
            // decimated and sent), nothing is drawn on this machine.
            let viewer = plot_over_websocket(&url, "arm/endpoint");
            std::thread::sleep(Duration::from_secs(5));
            let cpu_before = cpu_seconds(studio.pid());
            let measuring = Instant::now();
            let seen = jitter_p99(&socket, WINDOW);
            let cpu = (cpu_seconds(studio.pid()) - cpu_before) / measuring.elapsed().as_secs_f64();
            let points = viewer.finish();
            assert!(points > 1000, "the WebSocket client got {points} points");
            drop(studio);
            println!(
                "| {label} | watched {} | {:.0} | {:.0} | {:.1} % ({points} points to the client) |",
                round + 1,
                seen.0,
                seen.1,
                cpu * 100.0
            );
            watched.push(seen);
            continue;
        }
        let page = runtime.block_on(async {
            let page = browser(&driver, profile.path()).await;
            page.goto(&url).await.unwrap();
            if rates {
                until(&page, "the load topics", "state.network && state.network.topics.filter(t => t.name.startsWith('load/') && t.rate_hz > 50).length === 50").await;
            } else {
                until(&page, "the load topics", "state.network && state.network.topics.filter(t => t.name.startsWith('load/')).length === 50").await;
            }
            click(&page, "#tab-plots").await;
            page.execute("const s = document.getElementById('plot-topic'); s.value = 'arm/endpoint'; s.dispatchEvent(new Event('input')); return true;", vec![]).await.unwrap();
            until(&page, "arm/endpoint's fields", "[...document.getElementById('plot-field').options].some(o => o.value === 'x (m)')").await;
            page.execute("document.getElementById('plot-field').value = 'x (m)'; return true;", vec![]).await.unwrap();
            click(&page, "#plot-add").await;
            until(&page, "points", "Number(document.querySelector('.plot').dataset.points) > 100").await;
            // The browser's start-up work is over before measuring.
            tokio::time::sleep(Duration::from_secs(5)).await;
            page
        });
        let cpu_before = cpu_seconds(studio.pid());
        let browser_before = browser_cpu_seconds();
        let measuring = Instant::now();
        let seen = jitter_p99(&socket, WINDOW);
        let cpu = (cpu_seconds(studio.pid()) - cpu_before) / measuring.elapsed().as_secs_f64();
        let browser = (browser_cpu_seconds() - browser_before) / measuring.elapsed().as_secs_f64();
        runtime.block_on(async { page.close().await.unwrap() });
        drop(studio);
        println!(
            "| {label} | watched {} | {:.0} | {:.0} | {:.1} % (browser {:.0} %) |",
            round + 1,
            seen.0,
            seen.1,
            cpu * 100.0,
            browser * 100.0
        );
        watched.push(seen);
        // The browser's processes end before the next quiet phase.
        std::thread::sleep(Duration::from_secs(2));
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    publisher.join().unwrap();
    // The median over the rounds: a disturbance of the machine in one phase moves it little.
    let median = |v: &[(f64, f64)], f: fn(&(f64, f64)) -> f64| {
        let mut x: Vec<f64> = v.iter().map(f).collect();
        x.sort_by(f64::total_cmp);
        if x.len() % 2 == 1 {
            x[x.len() / 2]
        } else {
            (x[x.len() / 2 - 1] + x[x.len() / 2]) / 2.0
        }
    };
    println!(
        "| {label} | median watched / median alone | {:.0} / {:.0} = {:.2} | {:.0} / {:.0} = {:.2} | |",
        median(&watched, |x| x.0),
        median(&alone, |x| x.0),
        median(&watched, |x| x.0) / median(&alone, |x| x.0),
        median(&watched, |x| x.1),
        median(&alone, |x| x.1),
        median(&watched, |x| x.1) / median(&alone, |x| x.1)
    );
}
