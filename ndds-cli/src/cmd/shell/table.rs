//! What the shell prints, as text: a CSMat's labelled table (`show`, `watch`), the habitats'
//! statistics (`stats`) and the listings (`ls`). Pure: values in, text out.

use ndds_runtime::describe::{MatDescription, ModuleDescription};
use ndds_runtime::{CsMat, HabitatStats, Pace};

use super::commands::Listing;
use super::view::{PortRole, SystemView, kind_word};

/// A CSMat's values as the system answered them (`ReadMats`).
#[derive(Clone, Debug, PartialEq)]
pub struct MatValues {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Row-major.
    pub data: Vec<f64>,
}

/// `NAME  (R x C)` and the table, rows and columns labelled with the fields and units of the
/// description (when they fit the shape), as `ndds echo` prints CSMats.
pub fn mat_table(name: &str, description: Option<&MatDescription>, values: &MatValues) -> String {
    let (rows, cols) = (values.rows, values.cols);
    let Ok(mut mat) = CsMat::from_row_slice(name, rows, cols, &values.data) else {
        return format!(
            "{name}  ({rows} x {cols}), but {} values came\n",
            values.data.len()
        );
    };
    if let Some(d) = description.filter(|d| d.row_fields.len() == rows) {
        let fields = d.row_fields.iter().map(|(n, u)| (n.as_str(), u.as_str()));
        mat = mat.clone().with_row_fields(fields).unwrap_or(mat);
    }
    if let Some(d) = description.filter(|d| d.col_fields.len() == cols) {
        let fields = d.col_fields.iter().map(|(n, u)| (n.as_str(), u.as_str()));
        mat = mat.clone().with_col_fields(fields).unwrap_or(mat);
    }
    format!("{name}  ({rows} x {cols})\n{mat}\n")
}

/// A module: where it runs, what it is, and the CSMats it reads and writes.
pub fn module_text(module: &ModuleDescription) -> String {
    let mut rows = vec![
        vec!["habitat".to_owned(), module.habitat.clone()],
        vec![
            "state".to_owned(),
            if module.active { "active" } else { "inactive" }.to_owned(),
        ],
    ];
    if !module.component.is_empty() {
        rows.push(vec!["component".to_owned(), module.component.clone()]);
    }
    if !module.groups.is_empty() {
        rows.push(vec!["groups".to_owned(), module.groups.join(", ")]);
    }
    for port in module.inputs.iter().chain(&module.outputs) {
        let verb = if port.usage == "output" {
            "writes"
        } else {
            "reads"
        };
        let usage = if port.usage == "output" {
            String::new()
        } else {
            format!(" ({})", port.usage)
        };
        let role = if port.role == port.mat {
            String::new()
        } else {
            format!(" as {}", port.role)
        };
        rows.push(vec![verb.to_owned(), format!("{}{role}{usage}", port.mat)]);
    }
    format!("module {}\n{}", module.name, aligned(&rows, &[], "  "))
}

/// One line per habitat: state, nominal and achieved rate (over the span `paces` were
/// measured on; `-` where there is none), samples, overruns, module errors and the 99th
/// percentiles of execution time and period jitter; then the active configuration.
pub fn stats_table(stats: &[HabitatStats], paces: &[Option<Pace>]) -> String {
    let mut rows = vec![
        [
            "habitat",
            "state",
            "rate Hz",
            "achieved Hz",
            "samples",
            "overruns",
            "module errors",
            "exec p99 us",
            "jitter p99 us",
        ]
        .map(str::to_owned)
        .to_vec(),
    ];
    for (i, s) in stats.iter().enumerate() {
        let achieved = paces.get(i).copied().flatten();
        rows.push(vec![
            s.habitat.clone(),
            if s.running { "running" } else { "stopped" }.to_owned(),
            number(s.rate_hz),
            achieved.map_or_else(|| "-".to_owned(), |p| format!("{:.1}", p.achieved_hz)),
            s.samples.to_string(),
            s.overruns.to_string(),
            s.module_errors.to_string(),
            format!("{:.1}", s.exec.p99_us),
            format!("{:.1}", s.period_jitter.p99_us),
        ]);
    }
    let mut text = aligned(&rows, &[2, 3, 4, 5, 6, 7, 8], "");
    let configuration = stats
        .iter()
        .map(|s| s.configuration.as_str())
        .find(|c| !c.is_empty());
    if let Some(c) = configuration {
        text.push_str(&format!("configuration {c}\n"));
    }
    text
}

/// `ls`: every listing, or one.
pub fn listing(view: &SystemView, which: Option<Listing>) -> String {
    let wanted: Vec<Listing> = match which {
        Some(one) => vec![one],
        None => Listing::ALL.to_vec(),
    };
    let mut text = String::new();
    for what in wanted {
        let rows = listing_rows(view, what);
        text.push_str(&format!("{} ({})\n", what.word(), rows.len()));
        text.push_str(&aligned(&rows, &[], "  "));
    }
    text
}

fn listing_rows(view: &SystemView, what: Listing) -> Vec<Vec<String>> {
    let d = &view.description;
    match what {
        Listing::Habitats => (d.habitats.iter())
            .map(|h| {
                vec![
                    h.name.clone(),
                    format!("{} Hz", number(h.rate_hz)),
                    if h.running { "running" } else { "stopped" }.to_owned(),
                    h.clock.clone(),
                    format!("order: {}", h.order.join(", ")),
                ]
            })
            .collect(),
        Listing::Modules => (d.modules.iter())
            .map(|m| {
                vec![
                    m.name.clone(),
                    format!("in {}", m.habitat),
                    m.component.clone(),
                    if m.active { "active" } else { "inactive" }.to_owned(),
                    m.groups.join(", "),
                ]
            })
            .collect(),
        Listing::Mats => (d.mats.iter())
            .map(|m| {
                let writer = view.writer_of(&m.name);
                vec![
                    m.name.clone(),
                    format!("{}x{}", m.rows, m.cols),
                    writer.map_or_else(|| "settable".to_owned(), |w| format!("written by {w}")),
                    fields("rows", &m.row_fields),
                    fields("cols", &m.col_fields),
                ]
            })
            .collect(),
        Listing::Configurations => (d.configurations.iter())
            .map(|c| {
                let groups: Vec<String> = (c.groups.iter())
                    .map(|(category, group)| format!("{category}/{group}"))
                    .collect();
                let active = d.configuration.as_deref() == Some(c.name.as_str());
                vec![
                    c.name.clone(),
                    if active { "(active)" } else { "" }.to_owned(),
                    groups.join(", "),
                ]
            })
            .collect(),
        Listing::Machines => (d.machines.iter())
            .map(|m| {
                let stimuli: Vec<String> = (m.stimuli.iter())
                    .map(|(name, kind)| format!("{name} ({})", kind_word(*kind)))
                    .collect();
                vec![m.name.clone(), format!("stimuli: {}", stimuli.join(", "))]
            })
            .collect(),
        Listing::Ports => (view.ports.iter())
            .map(|p| {
                let role = match view.port_role(p) {
                    PortRole::Command => {
                        "the system's command port (what this shell uses)".to_owned()
                    }
                    PortRole::Machine => {
                        format!("state machine `{}`: send {} STIMULUS...", &p[4..], &p[4..])
                    }
                    PortRole::Declared => format!("takes text: query {p} TEXT"),
                };
                vec![p.clone(), role]
            })
            .collect(),
    }
}

/// `rows: q1 [rad], q2 [rad]`, or nothing without fields.
fn fields(axis: &str, fields: &[(String, String)]) -> String {
    if fields.is_empty() {
        return String::new();
    }
    let each: Vec<String> = (fields.iter())
        .map(|(name, unit)| match unit.as_str() {
            "" => name.clone(),
            unit => format!("{name} [{unit}]"),
        })
        .collect();
    format!("{axis}: {}", each.join(", "))
}

/// `200`, `12.5`, `0.333`: at most three decimals, none when whole.
pub fn number(value: f64) -> String {
    let text = format!("{value:.3}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" { "0" } else { text }.to_owned()
}

/// The rows as columns two spaces apart, each line after `indent`; the columns in `right`
/// are right-aligned (numbers), the others left-aligned. Trailing blanks are cut.
fn aligned(rows: &[Vec<String>], right: &[usize], indent: &str) -> String {
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0);
    let widths: Vec<usize> = (0..columns)
        .map(|c| {
            let cells = rows.iter().filter_map(|r| r.get(c));
            cells.map(|cell| cell.chars().count()).max().unwrap_or(0)
        })
        .collect();
    let mut text = String::new();
    for row in rows {
        let mut line = String::from(indent);
        for (c, cell) in row.iter().enumerate() {
            if c > 0 {
                line.push_str("  ");
            }
            let w = widths[c];
            if right.contains(&c) {
                line.push_str(&format!("{cell:>w$}"));
            } else {
                line.push_str(&format!("{cell:<w$}"));
            }
        }
        text.push_str(line.trim_end());
        text.push('\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::super::view::tests::arm;
    use super::*;

    #[test]
    fn a_mat_is_labelled_with_its_fields_and_units() {
        let view = arm();
        let values = MatValues {
            rows: 2,
            cols: 1,
            data: vec![0.5, 1.25],
        };
        let table = mat_table("joint_goal", view.mat("joint_goal").ok(), &values);
        assert_eq!(
            table,
            "joint_goal  (2 x 1)\n             0\nq1 [rad]   0.5\nq2 [rad]  1.25\n"
        );
        // Without fields (or fields that do not fit the shape), rows and columns are numbered.
        let three = MatValues {
            rows: 3,
            cols: 1,
            data: vec![1.0, 2.0, 3.0],
        };
        let table = mat_table("joint_goal", view.mat("joint_goal").ok(), &three);
        assert_eq!(table, "joint_goal  (3 x 1)\n   0\n0  1\n1  2\n2  3\n");
        let short = MatValues {
            rows: 2,
            cols: 2,
            data: vec![1.0],
        };
        assert!(mat_table("m", None, &short).contains("but 1 values came"));
    }

    #[test]
    fn stats_show_nominal_and_achieved_rates_side_by_side() {
        let stats = |habitat: &str, rate_hz: f64, samples: u64| HabitatStats {
            runtime: "arm".into(),
            habitat: habitat.into(),
            running: samples > 0,
            rate_hz,
            samples,
            overruns: 2,
            module_errors: 0,
            configuration: "JointPD".into(),
            ..HabitatStats::default()
        };
        let earlier = [stats("control", 100.0, 1000), stats("plant", 500.0, 0)];
        let later = [stats("control", 100.0, 1050), stats("plant", 500.0, 0)];
        let paces: Vec<Option<Pace>> = (earlier.iter().zip(&later))
            .map(|(e, l)| Pace::between(e, l, Duration::from_millis(500)))
            .collect();
        let table = stats_table(&later, &paces);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(
            lines[0],
            "habitat  state    rate Hz  achieved Hz  samples  overruns  module errors  \
             exec p99 us  jitter p99 us"
        );
        assert_eq!(
            lines[1],
            "control  running      100        100.0     1050         2              0          \
             0.0            0.0"
        );
        assert!(lines[2].starts_with("plant    stopped      500            -        0"));
        assert_eq!(lines[3], "configuration JointPD");
    }

    #[test]
    fn ls_lists_each_kind_under_a_heading() {
        let view = arm();
        let all = listing(&view, None);
        for heading in [
            "habitats (2)",
            "modules (3)",
            "mats (5)",
            "configurations (2)",
            "machines (1)",
            "ports (3)",
        ] {
            assert!(all.contains(&format!("{heading}\n")), "{heading} in\n{all}");
        }
        let mats = listing(&view, Some(Listing::Mats));
        assert!(
            mats.contains(
                "  joint_goal     2x1  settable                rows: q1 [rad], q2 [rad]\n"
            ),
            "{mats}"
        );
        assert!(
            mats.contains("  joints         2x1  written by arm"),
            "{mats}"
        );
        let configurations = listing(&view, Some(Listing::Configurations));
        assert_eq!(
            configurations,
            "configurations (2)\n  JointPD   (active)  controllers/PD\n  endptLQG            \
             controllers/LQG\n"
        );
        let machines = listing(&view, Some(Listing::Machines));
        assert!(machines.contains("arm  stimuli: Coarse (transient), Object (condition)"));
        let ports = listing(&view, Some(Listing::Ports));
        assert!(
            ports.contains("arm-configure  takes text: query arm-configure TEXT"),
            "{ports}"
        );
        assert!(ports.contains("fsm.arm        state machine `arm`: send arm STIMULUS..."));
        let habitats = listing(&view, Some(Listing::Habitats));
        assert!(
            habitats.contains("  control  200 Hz  running  timer  order: joint_pd, joint_error")
        );
    }

    #[test]
    fn a_module_says_what_it_reads_and_writes() {
        let view = arm();
        let text = module_text(view.module("joint_pd").unwrap());
        assert_eq!(
            text,
            "module joint_pd\n  habitat  control\n  state    active\n  reads    joints as input \
             (input)\n  writes   command as output\n"
        );
    }

    #[test]
    fn numbers_drop_needless_decimals() {
        assert_eq!(number(200.0), "200");
        assert_eq!(number(12.5), "12.5");
        assert_eq!(number(1.0 / 3.0), "0.333");
        assert_eq!(number(-0.0001), "0");
    }
}
