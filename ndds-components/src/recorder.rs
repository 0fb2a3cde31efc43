//! Recording: the `recorder` keeps the last `capacity` samples of its inputs in memory, for
//! code to read through a [`RecorderHandle`] and, if given a `file`, writes them when sampling
//! ends: as CSV, or as an MCAP recording when the file's name ends in `.mcap` (one channel per
//! input, named after it, each sample the input CSMat with its field names and units, logged
//! at the wall-clock time sampling began plus the sample's nominal time: `ndds play` and
//! `ndds bag` take it like a recording by `ndds record`).
//!
//! | type       | module       | reads    | writes |
//! |------------|--------------|----------|--------|
//! | `recorder` | [`Recorder`] | `inputs` | —      |
//!
//! Each sample is one row: the sample's nominal time (s since sampling began), then every
//! element of every input, input by input, each row by row. The columns are named `time` and
//! `<mat>[<row>,<col>]`, or `<mat>.<field>` for a column whose rows have field names; the CSV
//! file quotes names holding a comma (`"y[0,0]"`), as CSV requires.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, TryLockError};

use ndds_runtime::csmat::CsMat;
use ndds_runtime::{Binder, Component, Mat, ModuleError, Params, Registry, RoutineResult};
use ndds_runtime::{SampleContext, SampleModule};

use crate::params::failed;

/// Most values (samples × columns) one recorder holds: 1 GiB of `f64`.
const MAX_VALUES: usize = 1 << 27;

/// The recording: `capacity` rows of `width` values in one buffer, filled in place.
#[derive(Default)]
struct Ring {
    columns: Vec<String>,
    width: usize,
    capacity: usize,
    data: Vec<f64>,
    /// The row the next sample goes to.
    next: usize,
    /// Rows held (at most `capacity`).
    len: usize,
    /// Samples recorded since sampling began, overwritten ones included.
    recorded: u64,
}

impl Ring {
    /// The rows held, oldest first.
    fn rows(&self) -> Vec<Vec<f64>> {
        let first = if self.len < self.capacity {
            0
        } else {
            self.next
        };
        (0..self.len)
            .map(|k| {
                let row = (first + k) % self.capacity;
                self.data[row * self.width..(row + 1) * self.width].to_vec()
            })
            .collect()
    }
}

struct Shared {
    ring: Mutex<Ring>,
    /// Each input as it was when sampling began (name, shape, fields): what MCAP samples are
    /// rebuilt from.
    templates: Mutex<Vec<CsMat>>,
    /// Wall-clock time sampling began.
    began: Mutex<std::time::SystemTime>,
    /// Samples not recorded because a reader held the recording.
    dropped: AtomicU64,
}

/// Read access to a [`Recorder`]'s recording, from any thread (cheap to clone). Each call
/// locks the recording briefly; a sample that finds it locked is not recorded but counted in
/// [`dropped`](Self::dropped).
#[derive(Clone)]
pub struct RecorderHandle(Arc<Shared>);

impl RecorderHandle {
    fn ring(&self) -> MutexGuard<'_, Ring> {
        self.0.ring.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The column names: `time`, then one per input element (empty until sampling begins).
    pub fn columns(&self) -> Vec<String> {
        self.ring().columns.clone()
    }

    /// Rows held now (at most [`capacity`](Self::capacity)).
    pub fn len(&self) -> usize {
        self.ring().len
    }

    /// Whether no row is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Rows it holds at most; older rows are overwritten.
    pub fn capacity(&self) -> usize {
        self.ring().capacity
    }

    /// Samples recorded since sampling began, including those overwritten since.
    pub fn recorded(&self) -> u64 {
        self.ring().recorded
    }

    /// Samples not recorded because a reader held the recording at the time.
    pub fn dropped(&self) -> u64 {
        self.0.dropped.load(Ordering::Relaxed)
    }

    /// The rows held, oldest first: `[time, values…]` in [`columns`](Self::columns) order.
    pub fn rows(&self) -> Vec<Vec<f64>> {
        self.ring().rows()
    }

    /// The column `name` (see [`columns`](Self::columns)), oldest first.
    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let ring = self.ring();
        let index = ring.columns.iter().position(|c| c == name)?;
        Some(ring.rows().iter().map(|row| row[index]).collect())
    }

    /// Writes the rows held as an MCAP recording (see the module docs).
    pub fn write_mcap(&self, path: &Path) -> Result<(), ndds_bag::BagError> {
        let rows = self.rows();
        let templates = self
            .0
            .templates
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        let began = *self.0.began.lock().unwrap_or_else(PoisonError::into_inner);
        let began = ndds_bag::format::nanos(began);
        let mut writer = ndds_bag::BagWriter::create(path, ndds_bag::WriteOptions::default())?;
        let desc = ndds_client::TypeDescription::of::<CsMat>();
        let channels: Vec<_> = templates
            .iter()
            .map(|t| writer.add_channel(t.name(), &desc, ndds_bag::format::ChannelMeta::default()))
            .collect();
        let mut mats = templates;
        let mut payload = Vec::new();
        for (seq, row) in rows.iter().enumerate() {
            let log_time = began.saturating_add((row[0] * 1e9) as u64);
            let mut at = 1;
            for (mat, channel) in mats.iter_mut().zip(&channels) {
                let (rows, cols) = mat.shape();
                for r in 0..rows {
                    for c in 0..cols {
                        mat.matrix_mut()[(r, c)] = row[at];
                        at += 1;
                    }
                }
                payload.clear();
                payload = postcard::to_extend(mat, payload).map_err(|err| {
                    ndds_bag::BagError::Usage(format!("encoding {}: {err}", mat.name()))
                })?;
                writer.write(ndds_bag::write::Record {
                    channel: *channel,
                    seq: seq as u64 + 1,
                    log_time,
                    publish_time: log_time,
                    data: &payload,
                })?;
            }
        }
        writer.finish()
    }

    /// Writes the rows held as CSV: a header line of column names, then one line per row.
    pub fn write_csv(&self, path: &Path) -> std::io::Result<()> {
        let (columns, rows) = {
            let ring = self.ring();
            (ring.columns.clone(), ring.rows())
        };
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        let header: Vec<String> = columns.iter().map(|c| csv_field(c)).collect();
        writeln!(out, "{}", header.join(","))?;
        let mut line = String::new();
        for row in rows {
            line.clear();
            for (i, x) in row.iter().enumerate() {
                let sep = if i == 0 { "" } else { "," };
                let _ = write!(line, "{sep}{x}");
            }
            writeln!(out, "{line}")?;
        }
        out.flush()
    }
}

/// `text` as one CSV field (quoted when it holds a comma, quote or line break).
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

/// The column names of `mat`'s elements, row by row.
fn column_names(name: &str, mat: &CsMat, out: &mut Vec<String>) {
    let fields = mat.row_fields();
    let named = mat.cols() == 1 && !fields.is_empty() && fields.iter().all(|f| !f.name.is_empty());
    if named {
        out.extend(fields.iter().map(|f| format!("{name}.{}", f.name)));
        return;
    }
    for r in 0..mat.rows() {
        for c in 0..mat.cols() {
            out.push(format!("{name}[{r},{c}]"));
        }
    }
}

/// Records its inputs each sample (time, then every element) into a ring of the last
/// `capacity` samples, read from code through a RecorderHandle; with `file`, writes them as
/// CSV or MCAP (`.mcap`) when sampling ends.
///
/// Each row is `[time, every element of every input]`. The ring is allocated when sampling
/// begins (`startup`, which also starts a new recording), so `execute` only copies values.
/// Read it through [`handle`](Self::handle); with a `file`, `shutdown` writes it there as CSV
/// (see [`RecorderHandle::write_csv`]).
#[derive(Component)]
#[component(name = "recorder", finish = Self::name_after_module)]
pub struct Recorder {
    /// the CSMats to record (at least one)
    #[inputs]
    inputs: Vec<Mat>,
    /// samples kept (the newest)
    #[param(default = 10000, min = 1, max = 100000000)]
    _capacity: usize,
    /// file written when sampling ends: CSV (header: `time, <mat>[<row>,<col>], …`), or an MCAP
    /// recording when it ends in .mcap (one channel per input)
    #[param]
    file: Option<PathBuf>,
    /// Each input's shape when sampling began.
    shapes: Vec<(usize, usize)>,
    /// The module's name, for messages.
    name: String,
    #[state(init = Arc::new(Shared::new(_capacity)))]
    shared: Arc<Shared>,
}

impl Shared {
    /// An empty recording of `capacity` samples (allocated when sampling begins).
    fn new(capacity: usize) -> Self {
        let ring = Ring {
            capacity,
            ..Ring::default()
        };
        Self {
            ring: Mutex::new(ring),
            templates: Mutex::new(Vec::new()),
            began: Mutex::new(std::time::SystemTime::UNIX_EPOCH),
            dropped: AtomicU64::new(0),
        }
    }
}

impl Recorder {
    /// Records `inputs` (at least one), keeping `capacity` (≥ 1) samples.
    pub fn new(
        b: &mut Binder<'_>,
        inputs: &[&str],
        capacity: usize,
        file: Option<&Path>,
    ) -> Result<Self, ModuleError> {
        if capacity == 0 {
            return Err(ModuleError::param("capacity", "expected at least 1 sample"));
        }
        let names: Vec<String> = inputs.iter().map(|i| (*i).to_owned()).collect();
        let params = Params::new().with("inputs", names);
        let mut recorder = Self::build(b, &params)?;
        // Set here, not as parameters: a path need not be UTF-8, and a Rust caller's capacity
        // has no upper limit but memory's (checked when sampling begins).
        recorder.shared = Arc::new(Shared::new(capacity));
        recorder.file = file.map(Path::to_path_buf);
        Ok(recorder)
    }

    fn name_after_module(&mut self, b: &mut Binder<'_>) -> Result<(), ModuleError> {
        self.name = b.module_name().to_owned();
        Ok(())
    }

    /// A handle to read the recording with.
    pub fn handle(&self) -> RecorderHandle {
        RecorderHandle(Arc::clone(&self.shared))
    }

    /// A failure worded "recorder `NAME`: TEXT".
    fn error(&self, text: impl std::fmt::Display) -> ModuleError {
        failed(format!("recorder `{}`: {text}", self.name))
    }

    /// Allocates the ring for the inputs' shapes now and empties it.
    fn prepare(&mut self) -> RoutineResult {
        self.shapes.clear();
        let mut columns = vec!["time".to_owned()];
        let mut templates = Vec::new();
        for input in &self.inputs {
            let value = input.read();
            self.shapes.push(value.shape());
            column_names(input.name(), &value, &mut columns);
            let mut template = value.clone();
            template.set_name(input.name());
            templates.push(template);
        }
        *self
            .shared
            .templates
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = templates;
        *self
            .shared
            .began
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = std::time::SystemTime::now();
        let mut ring = self
            .shared
            .ring
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let (width, capacity) = (columns.len(), ring.capacity);
        let Some(size) = capacity.checked_mul(width) else {
            return Err(self.error("capacity × columns overflows"));
        };
        if size > MAX_VALUES {
            return Err(self.error(format_args!(
                "{capacity} samples of {width} values exceed the recorder's limit of \
                 {MAX_VALUES} values (1 GiB); lower `capacity`"
            )));
        }
        if ring.data.len() != size {
            ring.data = Vec::new();
            ring.data.try_reserve_exact(size).map_err(|err| {
                self.error(format_args!(
                    "cannot allocate {capacity} samples of {width} values: {err}"
                ))
            })?;
            ring.data.resize(size, 0.0);
        }
        ring.columns = columns;
        ring.width = width;
        ring.next = 0;
        ring.len = 0;
        ring.recorded = 0;
        self.shared.dropped.store(0, Ordering::Relaxed);
        Ok(())
    }

    /// Copies this sample into `ring`'s next row.
    fn record(&self, ring: &mut Ring, time: f64) -> RoutineResult {
        let (width, next) = (ring.width, ring.next);
        if ring.data.len() < (next + 1) * width || width == 0 {
            return Err(self.error("not prepared: sampling has not begun"));
        }
        let row = &mut ring.data[next * width..(next + 1) * width];
        row[0] = time;
        let mut at = 1;
        for (input, &shape) in self.inputs.iter().zip(&self.shapes) {
            let value = input.read();
            if value.shape() != shape {
                return Err(self.error(format_args!(
                    "input `{}` is {}x{} but was {}x{} when sampling began",
                    input.name(),
                    value.rows(),
                    value.cols(),
                    shape.0,
                    shape.1
                )));
            }
            // Row by row, as the column names go.
            for r in 0..shape.0 {
                for c in 0..shape.1 {
                    row[at] = value.matrix()[(r, c)];
                    at += 1;
                }
            }
        }
        ring.next = (next + 1) % ring.capacity;
        ring.len = (ring.len + 1).min(ring.capacity);
        ring.recorded += 1;
        Ok(())
    }
}

impl SampleModule for Recorder {
    fn execute(&mut self, ctx: &SampleContext) -> RoutineResult {
        let mut ring = match self.shared.ring.try_lock() {
            Ok(ring) => ring,
            Err(TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(TryLockError::WouldBlock) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                return Ok(());
            }
        };
        self.record(&mut ring, ctx.time.as_secs_f64())
    }

    fn startup(&mut self, _: &SampleContext) -> RoutineResult {
        self.prepare()
    }

    fn shutdown(&mut self, _: &SampleContext) -> RoutineResult {
        let Some(path) = &self.file else {
            return Ok(());
        };
        if path.extension().is_some_and(|e| e == "mcap") {
            // A recording of an earlier session is replaced, as a CSV file is.
            let _ = std::fs::remove_file(path);
            return self
                .handle()
                .write_mcap(path)
                .map_err(|err| self.error(format_args!("writing `{}`: {err}", path.display())));
        }
        self.handle()
            .write_csv(path)
            .map_err(|err| self.error(format_args!("writing `{}`: {err}", path.display())))
    }
}

/// Registers `recorder`.
pub(crate) fn register(registry: &mut Registry) {
    registry.add::<Recorder>();
}

#[cfg(test)]
mod tests {
    use super::{Recorder, RecorderHandle};
    use crate::testing::{Outcome, TestResult, assert_refuses, refusal};
    use ndds_runtime::{Clock, CsMat, HabitatOptions, Params, Runtime};

    /// A 100 Hz manual habitat `h` with a ramp `y = t` and a constant `pair = [1, 2]` with
    /// named rows, recorded by `rec` keeping `capacity` samples.
    fn recording(capacity: usize) -> Outcome<(Runtime, RecorderHandle)> {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        let ramp = Params::new().with("output", "y").with("slope", 1.0);
        rt.install_component("h", "ramp", "ramp", &ramp)?;
        let pair = CsMat::from_row_slice("pair", 2, 1, &[1.0, 2.0])?
            .with_row_fields([("left", "m"), ("right", "m")])?;
        rt.create_mat(pair)?;
        let mut handle = None;
        rt.install("h", "rec", |b| {
            let recorder = Recorder::new(b, &["y", "pair"], capacity, None)?;
            handle = Some(recorder.handle());
            Ok(recorder)
        })?;
        let handle = handle.ok_or("no handle")?;
        rt.habitat("h").start()?;
        Ok((rt, handle))
    }

    fn steps(rt: &Runtime, n: usize) -> TestResult {
        for _ in 0..n {
            rt.habitat("h").step()?;
        }
        Ok(())
    }

    #[test]
    fn records_each_sample_exactly() -> TestResult {
        let (rt, handle) = recording(100)?;
        assert_eq!(
            handle.columns(),
            ["time", "y[0,0]", "pair.left", "pair.right"]
        );
        assert!(handle.is_empty());
        steps(&rt, 50)?;
        let rows = handle.rows();
        assert_eq!(rows.len(), 50);
        for (k, row) in rows.iter().enumerate() {
            let t = k as f64 / 100.0;
            assert_eq!(row, &[t, t, 1.0, 2.0], "sample {k}");
        }
        assert_eq!(handle.column("pair.right"), Some(vec![2.0; 50]));
        assert_eq!((handle.recorded(), handle.dropped()), (50, 0));
        Ok(())
    }

    #[test]
    fn the_ring_keeps_the_newest_samples() -> TestResult {
        let (rt, handle) = recording(10)?;
        steps(&rt, 25)?;
        assert_eq!(
            (handle.len(), handle.capacity(), handle.recorded()),
            (10, 10, 25)
        );
        let times = handle.column("time").ok_or("no time column")?;
        let expected: Vec<f64> = (15..25).map(|k| k as f64 / 100.0).collect();
        assert_eq!(times, expected);
        // A new sampling session starts a new recording.
        rt.habitat("h").stop();
        rt.habitat("h").start()?;
        steps(&rt, 3)?;
        assert_eq!(handle.column("time"), Some(vec![0.0, 0.01, 0.02]));
        Ok(())
    }

    #[test]
    fn a_sample_finding_the_recording_locked_is_counted_as_dropped() -> TestResult {
        let (rt, handle) = recording(10)?;
        steps(&rt, 2)?;
        {
            let _reader = handle.0.ring.lock();
            steps(&rt, 1)?;
        }
        steps(&rt, 1)?;
        assert_eq!((handle.recorded(), handle.dropped()), (3, 1));
        assert_eq!(handle.column("time"), Some(vec![0.0, 0.01, 0.03]));
        Ok(())
    }

    #[test]
    fn writes_an_mcap_recording_when_sampling_ends() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("run.mcap");
        let (rt, handle) = recording(100)?;
        // The recording made by `recording` has no file: write it as the module would.
        steps(&rt, 20)?;
        handle.write_mcap(&path)?;
        let mut reader = ndds_bag::BagReader::open(&path)?;
        let mut by_topic: std::collections::BTreeMap<String, Vec<(u64, CsMat)>> =
            Default::default();
        while let Some(message) = reader.next_message()? {
            let mat: CsMat = postcard::from_bytes(&message.data)?;
            by_topic
                .entry(message.channel.topic.clone())
                .or_default()
                .push((message.log_time, mat));
        }
        assert_eq!(reader.ending(), &ndds_bag::Ending::Complete);
        assert_eq!(by_topic.keys().collect::<Vec<_>>(), ["pair", "y"]);
        let ys = &by_topic["y"];
        assert_eq!(ys.len(), 20);
        for (k, (log_time, y)) in ys.iter().enumerate() {
            assert_eq!(y.get(0, 0)?, k as f64 / 100.0, "sample {k}");
            // 10 ms apart, from when sampling began.
            assert_eq!(log_time - ys[0].0, k as u64 * 10_000_000);
        }
        // CSMats keep their field names and units.
        let pair = &by_topic["pair"][0].1;
        assert_eq!(pair.row_fields()[1].name, "right");
        assert_eq!(pair.row_fields()[1].unit, "m");
        assert_eq!(pair.get(1, 0)?, 2.0);
        Ok(())
    }

    #[test]
    fn writes_csv_when_sampling_ends() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("run.csv");
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        rt.create_mat(CsMat::from_row_slice("m,x", 1, 2, &[0.5, -1.0])?)?;
        let ramp = Params::new().with("output", "y").with("slope", 2.0);
        rt.install_component("h", "ramp", "ramp", &ramp)?;
        let params = Params::new()
            .with("inputs", vec!["y".to_owned(), "m,x".to_owned()])
            .with("capacity", 3.0)
            .with("file", path.to_str().ok_or("path")?);
        rt.install_component("h", "rec", "recorder", &params)?;
        let h = rt.habitat("h");
        h.start()?;
        steps(&rt, 4)?;
        assert!(!path.exists());
        h.stop();
        let csv = std::fs::read_to_string(&path)?;
        // Names holding a comma are quoted, as CSV requires.
        let expected = "time,\"y[0,0]\",\"m,x[0,0]\",\"m,x[0,1]\"\n\
                        0.01,0.02,0.5,-1\n0.02,0.04,0.5,-1\n0.03,0.06,0.5,-1\n";
        assert_eq!(csv, expected);
        assert_eq!(h.stats().module_errors, 0);
        Ok(())
    }

    #[test]
    fn bad_parameters_and_unwritable_files_are_errors() -> TestResult {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        rt.create_mat(CsMat::zeros("y", 1, 1))?;
        let params = Params::new().with("inputs", vec!["y".to_owned()]);
        let err = refusal(&rt, "recorder", &params.clone().with("capacity", 0.0));
        assert_refuses(&err, "capacity", &["whole number from 1"]);
        let empty = Params::new().with("inputs", Vec::<String>::new());
        assert_refuses(
            &refusal(&rt, "recorder", &empty),
            "inputs",
            &["at least one"],
        );

        let dir = tempfile::tempdir()?;
        let path = dir.path().join("missing").join("run.csv");
        let params = params.with("file", path.to_str().ok_or("path")?);
        rt.install_component("h", "rec", "recorder", &params)?;
        let h = rt.habitat("h");
        h.start()?;
        steps(&rt, 2)?;
        h.stop();
        assert_eq!(h.stats().module_errors, 1, "the failed write is reported");
        Ok(())
    }

    /// A ring larger than 1 GiB is refused when it would be allocated, not attempted.
    #[test]
    fn a_huge_recording_is_refused_not_allocated() -> TestResult {
        let rt = Runtime::new("t");
        crate::register(&rt);
        rt.create_habitat("h", HabitatOptions::rate(100.0).clock(Clock::Manual))?;
        rt.create_mat(CsMat::zeros("wide", 8, 1))?;
        let params = Params::new()
            .with("inputs", vec!["wide".to_owned()])
            .with("capacity", 1e8);
        let recorder = rt.install_component("h", "rec", "recorder", &params);
        assert!(recorder.is_ok(), "{recorder:?}");
        let h = rt.habitat("h");
        h.start()?;
        steps(&rt, 3)?;
        let stats = h.stats();
        assert!(stats.module_errors >= 1, "{stats:?}");
        Ok(())
    }
}
