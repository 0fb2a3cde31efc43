//! Work schedules: the work schedule division of a module body (Shin, 1985, section 6 and
//! CHIP_IT in the appendix).
//!
//! A schedule is a list of steps, each a priority and a sequence of calls. The module's control
//! logic never names a step: it calls [`WorkSchedule::perform`], which runs the calls of the
//! most urgent step not yet done, and [`WorkSchedule::more`], which says how many steps are
//! left; [`WorkSchedule::reinstate`] starts the schedule over. Which chip goes where is then an
//! edit of the schedule, not of the module body.
//!
//! - **Order.** The lowest priority number first. The paper leaves steps of equal number in
//!   arbitrary order; here they go in the order they were declared, so that a run can be
//!   predicted and repeated.
//! - **Return codes.** Each call returns a code: [`DONE`] (0) means it did its work; anything
//!   else stops the step at that call. The step is then *failed*: `perform` passes it over and
//!   `more` no longer counts it, so a module whose feeder ran empty signals its operator and
//!   goes on with the other steps. [`WorkSchedule::retry_failed`] (the operator refilled the
//!   feeder) makes failed steps eligible again, resuming at the call that failed — the calls
//!   before it did their work and are not repeated.
//! - **Text.** [`WorkSchedule::parse`] reads the paper's notation, one step per line:
//!
//! ```text
//! -- CHIP_IT: every chip has the same priority
//! 1) GRASP(1), INSERT(10.5, 20, 3)
//! 1) GRASP(4), INSERT(12, 20, 3);
//! 2) REPORT("card done")
//! ```
//!
//! A call is a name with an optional list of arguments (numbers, names, or quoted text);
//! `--` and `#` start comments; a `;` may end a step. Every problem is reported with its line
//! and column.
//!
//! Nothing here runs a call by itself: `perform` takes the function that does, so the schedule
//! is the same pure state whether it drives a robot, a simulation or a test.

use std::fmt;

/// The return code of a call that did its work.
pub const DONE: i32 = 0;

/// A schedule of steps over calls of type `C` (closures, or [`Call`]s read from text).
#[derive(Clone, Debug, PartialEq)]
pub struct WorkSchedule<C> {
    steps: Vec<Step<C>>,
    states: Vec<StepState>,
}

/// One step: its priority (lowest first) and its calls, run in turn.
#[derive(Clone, Debug, PartialEq)]
pub struct Step<C> {
    /// Lower numbers are performed first.
    pub priority: u32,
    /// The calls, in the order they run.
    pub calls: Vec<C>,
    /// The line it was read from, if it was read from text.
    pub line: Option<usize>,
}

/// Where a step stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepState {
    /// Not yet done: `perform` will run it from call `next`.
    Pending {
        /// The first call not yet done.
        next: usize,
    },
    /// Every call returned [`DONE`].
    Done,
    /// Call `call` returned `code`; passed over until [`WorkSchedule::retry_failed`].
    Failed {
        /// The call that failed (and where a retry resumes).
        call: usize,
        /// What it returned.
        code: i32,
    },
}

/// What one [`WorkSchedule::perform`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Performed {
    /// Step `step` ran to its end.
    Done {
        /// Its index, in declaration order.
        step: usize,
    },
    /// Step `step` stopped at call `call`, which returned `code`.
    Failed {
        /// Its index, in declaration order.
        step: usize,
        /// The call that failed.
        call: usize,
        /// What it returned.
        code: i32,
    },
    /// No step was left to perform.
    Nothing,
}

impl<C> Default for WorkSchedule<C> {
    fn default() -> Self {
        WorkSchedule {
            steps: Vec::new(),
            states: Vec::new(),
        }
    }
}

impl<C> WorkSchedule<C> {
    /// An empty schedule.
    pub fn new() -> Self {
        Self::default()
    }

    /// The schedule with one more step (declared after the others).
    pub fn step(mut self, priority: u32, calls: impl IntoIterator<Item = C>) -> Self {
        self.push(Step {
            priority,
            calls: calls.into_iter().collect(),
            line: None,
        });
        self
    }

    /// Adds a step after the others, pending.
    pub fn push(&mut self, step: Step<C>) {
        self.steps.push(step);
        self.states.push(StepState::Pending { next: 0 });
    }

    /// The steps, in declaration order.
    pub fn steps(&self) -> &[Step<C>] {
        &self.steps
    }

    /// Where step `index` stands (`None` past the last step).
    pub fn state(&self, index: usize) -> Option<StepState> {
        self.states.get(index).copied()
    }

    /// Every step pending again from its first call (the paper's `REINSTATE`).
    pub fn reinstate(&mut self) {
        self.states.fill(StepState::Pending { next: 0 });
    }

    /// How many steps `perform` may still run (the paper's `MORE`): failed ones are not counted.
    pub fn more(&self) -> usize {
        self.states
            .iter()
            .filter(|s| matches!(s, StepState::Pending { .. }))
            .count()
    }

    /// The step `perform` would run next: the pending one with the lowest priority number,
    /// the first declared among equals.
    pub fn next(&self) -> Option<usize> {
        self.states
            .iter()
            .enumerate()
            .filter(|(_, s)| matches!(s, StepState::Pending { .. }))
            .min_by_key(|(index, _)| (self.steps[*index].priority, *index))
            .map(|(index, _)| index)
    }

    /// Runs the calls of the next step with `run`, from its first call not yet done, until one
    /// returns something other than [`DONE`] or the step ends (the paper's `PERFORM`).
    pub fn perform(&mut self, mut run: impl FnMut(&C) -> i32) -> Performed {
        let Some(step) = self.next() else {
            return Performed::Nothing;
        };
        let StepState::Pending { next } = self.states[step] else {
            return Performed::Nothing;
        };
        for (call, c) in self.steps[step].calls.iter().enumerate().skip(next) {
            let code = run(c);
            if code != DONE {
                self.states[step] = StepState::Failed { call, code };
                return Performed::Failed { step, call, code };
            }
            // Done calls are not repeated, even if `run` panics on a later one.
            self.states[step] = StepState::Pending { next: call + 1 };
        }
        self.states[step] = StepState::Done;
        Performed::Done { step }
    }

    /// The failed steps: index, the call that failed and its code.
    pub fn failed(&self) -> impl Iterator<Item = (usize, usize, i32)> + '_ {
        self.states
            .iter()
            .enumerate()
            .filter_map(|(index, state)| match *state {
                StepState::Failed { call, code } => Some((index, call, code)),
                _ => None,
            })
    }

    /// Makes every failed step pending again, resuming at the call that failed; how many.
    pub fn retry_failed(&mut self) -> usize {
        let mut count = 0;
        for state in &mut self.states {
            if let StepState::Failed { call, .. } = *state {
                *state = StepState::Pending { next: call };
                count += 1;
            }
        }
        count
    }
}

/// A call read from a schedule's text: a name and its arguments.
#[derive(Clone, Debug, PartialEq)]
pub struct Call {
    /// What to call, as written.
    pub name: String,
    /// Its arguments.
    pub args: Vec<Arg>,
}

/// An argument of a [`Call`].
#[derive(Clone, Debug, PartialEq)]
pub enum Arg {
    /// A number (`12`, `-0.5`, `1e3`).
    Number(f64),
    /// A name (`X1`, `left_feeder`), for the module to look up.
    Name(String),
    /// Quoted text (`"card done"`), without the quotes.
    Text(String),
}

impl fmt::Display for Arg {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Arg::Number(n) => write!(f, "{n}"),
            Arg::Name(name) => f.write_str(name),
            Arg::Text(text) => {
                f.write_str("\"")?;
                for c in text.chars() {
                    if matches!(c, '"' | '\\') {
                        f.write_str("\\")?;
                    }
                    write!(f, "{c}")?;
                }
                f.write_str("\"")
            }
        }
    }
}

impl fmt::Display for Call {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)?;
        if !self.args.is_empty() {
            f.write_str("(")?;
            for (i, arg) in self.args.iter().enumerate() {
                if i > 0 {
                    f.write_str(", ")?;
                }
                write!(f, "{arg}")?;
            }
            f.write_str(")")?;
        }
        Ok(())
    }
}

impl fmt::Display for WorkSchedule<Call> {
    /// The schedule as text that [`WorkSchedule::parse`] reads back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for step in &self.steps {
            write!(f, "{})", step.priority)?;
            for (i, call) in step.calls.iter().enumerate() {
                f.write_str(if i == 0 { " " } else { ", " })?;
                write!(f, "{call}")?;
            }
            f.write_str("\n")?;
        }
        Ok(())
    }
}

/// A schedule's text that does not read, and where.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("line {line}, column {column}: {what}")]
pub struct ScheduleError {
    /// From 1.
    pub line: usize,
    /// From 1, in characters.
    pub column: usize,
    /// What was expected or found.
    pub what: String,
}

/// Longest schedule text read, in bytes (a schedule is written by hand).
pub const MAX_TEXT: usize = 1 << 20;

impl WorkSchedule<Call> {
    /// Reads a schedule in the paper's notation (see the module's documentation).
    pub fn parse(text: &str) -> Result<Self, ScheduleError> {
        if text.len() > MAX_TEXT {
            return Err(ScheduleError {
                line: 1,
                column: 1,
                what: format!(
                    "{} bytes is more than a schedule may have ({MAX_TEXT})",
                    text.len()
                ),
            });
        }
        let mut schedule = WorkSchedule::new();
        for (index, line) in text.lines().enumerate() {
            let mut cursor = Cursor {
                chars: line.char_indices().peekable(),
                line: index + 1,
                text: line,
            };
            cursor.skip_space();
            if cursor.at_end() {
                continue;
            }
            let priority = cursor.priority()?;
            cursor.expect(')')?;
            let mut calls = vec![cursor.call()?];
            loop {
                cursor.skip_space();
                match cursor.peek() {
                    None => break,
                    Some(',') => {
                        cursor.bump();
                        calls.push(cursor.call()?);
                    }
                    Some(';') => {
                        cursor.bump();
                        cursor.skip_space();
                        if !cursor.at_end() {
                            return Err(cursor.error("nothing after `;` but a comment"));
                        }
                        break;
                    }
                    Some(other) => {
                        return Err(cursor.error(&format!(
                            "expected `,` or the end of the step, found `{other}`"
                        )));
                    }
                }
            }
            schedule.push(Step {
                priority,
                calls,
                line: Some(index + 1),
            });
        }
        Ok(schedule)
    }
}

/// Reads one line of a schedule.
struct Cursor<'a> {
    chars: std::iter::Peekable<std::str::CharIndices<'a>>,
    line: usize,
    text: &'a str,
}

impl Cursor<'_> {
    fn peek(&mut self) -> Option<char> {
        self.chars.peek().map(|(_, c)| *c)
    }

    fn bump(&mut self) -> Option<char> {
        self.chars.next().map(|(_, c)| c)
    }

    /// Skips blanks; a comment (`--` or `#`) ends the line.
    fn skip_space(&mut self) {
        while let Some(c) = self.peek() {
            if c.is_whitespace() {
                self.bump();
            } else if c == '#' || self.rest().starts_with("--") {
                while self.bump().is_some() {}
            } else {
                break;
            }
        }
    }

    fn rest(&mut self) -> &str {
        match self.chars.peek() {
            Some((at, _)) => &self.text[*at..],
            None => "",
        }
    }

    fn at_end(&mut self) -> bool {
        self.peek().is_none()
    }

    fn column(&mut self) -> usize {
        let at = self.chars.peek().map_or(self.text.len(), |(at, _)| *at);
        self.text[..at].chars().count() + 1
    }

    fn error(&mut self, what: &str) -> ScheduleError {
        ScheduleError {
            line: self.line,
            column: self.column(),
            what: what.to_string(),
        }
    }

    fn found(&mut self) -> String {
        match self.peek() {
            Some(c) => format!("`{c}`"),
            None => "the end of the line".into(),
        }
    }

    fn expect(&mut self, wanted: char) -> Result<(), ScheduleError> {
        self.skip_space();
        if self.peek() == Some(wanted) {
            self.bump();
            Ok(())
        } else {
            let found = self.found();
            Err(self.error(&format!("expected `{wanted}`, found {found}")))
        }
    }

    fn priority(&mut self) -> Result<u32, ScheduleError> {
        let column = self.column();
        let mut digits = String::new();
        while let Some(c) = self.peek().filter(char::is_ascii_digit) {
            digits.push(c);
            self.bump();
        }
        if digits.is_empty() {
            let found = self.found();
            return Err(self.error(&format!(
                "a step starts with its priority, as in `1)`; found {found}"
            )));
        }
        digits.parse().map_err(|_| ScheduleError {
            line: self.line,
            column,
            what: format!("priority {digits} is larger than {}", u32::MAX),
        })
    }

    fn word(&mut self) -> String {
        let mut word = String::new();
        while let Some(c) = self
            .peek()
            .filter(|c| c.is_alphanumeric() || matches!(c, '_' | '.' | '-' | '+'))
        {
            // `--` starts a comment, even right after a word.
            if c == '-' && self.rest().starts_with("--") {
                break;
            }
            word.push(c);
            self.bump();
        }
        word
    }

    fn call(&mut self) -> Result<Call, ScheduleError> {
        self.skip_space();
        if !self.peek().is_some_and(|c| c.is_alphabetic() || c == '_') {
            let found = self.found();
            return Err(self.error(&format!("expected a call, found {found}")));
        }
        let name = self.word();
        let mut args = Vec::new();
        self.skip_space();
        if self.peek() == Some('(') {
            self.bump();
            self.skip_space();
            if self.peek() == Some(')') {
                self.bump();
            } else {
                loop {
                    args.push(self.arg()?);
                    self.skip_space();
                    match self.bump() {
                        Some(',') => {}
                        Some(')') => break,
                        Some(other) => {
                            return Err(ScheduleError {
                                what: format!("expected `,` or `)`, found `{other}`"),
                                ..self.error_before()
                            });
                        }
                        None => {
                            return Err(self.error(&format!("`(` of `{name}` is not closed")));
                        }
                    }
                }
            }
        }
        Ok(Call { name, args })
    }

    /// An error at the character just consumed.
    fn error_before(&mut self) -> ScheduleError {
        let column = self.column().saturating_sub(1).max(1);
        ScheduleError {
            line: self.line,
            column,
            what: String::new(),
        }
    }

    fn arg(&mut self) -> Result<Arg, ScheduleError> {
        self.skip_space();
        match self.peek() {
            Some('"') => {
                let start = self.error("");
                self.bump();
                let mut text = String::new();
                loop {
                    match self.bump() {
                        Some('"') => return Ok(Arg::Text(text)),
                        Some('\\') => match self.bump() {
                            Some(c) => text.push(c),
                            None => break,
                        },
                        Some(c) => text.push(c),
                        None => break,
                    }
                }
                Err(ScheduleError {
                    what: "quoted text is not closed".into(),
                    ..start
                })
            }
            Some(c) if c.is_ascii_digit() || matches!(c, '-' | '+' | '.') => {
                let column = self.column();
                let word = self.word();
                word.parse::<f64>()
                    .ok()
                    .filter(|n| n.is_finite())
                    .map(Arg::Number)
                    .ok_or(ScheduleError {
                        line: self.line,
                        column,
                        what: format!("`{word}` is not a number"),
                    })
            }
            Some(c) if c.is_alphabetic() || c == '_' => Ok(Arg::Name(self.word())),
            _ => {
                let found = self.found();
                Err(self.error(&format!("expected an argument, found {found}")))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CHIP_IT: &str = "\
-- CHIP_IT's schedule: every chip the same priority
1) GRASP(1), INSERT(10.5, 20, 3)
1) GRASP(4), INSERT(X1, Y1, Z1);   -- another chip

2) REPORT(\"card done\")
";

    fn name(call: &Call) -> String {
        call.to_string()
    }

    #[test]
    fn the_lowest_number_goes_first_and_equal_numbers_in_declaration_order() {
        let mut schedule = WorkSchedule::new()
            .step(2, ["c"])
            .step(1, ["a"])
            .step(3, ["d"])
            .step(1, ["b"]);
        let mut ran = Vec::new();
        assert_eq!(schedule.more(), 4);
        while schedule.more() > 0 {
            let done = schedule.perform(|c| {
                ran.push(*c);
                DONE
            });
            assert!(matches!(done, Performed::Done { .. }));
        }
        assert_eq!(ran, ["a", "b", "c", "d"]);
        assert_eq!(schedule.perform(|_| DONE), Performed::Nothing);
        // REINSTATE: all of it again.
        schedule.reinstate();
        assert_eq!(schedule.more(), 4);
        assert_eq!(schedule.next(), Some(1));
    }

    #[test]
    fn an_empty_feeder_fails_its_step_and_the_others_go_on() {
        // Chip steps grasp from a feeder, then insert; feeder 4 is empty.
        let mut schedule = WorkSchedule::new()
            .step(1, [("grasp", 1), ("insert", 1)])
            .step(1, [("grasp", 4), ("insert", 4)])
            .step(1, [("grasp", 7), ("insert", 7)]);
        let mut feeders = std::collections::HashMap::from([(1, 1), (4, 0), (7, 1)]);
        let mut inserted = Vec::new();
        let mut signalled = Vec::new();
        fn run(
            feeders: &mut std::collections::HashMap<i32, i32>,
            inserted: &mut Vec<i32>,
            (what, feeder): &(&str, i32),
        ) -> i32 {
            match *what {
                "grasp" => {
                    let left = feeders.get_mut(feeder).unwrap();
                    if *left == 0 {
                        return 17; // empty
                    }
                    *left -= 1;
                }
                _ => inserted.push(*feeder),
            }
            DONE
        }
        while schedule.more() > 0 {
            if let Performed::Failed { step, call, code } =
                schedule.perform(|c| run(&mut feeders, &mut inserted, c))
            {
                signalled.push((step, call, code));
            }
        }
        assert_eq!(inserted, [1, 7]);
        assert_eq!(signalled, [(1, 0, 17)]);
        assert_eq!(schedule.failed().collect::<Vec<_>>(), [(1, 0, 17)]);
        assert_eq!(
            schedule.state(1),
            Some(StepState::Failed { call: 0, code: 17 })
        );
        // The operator refills feeder 4: the failed step is retried and completes.
        feeders.insert(4, 2);
        assert_eq!(schedule.retry_failed(), 1);
        assert_eq!(schedule.more(), 1);
        assert_eq!(
            schedule.perform(|c| run(&mut feeders, &mut inserted, c)),
            Performed::Done { step: 1 }
        );
        assert_eq!(inserted, [1, 7, 4]);
        assert_eq!(schedule.more(), 0);
    }

    #[test]
    fn a_retried_step_resumes_at_the_call_that_failed() {
        let mut schedule = WorkSchedule::new().step(1, ["grasp", "insert", "check"]);
        let mut ran = Vec::new();
        let failed = schedule.perform(|c| {
            ran.push(*c);
            if *c == "insert" { 3 } else { DONE }
        });
        assert_eq!(
            failed,
            Performed::Failed {
                step: 0,
                call: 1,
                code: 3
            }
        );
        assert_eq!(schedule.more(), 0, "a failed step is not counted");
        assert_eq!(schedule.perform(|_| DONE), Performed::Nothing);
        schedule.retry_failed();
        assert_eq!(schedule.state(0), Some(StepState::Pending { next: 1 }));
        schedule.perform(|c| {
            ran.push(*c);
            DONE
        });
        // The grasp is not repeated.
        assert_eq!(ran, ["grasp", "insert", "insert", "check"]);
        assert_eq!(schedule.state(0), Some(StepState::Done));
    }

    #[test]
    fn the_papers_notation_reads_and_writes_back() {
        let schedule = WorkSchedule::parse(CHIP_IT).unwrap();
        let steps = schedule.steps();
        assert_eq!(steps.len(), 3);
        assert_eq!(
            (steps[0].priority, steps[0].line, &steps[0].calls),
            (
                1,
                Some(2),
                &vec![
                    Call {
                        name: "GRASP".into(),
                        args: vec![Arg::Number(1.0)]
                    },
                    Call {
                        name: "INSERT".into(),
                        args: vec![Arg::Number(10.5), Arg::Number(20.0), Arg::Number(3.0)]
                    }
                ]
            )
        );
        assert_eq!(
            steps[1].calls[1].args,
            [
                Arg::Name("X1".into()),
                Arg::Name("Y1".into()),
                Arg::Name("Z1".into())
            ]
        );
        assert_eq!(
            (steps[2].priority, steps[2].line),
            (2, Some(5)),
            "blank and comment lines are skipped"
        );
        assert_eq!(steps[2].calls[0].args, [Arg::Text("card done".into())]);
        let text = schedule.to_string();
        assert_eq!(
            text,
            "1) GRASP(1), INSERT(10.5, 20, 3)\n1) GRASP(4), INSERT(X1, Y1, Z1)\n2) REPORT(\"card done\")\n"
        );
        let again = WorkSchedule::parse(&text).unwrap();
        assert_eq!(
            again.steps().iter().map(|s| &s.calls).collect::<Vec<_>>(),
            steps.iter().map(|s| &s.calls).collect::<Vec<_>>()
        );
        // Calls without arguments, with or without parentheses; negative numbers.
        let bare = WorkSchedule::parse("3) home, wait(), move(-1.5, +2e1)").unwrap();
        assert_eq!(
            bare.steps()[0].calls.iter().map(name).collect::<Vec<_>>(),
            ["home", "wait", "move(-1.5, 20)"]
        );
    }

    #[test]
    fn every_mistake_is_named_with_its_line_and_column() {
        let cases: &[(&str, (usize, usize), &str)] = &[
            ("GRASP(1)", (1, 1), "starts with its priority"),
            ("1 GRASP(1)", (1, 3), "expected `)`, found `G`"),
            ("\n1) GRASP(1", (2, 11), "`(` of `GRASP` is not closed"),
            ("1) GRASP(1 2)", (1, 12), "expected `,` or `)`, found `2`"),
            (
                "1) GRASP(1),",
                (1, 13),
                "expected a call, found the end of the line",
            ),
            (
                "1) GRASP(1) INSERT",
                (1, 13),
                "expected `,` or the end of the step",
            ),
            ("1) GRASP(1); INSERT", (1, 14), "nothing after `;`"),
            ("1) MOVE(1.2.3)", (1, 9), "`1.2.3` is not a number"),
            ("1) SAY(\"hi)", (1, 8), "quoted text is not closed"),
            ("1) GRASP(,)", (1, 10), "expected an argument, found `,`"),
            ("99999999999) GRASP", (1, 1), "larger than"),
            ("1) 5", (1, 4), "expected a call, found `5`"),
        ];
        for (text, (line, column), what) in cases {
            let err = WorkSchedule::parse(text).unwrap_err();
            assert_eq!((err.line, err.column), (*line, *column), "{text}: {err}");
            assert!(err.what.contains(what), "{text}: {err}");
        }
        let huge = "1) a\n".repeat(MAX_TEXT / 4);
        assert!(
            WorkSchedule::parse(&huge)
                .unwrap_err()
                .what
                .contains("more than")
        );
    }

    fn arg() -> impl proptest::strategy::Strategy<Value = Arg> {
        use proptest::prelude::*;
        prop_oneof![
            (-1e9f64..1e9).prop_map(Arg::Number),
            "[A-Za-z_][A-Za-z0-9_]{0,8}".prop_map(Arg::Name),
            any::<String>()
                .prop_filter("one line", |t| !t.contains(['\n', '\r']))
                .prop_map(Arg::Text),
        ]
    }

    proptest::proptest! {
        #[test]
        fn any_schedule_written_as_text_reads_back(
            steps in proptest::collection::vec(
                (0u32..1000, proptest::collection::vec(
                    ("[A-Za-z_][A-Za-z0-9_]{0,8}", proptest::collection::vec(arg(), 0..4)),
                    1..4,
                )),
                0..6,
            )
        ) {
            let mut schedule = WorkSchedule::new();
            for (priority, calls) in steps {
                schedule = schedule.step(
                    priority,
                    calls.into_iter().map(|(name, args)| Call { name, args }),
                );
            }
            let again = WorkSchedule::parse(&schedule.to_string()).unwrap();
            let calls = |s: &WorkSchedule<Call>| {
                s.steps().iter().map(|s| (s.priority, s.calls.clone())).collect::<Vec<_>>()
            };
            proptest::prop_assert_eq!(calls(&again), calls(&schedule));
        }

        #[test]
        fn no_text_panics_the_reader(text in "\\PC{0,200}") {
            let _ = WorkSchedule::parse(&text);
        }
    }

    #[test]
    fn a_panicking_call_leaves_the_calls_before_it_done() {
        let mut schedule = WorkSchedule::new().step(1, [1, 2, 3]);
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            schedule.perform(|c| if *c == 2 { panic!("robot fault") } else { DONE })
        }));
        assert!(caught.is_err());
        assert_eq!(schedule.state(0), Some(StepState::Pending { next: 1 }));
    }
}
